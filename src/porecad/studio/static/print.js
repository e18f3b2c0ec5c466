// porecad studio: the Print panel (studio/print_panel.py on the server). Slices the form's design for the
// printer profile, shows its layers with the printability findings marked, and links the slice ZIP.
// Findings are told apart by their code (never by their text): the page titles each code, the server's
// sentence follows.
const $ = (id) => document.getElementById(id);
const studio = () => window.porecadStudio;
const TITLES = {
  'thin-wall': 'Thin walls', 'narrow-channel': 'Narrow channels', 'closed-pore': 'Closed pores',
  'mid-air-start': 'Starts in mid-air', 'unsupported-overhang': 'Needs supports',
};
const COLOURS = { 'thin-wall': '#ff4d4d', 'narrow-channel': '#ffb020', 'closed-pore': '#c77dff', 'mid-air-start': '#3fa9ff' };
const pr = { id: null, summary: null, image: null, dirty: false, shown: -1 };

function axisName(d) {
  return d.map((x, i) => (Math.abs(x) < 1e-9 ? '' : (x > 0 ? '+' : '−') + 'xyz'[i])).join('');
}
async function loadProfile() {
  const res = await studio().call('GET', 'api/print/profile');
  $('print-profile').value = res.text;
  showPrinter(res.printer);
  const sel = $('print-orient');
  const opt = (value, text) => { const o = document.createElement('option'); o.value = value; o.textContent = text; sel.append(o); };
  opt('none', 'as designed (+z up)');
  opt('auto', 'auto: least support');
  for (const d of res.directions) opt(d.join(','), axisName(d) + ' up');
}
function showPrinter(p) {
  $('print-printer').textContent = `${p.name}: ${p.pixel * 1000} µm pixel, ${p.layer * 1000} µm layer`;
  $('print-pixel').placeholder = p.pixel;
  $('print-layer').placeholder = p.layer;
  pr.dirty = false;
}
async function applyProfile() {
  const res = await studio().call('POST', 'api/print/profile', JSON.stringify({ text: $('print-profile').value }));
  showPrinter(res.printer);
  return res;
}
$('print-profile').addEventListener('input', () => { pr.dirty = true; });
$('print-profile-apply').addEventListener('click', () => applyProfile().then(() => studio().say('printer profile in use', 'info'), (e) => studio().say(e.message)));
$('print-profile-input').addEventListener('change', async (ev) => {
  const file = ev.target.files[0];
  ev.target.value = '';
  if (!file) return;
  $('print-profile').value = await file.text();
  try { await applyProfile(); studio().say(`${file.name}: printer profile in use`, 'info'); } catch (e) { studio().say(e.message); }
});

$('print-btn').addEventListener('click', async () => {
  $('print-result').hidden = true;
  try {
    if (pr.dirty) await applyProfile();
    const num = (id) => ($(id).value === '' ? null : Number($(id).value));
    const res = await studio().call('POST', 'api/print/slice', JSON.stringify({
      design: studio().formDesign(), orient: $('print-orient').value, pixel: num('print-pixel'), layer: num('print-layer') }));
    pr.id = res.id;
    $('print-cancel').hidden = false;
    $('print-progress').hidden = false;
    poll(res.id);
  } catch (e) { studio().say(e.message); }
});
$('print-cancel').addEventListener('click', () => studio().call('POST', 'api/print/cancel').catch((e) => studio().say(e.message)));

async function poll(id) {
  while (id === pr.id) {
    let s;
    try { s = await studio().call('GET', 'api/print/status'); } catch (e) { studio().say(e.message); return; }
    if (s.id !== id) return;
    $('print-progress').max = s.total || 1;
    $('print-progress').value = s.done || 0;
    if (s.state === 'running') {
      const checking = s.stage === 'slices' && s.done >= s.total;
      $('print-status').textContent = (s.cancelling ? 'cancelling at the next step · ' : '') +
        (s.stage === 'slices' && !checking ? `slicing: layer ${s.done}/${s.total}` : (checking ? 'checking printability…' : `${s.stage} the part…`));
    } else {
      $('print-cancel').hidden = true;
      $('print-progress').hidden = true;
      if (s.state === 'done') show(s);
      else if (s.state === 'cancelled') $('print-status').textContent = 'slicing cancelled; nothing was kept';
      else { $('print-status').textContent = 'slicing failed'; studio().say(s.error); }
      return;
    }
    await new Promise((r) => setTimeout(r, 250));
  }
}

function show(s) {
  const r = s.summary, fmt = studio().fmt;
  pr.summary = r;
  const hours = r.print_time_s / 3600;
  const dir = r.orientation ? axisName(r.orientation.chosen.map((x) => Math.abs(x) < 1e-9 ? 0 : x)) + ' up' : 'as designed';
  $('print-status').textContent = `${r.layers} layers of ${r.image[0]}×${r.image[1]} px, ${fmt(r.height, 2)} mm high, ` +
    `about ${hours >= 1 ? fmt(hours, 1) + ' h' : fmt(r.print_time_s / 60, 0) + ' min'} to print; built ${dir} ` +
    `(sliced in ${fmt(s.seconds, 1)} s, ${(s.bytes / 1e6).toFixed(2)} MB${s.preview_factor > 1 ? `; shown at 1/${s.preview_factor}` : ''})`;
  const ul = $('print-warnings');
  ul.textContent = '';
  for (const w of r.warning_details) {
    const li = document.createElement('li');
    li.dataset.code = w.code;
    const b = document.createElement('b');
    b.textContent = (TITLES[w.code] || w.code) + ': ';
    b.style.color = COLOURS[w.code] || '';
    li.append(b, w.message);
    const at = r.marks[w.code];
    if (at) { li.classList.add('jump'); li.title = 'show the layer'; li.addEventListener('click', () => { $('print-slider').value = at[0].layer; drawLayer(); }); }
    ul.append(li);
  }
  if (!r.warning_details.length) {
    const li = document.createElement('li');
    li.className = 'ok';
    li.textContent = 'no printability findings for this printer';
    ul.append(li);
  }
  $('print-slider').max = r.layers - 1;
  $('print-slider').value = Math.floor((r.layers - 1) / 2);
  $('print-zip').href = `api/print/zip?id=${s.id}`;
  $('print-report').href = `api/print/report?id=${s.id}`;
  $('print-result').hidden = false;
  pr.shown = -1;
  drawLayer();
}

function drawLayer() {
  const r = pr.summary;
  if (!r) return;
  const k = Number($('print-slider').value);
  $('print-layer-info').textContent = `layer ${k + 1} of ${r.layers} · z = ${studio().fmt(r.first_layer_z + k * r.layer, 3)} mm (print frame)`;
  const img = new Image();
  img.onload = () => { if (Number($('print-slider').value) === k) paint(img, k); };
  img.onerror = () => studio().say(`layer ${k} could not be loaded`);
  img.src = `api/print/layer/${k}.png?id=${pr.id}`;
}
function paint(img, k) {
  const cv = $('print-canvas');
  const ctx = cv.getContext('2d');
  ctx.fillStyle = '#000';
  ctx.fillRect(0, 0, cv.width, cv.height);
  const scale = Math.min(cv.width / img.width, cv.height / img.height);
  const w = img.width * scale, h = img.height * scale, x0 = (cv.width - w) / 2, y0 = (cv.height - h) / 2;
  ctx.imageSmoothingEnabled = scale < 1;
  ctx.drawImage(img, x0, y0, w, h);
  ctx.strokeStyle = '#566';
  ctx.strokeRect(x0 + 0.5, y0 + 0.5, w - 1, h - 1);
  let n = 0;
  for (const [code, pts] of Object.entries(pr.summary.marks)) {
    ctx.strokeStyle = COLOURS[code] || '#fff';
    ctx.lineWidth = 2;
    for (const p of pts) {
      if (Math.abs(p.layer - k) > 1) continue;
      ctx.beginPath();
      ctx.arc(x0 + p.u * w, y0 + p.v * h, 7, 0, 2 * Math.PI);
      ctx.stroke();
      n++;
    }
  }
  pr.shown = k;
  cv.dataset.layer = k;
  cv.dataset.marks = n;
}
$('print-slider').addEventListener('input', drawLayer);

loadProfile().catch((e) => studio().say(e.message));
