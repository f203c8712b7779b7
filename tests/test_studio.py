"""``animegraph studio``: the server over plain HTTP, and the page in a real browser
(Debian's chromium driven by Playwright; skipped with the reason where it is absent)."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np
import pytest

CHROMIUM = Path("/usr/bin/chromium")
#: Longest wait for the server or the page (a bound on a hang, not a measurement).
BOUND_S = 180.0
#: Chromium's switches: headless, no sandbox (root in a container), no network of its own;
#: WebGL through SwiftShader (software), as a machine without a GPU has it.
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                 "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--use-gl=swiftshader",
                 "--enable-unsafe-swiftshader", "--autoplay-policy=no-user-gesture-required"]


class Studio:
    """A running ``animegraph studio`` process and its URL (``browser``: the
    ``$BROWSER`` it opens, else none)."""

    def __init__(self, db: Path, tmp: Path, browser: str | None = None):
        env = {**os.environ, "PYTHONUNBUFFERED": "1",
               "PYTHONPATH": os.pathsep.join([str(Path(__file__).resolve().parents[1]),
                                              os.environ.get("PYTHONPATH", "")])}
        if browser is not None:
            env["BROWSER"] = browser
        self.log = tmp / "studio.log"
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "animegraph", "studio", "--db", str(db), "--port", "0",
             *(["--no-browser"] if browser is None else [])], stdout=self.log.open("w"),
            stderr=subprocess.STDOUT, env=env, start_new_session=True)
        deadline = time.monotonic() + BOUND_S
        while not (found := re.search(r"http://127\.0\.0\.1:\d+/\?token=\S+",
                                      self.log.read_text())):
            if self.proc.poll() is not None or time.monotonic() > deadline:
                self.stop()
                pytest.fail(f"the studio did not start: {self.log.read_text()}")
            time.sleep(0.1)
        self.url = found.group(0)
        self.base, self.token = self.url.split("/?token=")

    def get(self, path: str, *, token: bool = True, data: bytes | None = None,
            headers: dict | None = None) -> tuple[int, bytes, dict]:
        sep = "&" if "?" in path else "?"
        url = self.base + path + (f"{sep}token={self.token}" if token else "")
        request = urllib.request.Request(url, data=data, headers=headers or {})
        try:
            with urllib.request.urlopen(request, timeout=BOUND_S) as response:
                return response.status, response.read(), dict(response.headers)
        except urllib.error.HTTPError as exc:
            return exc.code, exc.read(), dict(exc.headers)

    def stop(self) -> int:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=BOUND_S)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        return self.proc.returncode


def unpack(body: bytes) -> tuple[dict, dict]:
    """The page's binary animation message: its header and its float32 blocks by name."""
    length = int.from_bytes(body[:4], "little")
    header = json.loads(body[4:4 + length])
    blocks, offset = {}, 4 + length
    for name, shape in header["blocks"]:
        size = int(np.prod(shape))
        blocks[name] = np.frombuffer(body, dtype="<f4", count=size, offset=offset).reshape(shape)
        offset += 4 * size
    assert offset == len(body)
    return header, blocks


@pytest.fixture(scope="module")
def studio(tiny_db, tmp_path_factory):
    server = Studio(tiny_db[0], tmp_path_factory.mktemp("studio"))
    yield server
    assert server.stop() == 0
    assert "studio stopped" in server.log.read_text()


def test_no_token_is_refused(studio):
    for path in ("/", "/api/overview", "/static/app.js", "/no/such/page"):
        status, body, _ = studio.get(path, token=False)
        assert status == 403, path
    status, body, _ = studio.get("/api/overview?token=wrong", token=False)
    assert status == 403
    assert "token" in json.loads(body)["error"]
    status, body, headers = studio.get("/")
    assert status == 200 and b"animegraph studio" in body
    assert "animegraph_studio_token" in headers.get("Set-Cookie", "")
    assert "HttpOnly" in headers["Set-Cookie"]
    policy = headers["Content-Security-Policy"]
    assert "default-src 'self'" in policy and "frame-ancestors 'none'" in policy
    assert re.search(r"script-src 'self' 'sha256-[A-Za-z0-9+/=]{44}'", policy)
    assert headers["X-Frame-Options"] == "DENY" and headers["Referrer-Policy"] == "no-referrer"


def test_api_answers_and_refuses_in_one_line(studio, tiny_db):
    status, body, _ = studio.get("/api/overview")
    info = json.loads(body)
    assert status == 200 and info["n_clips"] == 34 and len(info["clip_durations"]) == 34
    status, body, _ = studio.get("/api/clips?emotion=happy&limit=500")
    rows = json.loads(body)
    assert status == 200 and rows["rows"]
    assert {r[rows["columns"].index("emotion")] for r in rows["rows"]} == {"happy"}
    status, body, _ = studio.get("/api/clips?phoneme=QQ")
    assert status == 400 and "not an ARPAbet phone" in json.loads(body)["error"]
    status, body, _ = studio.get("/api/sql", data=json.dumps(
        {"sql": "COPY clips TO '/tmp/x.csv'"}).encode(),
        headers={"Content-Type": "application/json"})
    assert status == 400 and "only SELECT" in json.loads(body)["error"]
    # No path reaches the file system: the page's files are a fixed list.
    for path in ("/static/../server.py", "/static/%2e%2e/server.py", "/static/face.py",
                 "/api/outputs/abc/files/..%2f..%2fetc%2fpasswd"):
        status, _, _ = studio.get(path)
        assert status in (400, 404), path
    status, body, _ = studio.get("/api/clip/face?corpus=x&clip_id=y")
    assert status == 400 and "not in the database" in json.loads(body)["error"]
    status, body, _ = studio.get("/no/such/page")
    assert status == 404 and b"<h1>404</h1>" in body


def test_clip_face_is_render_s_deformation(studio, tiny_db):
    """The vertices the page gets are ``animate``'s, at the page's frame rate."""
    from animegraph.apps.query import load_clip
    from animegraph.apps.studio.face import PAGE_FPS
    from animegraph.face.animation import animate
    from animegraph.face.render import deformer_for
    from animegraph.motion.files import Motion
    from db.store import Database

    db = Database.open(tiny_db[0])
    clip_id = db.table("clips", columns=["clip_id"]).column("clip_id")[0].as_py()
    corpus = db.table("clips", columns=["corpus"]).column("corpus")[0].as_py()
    status, body, _ = studio.get(f"/api/clip/face?corpus={corpus}&clip_id={clip_id}")
    assert status == 200
    header, blocks = unpack(body)
    clip = load_clip(db, corpus, clip_id)
    animation = animate(Motion(values=clip.motion, names=clip.names, fps=clip.fps),
                        deformer_for(clip.names), fps=PAGE_FPS)
    np.testing.assert_allclose(blocks["vertices"], animation.vertices, atol=1e-3)
    # The ARKit weights fitted for a glTF head: the shapes they weigh give the mesh's
    # motion better than the rest pose does (its jaw and lips, at least).
    from animegraph.face.arkit import arkit_shapes

    weights = blocks["arkit"]
    assert weights.shape == (header["n_frames"], 52) and 0 <= weights.min() <= weights.max() <= 1
    moved = animation.local - animation.mesh.vertices
    fitted = np.tensordot(weights, arkit_shapes(), axes=1)
    assert np.linalg.norm(moved - fitted) < 0.8 * np.linalg.norm(moved)
    # Asked again, the answer comes from the studio's cache: the same bytes.
    assert studio.get(f"/api/clip/face?corpus={corpus}&clip_id={clip_id}")[1] == body
    assert [p["phone"] for p in header["phones"]] == [p["phone"] for p in clip.phones]
    status, wav, headers = studio.get(f"/api/clip/audio?corpus={corpus}&clip_id={clip_id}")
    assert status == 200 and wav[:4] == b"RIFF" and headers["Content-Type"] == "audio/wav"


def test_sql_csv_export_is_the_sql_command_s(studio, tiny_db):
    query = "SELECT emotion, count(*) AS n FROM clips GROUP BY 1 ORDER BY 1"
    status, body, headers = studio.get("/api/sql.csv", data=f"sql={query}".encode(),
                                       headers={"Content-Type":
                                                "application/x-www-form-urlencoded"})
    assert status == 200 and "attachment" in headers["Content-Disposition"]
    cli = subprocess.run([sys.executable, "-m", "animegraph", "sql", query, "--db",
                          str(tiny_db[0]), "--format", "csv"], capture_output=True, text=True,
                         check=True)
    assert body.decode() == cli.stdout


# --- in a real browser -------------------------------------------------------------


def wait_until(page, expression: str, bound_s: float = BOUND_S):
    """Poll ``expression`` in the page until it is truthy (its value). Playwright's own
    ``wait_for_function`` evaluates a string, which the page's content policy forbids
    (no 'unsafe-eval'): the tests keep the policy on, so the page is tested under it."""
    deadline = time.monotonic() + bound_s
    while not (value := page.evaluate(expression)):
        if time.monotonic() > deadline:
            pytest.fail(f"gave up waiting for {expression}")
        page.wait_for_timeout(50)
    return value


@pytest.fixture(scope="module")
def playwright():
    """Playwright's driver, one for the module (its sync API runs one at a time)."""
    if not CHROMIUM.exists():
        pytest.skip(f"needs Debian's chromium at {CHROMIUM} (apt-get install chromium; "
                    ".ci/run installs it)")
    sync_api = pytest.importorskip("playwright.sync_api",
                                   reason="needs playwright (pip install -e '.[dev]')")
    with sync_api.sync_playwright() as p:
        yield p


@pytest.fixture(scope="module")
def page(studio, playwright):
    browser = playwright.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
    page = browser.new_page(viewport={"width": 1280, "height": 800})
    errors = []
    page.on("pageerror", lambda exc: errors.append(str(exc)))
    # The content policy is on (no bypass): anything it blocks is an error here.
    page.on("console", lambda m: errors.append(m.text)
            if "Content Security Policy" in m.text else None)
    page.goto(studio.url)
    wait_until(page, "document.body.dataset.ready")
    assert page.evaluate("document.body.dataset.ready") == "1", errors
    yield page
    browser.close()
    assert not errors


def test_page_overview_and_clip_table(page):
    assert page.locator("#summary dt").count() >= 5
    assert page.locator("#chart-phones svg rect").count() >= 20
    assert page.locator("#chart-emotions svg rect").count() == 5
    page.click("nav button[data-tab=clips]")
    rows = page.locator("#clip-table tbody tr")
    assert rows.count() == 34
    page.select_option("#clip-filters [name=emotion]", "sad")
    loads = page.evaluate("window.studio.clipsLoaded")
    page.click("#clip-filters button[type=submit]")
    wait_until(page, f"window.studio.clipsLoaded > {loads}")
    emotions = page.locator("#clip-table tbody tr td:nth-child(3)").all_inner_texts()
    assert emotions and set(emotions) == {"sad"} and len(emotions) < 34
    page.fill("#clip-filters [name=phoneme]", "QQ")
    page.click("#clip-filters button[type=submit]")
    page.wait_for_selector("#clip-status.error")
    assert "not an ARPAbet phone" in page.inner_text("#clip-status")
    page.fill("#clip-filters [name=phoneme]", "")
    page.select_option("#clip-filters [name=emotion]", "")
    loads = page.evaluate("window.studio.clipsLoaded")
    page.click("#clip-filters button[type=submit]")
    wait_until(page, f"window.studio.clipsLoaded > {loads}")


#: The phone strip's labels that spill out of their phone, and phones that overlap the next.
PHONE_STRIP_FAULTS = """(() => {
  const spans = [...document.querySelectorAll('#view-a .phone')];
  const faults = spans.filter((s) => s.scrollWidth > s.clientWidth).map((s) => s.title);
  const boxes = spans.map((s) => [s.getBoundingClientRect(), s.title])
    .sort((a, b) => a[0].left - b[0].left);
  for (let i = 1; i < boxes.length; i++) {
    if (boxes[i][0].left < boxes[i - 1][0].right - 0.5) faults.push(boxes[i][1]);
  }
  return faults; })()"""


def _mouth_over_time(page, n: int = 12) -> list[float]:
    values = []
    for _ in range(n):
        values.append(page.evaluate("window.studio.face.mouth"))
        page.wait_for_timeout(120)
    return values


def test_clip_plays_on_the_face(page, tmp_path_factory):
    page.click("nav button[data-tab=clips]")
    page.click("#clip-table tbody tr:nth-child(2)")
    wait_until(page, "window.studio.lastPlay && window.studio.lastPlay.started")
    mouth = _mouth_over_time(page)
    assert np.ptp(mouth) > 1.0, mouth  # millimetres: the lips move while it plays
    assert page.evaluate("window.studio.face.frameTimes.length") > 3
    assert page.locator("[data-role=phones] .phone").count() > 5
    # The phone strip: no label spills out of its phone, no phone overlaps the next.
    assert page.evaluate(PHONE_STRIP_FAULTS) == [], page.inner_text("#view-a .phones")
    wait_until(page, "!window.studio.face.playing")
    page.evaluate("window.studio.face.seek(window.studio.face.duration() / 2)")
    shot = tmp_path_factory.mktemp("studio-artefacts") / "face.png"
    page.locator("#view-a .canvas-wrap").screenshot(path=str(shot))
    assert shot.stat().st_size > 10_000
    # Kept for a look: pytest's temporary folder (printed with -rA).
    print(f"face screenshot: {shot}")


def _play_row(page, selector: str) -> None:
    page.click("nav button[data-tab=clips]")
    page.evaluate("window.studio.lastPlay = null")
    page.click(selector)
    wait_until(page, "window.studio.lastPlay && window.studio.lastPlay.started")


def _over_time(page, expression: str, n: int = 12) -> np.ndarray:
    values = []
    for _ in range(n):
        values.append(page.evaluate(expression))
        page.wait_for_timeout(120)
    return np.array(values)


def test_the_mouth_inside_moves_with_the_jaw(page):
    """Teeth, tongue and a dark cavity behind the lips: the lower teeth rise and fall
    with the lower lip while a clip plays, and stay below the upper teeth's roots."""
    _play_row(page, "#clip-table tbody tr:nth-child(3)")
    view = "window.studio.face.views[0]"
    teeth = _over_time(page, f"[{view}.lowerTeethY, {view}.mouth, "
                             f"{view}.teeth[0].attributes.position.array[3 * (11 + 5) + 1]]")
    lower, mouth, upper_root = teeth.T
    assert np.ptp(lower) > 1.0 and np.ptp(mouth) > 1.0, teeth
    assert np.all(lower < upper_root)
    wait_until(page, "!window.studio.face.playing")


def test_two_takes_play_side_by_side(page):
    """Clip B (its row's B button) plays in a second view beside clip A, both from the
    start on one clock: both mouths move."""
    _play_row(page, "#clip-table tbody tr:nth-child(4)")
    page.evaluate("window.studio.lastPlay = null")
    page.click("#clip-table tbody tr:nth-child(9) .compare-b")
    wait_until(page, "window.studio.lastPlay && window.studio.lastPlay.started")
    assert page.is_visible("#view-b canvas") and page.is_visible("#view-a canvas")
    ids = page.evaluate("window.studio.face.views.map(v => v.anim.header.clip_id)")
    assert len(set(ids)) == 2
    mouths = _over_time(page, "window.studio.face.views.map(v => v.mouth)")
    assert np.ptp(mouths[:, 0]) > 1.0 and np.ptp(mouths[:, 1]) > 1.0, mouths
    assert page.evaluate("window.studio.face.playing")
    page.click("#compare-close")
    assert page.is_hidden("#view-b")
    assert not page.evaluate("window.studio.face.playing")


def test_your_own_gltf_head_plays_its_arkit_morphs(page, tmp_path):
    """A glTF head with ARKit-named morph targets, chosen in the page (read there, never
    sent): the clip's ARKit weights drive its morph targets; a file that is not one is
    refused in one line."""
    from animegraph.face.arkit import arkit_animation
    from animegraph.face.gltf import write_arkit_glb
    from animegraph.motion.files import Motion
    from ingest.formats.livelink import ARKIT_BLENDSHAPES

    still = Motion(values=np.zeros((3, 52)), names=tuple(ARKIT_BLENDSHAPES), fps=30.0)
    head = write_arkit_glb(arkit_animation(still), np.zeros((3, 52)), tmp_path / "head.glb")
    page.set_input_files("#head-file", str(head))
    wait_until(page, "window.studio.head")
    assert page.inner_text("#head-status") == "head.glb: 52 ARKit morph targets"
    _play_row(page, "#clip-table tbody tr:nth-child(2)")
    head_js = "window.studio.face.views[0].head"
    morphs = _over_time(page, f"[{head_js}.jawOpen, {head_js}.meshes[0][0]"
                              ".morphTargetInfluences.reduce((a, b) => a + b, 0)]")
    assert np.ptp(morphs[:, 0]) > 0.02 and np.ptp(morphs[:, 1]) > 0.02, morphs
    assert not page.evaluate("window.studio.face.views[0].face.visible")
    wait_until(page, "!window.studio.face.playing")
    page.click("#head-drop")
    assert page.evaluate("window.studio.face.views[0].face.visible")
    (tmp_path / "notes.glb").write_bytes(b"not a head")
    page.set_input_files("#head-file", str(tmp_path / "notes.glb"))
    page.wait_for_selector("#head-status.error")
    error = page.inner_text("#head-status")
    assert error.startswith("not a glTF head") and "\n" not in error


def test_the_live_tab_draws_the_live_command_s_frames(page, tiny_db):
    """The live command's WebSocket server (its own class, on a free port) sends a clip's
    frames as it would a live line; the page, through the studio, draws each: the mouth
    moves, and the end of the stream is said."""
    pytest.importorskip("websockets", reason="needs websockets (pip install -e '.[dev]')")
    from animegraph.apps.query import load_clip
    from animegraph.live.websocket import FrameServer
    from db.store import Database

    db = Database.open(tiny_db[0])
    first = db.table("clips", columns=["corpus", "clip_id"]).to_pylist()[1]
    clip = load_clip(db, first["corpus"], first["clip_id"], speech=False)
    step = max(1, round(clip.fps / 30))
    server = FrameServer(0, clip.names, clip.fps / step)
    try:
        page.click("nav button[data-tab=live]")
        page.fill("#live-form [name=port]", str(server.port))
        page.click("#live-form button[type=submit]")
        wait_until(page, "/^live: /.test(document.querySelector('#live-status').textContent)")
        mouths = []
        for index, frame in enumerate(clip.motion[::step]):
            server.send(index, frame)
            page.wait_for_timeout(1000 / 30)
            mouths.append(page.evaluate("window.studio.face.mouth"))
        server.close(len(mouths))
        wait_until(page, "window.studio.live.ended")
    finally:
        server.close()
    assert page.evaluate("window.studio.live.frames") > 5
    assert np.ptp(mouths) > 1.0, mouths
    assert page.inner_text("#live-status").startswith("the live stream ended: ")
    # Nothing listens on the port now: one line says so.
    page.click("#live-form button[type=submit]")
    wait_until(page, "window.studio.live.ended")
    assert page.inner_text("#live-status").startswith("cannot read ws://127.0.0.1:")


def test_sql_console(page):
    page.click("nav button[data-tab=sql]")
    page.fill("#sql-form [name=sql]", "SELECT phoneme, count(*) AS n FROM animes GROUP BY 1 "
              "ORDER BY n DESC")
    page.click("#sql-form button[type=submit]")
    page.wait_for_selector(".sql-table tbody tr")
    assert page.locator(".sql-table tbody tr").count() > 20
    assert page.is_hidden("#sql-error")
    page.fill("#sql-form [name=sql]", "DELETE FROM clips")
    page.click("#sql-form button[type=submit]")
    page.wait_for_selector("#sql-error:not([hidden])")
    assert page.inner_text("#sql-error") == ("only SELECT queries run here (the database is "
                                             "read-only); got DELETE")
    with page.expect_download() as download:
        page.fill("#sql-form [name=sql]", "SELECT clip_id FROM clips ORDER BY 1 LIMIT 3")
        page.click("#sql-csv")
    lines = Path(download.value.path()).read_text().splitlines()
    assert lines[0] == '"clip_id"' and len(lines) == 4


def test_synthesized_line_plays(page, tiny_corpus, tmp_path_factory):
    speech = next(iter(sorted(tiny_corpus.rglob("*.wav"))))
    page.click("nav button[data-tab=synth]")
    page.set_input_files("#synth-form [name=audio]", str(speech))
    page.fill("#synth-form [name=emotion]", "happy")
    page.click("#synth-form button[type=submit]")
    wait_until(page, "window.studio.synthesized || "
                     "!document.querySelector('#synth-error').hidden")
    assert page.is_hidden("#synth-error"), page.inner_text("#synth-error")
    wait_until(page, "window.studio.lastPlay.started")
    mouth = _mouth_over_time(page)
    assert np.ptp(mouth) > 1.0, mouth
    assert page.evaluate(PHONE_STRIP_FAULTS) == []
    # Beside it, the recorded clip the search took most of its phones from, in step.
    nearest = page.evaluate("window.studio.nearest")
    assert nearest and nearest["phones_from_it"] >= 1 and page.is_visible("#view-b canvas")
    assert page.evaluate("window.studio.face.views[1].anim.header.clip_id") == \
        nearest["clip_id"]
    names = page.locator("#synth-files a").all_inner_texts()
    assert {"speech.wav", "motion.c3d", "motion.csv", "motion.npz"} <= set(names)
    with page.expect_download() as download:
        page.click("#synth-files a:text('motion.csv')")
    head = Path(download.value.path()).read_text().splitlines()[0]
    assert head.startswith("frame,time,")


def test_command_line_errors_are_one_line(tmp_path, capsys):
    from animegraph.apps.cli import main

    assert main(["studio", "--db", str(tmp_path / "none.db"), "--port", "70000",
                 "--no-browser"]) == 2
    assert capsys.readouterr().err.strip() == ("animegraph: error: studio: --port must be 0 "
                                               "to 65535, got 70000")
    assert main(["studio", "--db", str(tmp_path / "none.db"), "--no-browser"]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("animegraph: error: ") and "\n" not in err


def test_a_port_in_use_is_one_line(tiny_db):
    import socket

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(
            [str(Path(__file__).resolve().parents[1]), os.environ.get("PYTHONPATH", "")])}
        run = subprocess.run([sys.executable, "-m", "animegraph", "studio", "--db",
                              str(tiny_db[0]), "--port", str(port), "--no-browser"],
                             capture_output=True, text=True, env=env, timeout=BOUND_S)
    assert run.returncode == 2 and run.stdout == ""
    assert run.stderr == (f"animegraph: error: studio: port {port} is in use: choose "
                          "another --port, or --port 0 for any free one\n")


def test_uploads_are_bounded_and_checked(tiny_db, monkeypatch):
    """In process (aiohttp's test server), with the bound lowered to 1 kB."""
    import asyncio

    from aiohttp import FormData
    from aiohttp.test_utils import TestClient, TestServer

    from animegraph.apps.studio import api, synth
    from animegraph.apps.studio.server import make_app

    monkeypatch.setattr(synth, "MAX_UPLOAD_BYTES", 1024)

    async def post(client, name: str, payload: bytes) -> tuple[int, dict]:
        form = FormData()
        form.add_field("audio", payload, filename=name, content_type="application/octet-stream")
        form.add_field("text", "hello")
        response = await client.post("/api/synth?token=t", data=form)
        return response.status, await response.json()

    async def run() -> list:
        app = make_app(tiny_db[0], "t")
        folder = Path(app[api.STUDIO].synth_dir.name)
        async with TestClient(TestServer(app)) as client:
            answers = [await post(client, "big.wav", b"\0" * 4096),
                       await post(client, "notes.txt", b"abc"),
                       await post(client, "../../x.wav", b"RIFF")]
            response = await client.post("/api/synth?token=t", data=FormData({"text": "x"}))
            answers.append((response.status, await response.json()))
            left = sorted(folder.rglob("*"))
        return answers, left, folder

    # In a thread of its own: Playwright's sync API may hold this thread's event loop.
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(1) as pool:
        answers, left, folder = pool.submit(asyncio.run, run()).result()
    assert answers[0] == (400, {"error": "the recording is over 1024 bytes: the studio takes "
                                         "no larger one"})
    assert answers[1][0] == 400 and "must be one of" in answers[1][1]["error"]
    # A name from the browser is never a path: the upload went under the server's name
    # and, not being audio, was refused in one line; nothing is left behind.
    assert answers[2][0] == 400 and "\n" not in answers[2][1]["error"]
    assert answers[3] == (400, {"error": "send the recording and its fields as "
                                         "multipart/form-data"})
    assert left == []
    assert not folder.exists()  # removed when the app stopped


@pytest.mark.shared
def test_an_iphone_database_plays_its_arkit_shapes(tmp_path, playwright):
    """An ARKit database (a Live Link Face capture) is shown through the ARKit shapes on
    the canonical face, as ``render`` draws it."""
    from conftest import require_shared

    from animegraph.apps.query import load_clip
    from animegraph.apps.studio.face import PAGE_FPS
    from animegraph.face.arkit import arkit_animation
    from animegraph.face.mesh import canonical_mesh
    from animegraph.motion.files import Motion
    from db.store import Database
    from ingest.formats.wav import read_wav, write_wav
    from ingest.pipeline import ingest

    capture = require_shared("livelink", "neurosync_testset.csv")
    corpus = tmp_path / "corpus"
    corpus.mkdir()
    lines = capture.read_text().splitlines()
    n = int(6.0 * 59.9)  # the capture's first 6 s, a take of its own
    (corpus / "take.csv").write_text("\n".join(lines[: n + 1]) + "\n")
    audio, rate = read_wav(capture.with_suffix(".wav"))
    write_wav(corpus / "take.wav", audio[: int(n / 59.9 * rate)], rate)
    report = ingest([corpus], tmp_path / "db")
    assert [c.status for c in report.clips] == ["added"]
    server = Studio(tmp_path / "db", tmp_path)
    try:
        status, body, _ = server.get("/api/mesh")
        assert status == 200 and json.loads(body)["n_vertices"] == 468
        assert json.loads(body)["arkit"] is True
        status, shapes_body, _ = server.get("/api/mesh/arkit")
        assert status == 200 and len(shapes_body) == 52 * 468 * 3 * 4
        db = Database.open(tmp_path / "db")
        corpus_name = db.table("clips", columns=["corpus"]).column("corpus")[0].as_py()
        status, body, _ = server.get(f"/api/clip/face?corpus={corpus_name}&clip_id=take")
        assert status == 200, body
    finally:
        assert server.stop() == 0
    on_page = Studio(tmp_path / "db", tmp_path)
    header, blocks = unpack(body)
    assert "vertices" not in blocks  # the page morphs the mesh by the weights itself
    clip = load_clip(db, corpus_name, "take")
    expected = arkit_animation(Motion(values=clip.motion, names=clip.names, fps=clip.fps),
                               fps=PAGE_FPS).vertices
    # What the page computes (face.js, FaceView.apply): rest + weights @ shapes, then
    # the head's rotation and translation.
    shapes = np.frombuffer(shapes_body, dtype="<f4").reshape(52, 468, 3)
    local = canonical_mesh().vertices[None] + np.tensordot(blocks["arkit"], shapes, axes=1)
    rotation = blocks["rigid"][:, :9].reshape(-1, 3, 3)
    world = np.einsum("nij,nvj->nvi", rotation, local) + blocks["rigid"][:, None, 9:]
    np.testing.assert_allclose(world, expected, atol=2e-3)
    assert np.ptp(world[:, 14, 1]) > 1.0  # the lower lip moves (mm)
    # And in the browser: the frame on screen is that one.
    browser = playwright.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
    try:
        page = browser.new_page(viewport={"width": 1280, "height": 800})
        page.goto(on_page.url)
        wait_until(page, "document.body.dataset.ready === '1'")
        page.click("nav button[data-tab=clips]")
        page.click("#clip-table tbody tr:nth-child(1)")
        wait_until(page, "window.studio.lastPlay && window.studio.lastPlay.started")
        page.evaluate("window.studio.face.pause()")
        k = header["n_frames"] // 2
        drawn = page.evaluate(f"window.studio.face.seek({k} / {header['fps']}), "
                              "Array.from(window.studio.face.views[0].positions.array)")
    finally:
        browser.close()
        on_page.stop()
    np.testing.assert_allclose(np.reshape(drawn, (468, 3)), expected[k], atol=2e-3)


def test_it_opens_the_browser_named_by_BROWSER(tiny_db, tmp_path):  # noqa: N802
    """Without --no-browser the URL (with its token) goes to ``$BROWSER``, as Python's
    webbrowser (and Jupyter) hand it over."""
    opened = tmp_path / "opened.txt"
    browser = tmp_path / "browser.sh"
    browser.write_text(f"#!/bin/sh\necho \"$1\" > {opened}\n")
    browser.chmod(0o755)
    server = Studio(tiny_db[0], tmp_path, browser=f"{browser} %s")
    try:
        deadline = time.monotonic() + BOUND_S
        while not (opened.exists() and opened.read_text().strip()):
            assert time.monotonic() < deadline, "the browser was not opened"
            time.sleep(0.1)
        assert opened.read_text().strip() == server.url
    finally:
        assert server.stop() == 0


def test_a_line_recorded_from_the_microphone_plays(studio, playwright, tiny_corpus):
    """Chromium's fake microphone plays a corpus recording; the page records it
    (MediaRecorder, WebM/Opus), the server decodes and synthesizes it."""
    speech = next(iter(sorted(tiny_corpus.rglob("*.wav"))))
    microphone = ["--use-fake-ui-for-media-stream", "--use-fake-device-for-media-stream",
                  f"--use-file-for-fake-audio-capture={speech}"]
    browser = playwright.chromium.launch(executable_path=str(CHROMIUM),
                                         args=CHROMIUM_ARGS + microphone)
    try:
        page = browser.new_page(viewport={"width": 1280, "height": 800})
        page.goto(studio.url)
        wait_until(page, "document.body.dataset.ready === '1'")
        page.click("nav button[data-tab=synth]")
        page.click("#record")
        wait_until(page, "document.querySelector('#record').textContent === 'Stop'")
        page.wait_for_timeout(3000)
        page.click("#record")
        wait_until(page, "/recorded/.test(document.querySelector"
                         "('#record-status').textContent)")
        page.click("#synth-form button[type=submit]")
        wait_until(page, "window.studio.synthesized || "
                         "!document.querySelector('#synth-error').hidden")
        assert page.is_hidden("#synth-error"), page.inner_text("#synth-error")
        wait_until(page, "window.studio.lastPlay.started")
        assert np.ptp(_mouth_over_time(page)) > 1.0
    finally:
        browser.close()


def test_the_studio_checks_a_version_s_files_once(tiny_db, monkeypatch):
    """The studio's database (:class:`db.store.Database`, which remembers its checks by
    file identity, :mod:`db.memo`) hashes the model arrays and checks each table's
    footers once (a version's files do not change), and gives the same arrays as a
    fresh read, read-only."""
    import db.memo
    import db.store
    from animegraph.apps.query import load_clip
    from db.store import Database

    monkeypatch.setattr(db.memo, "SETTLE_NS", 0)  # the fixture's files are seconds old
    db.store._CHECKED.clear()
    db.store._ARRAYS.clear()
    hashed, footers = [], []
    real_hash, real_check = db.store.file_sha256, Database._check_footers
    monkeypatch.setattr(db.store, "file_sha256", lambda path: hashed.append(path)
                        or real_hash(path))
    monkeypatch.setattr(Database, "_check_footers", lambda self, name, files:
                        footers.append(name) or real_check(self, name, files))
    view = Database.open(tiny_db[0])
    clips = view.table("clips", columns=["corpus", "clip_id"]).to_pylist()[:3]
    load_clip(view, clips[0]["corpus"], clips[0]["clip_id"], speech=False)
    first = list(footers)
    assert len(hashed) == 1 and {"clips", "frames", "model_arrays"} <= set(first)
    for clip in clips[1:]:  # the next clips check nothing again
        load_clip(view, clip["corpus"], clip["clip_id"], speech=False)
    assert len(hashed) == 1 and footers == first
    kept = view.arrays()
    db.store._ARRAYS.clear()
    fresh = Database.open(tiny_db[0]).arrays()
    assert kept.keys() == fresh.keys()
    for name, array in kept.items():
        np.testing.assert_array_equal(array, fresh[name])
        assert not array.flags.writeable
