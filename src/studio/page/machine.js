// The Machine panel: connect to a GRBL controller, watch its readout
// (pushed over a WebSocket as it changes), jog, zero, probe, frame, the
// realtime commands and a console. Every action is a call to the studio,
// which owns the port; the page only shows and asks.
'use strict';

const M = { ws: null, connected: false, state: null, job: null };

async function machineCall(what, body) {
  try {
    return await call('/api/machine/' + what, { method: 'POST', body: JSON.stringify(body || {}),
      headers: { 'Content-Type': 'application/json' } });
  } catch (e) {
    consoleLine({ dir: 'note', text: e.message });
    return null;
  }
}

async function findPorts() {
  try {
    const r = await fetch('/api/machine/ports', { headers: { 'X-Relievo-Secret': SECRET } });
    const list = (await r.json()).ports || [];
    $('m-ports').innerHTML = '';
    for (const p of list) {
      const o = document.createElement('option');
      o.value = p;
      $('m-ports').appendChild(o);
    }
    if (!$('m-port').value && list.length) $('m-port').value = list[0];
  } catch (e) { /* no ports listed: the field still takes a path */ }
}

function consoleLine(c) {
  const box = $('m-console');
  const d = document.createElement('div');
  const kind = c.text.startsWith('error:') ? ' error' : c.text.startsWith('ALARM:') ? ' alarm' : '';
  d.className = c.dir + kind;
  d.textContent = (c.dir === 'sent' ? '> ' : c.dir === 'note' ? '# ' : '') + c.text;
  if (c.meaning) {
    const m = document.createElement('span');
    m.className = 'meaning';
    m.textContent = '  (' + c.meaning + ')';
    d.appendChild(m);
  }
  const atEnd = box.scrollTop + box.clientHeight >= box.scrollHeight - 4;
  box.appendChild(d);
  while (box.childElementCount > 600) box.firstChild.remove();
  if (atEnd) box.scrollTop = box.scrollHeight;
}

function fmt(v) { return v === undefined || v === null ? '–' : v.toFixed(3); }

function showReadout(r) {
  for (const c of r.console || []) consoleLine(c);
  M.connected = !!r.connected;
  $('m-conn').textContent = M.connected ? 'Disconnect' : 'Connect';
  const st = $('m-state');
  const name = !r.connected ? (r.error ? 'link lost' : 'not connected') : r.silent ? 'no answer' : (r.state || '…');
  st.textContent = name;
  st.className = (r.connected && r.state ? r.state.split(':')[0] : '');
  M.state = r.connected ? r.state : null;
  $('m-alarm').textContent = r.alarm ? `ALARM:${r.alarm.code} ${r.alarm.meaning}` : (r.error || '');
  const w = r.wpos || [], m = r.mpos || [];
  ['x', 'y', 'z'].forEach((a, k) => { $('m-w' + a).textContent = fmt(w[k]); $('m-m' + a).textContent = fmt(m[k]); });
  const ov = r.overrides ? ` · overrides feed ${r.overrides[0]}% rapid ${r.overrides[1]}% spindle ${r.overrides[2]}%` : '';
  const bf = r.buffer ? ` · buffer ${r.buffer[0]} blocks ${r.buffer[1]} bytes free` : '';
  const fs = r.connected ? `feed ${r.feed ?? '–'} mm/min · spindle ${r.spindle ?? '–'} rpm${ov}${bf}` : '';
  $('m-fs').textContent = fs + (r.pending ? ` · ${r.pending} line(s) waiting` : '');
  if (r.job !== undefined) M.job = r.job;
  showJob(M.job);
  drawMap(r.connected ? r.wpos : null);
}

function clock(s) {
  if (s === undefined || s === null) return '–';
  s = Math.round(s);
  return `${Math.floor(s / 60)}:${String(s % 60).padStart(2, '0')}`;
}

function showJob(j) {
  const running = !!(j && j.running);
  $('m-run').disabled = $('m-check').disabled = running || !M.connected;
  $('m-stop').disabled = !running;
  if (!j) return;
  const share = j.total ? j.acked / j.total : 0;
  $('m-bar').style.width = (100 * share).toFixed(1) + '%';
  const t = $('m-jobtext');
  if (j.outcome) {
    t.textContent = j.outcome;
    t.className = j.ok ? 'good' : 'bad';
  } else {
    t.className = '';
    t.textContent = `${j.check ? 'checking' : 'running'} ${j.name}: ${j.acked} of ${j.total || '…'} lines · ${clock(j.elapsed)} elapsed · ${clock(j.left)} left`;
  }
  $('m-pause').hidden = !j.paused;
  $('m-pausetext').textContent = j.paused || '';
  $('m-pausetool').textContent = j.paused ? inTable(j.paused) : '';
  $('m-resume').hidden = !(j.resumable && !running);
}

/// The tool a pause names (its `tool: SPEC` note), as the machine's tool
/// table lists it.
function inTable(paused) {
  const spec = (paused.match(/tool: ([^ )\]]+)/) || [])[1];
  const m = machineNow();
  const t = spec && m && m.tools.find((x) => x.tool === spec);
  return t ? `${t.id} in ${m.name}'s tool table: ${t.name}` : (spec ? `${spec} is not in the machine's tool table` : '');
}

/// The machine chosen in the cutting settings, as the studio describes it.
function machineNow() {
  return S.options && S.options.machines.find((x) => x.id === $('machine').value);
}

/// The tool setter's place from the machine file, unless one is typed.
function setterFromMachine() {
  const m = machineNow();
  if (m && m.setter && !$('m-setter').dataset.typed) $('m-setter').value = m.setter.join(',');
}

/// The job from above (its cutting moves over the stock) with the tool's
/// marker where the machine reports it, in work coordinates.
const MAP = { job: null, base: null, fit: null };

function mapFit(h) {
  const c = $('m-map'), pad = 14;
  const st = h.stock;
  const s = Math.min((c.width - 2 * pad) / st.width, (c.height - 2 * pad) / st.height);
  const ox = (c.width - s * st.width) / 2 - s * st.x0, oy = (c.height + s * st.height) / 2 + s * st.y0;
  return { s, px: (x) => ox + s * x, py: (y) => oy - s * y };
}

function mapBase() {
  const c = $('m-map');
  const base = document.createElement('canvas');
  base.width = c.width; base.height = c.height;
  const g = base.getContext('2d');
  g.fillStyle = '#3a3835'; g.fillRect(0, 0, c.width, c.height);
  const j = S.job;
  if (!j) return { base, fit: null };
  const h = j.head, f = mapFit(h), st = h.stock;
  g.fillStyle = '#c9a66b';
  g.fillRect(f.px(st.x0), f.py(st.y0 + st.height), f.s * st.width, f.s * st.height);
  const m = j.arrays.moves;
  g.strokeStyle = 'rgba(60, 40, 20, 0.55)'; g.lineWidth = 1;
  g.beginPath();
  for (let i = 0; i + 7 < m.length; i += 8) {
    if (m[i + 3] < 0.5) continue;  // rapids left out
    g.moveTo(f.px(m[i]), f.py(m[i + 1]));
    g.lineTo(f.px(m[i + 4]), f.py(m[i + 5]));
  }
  g.stroke();
  return { base, fit: f };
}

function drawMap(wpos) {
  if (!MAP.base || MAP.job !== S.job) { Object.assign(MAP, mapBase()); MAP.job = S.job; }
  const c = $('m-map'), g = c.getContext('2d');
  g.drawImage(MAP.base, 0, 0);
  if (!wpos || !MAP.fit) return;
  const x = MAP.fit.px(wpos[0]), y = MAP.fit.py(wpos[1]);
  g.strokeStyle = '#ff2d20'; g.fillStyle = 'rgba(255, 45, 32, 0.85)'; g.lineWidth = 2;
  g.beginPath(); g.arc(x, y, 6, 0, 2 * Math.PI); g.fill();
  g.beginPath(); g.moveTo(x - 12, y); g.lineTo(x + 12, y); g.moveTo(x, y - 12); g.lineTo(x, y + 12); g.stroke();
}

function watch() {
  if (M.ws) M.ws.close();
  const ws = new WebSocket(`ws://${location.host}/api/machine/live?secret=${encodeURIComponent(SECRET)}`);
  M.ws = ws;
  ws.onmessage = (e) => showReadout(JSON.parse(e.data));
  ws.onclose = () => { if (M.ws === ws) M.ws = null; };
}

async function connect() {
  if (M.connected) {
    await machineCall('disconnect');
    showReadout({ connected: false, console: [{ dir: 'note', text: 'disconnected' }] });
    return;
  }
  const port = $('m-port').value.trim();
  consoleLine({ dir: 'note', text: `connecting to ${port}…` });
  const r = await machineCall('connect', { port, baud: parseInt($('m-baud').value, 10) });
  if (r) { showReadout(r); watch(); }
}

function jogStep() { return $('m-step').value; }
function jogFeed() { return parseFloat($('m-feed').value) || 1000; }

/// A jog by one step, or (hold to jog) a long jog cancelled on release.
function jogStart(dir) {
  const axis = dir[0], sign = dir[1] === '+' ? 1 : -1;
  const step = jogStep();
  const far = 1000;  // GRBL stops at soft limits; the release cancels it
  const d = (step === 'hold' ? far : parseFloat(step)) * sign;
  machineCall('jog', { [axis]: d, feed: jogFeed() });
}
function jogEnd() {
  if (jogStep() === 'hold') machineCall('realtime', { name: 'jog_cancel' });
}

function machineInit() {
  findPorts();
  $('m-conn').addEventListener('click', connect);
  for (const b of document.querySelectorAll('[data-jog]')) {
    b.addEventListener('pointerdown', () => jogStart(b.dataset.jog));
    b.addEventListener('pointerup', jogEnd);
    b.addEventListener('pointerleave', (e) => { if (e.buttons) jogEnd(); });
  }
  for (const b of document.querySelectorAll('[data-zero]')) b.addEventListener('click', () => machineCall('zero', { axes: b.dataset.zero }));
  for (const b of document.querySelectorAll('[data-rt]')) b.addEventListener('click', () => machineCall('realtime', { name: b.dataset.rt }));
  $('m-home').addEventListener('click', () => machineCall('home'));
  $('m-unlock').addEventListener('click', () => machineCall('unlock'));
  $('m-reset').addEventListener('click', () => {
    if (confirm('Soft reset stops everything at once; a machine in motion loses its position. Reset?')) machineCall('realtime', { name: 'reset' });
  });
  $('m-probe-go').addEventListener('click', () => machineCall('probe', { thickness: parseFloat($('m-plate').value) || 0 }));
  $('m-frame').addEventListener('click', () => machineCall('frame', {}));
  $('m-setter').addEventListener('input', () => { $('m-setter').dataset.typed = '1'; });
  $('machine').addEventListener('change', setterFromMachine);
  $('machine-tab').addEventListener('click', setterFromMachine);
  const setter = (step) => machineCall('setter', { step, setter: $('m-setter').value });
  $('m-setter-ref').addEventListener('click', () => setter('reference'));
  $('m-setter-new').addEventListener('click', () => setter('apply'));
  const uploaded = () => $('m-source').value === 'upload';
  $('m-run').addEventListener('click', () => machineCall('run', { uploaded: uploaded() }));
  $('m-check').addEventListener('click', () => machineCall('run', { check: true, uploaded: uploaded() }));
  $('m-resume').addEventListener('click', () => machineCall('run', { resume: true, uploaded: uploaded() }));
  $('m-nc').addEventListener('change', async () => {
    const f = $('m-nc').files[0];
    if (!f) return;
    try {
      const r = await call('/api/machine/upload?name=' + encodeURIComponent(f.name), { method: 'POST', body: f });
      let o = $('m-source').querySelector('option[value=upload]');
      if (!o) { o = document.createElement('option'); o.value = 'upload'; $('m-source').appendChild(o); }
      o.textContent = `${r.name} (${r.lines} lines)`;
      $('m-source').value = 'upload';
      consoleLine({ dir: 'note', text: `${r.name}: ${r.lines} lines to run` });
    } catch (e) {
      consoleLine({ dir: 'note', text: e.message });
    }
  });
  $('m-stop').addEventListener('click', () => machineCall('stop'));
  $('m-continue').addEventListener('click', () => machineCall('continue'));
  $('m-send').addEventListener('submit', (e) => {
    e.preventDefault();
    const l = $('m-line').value.trim();
    if (l) machineCall('line', { line: l });
    $('m-line').value = '';
  });
  const keys = { ArrowLeft: 'x-', ArrowRight: 'x+', ArrowUp: 'y+', ArrowDown: 'y-', PageUp: 'z+', PageDown: 'z-' };
  const panel = $('machine-panel');
  panel.tabIndex = -1;
  panel.addEventListener('keydown', (e) => {
    if (e.target.tagName === 'INPUT' || e.repeat || !keys[e.key]) return;
    e.preventDefault();
    jogStart(keys[e.key]);
  });
  panel.addEventListener('keyup', (e) => { if (keys[e.key] && e.target.tagName !== 'INPUT') jogEnd(); });
  // a studio reopened while the machine stays connected shows it at once
  fetch('/api/machine/state', { headers: { 'X-Relievo-Secret': SECRET } })
    .then((r) => r.json()).then((r) => { if (r.connected) { showReadout(r); watch(); } }).catch(() => {});
}

machineInit();
