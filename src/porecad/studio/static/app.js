// porecad studio: the page. Every URL here is relative to /s/TOKEN/, so every request carries the token.
// three.js: the classic script porecad/vendor/three.classic.js (loaded before this one) defines window.THREE
const THREE = window.THREE;
const { OrbitControls } = THREE;

const $ = (id) => document.getElementById(id);
const state = { schema: null, design: {}, gen: 0, shown: {}, timer: null, exportId: null, curve: null,
                points: [], sections: null, window: null, analysis: null, levels: {}, fitted: null };

// ------------------------------------------------------------------------------------------- messages
function say(text, kind = 'error') {
  const m = $('message');
  m.textContent = text;
  m.className = 'message ' + kind;
  m.hidden = !text;
}
$('message').addEventListener('click', () => { $('message').hidden = true; });

async function call(method, path, body, headers) {
  let resp;
  try {
    resp = await fetch(path, { method, body, headers: headers || (body ? { 'content-type': 'application/json' } : {}) });
  } catch (e) {
    throw new Error('the studio server cannot be reached (' + e.message + ')');
  }
  const type = resp.headers.get('content-type') || '';
  if (!type.includes('json')) {
    if (!resp.ok) throw new Error('HTTP ' + resp.status);
    return resp;
  }
  const data = await resp.json();
  if (!resp.ok || data.error) { const err = new Error(data.error || ('HTTP ' + resp.status)); err.data = data; throw err; }
  return data;
}
const fmt = (x, d = 3) => (x === null || x === undefined || Number.isNaN(x)) ? '–' : Number(x).toFixed(d);
const mm = (x) => (x === null || x === undefined) ? '–' : fmt(x, x < 1 ? 3 : 2) + ' mm';

// ------------------------------------------------------------------------------------------- form
function fieldVisible(f) {
  if (!f.jobs.includes(state.design.job)) return false;
  for (const [k, vals] of Object.entries(f.when || {})) {
    const v = k === 'body_kind' ? bodyKind() : state.design[k];
    if (vals.includes('nonzero')) { if (!Number(v)) return false; continue; }
    if (!vals.includes(v === undefined ? fieldDefault(k) : v)) return false;
  }
  return true;
}
function defaultOf(f) {  // the recipe schema's default for the design's job (a field may serve several jobs)
  return f.defaults && f.defaults[state.design.job] !== undefined ? f.defaults[state.design.job] : f.default;
}
function fieldDefault(name) {
  const f = state.schema.fields.find((x) => x.name === name);
  return f ? defaultOf(f) : undefined;
}
function bodyKind() {
  const job = state.design.job;
  const name = job === 'vessel' ? state.design.centreline : state.design.body;
  if ((state.schema.built_in[job] || []).includes(name)) return 'builtin';
  const up = state.schema.uploads.find((u) => u.name === name);
  return up ? up.kind : 'builtin';
}
function bodyOptions(f) {
  const job = state.design.job;
  const opts = f.name === 'centreline' ? [] : (state.schema.built_in[job] || []).map((b) => [b, b + ' (built-in)']);
  const kinds = state.schema.upload_kinds[job] || [];
  for (const u of state.schema.uploads) if (kinds.includes(u.kind)) opts.push([u.name, u.name]);
  if (!opts.length) opts.push(['', '(upload a file)']);
  return opts;
}
function buildForm() {
  const form = $('form');
  form.textContent = '';
  for (const f of state.schema.fields) {
    const row = document.createElement('div');
    row.className = 'field';
    row.dataset.field = f.name;
    const label = document.createElement('label');
    label.textContent = f.label;
    label.htmlFor = 'f-' + f.name;
    if (f.help) label.title = f.help;
    let input;
    if (f.kind === 'select' || f.kind === 'body') {
      input = document.createElement('select');
    } else {
      input = document.createElement('input');
      input.type = f.kind === 'check' ? 'checkbox' : (f.kind === 'number' || f.kind === 'int') ? 'number' : 'text';
      if (input.type === 'number') input.step = f.step || (f.kind === 'int' ? 1 : 'any');
    }
    input.id = 'f-' + f.name;
    input.name = f.name;
    if (f.help) input.title = f.help;
    input.addEventListener(input.tagName === 'SELECT' || input.type === 'checkbox' ? 'change' : 'input', () => onInput(f, input));
    row.append(label, input);
    form.append(row);
  }
}
function fillForm() {
  $('job').value = state.design.job;
  for (const f of state.schema.fields) {
    const input = $('f-' + f.name);
    const row = input.parentElement;
    row.classList.toggle('hidden', !fieldVisible(f));
    row.classList.remove('bad');
    if (f.kind === 'select' || f.kind === 'body') {
      const opts = f.kind === 'body' ? bodyOptions(f) : f.options.map((o) => [o, o]);
      input.textContent = '';
      for (const [v, t] of opts) { const o = document.createElement('option'); o.value = v; o.textContent = t; input.append(o); }
    }
    let v = state.design[f.name];
    if (v === undefined) v = defaultOf(f);
    if (f.kind === 'body' && !bodyOptions(f).some(([o]) => o === v)) {
      v = bodyOptions(f)[0][0];
      if (fieldVisible(f)) state.design[f.name] = v;
    }
    if (f.kind === 'check') input.checked = !!v;
    else if (f.kind === 'int3') input.value = Array.isArray(v) ? v.join(' ') : (v ?? '');
    else input.value = v ?? '';
  }
}
function onInput(f, input) {
  let v;
  if (f.kind === 'check') v = input.checked;
  else if (f.kind === 'number' || f.kind === 'int') v = input.value === '' ? null : Number(input.value);
  else v = input.value;
  state.design[f.name] = v;
  if (f.kind === 'select' || f.kind === 'body' || f.kind === 'check') fillForm();
  schedule();
}
function formDesign() {
  const d = { job: state.design.job };
  for (const f of state.schema.fields) {
    if (!fieldVisible(f) && !['min_feature'].includes(f.name)) continue;
    const v = state.design[f.name] === undefined ? defaultOf(f) : state.design[f.name];
    if (v !== null && v !== undefined && v !== '') d[f.name] = v;
  }
  return d;
}
function schedule(delay = 200) {
  clearTimeout(state.timer);
  state.timer = setTimeout(preview, delay);
}

// ------------------------------------------------------------------------------------------- 3D view
const canvas = $('canvas');
const renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
renderer.localClippingEnabled = true;
const scene = new THREE.Scene();
scene.background = new THREE.Color(0xe9edf2);
const camera = new THREE.PerspectiveCamera(40, 1, 0.01, 1e6);
camera.up.set(0, 0, 1);
camera.position.set(3, -4, 3);
const controls = new OrbitControls(camera, canvas);
scene.add(new THREE.HemisphereLight(0xffffff, 0x55606a, 1.6));
const sun = new THREE.DirectionalLight(0xffffff, 1.8);
scene.add(sun);
const clip = new THREE.Plane(new THREE.Vector3(0, 0, -1), 0);
const meshes = { part: null, window: null };
const materials = {
  part: new THREE.MeshStandardMaterial({ color: 0xd9a066, roughness: 0.55, metalness: 0.05, side: THREE.DoubleSide }),
  window: new THREE.MeshStandardMaterial({ color: 0x5b8fd9, roughness: 0.5, metalness: 0.05, side: THREE.DoubleSide,
                                           clippingPlanes: [clip] }),
};
let box = null;
function resize() {
  const w = canvas.clientWidth, h = canvas.clientHeight;
  if (canvas.width !== Math.floor(w * renderer.getPixelRatio()) || canvas.height !== Math.floor(h * renderer.getPixelRatio())) {
    renderer.setSize(w, h, false);
    camera.aspect = w / Math.max(h, 1);
    camera.updateProjectionMatrix();
  }
}
function render() {
  resize();
  sun.position.copy(camera.position).add(new THREE.Vector3(1, 1, 2));
  renderer.render(scene, camera);
}
controls.addEventListener('change', render);
window.addEventListener('resize', render);
function fit() {
  const which = showMode() === 'window' && meshes.window ? meshes.window : meshes.part;
  if (!which) return;
  const b = new THREE.Box3().setFromObject(which);
  const c = b.getCenter(new THREE.Vector3());
  const r = b.getSize(new THREE.Vector3()).length() / 2 || 1;
  const dir = new THREE.Vector3(0.9, -1.3, 0.9).normalize();
  camera.position.copy(c).addScaledVector(dir, r / Math.tan(THREE.MathUtils.degToRad(camera.fov / 2)) * 1.2);
  camera.near = r / 100; camera.far = r * 100; camera.updateProjectionMatrix();
  controls.target.copy(c);
  controls.update();
  render();
}
$('fit').addEventListener('click', fit);
function showMode() { return document.querySelector('input[name=show]:checked').value; }
for (const r of document.querySelectorAll('input[name=show]')) r.addEventListener('change', () => { state.userShow = true; applyShow(); fit(); });
function applyShow() {
  const mode = showMode();
  if (meshes.part) meshes.part.visible = mode === 'part' || !meshes.window;
  if (meshes.window) meshes.window.visible = mode === 'window';
  render();
}
function setMesh(which, buf) {
  const dv = new DataView(buf);
  const magic = String.fromCharCode(dv.getUint8(0), dv.getUint8(1), dv.getUint8(2), dv.getUint8(3));
  if (magic !== 'PCM1') throw new Error('bad preview mesh');
  const nv = dv.getUint32(4, true), nf = dv.getUint32(8, true);
  const pos = new Float32Array(buf, 12, nv * 3);
  const idx = new Uint32Array(buf, 12 + nv * 12, nf * 3);
  const g = new THREE.BufferGeometry();
  g.setAttribute('position', new THREE.BufferAttribute(pos, 3));
  g.setIndex(new THREE.BufferAttribute(idx, 1));
  g.computeVertexNormals();
  if (meshes[which]) { scene.remove(meshes[which]); meshes[which].geometry.dispose(); }
  meshes[which] = new THREE.Mesh(g, materials[which]);
  scene.add(meshes[which]);
  g.computeBoundingBox();
  const key = state.design.job + ':' + [g.boundingBox.min.toArray(), g.boundingBox.max.toArray()].flat().map((x) => x.toFixed(1)).join(',');
  applyShow();
  if (which === 'part' && key !== state.fitted) { state.fitted = key; fit(); }
  render();
}

// ------------------------------------------------------------------------------------------- preview
async function preview() {
  const design = formDesign();
  for (const row of document.querySelectorAll('form .field.bad')) row.classList.remove('bad');
  let res;
  try {
    res = await call('POST', 'api/preview', JSON.stringify({ design }));
  } catch (e) {
    say(e.message);
    const field = e.data && (e.data.field || keyField(e.data.key));
    if (field && $('f-' + field)) $('f-' + field).parentElement.classList.add('bad');
    $('preview-status').textContent = 'not previewed: see the message below';
    return;
  }
  if ($('message').classList.contains('error')) say('');
  state.gen = res.gen;
  state.shown = {};
  state.levels = {};
  state.analysis = null;
  state.window = null;
  state.curve = res.curve;
  state.points = res.points || [];
  $('recipe').textContent = res.recipe;
  drawCurve();
  poll(res.gen);
}
function keyField(key) {
  if (!key) return null;
  const map = { 'tpms.porosity': 'value', 'tpms.threshold': 'value', 'tpms.cell_size': 'cell_size', 'tpms.type': 'type',
    'tpms.structure': 'structure', 'domain.cells': 'cells', 'sampling.resolution': 'resolution', 'sampling.voxel': 'voxel',
    'domain.skin': 'skin', 'domain.boundary': 'boundary', 'tpms.periods': 'periods', 'grid': 'grid',
    'mesh.resolution': 'resolution', 'tis.relative': 'relative', 'tis.lambda': 'lambda', 'domain.tets': 'tets',
    'voxel': 'voxel', 'wall': 'wall', 'domain.path': 'body', 'body.path': 'body', 'input.path': 'centreline' };
  return map[key] || (key.startsWith('grading') ? 'grading' : key.startsWith('tdf') ? 'value' : null);
}
async function poll(gen) {
  while (gen === state.gen) {
    let s;
    try { s = await call('GET', 'api/preview/' + gen); } catch (e) { say(e.message); return; }
    if (gen !== state.gen) return;
    for (const name of ['coarse', 'window', 'refined']) {
      if (s.levels[name] && !state.shown[name]) {
        state.shown[name] = true;
        state.levels[name] = s.levels[name];
        const buf = await (await call('GET', 'api/preview/' + gen + '/' + name)).arrayBuffer();
        if (gen !== state.gen) return;
        setMesh(name === 'window' ? 'window' : 'part', buf);
        if (name === 'window') state.window = s.levels[name].window;
        if (name !== 'window' && s.levels[name].per_cell !== undefined) {
          // too few samples per cell for the whole part to show the lattice: show the window as built
          state.sketch = s.levels[name].per_cell < 6;
          if (!state.userShow) {
            document.querySelector(`input[name=show][value=${state.sketch ? 'window' : 'part'}]`).checked = true;
            applyShow();
            if (!state.sketch) fit();
          }
        }
        if (name === 'window' && state.sketch && !state.userShow) fit();
        readouts();
      }
    }
    if (s.analysis && !state.analysis) {
      state.analysis = s.analysis;
      const buf = await (await call('GET', 'api/preview/' + gen + '/sections')).arrayBuffer();
      if (gen !== state.gen) return;
      loadSections(buf);
      readouts();
    }
    const stage = s.stage ? s.stage + (s.progress ? ` ${s.progress[1]}/${s.progress[2]}` : '') : '';
    if (s.state === 'failed') { say(s.error); $('preview-status').textContent = 'preview failed'; return; }
    if (s.state === 'done' || s.state === 'superseded') { statusLine(); return; }
    statusLine(stage);
    await new Promise((r) => setTimeout(r, 250));
  }
}
function statusLine(stage) {
  const best = state.levels.refined || state.levels.coarse;
  let t = '';
  if (best) {
    const samp = best.sampling ? Object.entries(best.sampling).map(([k, v]) => `${k} ${fmt(v, k === 'voxel' ? 3 : 0)}`).join(', ') : '';
    const exp = best.export_sampling ? Object.entries(best.export_sampling).map(([k, v]) => `${k} ${fmt(v, k === 'voxel' ? 3 : 0)}`).join(', ') : '';
    t = `${state.levels.refined ? 'refined' : 'coarse'} preview in ${fmt(best.seconds, 1)} s (${samp}; export: ${exp})`;
    if (best.window_cells) t += ` · a window of ${best.window_cells.join('×')} cells`;
  }
  $('preview-status').textContent = stage ? `${t ? t + ' · ' : ''}computing ${stage}…` : (t || 'ready');
  const info = [];
  for (const [name, l] of Object.entries(state.levels)) {
    info.push(`${name}: ${(l.report.triangles || 0).toLocaleString()} triangles` +
      (l.lod_cell ? ` (shown: ${l.display_faces.toLocaleString()}, level of detail ${fmt(l.lod_cell, 2)} mm)` : ''));
  }
  $('view-info').textContent = info.join(' · ');
}
function readouts() {
  const best = (state.levels.refined || state.levels.coarse || {}).report || {};
  const w = state.levels.window;
  const rough = state.sketch || (best.warning_details || []).some((w) => w.code === 'voxel-coarse');
  $('readout-porosity').textContent = fmt(best.porosity) + (rough ? ' (coarse preview)' : '');
  $('readout-window').textContent = w ? fmt(w.report.porosity) : '–';
  const target = best.target_porosity ?? best.porosity_calibrated;
  $('readout-target').textContent = target !== undefined ? fmt(target) :
    (best.porosity_min !== undefined ? `${fmt(best.porosity_min)}–${fmt(best.porosity_max)}` : '–');
  $('readout-threshold').textContent = typeof best.threshold === 'number' ? fmt(best.threshold, 4) : '–';
  $('readout-triangles').textContent = best.triangles ? best.triangles.toLocaleString() + ' (preview)' : '–';
  const a = state.analysis;
  $('readout-pore').textContent = a ? `${mm(a.pore_size_d50)} (${fmt(a.pore_size_d10, 2)}–${fmt(a.pore_size_d90, 2)})` : '–';
  $('readout-strut').textContent = a ? `${mm(a.strut_size_d50)} (${fmt(a.strut_size_d10, 2)}–${fmt(a.strut_size_d90, 2)})` : '–';
  const flags = $('flags');
  flags.textContent = '';
  const flag = (text, ok, warn) => { const s = document.createElement('span'); s.className = 'flag ' + (ok ? 'ok' : warn ? 'warn' : 'bad'); s.textContent = text; flags.append(s); };
  if (best.closed !== undefined) {
    flag(best.closed ? 'closed' : 'open', best.closed);
    flag(best.manifold ? 'manifold' : 'non-manifold', best.manifold);
    flag(best.oriented ? 'oriented' : 'mis-oriented', best.oriented);
  }
  if (best.in_valid_range !== undefined) flag(best.in_valid_range ? 'in valid range' : 'outside valid range', best.in_valid_range, true);
  if (a && a.percolation) flag(Object.values(a.percolation).every(Boolean) ? 'pores connected' : 'pores not connected', Object.values(a.percolation).every(Boolean), true);
  const warns = [...(best.warnings || [])];
  if (best.in_valid_range === false) warns.push('outside the valid range: closed pores or floating pieces are possible');
  const minf = Number(state.design.min_feature ?? fieldDefault('min_feature'));
  if (a && minf > 0 && a.thin_fraction > 0.01) {
    warns.push(`walls thinner than the printer's minimum feature (${minf} mm): ${(100 * a.thin_fraction).toFixed(0)} % of the material (${a.of})`);
  }
  if (a && minf > 0 && a.voxel > minf && a.strut_size_d10 < minf + 2 * a.voxel) warns.push(`the thickness analysis voxel (${fmt(a.voxel, 3)} mm) is coarser than the minimum feature`);
  const ul = $('warnings');
  ul.textContent = '';
  for (const w2 of warns) { const li = document.createElement('li'); li.textContent = w2; ul.append(li); }
  statusLine();
  drawCurve();
}

// ------------------------------------------------------------------------------------------- sections
function loadSections(buf) {
  const dv = new DataView(buf);
  const n = dv.getUint32(0, true);
  const meta = JSON.parse(new TextDecoder().decode(new Uint8Array(buf, 4, n)));
  const [nz, ny, nx] = meta.shape;
  const count = nz * ny * nx;
  state.sections = { meta, strut: new Uint8Array(buf, 4 + n, count), pore: new Uint8Array(buf, 4 + n + count, count) };
  drawSection();
}
const VIRIDIS = [[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]];
function viridis(t) {
  const x = Math.max(0, Math.min(1, t)) * (VIRIDIS.length - 1);
  const i = Math.min(Math.floor(x), VIRIDIS.length - 2), f = x - i;
  return VIRIDIS[i].map((c, k) => c + (VIRIDIS[i + 1][k] - c) * f);
}
function drawSection() {
  const s = state.sections;
  const cv = $('section-canvas');
  const ctx = cv.getContext('2d');
  if (!s) { ctx.clearRect(0, 0, cv.width, cv.height); return; }
  const [nz, ny, nx] = s.meta.shape;
  const k = Math.min(nz - 1, Math.round($('section-slider').value / 100 * (nz - 1)));
  const img = ctx.createImageData(nx, ny);
  const minf = s.meta.min_feature || 0;
  for (let j = 0; j < ny; j++) {
    for (let i = 0; i < nx; i++) {
      const src = (k * ny + j) * nx + i, dst = ((ny - 1 - j) * nx + i) * 4;
      const st = s.strut[src];
      let c;
      if (st) {
        const t = (st - 1) * s.meta.strut_scale;
        c = minf && t < minf ? [220, 40, 40] : viridis(t / s.meta.strut_max);
      } else {
        const p = (s.pore[src] - 1) / 254;
        c = [30 + 40 * p, 34 + 44 * p, 44 + 50 * p];
      }
      img.data[dst] = c[0]; img.data[dst + 1] = c[1]; img.data[dst + 2] = c[2]; img.data[dst + 3] = 255;
    }
  }
  const tmp = document.createElement('canvas');
  tmp.width = nx; tmp.height = ny;
  tmp.getContext('2d').putImageData(img, 0, 0);
  ctx.imageSmoothingEnabled = false;
  ctx.fillStyle = '#222';
  ctx.fillRect(0, 0, cv.width, cv.height);
  const scale = Math.min(cv.width / nx, cv.height / ny);
  ctx.drawImage(tmp, (cv.width - nx * scale) / 2, (cv.height - ny * scale) / 2, nx * scale, ny * scale);
  const z = s.meta.origin[2] + k * s.meta.spacing;
  const leg = $('section-legend');
  leg.textContent = '';
  leg.append(`z = ${fmt(z, 2)} mm (${s.meta.of}) · wall 0 `);
  const bar = document.createElement('span'); bar.className = 'legend-bar'; leg.append(bar);
  leg.append(` ${fmt(s.meta.strut_max, 2)} mm` + (minf ? ` · red: < ${minf} mm` : '') + ' · pores dark');
  // the window mesh is cut at the section in the 3D view
  clip.constant = z;
  render();
}
$('section-slider').addEventListener('input', drawSection);

// ------------------------------------------------------------------------------------------- curve
function drawCurve() {
  const svg = $('curve');
  svg.textContent = '';
  const NS = 'http://www.w3.org/2000/svg';
  const el = (tag, attrs, text) => { const e = document.createElementNS(NS, tag); for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v); if (text !== undefined) e.textContent = text; svg.append(e); return e; };
  const c = state.curve;
  if (!c) { el('text', { x: 20, y: 95, 'font-size': 11, fill: '#66727f' }, 'no porosity–threshold curve for this job'); return; }
  const L = 38, R = 250, T = 10, B = 160;
  const xs = c.threshold, ys = c.porosity;
  const x0 = xs[0], x1 = xs[xs.length - 1];
  const X = (x) => L + (x - x0) / (x1 - x0 || 1) * (R - L), Y = (y) => B - y * (B - T);
  if (c.valid && c.valid.threshold) {
    const [a, b] = c.valid.threshold;
    el('rect', { x: X(Math.min(a, b)), y: T, width: Math.abs(X(b) - X(a)), height: B - T, fill: '#e3f1e4' });
  }
  el('line', { x1: L, y1: B, x2: R, y2: B, stroke: '#888' });
  el('line', { x1: L, y1: T, x2: L, y2: B, stroke: '#888' });
  el('path', { d: xs.map((x, i) => `${i ? 'L' : 'M'}${X(x).toFixed(1)},${Y(ys[i]).toFixed(1)}`).join(''), fill: 'none', stroke: '#2563eb', 'stroke-width': 2 });
  for (const p of state.points) el('circle', { cx: X(p.threshold), cy: Y(p.porosity), r: 4.5, fill: '#d9480f', stroke: '#fff' });
  el('text', { x: L - 4, y: T + 4, 'font-size': 9, 'text-anchor': 'end' }, '1');
  el('text', { x: L - 4, y: B, 'font-size': 9, 'text-anchor': 'end' }, '0');
  el('text', { x: L, y: B + 12, 'font-size': 9 }, fmt(x0, 2));
  el('text', { x: R, y: B + 12, 'font-size': 9, 'text-anchor': 'end' }, fmt(x1, 2));
  el('text', { x: (L + R) / 2, y: B + 24, 'font-size': 10, 'text-anchor': 'middle' }, `threshold C (${c.type} ${c.structure}; green: valid range)`);
  el('text', { x: 10, y: (T + B) / 2, 'font-size': 10, transform: `rotate(-90 10 ${(T + B) / 2})`, 'text-anchor': 'middle' }, 'porosity');
}

// ------------------------------------------------------------------------------------------- files
function listUploads() {
  const ul = $('uploads');
  ul.textContent = '';
  for (const u of state.schema.uploads) {
    const li = document.createElement('li');
    li.textContent = `${u.name} (${u.kind}${u.triangles ? ', ' + u.triangles.toLocaleString() + ' triangles' : ''})`;
    ul.append(li);
  }
}
$('upload-input').addEventListener('change', async (ev) => {
  const file = ev.target.files[0];
  ev.target.value = '';
  if (!file) return;
  if (file.size > state.schema.max_upload) { say(`${file.name}: ${file.size.toLocaleString()} bytes is over the upload limit of ${state.schema.max_upload.toLocaleString()} bytes`); return; }
  say(`uploading ${file.name}…`, 'info');
  try {
    const res = await call('PUT', 'api/upload?name=' + encodeURIComponent(file.name), file, { 'content-type': 'application/octet-stream' });
    state.schema.uploads = res.uploads;
    const u = res.upload;
    const repairs = (u.repairs || []).length ? ' — repaired: ' + u.repairs.join('; ') : '';
    say(`${u.name} uploaded (${u.kind}${u.triangles ? ', ' + u.triangles.toLocaleString() + ' triangles' : ''})${repairs}`, 'info');
    listUploads();
    const job = state.design.job;
    if ((state.schema.upload_kinds[job] || []).includes(u.kind)) state.design[job === 'vessel' ? 'centreline' : 'body'] = u.name;
    fillForm();
    schedule(0);
  } catch (e) { say(e.message); }
});
$('recipe-input').addEventListener('change', async (ev) => {
  const file = ev.target.files[0];
  ev.target.value = '';
  if (!file) return;
  try {
    const res = await call('POST', 'api/recipe', JSON.stringify({ text: await file.text() }));
    state.design = res.design;
    fillForm();
    say(res.notice || `${file.name} opened`, res.notice ? 'error' : 'info');
    schedule(0);
  } catch (e) { say(e.message); }
});
$('job').addEventListener('change', () => { state.design.job = $('job').value; fillForm(); schedule(0); });

// ------------------------------------------------------------------------------------------- export
$('export-btn').addEventListener('click', async () => {
  $('export-links').textContent = '';
  try {
    const res = await call('POST', 'api/export', JSON.stringify({ design: formDesign(), format: $('export-format').value, report: $('export-report').checked }));
    state.exportId = res.id;
    $('export-cancel').hidden = false;
    $('export-progress').hidden = false;
    pollExport(res.id);
  } catch (e) { say(e.message); }
});
$('export-cancel').addEventListener('click', async () => {
  if (state.exportId) await call('POST', `api/export/${state.exportId}/cancel`).catch((e) => say(e.message));
});
async function pollExport(id) {
  for (;;) {
    let s;
    try { s = await call('GET', 'api/export/' + id); } catch (e) { say(e.message); return; }
    $('export-progress').max = s.total || 1;
    $('export-progress').value = s.done || 0;
    $('export-status').textContent = s.state === 'running' ? `${s.cancelling ? 'cancelling' : 'building'}: ${s.stage} ${s.done}/${s.total}` : '';
    if (s.state !== 'running') {
      $('export-cancel').hidden = true;
      $('export-progress').hidden = true;
      if (s.state === 'done') showExport(id, s);
      else if (s.state === 'cancelled') { $('export-status').textContent = 'export cancelled; nothing was kept'; }
      else { $('export-status').textContent = 'export failed'; say(s.error); }
      return;
    }
    await new Promise((r) => setTimeout(r, 300));
  }
}
function showExport(id, s) {
  const r = s.summary || {};
  $('export-status').textContent = `built in ${fmt(s.seconds, 1)} s: ${(r.triangles || 0).toLocaleString()} triangles, ` +
    `porosity ${fmt(r.porosity)}, ${r.closed && r.manifold ? 'closed and manifold' : 'NOT closed'}`;
  const links = $('export-links');
  links.textContent = '';
  const link = (id2, text, href, download) => { const a = document.createElement('a'); a.id = id2; a.textContent = text; a.href = href; if (download) a.download = ''; else a.target = '_blank'; links.append(a); };
  const mesh = s.files.find((f) => f.startsWith(s.stem + '.') && state.schema.export_formats.includes(f.split('.').pop()));
  if (mesh) link('dl-mesh', 'mesh', `api/export/${id}/file/${mesh}`, true);
  const rec = s.files.find((f) => f.endsWith('.toml'));
  if (rec) link('dl-recipe', 'recipe', `api/export/${id}/file/${rec}`, true);
  if (s.report_files && s.report_files.includes('report.html')) link('dl-report', 'report', `api/export/${id}/report/report.html`, false);
  const js = s.files.find((f) => f.endsWith('.report.json'));
  if (js) link('dl-report-json', 'report (JSON)', `api/export/${id}/file/${js}`, true);
  link('dl-bundle', 'all (zip)', `api/export/${id}/bundle`, true);
}

// ------------------------------------------------------------------------------------------- start
async function start() {
  try {
    state.schema = await call('GET', 'api/schema');
  } catch (e) { say(e.message); return; }
  for (const j of state.schema.jobs) { const o = document.createElement('option'); o.value = j.name; o.textContent = j.title; $('job').append(o); }
  $('upload-input').accept = Object.values(state.schema.suffixes).flat().join(',');  // the server's upload kinds
  for (const f of state.schema.export_formats) { const o = document.createElement('option'); o.value = f; o.textContent = f.toUpperCase(); $('export-format').append(o); }
  state.design = Object.assign({}, state.schema.design);
  buildForm();
  fillForm();
  listUploads();
  if (state.schema.notices.length) say(state.schema.notices.join(' · '), 'info');
  render();
  preview();
}
window.porecadStudio = { state, meshes, call, say, formDesign, fmt };  // for print.js, tests and the console
start();
