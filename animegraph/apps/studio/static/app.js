// The studio's page: tabs over the JSON API (animegraph.apps.studio.api), the face beside them.
// window.studio exposes the state the tests and scripts/bench_studio.py read.

import { barChart, histogram } from "./charts.js";
import { FaceView, Player, unpack } from "./face.js";

const $ = (sel) => document.querySelector(sel);
const CLIP_ROWS = 500; // rows the clip table asks for
const state = { ready: false, face: null, lastPlay: null, clipsLoaded: 0 };
window.studio = state;

// Every API error is JSON {"error": "..."}: thrown as an Error with that line.
async function api(path, options = {}) {
  const response = await fetch(path, { credentials: "same-origin", ...options });
  if (!response.ok) {
    let message = `${response.status} ${response.statusText}`;
    try { message = (await response.json()).error || message; } catch (e) { /* not JSON */ }
    throw new Error(message);
  }
  return response;
}

function showTab(name) {
  document.querySelectorAll("nav button").forEach((b) => b.classList.toggle("active", b.dataset.tab === name));
  document.querySelectorAll(".panel").forEach((p) => p.classList.toggle("active", p.id === `tab-${name}`));
}

function fillTable(table, data, onRow, onHover, extra) {
  const head = document.createElement("thead");
  const tr = document.createElement("tr");
  for (const c of data.columns) { const th = document.createElement("th"); th.textContent = c; tr.append(th); }
  if (extra) tr.append(document.createElement("th"));
  head.append(tr);
  const body = document.createElement("tbody");
  for (const row of data.rows) {
    const r = document.createElement("tr");
    for (const cell of row) {
      const td = document.createElement("td");
      td.textContent = cell === null ? "" : typeof cell === "object" ? JSON.stringify(cell) : String(cell);
      r.append(td);
    }
    if (extra) { const td = document.createElement("td"); td.append(extra(row, r)); r.append(td); }
    if (onRow) r.addEventListener("click", () => onRow(row, r));
    if (onHover) r.addEventListener("pointerenter", () => onHover(row));
    body.append(r);
  }
  table.replaceChildren(head, body);
}

function overview(info) {
  $("#db-name").textContent = `${info.path} (${info.version})`;
  const rows = [
    ["motion", `${info.kind}, ${info.n_channels} channels at ${info.fps} fps`],
    ["clips", `${info.n_clips}; ${(info.duration_s / 60).toFixed(1)} min, ${info.n_frames} frames`],
    ["corpora", info.corpora.join(", ")],
    ["speakers", info.speakers.join(", ") || "(not given)"],
    ["animes", `${info.n_animes}; ${Object.keys(info.phones).length} phones` +
      (info.phones_missing.length ? `, missing ${info.phones_missing.join(" ")}` : "")],
    ["segmented", Object.entries(info.segmentation).map(([k, v]) => `${k} ${v}`).join(", ")],
    ["model", `${info.n_pcs} components keep ${(100 * info.variance_kept).toFixed(1)} % of the variance`],
    ["emotion model", info.emotion ? `${info.emotion.mappings.length} mappings; classifier ` +
      (info.emotion.classifier ? info.emotion.classifier.classes.join(", ") : "none") : "none"],
    ["baselines", info.baselines.map((b) => b.method).join(", ") || "none fitted"],
  ];
  const dl = $("#summary");
  dl.replaceChildren();
  for (const [k, v] of rows) {
    const dt = document.createElement("dt"); dt.textContent = k;
    const dd = document.createElement("dd"); dd.textContent = v;
    dl.append(dt, dd);
  }
  barChart($("#chart-emotions"), Object.entries(info.clips_per_emotion), { title: "clips per emotion" });
  histogram($("#chart-durations"), info.clip_durations, { title: "clip durations" });
  barChart($("#chart-phones"), Object.entries(info.phones), { title: "animes per phone" });
  for (const name of ["emotion", "speaker"]) {
    const select = $(`#clip-filters [name=${name}]`);
    const values = name === "emotion" ? Object.keys(info.clips_per_emotion) : info.speakers;
    for (const v of values) select.append(new Option(v, v));
  }
  for (const e of Object.keys(info.clips_per_emotion)) $("#emotion-list").append(new Option(e, e));
}

// A clip's face, asked for when the pointer comes onto its row: the server deforms it
// while the hand moves to click. The last few are kept.
const faces = new Map();
state.faces = faces;

function clipQuery(row, columns) {
  return new URLSearchParams({ corpus: row[columns.indexOf("corpus")],
                               clip_id: row[columns.indexOf("clip_id")] }).toString();
}

function clipFace(query) {
  if (!faces.has(query)) {
    const promise = api(`api/clip/face?${query}`).then((r) => r.arrayBuffer()).then(unpack);
    promise.catch(() => faces.delete(query));
    faces.set(query, promise);
    if (faces.size > 8) faces.delete(faces.keys().next().value);
  }
  return faces.get(query);
}

// Play a clip in view `slot` (0; 1 is the side-by-side view, started with the first
// from the beginning, on one clock).
async function playClip(row, tr, columns, slot = 0) {
  const clicked = performance.now();
  if (slot === 0) {
    document.querySelectorAll("#clip-table tr.playing").forEach((r) => r.classList.remove("playing"));
    tr.classList.add("playing");
  }
  const query = clipQuery(row, columns);
  const clipId = row[columns.indexOf("clip_id")];
  const anim = await clipFace(query);
  state.lastPlay = { clicked, fetched: performance.now(), started: null, clip: clipId, slot };
  state.face.onPlayStarted = (t) => { state.lastPlay.started = t; };
  const emotion = row[columns.indexOf("emotion")];
  state.face.show(slot, anim, `api/clip/audio?${query}`, `${slot ? "B: " : ""}${clipId} (${emotion})`);
}

async function searchClips(event) {
  if (event) event.preventDefault();
  const form = new FormData($("#clip-filters"));
  const query = new URLSearchParams([...form].filter(([, v]) => v !== ""));
  query.set("limit", String(CLIP_ROWS));
  const status = $("#clip-status");
  status.className = "status";
  try {
    const data = await (await api(`api/clips?${query}`)).json();
    const compare = (row, tr) => {
      const button = document.createElement("button");
      button.type = "button";
      button.className = "compare-b";
      button.textContent = "B";
      button.title = "play beside the clip in the first view (side by side, in step)";
      button.addEventListener("click", (e) => {
        e.stopPropagation();
        playClip(row, tr, data.columns, 1).catch(showFaceError);
      });
      return button;
    };
    fillTable($("#clip-table"), data, (row, tr) => playClip(row, tr, data.columns).catch(showFaceError),
              (row) => clipFace(clipQuery(row, data.columns)).catch(() => {}), compare);
    const n = data.rows.length;
    status.textContent = n >= CLIP_ROWS ? `the first ${n} clips (narrow the filters to see others)`
      : `${n} clip${n === 1 ? "" : "s"}`;
    state.clipsLoaded += 1;
  } catch (e) {
    $("#clip-table").replaceChildren();
    status.className = "error";
    status.textContent = e.message;
  }
}

function showFaceError(e) {
  document.querySelector("#view-a [data-role=title]").textContent = `error: ${e.message}`;
}

async function runSql(event) {
  if (event) event.preventDefault();
  const sql = $("#sql-form [name=sql]").value;
  const error = $("#sql-error");
  const out = $("#sql-results");
  error.hidden = true;
  try {
    const data = await (await api("api/sql", { method: "POST", headers: { "Content-Type": "application/json" },
                                              body: JSON.stringify({ sql }) })).json();
    out.replaceChildren();
    for (const s of data.statements) {
      const note = document.createElement("p");
      note.className = "status";
      note.textContent = `${s.rows.length} row${s.rows.length === 1 ? "" : "s"}${s.truncated ? " (first rows only)" : ""}`;
      const wrap = document.createElement("div");
      wrap.className = "table-wrap";
      const table = document.createElement("table");
      table.className = "sql-table";
      fillTable(table, s);
      wrap.append(table);
      out.append(note, wrap);
    }
  } catch (e) {
    out.replaceChildren();
    error.textContent = e.message;
    error.hidden = false;
  }
}

async function exportCsv() {
  const body = new URLSearchParams({ sql: $("#sql-form [name=sql]").value });
  try {
    const blob = await (await api("api/sql.csv", { method: "POST", body })).blob();
    const a = document.createElement("a");
    a.href = URL.createObjectURL(blob);
    a.download = "query.csv";
    a.click();
    setTimeout(() => URL.revokeObjectURL(a.href), 10000);
  } catch (e) {
    $("#sql-error").textContent = e.message;
    $("#sql-error").hidden = false;
  }
}

// The browser's microphone (MediaRecorder): what it records is sent instead of a file.
let recorder = null;
let recorded = null;

async function toggleRecording() {
  const button = $("#record"), status = $("#record-status");
  if (recorder) { recorder.stop(); return; }
  try {
    const stream = await navigator.mediaDevices.getUserMedia({ audio: true });
    const chunks = [];
    recorder = new MediaRecorder(stream);
    const began = performance.now();
    recorder.ondataavailable = (e) => chunks.push(e.data);
    recorder.onstop = () => {
      stream.getTracks().forEach((t) => t.stop());
      recorded = new Blob(chunks, { type: recorder.mimeType });
      status.textContent = `recorded ${((performance.now() - began) / 1000).toFixed(1)} s`;
      button.textContent = "Record again";
      recorder = null;
    };
    recorder.start();
    button.textContent = "Stop";
    status.textContent = "recording ...";
  } catch (e) {
    recorder = null;
    status.textContent = `no microphone: ${e.message}`;
  }
}

async function synthesize(event) {
  event.preventDefault();
  const form = $("#synth-form");
  const body = new FormData(form);
  if (recorded) body.set("audio", recorded, "recording.webm");
  const status = $("#synth-status"), error = $("#synth-error"), files = $("#synth-files");
  error.hidden = true;
  files.replaceChildren();
  status.textContent = "synthesizing ...";
  const button = form.querySelector("button");
  button.disabled = true;
  try {
    const made = await (await api("api/synth", { method: "POST", body })).json();
    const base = `api/outputs/${made.id}`;
    const anim = unpack(await (await api(`${base}/face`)).arrayBuffer());
    const h = anim.header;
    status.textContent = `done: ${h.phones.length} phones (${h.segmentation}), ${h.method}` +
      (h.emotion ? `, emotion ${h.emotion}` : "") + (h.warnings.length ? `; warnings: ${h.warnings.join("; ")}` : "");
    for (const name of made.files) {
      const li = document.createElement("li");
      const a = document.createElement("a");
      a.href = `${base}/files/${encodeURIComponent(name)}`;
      a.textContent = name;
      a.download = name;
      li.append(a);
      files.append(li);
    }
    // Beside it, the recorded clip nearest by the search: the one it took most phones from.
    const near = h.nearest;
    let nearAnim = null;
    if (near) {
      const query = new URLSearchParams({ corpus: near.corpus, clip_id: near.clip_id }).toString();
      nearAnim = await clipFace(query).catch(() => null);
      if (nearAnim) {
        state.face.show(1, nearAnim, `api/clip/audio?${query}`, `B: nearest recorded clip ` +
          `${near.clip_id} (${near.emotion}; ${near.phones_from_it} of ${near.phones} phones from it)`, false);
      }
    }
    state.lastPlay = { clicked: performance.now(), started: null, clip: made.id };
    state.face.onPlayStarted = (t) => { state.lastPlay.started = t; };
    state.face.show(0, anim, `${base}/files/speech.wav?inline=1`, "synthesized line");
    state.synthesized = made.id;
    state.nearest = nearAnim ? near : null;
  } catch (e) {
    status.textContent = "";
    error.textContent = e.message;
    error.hidden = false;
  } finally {
    button.disabled = false;
  }
}

// The user's own head, read from the chosen file in the page (it never goes to the server).
async function loadHead() {
  const file = $("#head-file").files[0];
  const status = $("#head-status");
  if (!file) return;
  status.className = "hint";
  try {
    const buffer = await file.arrayBuffer();
    let head = null;
    for (const v of state.face.views) head = await v.loadHead(buffer.slice(0));
    state.headBuffer = buffer;
    status.textContent = `${file.name}: ${head.matched} ARKit morph targets`;
    $("#head-drop").hidden = false;
    state.head = { name: file.name, matched: head.matched };
  } catch (e) {
    status.className = "error";
    status.textContent = e.message;
  }
}

// The live tab: the studio relays `animegraph live --websocket PORT` as face frames.
let liveSocket = null;

function connectLive(event) {
  event.preventDefault();
  if (liveSocket) liveSocket.close();
  const port = new FormData($("#live-form")).get("port");
  const status = $("#live-status");
  const scheme = location.protocol === "https:" ? "wss" : "ws";
  const socket = new WebSocket(`${scheme}://${location.host}/api/live?port=${encodeURIComponent(port)}`);
  socket.binaryType = "arraybuffer";
  liveSocket = socket;
  state.live = { frames: 0, status: "connecting", ended: false };
  status.className = "status";
  status.textContent = "connecting ...";
  $("#live-stop").disabled = false;
  socket.onmessage = (message) => {
    if (typeof message.data === "string") {
      const data = JSON.parse(message.data);
      status.className = data.type === "error" ? "error" : "status";
      status.textContent = data.text;
      state.live.status = data.type;
      return;
    }
    state.face.showLive(unpack(message.data));
    state.live.frames += 1;
  };
  socket.onclose = () => {
    state.live.ended = true;
    if (liveSocket === socket) { liveSocket = null; $("#live-stop").disabled = true; }
  };
}

async function main() {
  document.querySelectorAll("nav button").forEach((b) => b.addEventListener("click", () => showTab(b.dataset.tab)));
  $("#clip-filters").addEventListener("submit", searchClips);
  $("#sql-form").addEventListener("submit", runSql);
  $("#sql-form [name=sql]").addEventListener("keydown", (e) => {
    if (e.key === "Enter" && (e.ctrlKey || e.metaKey)) runSql(e);
  });
  $("#sql-csv").addEventListener("click", exportCsv);
  $("#synth-form").addEventListener("submit", synthesize);
  $("#live-form").addEventListener("submit", connectLive);
  $("#live-stop").addEventListener("click", () => { if (liveSocket) liveSocket.close(); });
  $("#record").addEventListener("click", toggleRecording);
  // A file chosen after a recording is what is sent.
  $("#synth-form [name=audio]").addEventListener("change", () => { recorded = null; });
  // The three answers are asked for at once; the clip table fills while the face is built.
  const clipsShown = searchClips();
  const meshLoaded = api("api/mesh").then((r) => r.json()).then(async (mesh) => {
    // An iPhone database's clips are ARKit weights: the page morphs the mesh by its shapes.
    const shapes = mesh.arkit ? new Float32Array(await (await api("api/mesh/arkit")).arrayBuffer())
      : null;
    return { mesh, shapes };
  }).catch((e) => ({ error: e.message }));
  const [info, face] = await Promise.all([api("api/overview").then((r) => r.json()), meshLoaded]);
  overview(info);
  if (face.error) showFaceError(new Error(face.error));
  else {
    const view = (id) => new FaceView($(id), face.mesh, face.shapes);
    state.face = new Player($("#controls"), view("#view-a"), () => {
      const second = view("#view-b"); // made on first use: it wears the head chosen before
      if (state.headBuffer) second.loadHead(state.headBuffer.slice(0)).catch(showFaceError);
      return second;
    });
    $("#compare-close").addEventListener("click", () => { state.face.pause(); state.face.setCompare(false); });
    $("#head-file").addEventListener("change", loadHead);
    $("#head-drop").addEventListener("click", () => {
      state.face.views.forEach((v) => v.dropHead());
      state.headBuffer = null;
      $("#head-drop").hidden = true;
      $("#head-status").textContent = "";
      $("#head-file").value = "";
    });
  }
  await clipsShown;
  state.readyAt = performance.now(); // ms since navigation began (scripts/bench_studio.py)
  state.ready = true;
  document.body.dataset.ready = "1";
}

main().catch((e) => {
  state.error = e.message;
  document.body.dataset.ready = "error";
  const p = document.createElement("p");
  p.className = "error";
  p.textContent = `the studio could not start: ${e.message}`;
  document.body.prepend(p);
});
