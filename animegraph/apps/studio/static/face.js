// The face: the canonical mesh drawn by three.js, its vertices set frame by frame from
// what the server computed with the project's own deformation (animegraph.apps.studio.face),
// interpolated between the server's frames at the display's rate; the speech plays
// beside it, the phones scroll under it.

import * as THREE from "three";
import { OrbitControls } from "./vendor/OrbitControls.js";

const PX_PER_S = 400; // phone strip: pixels per second
const FRAME_LOG = 1200; // display frame timestamps kept (the page's fps)

// One binary message of the server (animegraph.apps.studio.face.pack): uint32 header length,
// JSON header, padding, float32 vertices (n_frames, n_vertices, 3).
export function unpack(buffer) {
  const length = new DataView(buffer).getUint32(0, true);
  const header = JSON.parse(new TextDecoder().decode(new Uint8Array(buffer, 4, length)));
  const vertices = new Float32Array(buffer, 4 + length);
  if (vertices.length !== header.n_frames * header.n_vertices * 3) {
    throw new Error(`animation holds ${vertices.length} values, expected ` +
                    `${header.n_frames * header.n_vertices * 3}`);
  }
  return { header, vertices };
}

export class FaceView {
  constructor(root, mesh) {
    this.root = root;
    this.mesh = mesh;
    this.anim = null;
    this.time = 0;
    this.speed = 1;
    this.playing = false;
    this.mouth = 0; // inner-lip distance (mm) of the frame on screen
    this.frameTimes = []; // requestAnimationFrame timestamps while playing
    this.workTimes = []; // ms each of those frames took the page (vertices, normals, draw)
    this.onPlayStarted = null;
    this.canvas = root.querySelector("canvas");
    this.audio = new Audio();
    this.audio.preload = "auto";
    this._buildScene();
    this._bindControls();
    this._setVertices(this.rest);
    this.renderer.setAnimationLoop((now) => this._tick(now));
  }

  _buildScene() {
    const m = this.mesh;
    this.rest = new Float32Array(m.vertices);
    this.positions = new THREE.BufferAttribute(new Float32Array(m.vertices), 3);
    this.positions.setUsage(THREE.DynamicDrawUsage);
    const part = (indices) => {
      const geometry = new THREE.BufferGeometry();
      geometry.setAttribute("position", this.positions); // one attribute, shared
      geometry.setIndex(indices);
      return geometry;
    };
    this.skin = part(m.skin);
    this.inner = part(m.mouth);
    this.eyes = part(m.eyes);
    this.renderer = new THREE.WebGLRenderer({ canvas: this.canvas, antialias: true,
                                              preserveDrawingBuffer: false });
    this.renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color(0x202124);
    const skin = new THREE.MeshStandardMaterial({ color: 0xdbad94, roughness: 0.55,
                                                  metalness: 0.0, side: THREE.DoubleSide });
    const mouth = new THREE.MeshBasicMaterial({ color: 0x3a0c10, side: THREE.DoubleSide });
    const eyes = new THREE.MeshPhongMaterial({ color: 0x1c1614, shininess: 90,
                                               specular: 0x666666, side: THREE.DoubleSide });
    this.group = new THREE.Group();
    this.group.add(new THREE.Mesh(this.skin, skin), new THREE.Mesh(this.inner, mouth));
    if (!(m.eye_corners || []).length) this.group.add(new THREE.Mesh(this.eyes, eyes));
    this.eyeballs = (m.eye_corners || []).map(() => this._eyeball());
    this.group.add(...this.eyeballs);
    this.scene.add(this.group);
    this.scene.add(new THREE.HemisphereLight(0xfff4ea, 0x303040, 1.1));
    const key = new THREE.DirectionalLight(0xffffff, 2.0);
    key.position.set(-0.5, 0.6, 1.0);
    const fill = new THREE.DirectionalLight(0xc8d8ff, 0.6);
    fill.position.set(0.7, -0.1, 0.6);
    this.scene.add(key, fill);
    const box = new THREE.Box3().setFromBufferAttribute(this.positions);
    const centre = box.getCenter(new THREE.Vector3());
    const size = box.getSize(new THREE.Vector3());
    this.camera = new THREE.PerspectiveCamera(28, 1, 1, 5000);
    const distance = 1.15 * Math.max(size.x, size.y) / (2 * Math.tan(THREE.MathUtils.degToRad(14)));
    this.camera.position.set(centre.x, centre.y, centre.z + distance);
    this.controls = new OrbitControls(this.camera, this.canvas);
    this.controls.target.copy(centre);
    this.controls.update();
    this._resize();
    new ResizeObserver(() => this._resize()).observe(this.canvas.parentElement);
  }

  // An eyeball: a sphere coloured by direction (sclera, iris, pupil round +z), drawn
  // behind the eye opening instead of its dark fill.
  _eyeball() {
    const geometry = new THREE.SphereGeometry(1, 48, 36);
    const p = geometry.attributes.position;
    const colours = new Float32Array(p.count * 3);
    const sclera = new THREE.Color(0xece6e0), iris = new THREE.Color(0x4a3222);
    const pupil = new THREE.Color(0x050505);
    for (let i = 0; i < p.count; i++) {
      const z = p.getZ(i);
      const c = z > 0.96 ? pupil : z > 0.87 ? iris : sclera;
      colours.set([c.r, c.g, c.b], 3 * i);
    }
    geometry.setAttribute("color", new THREE.BufferAttribute(colours, 3));
    return new THREE.Mesh(geometry, new THREE.MeshPhongMaterial({
      vertexColors: true, shininess: 80, specular: 0x444444 }));
  }

  // Seat each eyeball behind its opening: centred between the corners, as wide as the
  // opening, facing out of the face (the lids' plane turned towards the viewer's side).
  _placeEyes() {
    const p = this.positions.array;
    const at = (i) => new THREE.Vector3(p[3 * i], p[3 * i + 1], p[3 * i + 2]);
    this.mesh.eye_corners.forEach(([outer, inner, upper, lower], k) => {
      const o = at(outer), n = at(inner), u = at(upper), l = at(lower);
      const across = n.clone().sub(o);
      const up = u.clone().sub(l);
      const width = across.length();
      const out = new THREE.Vector3().crossVectors(across, up).normalize();
      if (out.z < 0) out.negate();
      const radius = 0.5 * width;
      const centre = o.clone().add(n).multiplyScalar(0.5).addScaledVector(out, -0.55 * radius);
      const ball = this.eyeballs[k];
      ball.position.copy(centre);
      ball.scale.setScalar(radius);
      ball.quaternion.setFromUnitVectors(new THREE.Vector3(0, 0, 1), out);
    });
  }

  _resize() {
    const box = this.canvas.parentElement.getBoundingClientRect();
    const width = Math.max(64, Math.floor(box.width));
    const height = Math.max(64, Math.floor(box.height));
    this.renderer.setSize(width, height, false);
    this.camera.aspect = width / height;
    this.camera.updateProjectionMatrix();
  }

  _bindControls() {
    const q = (sel) => this.root.querySelector(sel);
    this.playButton = q("[data-role=play]");
    this.scrub = q("[data-role=scrub]");
    this.speedSelect = q("[data-role=speed]");
    this.clock = q("[data-role=clock]");
    this.mouthReadout = q("[data-role=mouth]");
    this.strip = q("[data-role=phones]");
    this.title = q("[data-role=title]");
    this.playButton.addEventListener("click", () => (this.playing ? this.pause() : this.play()));
    this.scrub.addEventListener("input", () => {
      this.seek(Number(this.scrub.value) / 1000 * this.duration());
    });
    this.speedSelect.addEventListener("change", () => this.setSpeed(Number(this.speedSelect.value)));
  }

  duration() {
    return this.anim ? this.anim.header.n_frames / this.anim.header.fps : 0;
  }

  // Show an animation (unpacked) with its speech at audioUrl; it plays if play is true.
  async show(anim, audioUrl, title, play = true) {
    this.pause();
    this.anim = anim;
    this.time = 0;
    this.title.textContent = title;
    this._layoutPhones(anim.header.phones || []);
    this.audio.src = audioUrl;
    this.scrub.disabled = false;
    this.playButton.disabled = false;
    this._apply(0);
    if (play) this.play();
  }

  play() {
    if (!this.anim) return;
    if (this.time >= this.duration() - 1e-3) this.time = 0;
    this.playing = true;
    this.frameTimes = [];
    this.workTimes = [];
    this._started = false;
    this.t0 = performance.now() - (this.time * 1000) / this.speed;
    this.audio.playbackRate = this.speed;
    try { this.audio.currentTime = this.time; } catch (e) { /* not loaded yet */ }
    this.audio.play().catch(() => {}); // no sound device: the face plays on its own clock
    this.playButton.textContent = "Pause";
  }

  pause() {
    this.playing = false;
    this.audio.pause();
    this.playButton.textContent = "Play";
  }

  seek(seconds) {
    this.time = Math.min(Math.max(seconds, 0), this.duration());
    this.t0 = performance.now() - (this.time * 1000) / this.speed;
    try { this.audio.currentTime = this.time; } catch (e) { /* not loaded yet */ }
    this._apply(this.time);
  }

  setSpeed(speed) {
    this.speed = speed;
    this.t0 = performance.now() - (this.time * 1000) / this.speed;
    this.audio.playbackRate = speed;
  }

  _tick(now) {
    if (this.playing) {
      this.frameTimes.push(now);
      if (this.frameTimes.length > FRAME_LOG) this.frameTimes.shift();
      this.time = ((now - this.t0) / 1000) * this.speed;
      // The wall clock leads; the speech is pulled back to it if it drifts.
      if (!this.audio.paused && Math.abs(this.audio.currentTime - this.time) > 0.08) {
        try { this.audio.currentTime = this.time; } catch (e) { /* seeking */ }
      }
      if (this.time >= this.duration()) {
        this.time = this.duration();
        this.pause();
      }
      this._apply(this.time);
    }
    this.controls.update();
    this.renderer.render(this.scene, this.camera);
    if (this.playing) {
      this.workTimes.push(performance.now() - now);
      if (this.workTimes.length > FRAME_LOG) this.workTimes.shift();
    }
    if (this.playing && !this._started) {
      this._started = true;
      if (this.onPlayStarted) this.onPlayStarted(performance.now());
    }
  }

  // The vertices at `seconds`, linearly between the server's frames.
  _apply(seconds) {
    const { header, vertices } = this.anim;
    const n = header.n_vertices * 3;
    const x = Math.min(Math.max(seconds * header.fps, 0), header.n_frames - 1);
    const k = Math.floor(x);
    const k1 = Math.min(k + 1, header.n_frames - 1);
    const f = x - k;
    const out = this.positions.array;
    const a = k * n, b = k1 * n;
    for (let i = 0; i < n; i++) out[i] = vertices[a + i] * (1 - f) + vertices[b + i] * f;
    this._updated();
    const dur = this.duration();
    this.scrub.value = String(Math.round((dur > 0 ? seconds / dur : 0) * 1000));
    this.clock.textContent = `${seconds.toFixed(2)} / ${dur.toFixed(2)} s`;
    this.strip.style.transform = `translateX(${-seconds * PX_PER_S}px)`;
  }

  _setVertices(values) {
    this.positions.array.set(values);
    this._updated();
  }

  _updated() {
    this.positions.needsUpdate = true;
    this.skin.computeVertexNormals();
    this.eyes.computeVertexNormals();
    if (this.eyeballs.length) this._placeEyes();
    const [u, l] = this.mesh.lip_pair;
    const p = this.positions.array;
    this.mouth = Math.hypot(p[3 * u] - p[3 * l], p[3 * u + 1] - p[3 * l + 1],
                            p[3 * u + 2] - p[3 * l + 2]);
    this.mouthReadout.textContent = `mouth ${this.mouth.toFixed(1)} mm`;
  }

  _layoutPhones(phones) {
    this.strip.replaceChildren();
    for (const p of phones) {
      const span = document.createElement("span");
      span.className = p.phone === "SIL" ? "phone sil" : "phone";
      span.textContent = p.phone === "SIL" ? "" : p.phone;
      span.style.left = `${p.start * PX_PER_S}px`;
      span.style.width = `${Math.max(1, (p.end - p.start) * PX_PER_S - 1)}px`;
      this.strip.append(span);
    }
  }
}
