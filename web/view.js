// palpa view: the zero iso-surface, proxy (green) and HIP (red) with the penetration line and the
// force, an optional φ cross-section, and a replay (time slider, play/pause, speed, |f| and
// penetration plots) or a live palpad. Talks only to palpa's own server (/api/..., /assets/...).
//
// window.palpaView is the page's state, read by the browser test (tests/browser) and handy in the
// console: {ready, info, mesh: {triangles, vertices, bboxMin, bboxMax}, index, time, proxy, hip,
// force, live: {...counters}, errors: []}. Positions are device metres, forces newtons.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import uPlot from 'uplot';

const state = (window.palpaView = {
  ready: false, info: null, mesh: null, index: -1, time: 0, proxy: null, hip: null, force: null,
  live: null, livePolls: 0, errors: [],
});

const $ = (id) => document.getElementById(id);

function fail(message) {
  state.errors.push(String(message));
  const box = $('error');
  box.hidden = false;
  box.textContent = String(message);
}

async function getJson(path) {
  const r = await fetch(path);
  if (!r.ok) throw new Error(`${path}: HTTP ${r.status}: ${await r.text()}`);
  return r.json();
}

// ---- 3-D scene -------------------------------------------------------------------------------
const container = $('scene');
const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
renderer.setPixelRatio(window.devicePixelRatio);
renderer.setClearColor(0x1d2025);
container.appendChild(renderer.domElement);
const scene = new THREE.Scene();
const camera = new THREE.PerspectiveCamera(40, 1, 1e-4, 10);
const controls = new OrbitControls(camera, renderer.domElement);
controls.enableDamping = false;
scene.add(new THREE.HemisphereLight(0xffffff, 0x445566, 1.2));
const headlight = new THREE.DirectionalLight(0xffffff, 1.6);
camera.add(headlight);
headlight.position.set(0.3, 0.5, 1);
scene.add(camera);

const group = new THREE.Group(); // proxy, HIP, line and force
scene.add(group);
group.visible = false;

function resize() {
  const w = container.clientWidth, h = container.clientHeight;
  renderer.setSize(w, h, false);
  camera.aspect = w / Math.max(1, h);
  camera.updateProjectionMatrix();
}
// The replay panel appearing below changes the scene's height, not only a window resize.
new ResizeObserver(resize).observe(container);

let size = 0.05; // bounding-box diagonal, m
let proxyBall, hipBall, line, arrow, forceScale = 0.01;

function decodeMesh(buf) {
  const dv = new DataView(buf);
  const magic = String.fromCharCode(dv.getUint8(0), dv.getUint8(1), dv.getUint8(2), dv.getUint8(3));
  if (magic !== 'PVM1') throw new Error(`/api/mesh: bad magic '${magic}'`);
  const nv = dv.getUint32(4, true), nt = dv.getUint32(8, true), flags = dv.getUint32(12, true);
  let off = 16;
  const positions = new Float32Array(buf, off, 3 * nv); off += 12 * nv;
  let normals = null;
  if (flags & 1) { normals = new Float32Array(buf, off, 3 * nv); off += 12 * nv; }
  const indices = new Uint32Array(buf, off, 3 * nt);
  return { nv, nt, positions, normals, indices };
}

function addMesh(m) {
  const g = new THREE.BufferGeometry();
  g.setAttribute('position', new THREE.BufferAttribute(m.positions, 3));
  if (m.normals) g.setAttribute('normal', new THREE.BufferAttribute(m.normals, 3));
  else g.computeVertexNormals();
  g.setIndex(new THREE.BufferAttribute(m.indices, 1));
  const material = new THREE.MeshStandardMaterial({ color: 0xc9b8a0, roughness: 0.6, metalness: 0.0,
    side: THREE.DoubleSide });
  scene.add(new THREE.Mesh(g, material));
  // The bounding box of exactly what was received (float32), for the header and the test.
  const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
  for (let i = 0; i < 3 * m.nv; i += 3)
    for (let a = 0; a < 3; ++a) {
      const x = m.positions[i + a];
      if (x < lo[a]) lo[a] = x;
      if (x > hi[a]) hi[a] = x;
    }
  state.mesh = { triangles: m.nt, vertices: m.nv, bboxMin: lo, bboxMax: hi };
  const centre = new THREE.Vector3((lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, (lo[2] + hi[2]) / 2);
  size = Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]) || 0.05;
  camera.near = size / 1000;
  camera.far = size * 100;
  camera.position.copy(centre).add(new THREE.Vector3(0.6, -1.2, 0.8).multiplyScalar(size * 1.1));
  camera.up.set(0, 0, 1);
  controls.target.copy(centre);
  controls.update();

  // The HIP is inside the object when in contact (paper Fig. 6b): the markers draw through the
  // surface, on top of it.
  const r = size * 0.018;
  const marker = (color) => new THREE.MeshStandardMaterial({ color, depthTest: false, transparent: true, opacity: 0.95 });
  proxyBall = new THREE.Mesh(new THREE.SphereGeometry(r, 24, 16), marker(0x2ecc40));
  hipBall = new THREE.Mesh(new THREE.SphereGeometry(r, 24, 16), marker(0xff4136));
  hipBall.renderOrder = 3;
  proxyBall.renderOrder = 4;
  const lg = new THREE.BufferGeometry().setFromPoints([new THREE.Vector3(), new THREE.Vector3()]);
  line = new THREE.Line(lg, new THREE.LineBasicMaterial({ color: 0xcccccc, depthTest: false }));
  arrow = new THREE.ArrowHelper(new THREE.Vector3(0, 0, 1), new THREE.Vector3(), size * 0.1, 0xffdc00,
    size * 0.03, size * 0.015);
  line.renderOrder = 2;
  group.add(proxyBall, hipBall, line, arrow);
}

// Places proxy, HIP, line and force arrow; positions in m, force in N.
function showContact(proxy, hip, force) {
  state.proxy = proxy; state.hip = hip; state.force = force;
  if (!proxyBall) return;
  group.visible = true;
  proxyBall.position.set(...proxy);
  hipBall.position.set(...hip);
  const pos = line.geometry.attributes.position;
  pos.setXYZ(0, ...proxy); pos.setXYZ(1, ...hip); pos.needsUpdate = true;
  line.geometry.computeBoundingSphere();
  const f = Math.hypot(...force);
  arrow.visible = f > 1e-9;
  if (arrow.visible) {
    arrow.position.set(...proxy);
    arrow.setDirection(new THREE.Vector3(force[0] / f, force[1] / f, force[2] / f));
    const len = Math.max(size * 0.02, f * forceScale);
    arrow.setLength(len, Math.min(len * 0.3, size * 0.03), Math.min(len * 0.15, size * 0.015));
  }
  const pen = Math.hypot(hip[0] - proxy[0], hip[1] - proxy[1], hip[2] - proxy[2]);
  $('readout').textContent =
    `|f|   ${f.toFixed(3)} N\npen.  ${(pen * 1e3).toFixed(3)} mm\n` +
    `proxy ${proxy.map((x) => (x * 1e3).toFixed(2)).join(', ')} mm`;
}

// ---- cross-section ---------------------------------------------------------------------------
let slicePlane = null, sliceSeq = 0;
async function updateSlice() {
  const info = state.info;
  if (!info) return;
  if (slicePlane) { scene.remove(slicePlane); slicePlane.material.map?.dispose(); slicePlane.geometry.dispose(); slicePlane = null; }
  if (!$('slice-on').checked) { $('slice-label').textContent = ''; return; }
  const axis = 'xyz'.indexOf($('slice-axis').value);
  const u = axis === 0 ? 1 : 0, v = axis === 2 ? 1 : 2; // as palpa slice (host/mesh/slice.h)
  const n = info.dims, o = info.origin_m, h = info.voxel_m;
  const lo = o[axis], hi = o[axis] + (n[axis] - 1) * h;
  const at = lo + ($('slice-at').value / 1000) * (hi - lo);
  $('slice-label').textContent = `${'xyz'[axis]} = ${(at * 1e3).toFixed(2)} mm`;
  const seq = ++sliceSeq;
  const r = await fetch(`/api/slice?axis=${'xyz'[axis]}&at=${at.toPrecision(17)}`);
  if (!r.ok) { fail(`/api/slice: HTTP ${r.status}: ${await r.text()}`); return; }
  const bitmap = await createImageBitmap(await r.blob());
  if (seq !== sliceSeq) return; // a newer request superseded this one
  const tex = new THREE.Texture(bitmap);
  tex.colorSpace = THREE.SRGBColorSpace;
  tex.flipY = false;
  tex.needsUpdate = true;
  // The panel spans node −½ … n − ½ on both of its axes; image row 0 is the top (v largest).
  const u0 = o[u] - h / 2, u1 = o[u] + (n[u] - 0.5) * h, v0 = o[v] - h / 2, v1 = o[v] + (n[v] - 0.5) * h;
  const g = new THREE.BufferGeometry();
  const corner = (uu, vv) => { const p = [0, 0, 0]; p[axis] = at; p[u] = uu; p[v] = vv; return p; };
  g.setAttribute('position', new THREE.Float32BufferAttribute(
    [...corner(u0, v0), ...corner(u1, v0), ...corner(u1, v1), ...corner(u0, v1)], 3));
  g.setAttribute('uv', new THREE.Float32BufferAttribute([0, 1, 1, 1, 1, 0, 0, 0], 2));
  g.setIndex([0, 1, 2, 0, 2, 3]);
  slicePlane = new THREE.Mesh(g, new THREE.MeshBasicMaterial({ map: tex, side: THREE.DoubleSide,
    transparent: true, opacity: 0.85 }));
  scene.add(slicePlane);
}
for (const id of ['slice-on', 'slice-axis', 'slice-at']) $(id).addEventListener('input', updateSlice);

// ---- replay ----------------------------------------------------------------------------------
let trace = null, playing = false, plot = null, lastFrame = 0;

// Last row with t ≤ time (binary search).
function rowAt(time) {
  const t = trace.t_s;
  let lo = 0, hi = t.length - 1;
  if (time <= t[0]) return 0;
  while (lo < hi) {
    const mid = (lo + hi + 1) >> 1;
    if (t[mid] <= time) lo = mid; else hi = mid - 1;
  }
  return lo;
}

function showRow(i) {
  state.index = i;
  state.time = trace.t_s[i];
  $('time').value = String(i);
  $('time-label').textContent = `${state.time.toFixed(3)} s`;
  showContact(trace.proxy_m[i], trace.hip_m[i], trace.force_n[i]);
  if (plot) plot.redraw(false, false);
}

// Plot points: at most ~4 per pixel column, keeping each bucket's peak so spikes stay visible.
function decimate(t, ys, max) {
  const n = t.length, step = Math.max(1, Math.ceil(n / max));
  const out = [[], ...ys.map(() => [])];
  for (let s = 0; s < n; s += step) {
    const e = Math.min(n, s + step);
    let k = s;
    for (let i = s; i < e; ++i) if (ys[0][i] > ys[0][k]) k = i;
    out[0].push(t[k]);
    ys.forEach((y, j) => out[j + 1].push(y[k]));
  }
  return out;
}

function setupReplay(tr) {
  trace = tr;
  state.trace = { rows: tr.t_s.length, t0: tr.t_s[0], t1: tr.t_s[tr.t_s.length - 1] };
  $('replay').hidden = false;
  $('h-mode').textContent = `replay ${tr.source} (${tr.t_s.length} rows)`;
  const n = tr.t_s.length;
  const fmag = new Array(n), pen = new Array(n);
  let fmax = 0;
  for (let i = 0; i < n; ++i) {
    const f = tr.force_n[i], p = tr.proxy_m[i], h = tr.hip_m[i];
    fmag[i] = Math.hypot(f[0], f[1], f[2]);
    pen[i] = Math.hypot(h[0] - p[0], h[1] - p[1], h[2] - p[2]) * 1e3;
    fmax = Math.max(fmax, fmag[i]);
  }
  forceScale = fmax > 0 ? (size * 0.25) / fmax : 0.01;
  const slider = $('time');
  slider.max = String(n - 1);
  slider.addEventListener('input', () => { playing = false; $('play').textContent = '▶ play'; showRow(Number(slider.value)); });
  $('play').addEventListener('click', () => {
    playing = !playing;
    if (playing && state.index >= n - 1) showRow(0);
    $('play').textContent = playing ? '❚❚ pause' : '▶ play';
    lastFrame = performance.now();
  });
  const cursor = {
    hooks: {
      draw: [(u) => {
        const x = Math.round(u.valToPos(state.time, 'x', true));
        const ctx = u.ctx;
        ctx.save();
        ctx.strokeStyle = '#d00';
        ctx.lineWidth = 2;
        ctx.beginPath();
        ctx.moveTo(x, u.bbox.top);
        ctx.lineTo(x, u.bbox.top + u.bbox.height);
        ctx.stroke();
        ctx.restore();
      }],
    },
  };
  const width = Math.max(400, $('plots').clientWidth - 8);
  const data = decimate(tr.t_s, [fmag, pen], 2 * width);
  plot = new uPlot({
    width, height: 190, plugins: [cursor],
    scales: { x: { time: false } },
    axes: [{ label: 't (s)' }, { label: '|f| (N)', scale: 'N' }, { label: 'pen. (mm)', scale: 'mm', side: 1, size: 60, labelSize: 30, grid: { show: false } }],
    series: [{ label: 't (s)' }, { label: '|f| (N)', stroke: '#d38b00', scale: 'N', width: 1.5 },
      { label: 'penetration (mm)', stroke: '#0074d9', scale: 'mm', width: 1.5 }],
  }, data, $('plots'));
  // Clicking the plot moves the time there.
  plot.over.addEventListener('click', () => {
    const left = plot.cursor.left;
    if (left != null && left >= 0) { playing = false; $('play').textContent = '▶ play'; showRow(rowAt(plot.posToVal(left, 'x'))); }
  });
  showRow(0);
}

function advance(now) {
  if (!playing || !trace) return;
  const dt = (now - lastFrame) / 1000;
  const speed = Number($('speed').value);
  const t = state.time + dt * speed;
  const last = trace.t_s.length - 1;
  if (t >= trace.t_s[last]) { showRow(last); playing = false; $('play').textContent = '▶ play'; return; }
  const i = rowAt(t);
  showRow(i);
  state.time = t; // keep sub-row time so slow speeds still advance
}

// ---- live ------------------------------------------------------------------------------------
// The counters palpad reports, under the names its status may use (first match wins).
const counterKeys = {
  'c-ticks': ['ticks', 'last_tick', 'samples'],
  'c-overruns': ['overruns'],
  'c-max-tick': ['max_tick_ns', 'max_compute_ns', 'max_tick_time_ns'],
  'c-clamps': ['clamps', 'force_clamps', 'clamped', 'clamped_forces'],
  'c-estops': ['estops', 'estop_count', 'estop_ticks', 'e_stops'],
};
function pick(obj, keys) { for (const k of keys) if (obj && obj[k] !== undefined) return obj[k]; return undefined; }

async function pollLive() {
  try {
    const r = await fetch('/api/live');
    const j = await r.json();
    state.livePolls += 1;
    const s = j.status;
    $('live-state').textContent = j.connected ? `connected to ${j.endpoint ?? ''} (${j.age_ms ?? 0} ms old)`
      : `not connected: ${j.last_error || j.error || 'waiting'}`;
    if (s) {
      // The controller may render another field than this page shows (an upload since): say so.
      const crc = s.field_crc32c === undefined ? '' : String(s.field_crc32c).replace(/^0x/, '');
      if (crc && state.info && crc !== state.info.crc32c)
        $('live-state').textContent += ` — WARNING: palpad renders field ${crc}, this page shows ${state.info.crc32c}`;
      const live = {};
      for (const [id, keys] of Object.entries(counterKeys)) {
        const v = pick(s, keys);
        live[id.slice(2)] = v;
        $(id).textContent = v === undefined ? '–' : id === 'c-max-tick' ? `${(v / 1000).toFixed(1)} µs` : String(v);
      }
      state.live = live;
      const hip = pick(s, ['hip_m']), proxy = pick(s, ['proxy_m']), force = pick(s, ['force_n']);
      if (Array.isArray(hip) && Array.isArray(proxy)) showContact(proxy, hip, Array.isArray(force) ? force : [0, 0, 0]);
    }
  } catch (e) {
    $('live-state').textContent = `poll failed: ${e}`;
  }
  setTimeout(pollLive, 33); // ≥ 30 Hz; the server keeps only the latest record
}

// ---- start -----------------------------------------------------------------------------------
function frame(now) {
  advance(now);
  lastFrame = now;
  controls.update();
  renderer.render(scene, camera);
  requestAnimationFrame(frame);
}

async function main() {
  resize();
  const info = (state.info = await getJson('/api/info'));
  $('field-name').textContent = info.field;
  $('h-dims').textContent = info.dims.join(' × ');
  $('h-voxel').textContent = `${(info.voxel_m * 1e3).toFixed(4)} mm`;
  $('h-method').textContent = info.method;
  $('h-crc').textContent = info.crc32c;
  const r = await fetch('/api/mesh');
  if (!r.ok) throw new Error(`/api/mesh: HTTP ${r.status}`);
  addMesh(decodeMesh(await r.arrayBuffer()));
  $('h-mesh').textContent = `${state.mesh.triangles} triangles`;
  if (info.trace) setupReplay(await getJson('/api/trace'));
  if (info.live && info.live.endpoint) {
    $('live-box').hidden = false;
    $('h-mode').textContent = `live ${info.live.endpoint}`;
    if (info.live.available) pollLive();
    else $('live-state').textContent = info.live.reason;
  }
  requestAnimationFrame(frame);
  // Ready once a frame with the mesh has been drawn.
  requestAnimationFrame(() => requestAnimationFrame(() => { state.ready = true; }));
}

main().catch((e) => { fail(e.message || e); console.error(e); });
