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
  $('m-resume').hidden = !(j.resumable && !running);
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
  $('m-run').addEventListener('click', () => machineCall('run', {}));
  $('m-check').addEventListener('click', () => machineCall('run', { check: true }));
  $('m-resume').addEventListener('click', () => machineCall('run', { resume: true }));
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
