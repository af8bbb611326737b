// mixstep's page: status, console, jog, heaters, files and the mix editor, talking to
// the firmware's HTTP API (docs/Host_Software.md). Plain script, no build step: the
// board serves this file gzipped from its flash, so it stays small.
'use strict';

const $ = (id) => document.getElementById(id);
const STATUS_MS = 1000, CONSOLE_MS = 500;
const GRAPH_S = 300;  // the most the graph shows: the last five minutes
const CONSOLE_KEEP = 500;  // lines kept in the console, so a long print can't fill memory
const TRACE_COLOURS = ['#e4572e', '#3b82f6', '#f59e0b', '#10b981'];

let gen = 0;  // bumped at each login, so the pollers of an older session stop
let lastStatus = null;  // for the mix editor when its tool changes
let history = [];  // {t: seconds, v: [[c, target_c] per heater]}
let lastJobState = null;
let editorShape = '';
let mixDirty = false;  // the user moved a slider: status polls leave the sliders alone
let mixPending = null;  // a saved mix the status doesn't report yet
const colourPending = {};  // drive -> {rgb, until}: a colour sent, not yet reported

function el(tag, attrs, ...kids) {
  const e = document.createElement(tag);
  Object.assign(e, attrs);
  e.append(...kids);
  return e;
}
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

// ---- errors and the user ----------------------------------------------------------

function toast(text, ok) {
  const t = el('div', {className: ok ? 'toast ok' : 'toast', textContent: text, role: 'alert'});
  t.dataset.test = 'toast';
  t.onclick = () => t.remove();
  $('toasts').append(t);
  setTimeout(() => t.remove(), ok ? 3000 : 10000);
}

// A poll that fails is shown once as a banner, not as a toast a second.
function offline(err) {
  const b = $('offline');
  b.textContent = 'Printer not answering: ' + err.message;
  b.hidden = false;
}
const online = () => { $('offline').hidden = true; };

// ---- the API --------------------------------------------------------------------

// 503: the printer's G-code buffer is full while it works through earlier lines, or
// its few connections are all busy; either clears in a moment, so wait and resend.
async function api(method, path, body) {
  for (let tries = 0; ; tries++) {
    const r = await fetch(path, {method, body, cache: 'no-store'});
    if (r.status === 503 && tries < 40) {
      await sleep(250);
      continue;
    }
    let data = null;
    try { data = await r.json(); } catch (e) { /* an empty or non-JSON body */ }
    if (r.ok) return data;
    if (r.status === 401) showLogin();
    const err = new Error((data && data.error) || r.status + ' ' + r.statusText);
    err.status = r.status;
    throw err;
  }
}

// One send at a time, so lines reach the printer in the order they were given. The
// console shows what each button sent, so the printer's answers there make sense.
let sendChain = Promise.resolve();
function gcode(text) {
  addLines(text.split('\n').map((l) => '> ' + l));
  const p = sendChain.then(() => api('POST', '/api/gcode', text)).then(() => true, (e) => {
    toast(text.split('\n')[0] + ': ' + e.message);
    return false;
  });
  sendChain = p;
  return p;
}

// ---- login ----------------------------------------------------------------------

function showLogin() {
  gen++;
  $('app').hidden = true;
  $('login').hidden = false;
  $('password').focus();
}

function showApp() {
  const g = ++gen;
  $('login').hidden = true;
  $('app').hidden = false;
  pollStatus(g);
  pollConsole(g);
  loadFiles();
}

async function start() {
  try {
    const s = await api('GET', '/api/session');
    online();
    if (s.login_needed && !s.logged_in) showLogin(); else showApp();
  } catch (e) {
    offline(e);
    setTimeout(start, 2000);
  }
}

$('login').onsubmit = async (e) => {
  e.preventDefault();
  $('login-error').textContent = '';
  try {
    await api('POST', '/api/login', $('password').value);
    $('password').value = '';
    showApp();
  } catch (err) {
    $('login-error').textContent = err.message;
  }
};

// ---- status ---------------------------------------------------------------------

async function pollStatus(g) {
  while (g === gen) {
    try {
      render(await api('GET', '/api/status'));
      online();
    } catch (e) {
      if (e.status !== 401) offline(e);
    }
    await sleep(STATUS_MS);
  }
}

const fmt = (v, d) => (v == null ? '–' : v.toFixed(d));

function minutes(m) {
  if (m == null) return '–';
  if (m < 60) return m + ' min';
  return Math.floor(m / 60) + ' h ' + String(m % 60).padStart(2, '0') + ' min';
}

const mixText = (mix) => percents(mix).map((v, i) => (v ? 'e' + i + ' ' + v + '%' : ''))
  .filter(Boolean).join(' · ');

function render(s) {
  lastStatus = s;
  const job = s.job || {state: 'idle'};
  // A file printed to its end stays selected (M26 could rewind it): done, and M24
  // would only be refused.
  const done = job.state === 'done';
  const state = s.halted ? 'halted' : done ? 'done' : job.state;
  const badge = $('state');
  badge.textContent = state;
  badge.className = 'badge ' + state;
  $('message').textContent = s.message || '';
  const p = s.position_mm;
  $('pos').textContent = ['x', 'y', 'z', 'e']
    .map((a) => a.toUpperCase() + ' ' + fmt(p[a], 2)).join('  ');
  const tool = s.tools[s.tool];
  $('tool').textContent = 'T' + s.tool;
  $('tool-swatch').style.background = tool ? tool.rgb : '';
  $('tool-mix').textContent = tool ? mixText(tool.mix) : '';
  $('job').textContent = job.file ? job.file + ' (' + (done ? 'done' : job.state) + ')' : 'no file';
  // The slicer's M73 figure when the file has one, else how far through the file.
  let pct = s.progress_pct;
  if (pct == null && job.file && job.size) pct = Math.floor(100 * job.bytes / job.size);
  const bar = $('progress');
  if (pct == null) bar.removeAttribute('value'); else bar.value = pct;
  $('progress-text').textContent = pct == null ? '–' : pct + ' %';
  $('left').textContent = minutes(s.left_min);
  $('queue').textContent = s.queue_moves + ' moves';
  $('fan').textContent = Math.round(100 * s.fan) + ' %';

  const printing = job.state === 'printing';
  $('pause').disabled = !printing;
  $('resume').disabled = job.state !== 'paused' || done;
  $('cancel').disabled = !job.file || job.state === 'idle';
  for (const b of document.querySelectorAll('[data-jog],[data-motion]')) {
    b.disabled = printing || s.halted;
  }

  $('heaters').replaceChildren(...s.heaters.map((h, i) => el('span', {className: 'heater'},
    el('i', {className: 'dot', style: 'background:' + TRACE_COLOURS[i % 4]}),
    h.name + ' ' + fmt(h.c, 1) + ' / ' + fmt(h.target_c, 0) + ' °C')));
  const now = performance.now() / 1000;
  history.push({t: now, v: s.heaters.map((h) => [h.c, h.target_c])});
  while (history[0].t < now - GRAPH_S) history.shift();
  drawGraph();

  renderEditor(s);
  if (lastJobState !== job.state) {
    if (lastJobState !== null) loadFiles();  // a print started or ended: sizes, free space
    lastJobState = job.state;
  }
}

// ---- the temperature graph ------------------------------------------------------

function drawGraph() {
  const c = $('graph');
  const dpr = window.devicePixelRatio || 1;
  const w = c.clientWidth, h = c.clientHeight;
  if (!w) return;  // hidden
  if (c.width !== Math.round(w * dpr)) {
    c.width = Math.round(w * dpr);
    c.height = Math.round(h * dpr);
  }
  const g = c.getContext('2d');
  g.setTransform(dpr, 0, 0, dpr, 0, 0);
  g.clearRect(0, 0, w, h);
  const ink = getComputedStyle(c).color;
  // The y axis from 0 to the next 50 °C over every reading and target, so a line
  // never leaves the canvas and the scale changes seldom.
  let top = 50;
  for (const p of history) for (const [cur, tgt] of p.v) top = Math.max(top, cur || 0, tgt || 0);
  top = Math.ceil(top / 50) * 50;
  // Until five minutes have been seen, the x axis spans what has (a minute at least),
  // so a fresh page's first readings aren't a sliver at the right edge.
  const left = 30, now = performance.now() / 1000;
  const span = Math.min(GRAPH_S, Math.max(60, now - (history.length ? history[0].t : now)));
  const x = (t) => left + (w - left) * (1 - (now - t) / span);
  const y = (v) => h - 4 - (h - 8) * v / top;
  g.font = '10px sans-serif';
  g.fillStyle = g.strokeStyle = ink;
  g.globalAlpha = 0.25;
  for (let v = 0; v <= top; v += top > 150 ? 50 : 25) {
    g.fillRect(left, Math.round(y(v)), w - left, 1);
    g.globalAlpha = 1;
    g.fillText(v, 2, y(v) + 3);
    g.globalAlpha = 0.25;
  }
  g.globalAlpha = 1;
  g.lineWidth = 1.5;
  const n = history.length ? history[history.length - 1].v.length : 0;
  for (let i = 0; i < n; i++) {
    g.strokeStyle = TRACE_COLOURS[i % 4];
    for (const [k, dash] of [[0, []], [1, [4, 4]]]) {  // reading solid, target dashed
      g.setLineDash(dash);
      g.beginPath();
      history.forEach((p, j) => {
        const v = p.v[i] ? p.v[i][k] : null;
        if (v != null) (j ? g.lineTo : g.moveTo).call(g, x(p.t), y(v));
      });
      g.stroke();
    }
  }
  g.setLineDash([]);
  c.dataset.points = history.length;
}
window.addEventListener('resize', drawGraph);

// ---- console --------------------------------------------------------------------

const consoleLines = [];

function addLines(lines) {
  if (!lines.length) return;
  const log = $('console-log');
  const atEnd = log.scrollTop + log.clientHeight >= log.scrollHeight - 8;
  consoleLines.push(...lines);
  consoleLines.splice(0, consoleLines.length - CONSOLE_KEEP);
  log.textContent = consoleLines.join('\n');
  if (atEnd) log.scrollTop = log.scrollHeight;
  // A button's G-code answered with an error is shown even with the console scrolled away.
  for (const l of lines) if (/^(Error|!!)/.test(l)) toast(l);
}

async function pollConsole(g) {
  while (g === gen) {
    try {
      addLines((await api('GET', '/api/console')).lines);
    } catch (e) {
      if (e.status !== 401) offline(e);
    }
    await sleep(CONSOLE_MS);
  }
}

const sent = [];
let sentAt = 0;
$('console-form').onsubmit = (e) => {
  e.preventDefault();
  const input = $('console-input');
  const line = input.value.trim();
  if (!line) return;
  gcode(line);
  sent.push(line);
  sentAt = sent.length;
  input.value = '';
};
$('console-input').onkeydown = (e) => {  // arrows walk back through what was sent
  if (e.key !== 'ArrowUp' && e.key !== 'ArrowDown') return;
  sentAt = Math.max(0, Math.min(sent.length, sentAt + (e.key === 'ArrowUp' ? -1 : 1)));
  e.target.value = sent[sentAt] || '';
  e.preventDefault();
};

// ---- buttons: jog, home, job control, heaters, fan -------------------------------

document.addEventListener('click', (e) => {
  const b = e.target.closest('button');
  if (!b) return;
  if (b.dataset.jog) {
    const step = document.querySelector('[name=step]:checked').value;
    const axis = b.dataset.jog[0], sign = b.dataset.jog[1] === '-' ? '-' : '';
    const feed = axis === 'Z' ? 600 : 3000;  // mm/min: Z screws are slow
    gcode('G91\nG1 ' + axis + sign + step + ' F' + feed + '\nG90');
  } else if (b.dataset.gcode) {
    if (!b.dataset.confirm || confirm(b.dataset.confirm)) gcode(b.dataset.gcode);
  }
});

for (const f of document.querySelectorAll('form.set')) {
  const code = f.dataset.code, input = f.querySelector('input');
  f.onsubmit = (e) => {
    e.preventDefault();
    gcode(code + ' S' + Math.round(input.value));
  };
  f.querySelector('[data-off]').onclick = () => gcode(code === 'M106' ? 'M107' : code + ' S0');
}

// ---- files ----------------------------------------------------------------------

const kB = (n) => (n < 1e6 ? (n / 1e3).toFixed(1) + ' kB' : n < 1e9 ? (n / 1e6).toFixed(2) + ' MB'
  : (n / 1e9).toFixed(1) + ' GB');
const filePath = (name) => '/api/files/' + encodeURIComponent(name);

async function loadFiles() {
  try {
    const d = await api('GET', '/api/files');
    $('files').tBodies[0].replaceChildren(...d.files.map((f) => {
      const row = el('tr', {},
        el('td', {textContent: f.name}),
        el('td', {textContent: kB(f.bytes)}),
        el('td', {}, el('button', {textContent: 'Print'}), ' ',
          el('button', {textContent: 'Delete', className: 'danger'})));
      row.dataset.file = f.name;
      const [print, del] = row.querySelectorAll('button');
      print.dataset.test = 'file-print';
      del.dataset.test = 'file-delete';
      print.onclick = () => gcode('M23 ' + f.name + '\nM24');
      del.onclick = () => deleteFile(f.name);
      return row;
    }));
    $('free').textContent = d.free_bytes == null ? '' : kB(d.free_bytes) + ' free';
  } catch (e) {
    toast('Files: ' + e.message);
  }
}

async function deleteFile(name) {
  if (!confirm('Delete ' + name + '?')) return;
  try {
    await api('DELETE', filePath(name));
  } catch (e) {
    toast('Delete ' + name + ': ' + e.message);
  }
  loadFiles();
}

// XMLHttpRequest rather than fetch: it reports the upload's progress, and a big file
// over the board's Wi-Fi takes a while.
$('upload').onclick = () => {
  const file = $('upload-file').files[0];
  if (!file) return toast('Choose a file first');
  const bar = $('upload-progress');
  const xhr = new XMLHttpRequest();
  xhr.open('PUT', filePath(file.name));
  xhr.upload.onprogress = (e) => { bar.value = e.total ? e.loaded / e.total : 0; };
  xhr.onloadend = () => {
    bar.hidden = true;
    $('upload').disabled = false;
    if (xhr.status >= 200 && xhr.status < 300) {
      toast('Uploaded ' + file.name, true);
      $('upload-file').value = '';
    } else {
      let msg = xhr.status ? xhr.status + ' ' + xhr.statusText : 'connection lost';
      try { msg = JSON.parse(xhr.responseText).error || msg; } catch (e) { /* not JSON */ }
      if (xhr.status === 401) showLogin();
      toast('Upload ' + file.name + ': ' + msg);
    }
    loadFiles();
  };
  bar.value = 0;
  bar.hidden = false;
  $('upload').disabled = true;
  xhr.send(file);
};

// ---- the mix editor -------------------------------------------------------------

const hexRgb = (hex) => [1, 3, 5].map((i) => parseInt(hex.slice(i, i + 2), 16));

// The server's rule: each channel the weighted mean of the drives' colours, rounded.
function mixRgb(weights, colours) {
  const sum = total(weights);
  if (!sum) return null;
  return '#' + [0, 1, 2].map((ch) => {
    let v = 0;
    weights.forEach((w, i) => { v += w * hexRgb(colours[i])[ch]; });
    return Math.round(v / sum).toString(16).padStart(2, '0');
  }).join('');
}

const sliders = () => [...document.querySelectorAll('#mix-sliders input[type=range]')];
const weights = () => sliders().map((r) => +r.value);
const driveColours = () => [...document.querySelectorAll('#drive-colours input')]
  .map((c) => c.value);
const total = (ws) => ws.reduce((a, b) => a + b, 0);
const sameRatio = (a, b) => a.every((w, i) => w * total(b) === b[i] * total(a));

function toolOptions(n) {
  return Array.from({length: n}, (_, t) => el('option', {value: t, textContent: 'T' + t}));
}

// Rebuilt only when the number of drives or tools changes, so that a slider being
// dragged is never replaced under the finger.
function buildEditor(s) {
  for (const id of ['mix-tool', 'grad-a', 'grad-b']) {
    const sel = $(id), was = sel.value;
    sel.replaceChildren(...toolOptions(s.tools.length));
    sel.value = was || (id === 'grad-b' ? Math.min(1, s.tools.length - 1) : 0);
  }
  $('mix-sliders').replaceChildren(...Array.from({length: s.drives}, (_, i) => {
    const range = el('input', {type: 'range', min: 0, max: 100, id: 'mix-w' + i});
    const num = el('input', {type: 'number', min: 0, max: 100, id: 'mix-n' + i});
    range.oninput = () => { num.value = range.value; edited(); };
    num.oninput = () => { range.value = num.value; edited(); };
    return el('label', {className: 'drive'},
      el('i', {className: 'dot', id: 'mix-dot' + i}), 'e' + i, range, num);
  }));
  $('drive-colours').replaceChildren(...Array.from({length: s.drives}, (_, i) => {
    const c = el('input', {type: 'color', id: 'drive-rgb' + i, title: 'filament in drive e' + i});
    c.oninput = previewMix;
    c.onchange = () => sendColour(i, c.value);
    return el('label', {}, 'e' + i + ' ', c);
  }));
}

function renderEditor(s) {
  const shape = s.drives + '/' + s.tools.length;
  if (shape !== editorShape) {
    buildEditor(s);
    editorShape = shape;
    mixDirty = false;
  }
  const now = Date.now();
  s.drive_rgb.forEach((rgb, i) => {
    const p = colourPending[i];
    if (p && (p.rgb === rgb || now > p.until)) delete colourPending[i];
    const input = $('drive-rgb' + i);
    if (!colourPending[i] && document.activeElement !== input) input.value = rgb;
  });
  const t = +$('mix-tool').value;
  const tool = s.tools[t];
  const m = mixPending;
  if (m && (m.tool !== t || sameRatio(tool.mix, m.w) || now > m.until)) mixPending = null;
  if (!mixDirty && !mixPending) setSliders(tool.mix);
  $('mix-now').style.background = tool.rgb;
  $('mix-now').title = 'T' + t + ' prints ' + tool.rgb;
  previewMix();
}

// Shown as percent shares summing to 100 (the printer keeps any ratio: 1:0:0 is
// 100:0:0), the points rounding leaves going to the largest remainders.
function percents(mix) {
  const sum = total(mix);
  if (!sum) return mix.map(() => 0);
  const exact = mix.map((w) => 100 * w / sum), out = exact.map(Math.floor);
  const left = 100 - out.reduce((a, b) => a + b, 0);
  exact.map((v, i) => [v - out[i], i]).sort((a, b) => b[0] - a[0]).slice(0, left)
    .forEach(([, i]) => out[i]++);
  return out;
}

function setSliders(mix) {
  percents(mix).forEach((v, i) => { $('mix-w' + i).value = $('mix-n' + i).value = v; });
}

function previewMix() {
  const colours = driveColours();
  colours.forEach((c, i) => { $('mix-dot' + i).style.background = c; });
  const rgb = mixRgb(weights(), colours);
  $('mix-preview').style.background = rgb || 'transparent';
  $('mix-preview-rgb').textContent = rgb || 'no drive feeds';
  $('mix-save').disabled = !rgb;
}

function edited() {
  mixDirty = true;
  previewMix();
}

$('mix-tool').onchange = () => {
  mixDirty = false;
  mixPending = null;
  if (lastStatus) renderEditor(lastStatus);
};
$('mix-revert').onclick = $('mix-tool').onchange;

$('mix-save').onclick = async () => {
  const t = +$('mix-tool').value, w = weights();
  // Held until the status reports the new mix, so the sliders don't jump back.
  mixPending = {tool: t, w, until: Date.now() + 5000};
  mixDirty = false;
  if (!await gcode('M567 P' + t + ' E' + w.join(':') + '\nM500')) mixPending = null;
};

async function sendColour(drive, hex) {
  colourPending[drive] = {rgb: hex, until: Date.now() + 5000};
  if (!await gcode('M926 Idrive_colour_rgb_' + drive + ' V' + parseInt(hex.slice(1), 16) + '\nM930')) {
    delete colourPending[drive];
  }
}

$('gradient').onsubmit = (e) => {
  e.preventDefault();
  gcode('M166 A' + $('grad-z0').value + ' Z' + $('grad-z1').value + ' I' + $('grad-a').value +
        ' J' + $('grad-b').value + ' S1');
};
$('grad-off').onclick = () => gcode('M166 S0');

start();
