// The face: the canonical mesh drawn by three.js, its vertices set frame by frame from
// what the server computed with the project's own deformation (animegraph.apps.studio.face)
// or, for an iPhone database, from its ARKit weights applied here as morph targets;
// interpolated between the server's frames at the display's rate. A FaceView is one
// viewport; the Player drives one or two of them (side by side) on one clock, with the
// speech of the first, the phones scrolling under each.
//
// Per display frame nothing is allocated: vertices, normals, eyes, teeth and the mouth's
// inside are written into arrays made once.

import * as THREE from "three";

const PX_PER_S = 400; // phone strip: pixels per second
const FRAME_LOG = 1200; // display frame timestamps kept (the page's fps)
const TEXT_EVERY_MS = 100; // the clock and mouth readouts change at most this often
// Teeth rows: [upper?, edge, root]: mm along the face's up axis from the lip's contour.
const TEETH = [[true, -3.0, 6.0], [false, 2.4, -6.0]];
// Tongue rows: [mm back, fraction of the cavity's depth back, mm down, narrowing].
const TONGUE = [[4.5, 0, -3.0, 0.7], [0, 0.55, -1.0, 0.75], [0, 1.0, -4.0, 0.6]];

// One binary message of the server (animegraph.apps.studio.face.pack): uint32 header length,
// JSON header (with `blocks`: [name, shape] each), padding, the blocks as float32.
export function unpack(buffer) {
  const length = new DataView(buffer).getUint32(0, true);
  const header = JSON.parse(new TextDecoder().decode(new Uint8Array(buffer, 4, length)));
  const blocks = {};
  let offset = 4 + length;
  for (const [name, shape] of header.blocks) {
    const size = shape.reduce((a, b) => a * b, 1);
    if (shape[0] !== header.n_frames || offset + 4 * size > buffer.byteLength) {
      throw new Error(`animation block ${name} does not fit the message`);
    }
    blocks[name] = new Float32Array(buffer, offset, size);
    offset += 4 * size;
  }
  if (offset !== buffer.byteLength) throw new Error("animation message has bytes left over");
  return { header, blocks };
}

// Linear interpolation of row `x` (fractional) of a (n, width) block into out.
function sampleRows(block, width, n, x, out) {
  const k = Math.min(Math.max(Math.floor(x), 0), n - 1);
  const k1 = Math.min(k + 1, n - 1);
  const f = Math.min(Math.max(x - k, 0), 1);
  const a = k * width, b = k1 * width;
  for (let i = 0; i < width; i++) out[i] = block[a + i] * (1 - f) + block[b + i] * f;
  return out;
}

// Vertex normals of an indexed triangle list, written into `normals` (area weighted).
function computeNormals(positions, index, normals) {
  normals.fill(0);
  for (let t = 0; t < index.length; t += 3) {
    const a = 3 * index[t], b = 3 * index[t + 1], c = 3 * index[t + 2];
    const ux = positions[b] - positions[a], uy = positions[b + 1] - positions[a + 1],
      uz = positions[b + 2] - positions[a + 2];
    const vx = positions[c] - positions[a], vy = positions[c + 1] - positions[a + 1],
      vz = positions[c + 2] - positions[a + 2];
    const nx = uy * vz - uz * vy, ny = uz * vx - ux * vz, nz = ux * vy - uy * vx;
    normals[a] += nx; normals[a + 1] += ny; normals[a + 2] += nz;
    normals[b] += nx; normals[b + 1] += ny; normals[b + 2] += nz;
    normals[c] += nx; normals[c + 1] += ny; normals[c + 2] += nz;
  }
  for (let i = 0; i < normals.length; i += 3) {
    const l = Math.hypot(normals[i], normals[i + 1], normals[i + 2]) || 1;
    normals[i] /= l; normals[i + 1] /= l; normals[i + 2] /= l;
  }
}

// A strip of `rows` rows of `cols` vertices, triangulated, with its own positions.
function stripGeometry(rows, cols) {
  const geometry = new THREE.BufferGeometry();
  const position = new THREE.BufferAttribute(new Float32Array(rows * cols * 3), 3);
  position.setUsage(THREE.DynamicDrawUsage);
  geometry.setAttribute("position", position);
  const index = [];
  for (let r = 0; r + 1 < rows; r++) {
    for (let c = 0; c + 1 < cols; c++) {
      const a = r * cols + c, b = a + 1, d = a + cols, e = d + 1;
      index.push(a, d, b, b, d, e);
    }
  }
  geometry.setIndex(index);
  const normal = new THREE.BufferAttribute(new Float32Array(rows * cols * 3), 3);
  normal.setUsage(THREE.DynamicDrawUsage);
  geometry.setAttribute("normal", normal);
  geometry.userData.index = Uint32Array.from(index);
  return geometry;
}

export class FaceView {
  // root: an element holding a canvas, [data-role=title], [data-role=phones] and
  // [data-role=mouth]; mesh: /api/mesh's JSON; shapes: the ARKit shapes (Float32Array,
  // 52 x n_vertices x 3) when the page morphs the mesh itself, else null.
  constructor(root, mesh, shapes = null) {
    this.root = root;
    this.mesh = mesh;
    this.shapes = shapes;
    this.anim = null;
    this.mouth = 0; // inner-lip distance (mm) of the frame on screen
    this.head = null; // the user's glTF head: { scene, meshes: [[mesh, [[morph, arkit]]]], matched }
    this.audio = new Audio();
    this.audio.preload = "auto";
    this.canvas = root.querySelector("canvas");
    this.title = root.querySelector("[data-role=title]");
    this.strip = root.querySelector("[data-role=phones]");
    this.mouthReadout = root.querySelector("[data-role=mouth]");
    this.nArkit = mesh.arkit_names.length;
    this.weights = new Float32Array(this.nArkit); // the frame's ARKit weights
    this.rigid = new Float32Array(12);
    this._buildScene();
    this._setVertices(this.rest);
  }

  _buildScene() {
    const m = this.mesh;
    this.rest = new Float32Array(m.vertices);
    this.positions = new THREE.BufferAttribute(new Float32Array(m.vertices), 3);
    this.positions.setUsage(THREE.DynamicDrawUsage);
    this.normals = new THREE.BufferAttribute(new Float32Array(m.vertices.length), 3);
    this.normals.setUsage(THREE.DynamicDrawUsage);
    this.skinIndex = Uint32Array.from(m.skin);
    const part = (indices) => {
      const geometry = new THREE.BufferGeometry();
      geometry.setAttribute("position", this.positions); // one attribute, shared
      geometry.setAttribute("normal", this.normals);
      geometry.setIndex(indices);
      return geometry;
    };
    this.renderer = new THREE.WebGLRenderer({ canvas: this.canvas, antialias: true });
    this.renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color(0x202124);
    const skin = new THREE.MeshStandardMaterial({ color: 0xdbad94, roughness: 0.55,
                                                  metalness: 0.0, side: THREE.DoubleSide });
    this.face = new THREE.Group();
    this.face.add(new THREE.Mesh(part(m.skin), skin));
    if (m.lips.length) {
      this._buildMouth();
    } else { // another mesh: its mouth triangles, dark, close the opening
      this.face.add(new THREE.Mesh(part(m.mouth), new THREE.MeshBasicMaterial({
        color: 0x3a0c10, side: THREE.DoubleSide })));
    }
    if (!m.eye_corners.length) {
      this.face.add(new THREE.Mesh(part(m.eyes), new THREE.MeshPhongMaterial({
        color: 0x1c1614, shininess: 90, specular: 0x666666, side: THREE.DoubleSide })));
    }
    this.eyeballs = m.eye_corners.map(() => this._eyeball());
    this.face.add(...this.eyeballs);
    this.scene.add(this.face);
    this.scene.add(new THREE.HemisphereLight(0xfff4ea, 0x303040, 1.1));
    const key = new THREE.DirectionalLight(0xffffff, 2.0);
    key.position.set(-0.5, 0.6, 1.0);
    const fill = new THREE.DirectionalLight(0xc8d8ff, 0.6);
    fill.position.set(0.7, -0.1, 0.6);
    this.scene.add(key, fill);
    const box = new THREE.Box3().setFromBufferAttribute(this.positions);
    this.centre = box.getCenter(new THREE.Vector3());
    this.size = box.getSize(new THREE.Vector3());
    this.camera = new THREE.PerspectiveCamera(28, 1, 1, 5000);
    const distance = 1.15 * Math.max(this.size.x, this.size.y) /
      (2 * Math.tan(THREE.MathUtils.degToRad(14)));
    this.camera.position.set(this.centre.x, this.centre.y, this.centre.z + distance);
    this.controls = new THREE.OrbitControls(this.camera, this.canvas);
    this.controls.target.copy(this.centre);
    this.controls.update();
    this._v = [0, 1, 2, 3, 4, 5].map(() => new THREE.Vector3()); // scratch vectors
    this._z = new THREE.Vector3(0, 0, 1);
    this.resize();
    new ResizeObserver(() => this.resize()).observe(this.canvas.parentElement);
  }

  // The mouth's inside (canonical topology): a dark cavity behind the lips' inner
  // contour (its walls run back from the contour), two rows of teeth seated behind the
  // upper and lower lip, and a tongue behind the lower teeth, rebuilt every frame from
  // the lips' vertices.
  _buildMouth() {
    const [upper, lower] = this.mesh.lips; // corner, inner contour, corner
    this.upperLip = upper;
    this.lowerLip = lower;
    this.ring = [...upper, ...lower.slice(1, -1).reverse()]; // closed loop round the opening
    const n = this.ring.length;
    const cavity = new THREE.BufferGeometry();
    this.cavityPos = new THREE.BufferAttribute(new Float32Array((2 * n + 1) * 3), 3);
    this.cavityPos.setUsage(THREE.DynamicDrawUsage);
    cavity.setAttribute("position", this.cavityPos);
    const index = [];
    for (let i = 0; i < n; i++) {
      const j = (i + 1) % n;
      index.push(i, j, n + i, j, n + j, n + i, n + i, n + j, 2 * n); // wall, back
    }
    cavity.setIndex(index);
    this.cavity = cavity;
    this.face.add(new THREE.Mesh(cavity, new THREE.MeshBasicMaterial({
      color: 0x240507, side: THREE.DoubleSide })));
    const cols = upper.length;
    this.teeth = [stripGeometry(2, cols), stripGeometry(2, cols)];
    const enamel = new THREE.MeshLambertMaterial({ color: 0xeee8da, side: THREE.DoubleSide });
    for (const g of this.teeth) this.face.add(new THREE.Mesh(g, enamel));
    this.tongue = stripGeometry(3, cols);
    this.face.add(new THREE.Mesh(this.tongue, new THREE.MeshLambertMaterial({
      color: 0x9c4a4e, side: THREE.DoubleSide })));
    this.lowerTeethY = 0; // the lower teeth's middle edge, height (mm): read by the tests
    this._ctr = new Float64Array(3);
  }

  // Face axes from the mouth corners and the eyes: across, up, forward (unit vectors).
  _axes(p) {
    const [across, up, forward, a, b] = this._v;
    const l = this.upperLip[0], r = this.upperLip[this.upperLip.length - 1];
    across.set(p[3 * r] - p[3 * l], p[3 * r + 1] - p[3 * l + 1], p[3 * r + 2] - p[3 * l + 2]);
    const width = across.length();
    across.normalize();
    const eyes = this.mesh.eye_corners;
    if (eyes.length) {
      const e = eyes[0][0], f = eyes[1][0];
      a.set((p[3 * e] + p[3 * f]) / 2, (p[3 * e + 1] + p[3 * f + 1]) / 2,
            (p[3 * e + 2] + p[3 * f + 2]) / 2);
      b.set((p[3 * l] + p[3 * r]) / 2, (p[3 * l + 1] + p[3 * r + 1]) / 2,
            (p[3 * l + 2] + p[3 * r + 2]) / 2);
      up.subVectors(a, b);
    } else {
      up.set(0, 1, 0);
    }
    up.addScaledVector(across, -up.dot(across)).normalize();
    forward.crossVectors(across, up).normalize();
    if (forward.z < 0) forward.negate();
    return width;
  }

  _placeMouth() {
    const p = this.positions.array;
    const width = this._axes(p);
    const [across, up, forward] = this._v;
    const n = this.ring.length;
    const c = this.cavityPos.array;
    const depth = 0.35 * width; // the cavity's back wall behind the lips (mm)
    let cx = 0, cy = 0, cz = 0;
    for (let i = 0; i < n; i++) {
      const v = this.ring[i];
      c[3 * i] = p[3 * v] - 0.5 * forward.x;
      c[3 * i + 1] = p[3 * v + 1] - 0.5 * forward.y;
      c[3 * i + 2] = p[3 * v + 2] - 0.5 * forward.z;
      cx += p[3 * v]; cy += p[3 * v + 1]; cz += p[3 * v + 2];
    }
    cx /= n; cy /= n; cz /= n;
    const ctr = this._ctr;
    ctr[0] = cx; ctr[1] = cy; ctr[2] = cz;
    for (let i = 0; i < n; i++) { // the back ring: the contour shrunk 10 % and set back
      for (let k = 0; k < 3; k++) {
        const centre = ctr[k];
        c[3 * (n + i) + k] = centre + 0.9 * (c[3 * i + k] - centre) - depth * forward.getComponent(k);
      }
    }
    c[6 * n] = cx - 1.1 * depth * forward.x; // the back wall's middle, deepest
    c[6 * n + 1] = cy - 1.1 * depth * forward.y;
    c[6 * n + 2] = cz - 1.1 * depth * forward.z;
    this.cavityPos.needsUpdate = true;
    // Teeth: an arc behind each lip, narrower than the mouth and set further back at the
    // sides; the upper row hangs from the upper lip, the lower row rises with the jaw.
    TEETH.forEach(([upper, edge, root], r) => {
      const lip = upper ? this.upperLip : this.lowerLip;
      const t = this.teeth[r].attributes.position.array;
      const cols = lip.length;
      for (let i = 0; i < cols; i++) {
        const s = 2 * i / (cols - 1) - 1; // -1 .. 1 across the mouth
        const back = 2.5 + 10.0 * s * s; // an arch: the side teeth deeper in the mouth
        const show = 1 - 0.8 * s * s; // and less of them below the lip
        const v = lip[i];
        for (let k = 0; k < 3; k++) { // across and depth drawn in by 22 %, height kept
          const centre = ctr[k];
          const at = k === 1 ? p[3 * v + 1] : centre + 0.78 * (p[3 * v + k] - centre);
          const off = -back * forward.getComponent(k);
          t[3 * i + k] = at + off + show * edge * up.getComponent(k);
          t[3 * (cols + i) + k] = at + off + root * up.getComponent(k);
        }
      }
      if (r === 1) this.lowerTeethY = t[3 * Math.floor(cols / 2) + 1];
      this.teeth[r].attributes.position.needsUpdate = true;
      computeNormals(t, this.teeth[r].userData.index, this.teeth[r].attributes.normal.array);
      this.teeth[r].attributes.normal.needsUpdate = true;
    });
    // The tongue: three rows from behind the lower teeth to the cavity's floor.
    const g = this.tongue.attributes.position.array;
    const cols = this.lowerLip.length;
    for (let i = 0; i < cols; i++) {
      const v = this.lowerLip[i];
      TONGUE.forEach(([back0, backDepth, drop, narrow], row) => {
        const back = back0 + backDepth * depth;
        for (let k = 0; k < 3; k++) {
          const centre = ctr[k];
          const at = k === 1 ? p[3 * v + 1] : centre + narrow * (p[3 * v + k] - centre);
          g[3 * (row * cols + i) + k] = at - back * forward.getComponent(k) +
            drop * up.getComponent(k);
        }
      });
    }
    this.tongue.attributes.position.needsUpdate = true;
    computeNormals(g, this.tongue.userData.index, this.tongue.attributes.normal.array);
    this.tongue.attributes.normal.needsUpdate = true;
  }

  // An eyeball: a sphere coloured by direction (sclera, iris, pupil round +z), drawn
  // behind the eye opening instead of its dark fill.
  _eyeball() {
    const geometry = new THREE.SphereGeometry(1, 32, 20);
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
    const [o, n, u, l, across, up] = this._v;
    const at = (v, i) => v.set(p[3 * i], p[3 * i + 1], p[3 * i + 2]);
    this.mesh.eye_corners.forEach(([outer, inner, upper, lower], k) => {
      at(o, outer); at(n, inner); at(u, upper); at(l, lower);
      across.subVectors(n, o);
      up.subVectors(u, l);
      const radius = 0.5 * across.length();
      const out = across.cross(up).normalize(); // across is spent from here on
      if (out.z < 0) out.negate();
      const ball = this.eyeballs[k];
      ball.position.addVectors(o, n).multiplyScalar(0.5).addScaledVector(out, -0.55 * radius);
      ball.scale.setScalar(radius);
      ball.quaternion.setFromUnitVectors(this._z, out);
    });
  }

  resize() {
    const box = this.canvas.parentElement.getBoundingClientRect();
    const width = Math.max(64, Math.floor(box.width));
    const height = Math.max(64, Math.floor(box.height));
    this.renderer.setSize(width, height, false);
    this.camera.aspect = width / height;
    this.camera.updateProjectionMatrix();
  }

  duration() {
    return this.anim ? this.anim.header.n_frames / this.anim.header.fps : 0;
  }

  // Show an animation (unpacked) with its speech at audioUrl.
  show(anim, audioUrl, title) {
    const { header, blocks } = anim;
    if (!blocks.vertices && !(blocks.arkit && blocks.rigid && this.shapes)) {
      throw new Error("this animation has neither vertices nor ARKit weights to draw");
    }
    this.anim = anim;
    this.title.textContent = title;
    this._layoutPhones(header.phones || []);
    this.audio.src = audioUrl;
    this.apply(0);
  }

  // The frame at `seconds`, linearly between the server's frames.
  apply(seconds) {
    if (!this.anim) return;
    const { header, blocks } = this.anim;
    const x = Math.min(Math.max(seconds * header.fps, 0), header.n_frames - 1);
    const out = this.positions.array;
    if (blocks.arkit) sampleRows(blocks.arkit, this.nArkit, header.n_frames, x, this.weights);
    if (blocks.vertices) {
      sampleRows(blocks.vertices, out.length, header.n_frames, x, out);
    } else { // an iPhone database: rest + sum_k w_k shape_k, then the head's rigid motion
      const n = out.length, s = this.shapes, w = this.weights;
      out.set(this.rest);
      for (let k = 0; k < this.nArkit; k++) {
        const wk = w[k];
        if (wk < 1e-4) continue;
        const base = k * n;
        for (let i = 0; i < n; i++) out[i] += wk * s[base + i];
      }
      const r = sampleRows(blocks.rigid, 12, header.n_frames, x, this.rigid);
      for (let i = 0; i < n; i += 3) {
        const a = out[i], b = out[i + 1], c = out[i + 2];
        out[i] = r[0] * a + r[1] * b + r[2] * c + r[9];
        out[i + 1] = r[3] * a + r[4] * b + r[5] * c + r[10];
        out[i + 2] = r[6] * a + r[7] * b + r[8] * c + r[11];
      }
    }
    this._updated();
    if (this.head && blocks.arkit) this._driveHead();
    this.strip.style.transform = `translateX(${-seconds * PX_PER_S}px)`;
  }

  _setVertices(values) {
    this.positions.array.set(values);
    this._updated();
  }

  _updated() {
    this.positions.needsUpdate = true;
    computeNormals(this.positions.array, this.skinIndex, this.normals.array);
    this.normals.needsUpdate = true;
    if (this.eyeballs.length) this._placeEyes();
    if (this.teeth) this._placeMouth();
    const [u, l] = this.mesh.lip_pair;
    const p = this.positions.array;
    this.mouth = Math.hypot(p[3 * u] - p[3 * l], p[3 * u + 1] - p[3 * l + 1],
                            p[3 * u + 2] - p[3 * l + 2]);
  }

  showText() {
    if (this.mouthReadout) this.mouthReadout.textContent = `mouth ${this.mouth.toFixed(1)} mm`;
  }

  render() {
    this.controls.update();
    this.renderer.render(this.scene, this.camera);
  }

  // The user's own head (a glTF 2.0 file's bytes): drawn instead of the canonical face,
  // its morph targets named by ARKit driven by the animation's ARKit weights.
  async loadHead(buffer) {
    const names = new Map(this.mesh.arkit_names.map((n, k) => [n.toLowerCase(), k]));
    // parse() throws on some bad files and calls back on others: one message for both.
    const gltf = await new Promise((resolve, reject) =>
      new THREE.GLTFLoader().parse(buffer, "", resolve, reject))
      .catch((e) => { throw new Error(`not a glTF head: ${e.message || e}`); });
    const meshes = [];
    let matched = 0;
    gltf.scene.traverse((node) => {
      if (!node.isMesh || !node.morphTargetDictionary) return;
      const pairs = [];
      for (const [name, index] of Object.entries(node.morphTargetDictionary)) {
        const k = names.get(name.toLowerCase().replace(/^.*[.:|]/, ""));
        if (k !== undefined) pairs.push([index, k]);
      }
      if (pairs.length) { meshes.push([node, pairs]); matched = Math.max(matched, pairs.length); }
    });
    if (!meshes.length) {
      throw new Error("the glTF has no morph targets named by ARKit (jawOpen, eyeBlinkLeft ...)");
    }
    if (this.head) this.scene.remove(this.head.scene);
    // Fit it where the canonical face is: same height, same centre.
    const box = new THREE.Box3().setFromObject(gltf.scene);
    const size = box.getSize(new THREE.Vector3());
    const scale = this.size.y / (size.y || 1);
    const pivot = new THREE.Group();
    gltf.scene.position.sub(box.getCenter(new THREE.Vector3()));
    pivot.add(gltf.scene);
    pivot.scale.setScalar(scale);
    pivot.position.copy(this.centre);
    this.scene.add(pivot);
    this.face.visible = false;
    this.head = { scene: pivot, meshes, matched, jawOpen: 0 };
    this.apply(this.time || 0);
    return this.head;
  }

  _driveHead() {
    const w = this.weights;
    for (const [node, pairs] of this.head.meshes) {
      for (const [index, k] of pairs) node.morphTargetInfluences[index] = w[k];
    }
    this.head.jawOpen = w[this.mesh.arkit_names.indexOf("jawOpen")];
  }

  dropHead() {
    if (!this.head) return;
    this.scene.remove(this.head.scene);
    this.head = null;
    this.face.visible = true;
  }

  _layoutPhones(phones) {
    // A label is drawn only where it fits its phone's span (a short phone shows its
    // name on hover): labels never overlap.
    this.strip.replaceChildren();
    for (const p of phones) {
      const span = document.createElement("span");
      const width = Math.max(1, (p.end - p.start) * PX_PER_S - 1);
      span.className = p.phone === "SIL" ? "phone sil" : "phone";
      span.title = `${p.phone} ${p.start.toFixed(2)}-${p.end.toFixed(2)} s`;
      if (p.phone !== "SIL" && width >= 8 * p.phone.length + 4) span.textContent = p.phone;
      span.style.left = `${p.start * PX_PER_S}px`;
      span.style.width = `${width}px`;
      this.strip.append(span);
    }
  }
}

// Play/pause/scrub/speed over one or two FaceViews on one clock (the wall clock leads;
// the first view's speech is pulled back to it if it drifts; the second's is muted).
export class Player {
  // first: the FaceView always shown; makeSecond(): the side-by-side one, made when first
  // needed (a second WebGL context costs the page's start).
  constructor(controls, first, makeSecond) {
    this.views = [first];
    this.makeSecond = makeSecond;
    this.time = 0;
    this.speed = 1;
    this.playing = false;
    this.compare = false;
    this.frameTimes = []; // requestAnimationFrame timestamps while playing
    this.workTimes = []; // ms each of those frames took the page (vertices, normals, draw)
    this.onPlayStarted = null;
    this._textAt = 0;
    const q = (sel) => controls.querySelector(sel);
    this.playButton = q("[data-role=play]");
    this.scrub = q("[data-role=scrub]");
    this.speedSelect = q("[data-role=speed]");
    this.clock = q("[data-role=clock]");
    this.playButton.addEventListener("click", () => (this.playing ? this.pause() : this.play()));
    this.scrub.addEventListener("input", () => {
      this.seek(Number(this.scrub.value) / 1000 * this.duration());
    });
    this.speedSelect.addEventListener("change", () => this.setSpeed(Number(this.speedSelect.value)));
    first.renderer.setAnimationLoop((now) => this._tick(now));
  }

  get mouth() { return this.views[0].mouth; }

  active() { return this.compare ? this.views : this.views.slice(0, 1); }

  duration() {
    return Math.max(0, ...this.active().map((v) => v.duration()));
  }

  setCompare(on) {
    if (on && this.views.length < 2) {
      const second = this.makeSecond();
      second.audio.muted = true; // one speech at a time: the first view's
      this.views.push(second);
    }
    this.compare = on;
    if (this.views[1]) this.views[1].root.hidden = !on;
    for (const v of this.views) v.resize();
  }

  // Show an animation in view `slot` (0, or 1: the side-by-side one); play from the start.
  show(slot, anim, audioUrl, title, play = true) {
    this.pause();
    if (slot === 1) this.setCompare(true);
    this.views[slot].show(anim, audioUrl, title);
    this.time = 0;
    this.scrub.disabled = false;
    this.playButton.disabled = false;
    this.seek(0);
    if (play) this.play();
  }

  // One live frame (an animation of one frame) on the first view, at once.
  showLive(anim) {
    if (this.playing) this.pause();
    const view = this.views[0];
    if (!view.anim || view.anim.header.kind !== "live") {
      view.title.textContent = "live";
      view._layoutPhones([]);
      view.audio.removeAttribute("src");
    }
    view.anim = anim;
    view.apply(0);
    view.showText();
  }

  play() {
    if (!this.active().some((v) => v.anim)) return;
    if (this.time >= this.duration() - 1e-3) this.time = 0;
    this.playing = true;
    this.frameTimes = [];
    this.workTimes = [];
    this._started = false;
    this.t0 = performance.now() - (this.time * 1000) / this.speed;
    for (const v of this.active()) {
      if (!v.anim) continue;
      v.audio.playbackRate = this.speed;
      try { v.audio.currentTime = Math.min(this.time, v.duration()); } catch (e) { /* not loaded */ }
      v.audio.play().catch(() => {}); // no sound device: the face plays on its own clock
    }
    this.playButton.textContent = "Pause";
  }

  pause() {
    this.playing = false;
    for (const v of this.views) v.audio.pause();
    this.playButton.textContent = "Play";
  }

  seek(seconds) {
    this.time = Math.min(Math.max(seconds, 0), this.duration());
    this.t0 = performance.now() - (this.time * 1000) / this.speed;
    for (const v of this.active()) {
      try { v.audio.currentTime = Math.min(this.time, v.duration()); } catch (e) { /* not loaded */ }
      v.apply(this.time);
      v.showText();
    }
    this._showClock();
  }

  setSpeed(speed) {
    this.speed = speed;
    this.t0 = performance.now() - (this.time * 1000) / this.speed;
    for (const v of this.views) v.audio.playbackRate = speed;
  }

  _showClock() {
    const dur = this.duration();
    this.scrub.value = String(Math.round((dur > 0 ? this.time / dur : 0) * 1000));
    this.clock.textContent = `${this.time.toFixed(2)} / ${dur.toFixed(2)} s`;
  }

  _tick(now) {
    const views = this.active();
    if (this.playing) {
      this.frameTimes.push(now);
      if (this.frameTimes.length > FRAME_LOG) this.frameTimes.shift();
      this.time = ((now - this.t0) / 1000) * this.speed;
      for (const v of views) {
        const audio = v.audio;
        if (!audio.paused && this.time < v.duration() && Math.abs(audio.currentTime - this.time) > 0.08) {
          try { audio.currentTime = this.time; } catch (e) { /* seeking */ }
        }
      }
      if (this.time >= this.duration()) {
        this.time = this.duration();
        this.pause();
      }
      for (const v of views) v.apply(this.time);
      if (now - this._textAt >= TEXT_EVERY_MS || !this.playing) { // text costs layout
        this._textAt = now;
        this._showClock();
        for (const v of views) v.showText();
      }
    }
    for (const v of views) v.render();
    if (this.playing) {
      this.workTimes.push(performance.now() - now);
      if (this.workTimes.length > FRAME_LOG) this.workTimes.shift();
    }
    if (this.playing && !this._started) {
      this._started = true;
      if (this.onPlayStarted) this.onPlayStarted(performance.now());
    }
  }
}
