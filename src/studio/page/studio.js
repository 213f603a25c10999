// relievo studio: shows what the server makes and sends it settings.
// Nothing is computed here but what it takes to draw.
'use strict';

const $ = (id) => document.getElementById(id);
const D = Math.PI / 180;
// vertices along a field's long side: drawn at once / once the view rests
const COARSE = 64, FINE = 1024;

// What the page holds; `window.studio` lets tests read the timings.
const S = {
  tab: 'relief',
  options: null,
  model: null,
  touched: new Set(),
  light: { az: 315, el: 20 },
  orbit: { az: 0, el: 62, zoom: 1 },
  relief: null,
  job: null,
  mesh: null,
  inputAt: 0,
  // how long a coarse field takes from draw to screen (ms)
  coarseMs: 50,
  stats: { relief: [], job: [] },
  drawn: 0,
};
window.studio = S;

function status(msg, error) {
  const s = $('status');
  s.textContent = msg || '';
  s.className = error ? 'error' : '';
}

// ---- the API ---------------------------------------------------------

/// A packet: a u32 length, a JSON head, then the arrays it lists.
function unpack(buf) {
  const n = new DataView(buf).getUint32(0, true);
  const head = JSON.parse(new TextDecoder().decode(new Uint8Array(buf, 4, n)));
  let at = 4 + n;
  const arrays = {};
  for (const a of head.arrays) {
    const T = a.type === 'f32' ? Float32Array : Uint32Array;
    arrays[a.name] = new T(buf, at, a.len);
    at += a.len * 4;
  }
  return { head, arrays };
}

/// POST/GET, an error message thrown for a refused request; null when
/// the server dropped it for a newer one.
// the studio's secret, in this page only: every request that changes
// anything carries it, so no other site's page can make one
const SECRET = (document.querySelector('meta[name=relievo-secret]') || {}).content || '';

async function call(url, opts) {
  if (opts && opts.method === 'POST') opts = { ...opts, headers: { ...(opts.headers || {}), 'X-Relievo-Secret': SECRET } };
  const r = await fetch(url, opts);
  if (r.status === 409) return null;
  const type = r.headers.get('Content-Type') || '';
  if (!r.ok) {
    let msg = r.status + ' ' + r.statusText;
    if (type.startsWith('application/json')) msg = (await r.json()).error || msg;
    throw new Error(msg);
  }
  return type.startsWith('application/json') ? r.json() : unpack(await r.arrayBuffer());
}

// ---- settings --------------------------------------------------------
// Sent by the command line's own names (its flags, as snake_case fields);
// the server reads them with the command line's definition.

function num(id) { return parseFloat($(id).value); }

function reliefSettings() {
  const s = {
    view: $('view').value,
    up: $('up').value || null,
    yaw: num('yaw'), pitch: num('pitch'), roll: num('roll'), fov: num('fov'),
    resolution: parseInt($('resolution').value, 10),
    width: num('width'),
    silhouette: num('silhouette'),
    flat_background: $('background').value === 'flat',
    free_background: $('background').value === 'free',
    mirror: $('mirror').checked,
    invert: $('invert').checked,
    method: $('method').value,
    material: $('material').value || null,
    depth: S.touched.has('depth') || !$('material').value ? num('depth') : null,
    alpha: S.touched.has('alpha') ? num('alpha') : null,
    steps: $('steps-on').checked ? num('steps') : null,
    smooth: $('smooth-on').checked ? num('smooth') : null,
    faceted: !$('smooth-on').checked,
    fade: $('fade').value.trim() || null,
    tilt: $('tilt').value.trim() || null,
    emphasize: [],
  };
  if (!S.touched.has('depth') && !$('material').value && s.depth === 5) s.depth = null;
  const bands = $('bands').value.trim();
  if (bands) s.bands = bands.split(',').map(Number);
  for (const el of document.querySelectorAll('#objects input')) {
    const g = parseFloat(el.value);
    if (g !== 1) s.emphasize.push([el.dataset.name, g]);
  }
  return more('relief', s);
}

/// The settings of the More section that are set, added to `s`.
function more(kind, s) {
  for (const el of document.querySelectorAll(`[data-more=${kind}]`)) {
    if (el.type === 'checkbox') { if (el.checked) s[el.dataset.name] = true; }
    else if (el.value.trim() !== '') s[el.dataset.name] = el.value.trim();
  }
  return s;
}

/// A control for every setting the server describes that the page has
/// none of: a checkbox for a switch, a list for a few values, else text
/// with the default as its placeholder; labelled with the flag.
function buildMore() {
  const kinds = [['relief', reliefSettings, () => reliefChanged()], ['cut', cutSettings, () => askJobSoon()]];
  for (const [kind, curated, changed] of kinds) {
    const shown = new Set(Object.keys(curated()));
    for (const el of document.querySelectorAll(kind === 'relief' ? '[data-k]' : '[data-c]')) {
      shown.add(kind === 'relief' ? el.dataset.k : el.dataset.c);
    }
    const box = $('more-' + kind);
    for (const d of S.options.settings[kind]) {
      if (shown.has(d.name) || !d.page) continue;
      const label = document.createElement('label');
      label.title = d.help;
      const name = document.createElement('code');
      name.textContent = d.flag;
      let el;
      if (d.switch) {
        el = document.createElement('input');
        el.type = 'checkbox';
      } else if (d.values.length) {
        el = document.createElement('select');
        el.append(new Option(d.default ? `${d.default} (default)` : 'default', ''));
        for (const v of d.values) if (v !== d.default) el.append(new Option(v, v));
      } else {
        el = document.createElement('input');
        el.type = 'text';
        el.placeholder = d.default || '';
      }
      el.dataset.more = kind;
      el.dataset.name = d.name;
      el.addEventListener(d.switch || d.values.length ? 'change' : 'input', changed);
      label.append(name, el);
      box.append(label);
    }
  }
}

function cutSettings() {
  return more('cut', {
    machine: $('machine').value,
    tool: $('tool').value,
    finish: $('finish').value,
    stepover: $('stepover').value.trim() || null,
    angle: num('angle') || 0,
    rough: $('rough').value || null,
    rest: $('rest').value || null,
    arcs: $('arcs').checked,
    origin: $('origin').value,
  });
}

// ---- one request at a time, the newest settings next -----------------

function scheduler(run) {
  let busy = false, again = false;
  async function go() {
    busy = true; again = false;
    $('busy').style.display = 'block';
    try { await run(); } catch (e) { status(e.message, true); }
    busy = false;
    if (again) go(); else $('busy').style.display = 'none';
  }
  return () => { if (busy) again = true; else go(); };
}

const askRelief = scheduler(async () => {
  const asked = S.inputAt;
  const t0 = performance.now();
  const p = await call('/api/relief', post({ relief: reliefSettings() }));
  if (!p) return;
  const got = performance.now();
  S.relief = p;
  // warnings beside the status, not as errors: the relief is made
  const warned = p.head.warnings.map((w) => 'warning: ' + w).join(' · ');
  $('warning').textContent = warned;
  $('warning').title = warned;
  status(`relief ${p.head.pixels[0]} × ${p.head.pixels[1]} px, ${p.head.width_mm.toFixed(1)} × ${p.head.height_mm.toFixed(1)} × ${p.head.depth_mm.toFixed(2)} mm`);
  $('command').textContent = p.head.command + (S.job ? '\n' + S.job.head.command : '');
  gfx.setField('relief', p.head.w, p.head.h, p.arrays.heights, null);
  const t1 = performance.now();
  draw();
  await frame();
  S.coarseMs = 0.7 * S.coarseMs + 0.3 * (performance.now() - t1);
  S.stats.relief.push({ total_ms: performance.now() - asked, request_ms: got - t0, shown_ms: performance.now() - t0 });
  S.drawn++;
  if (S.tab === 'job') askJob();
});

let jobTimer = 0;
function askJobSoon() { clearTimeout(jobTimer); jobTimer = setTimeout(askJob, 300); }
const askJob = scheduler(async () => {
  if (S.tab !== 'job') return;
  const t0 = performance.now();
  const p = await call('/api/job', post({ relief: reliefSettings(), cut: cutSettings() }));
  if (!p) return;
  S.job = p;
  const h = p.head;
  gfx.setField('job', h.cells[0], h.cells[1], p.arrays.cut, p.arrays.deviation);
  gfx.setMoves(p.arrays.moves);
  for (const id of ['dl-nc', 'dl-svg']) $(id).classList.remove('off');
  if (S.relief) $('command').textContent = S.relief.head.command + '\n' + h.command;
  summary();
  legend();
  draw();
  await frame();
  S.stats.job.push({ total_ms: performance.now() - t0 });
  S.drawn++;
});

function post(body) {
  return { method: 'POST', headers: { 'Content-Type': 'application/json' }, body: JSON.stringify(body) };
}
/// Resolves once the frame holding the last draw is on screen: the
/// second animation frame after it.
function frame() { return new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(() => r()))); }

function summary() {
  const h = S.job.head;
  const ok = (c, t) => `<span class="${c ? 'good' : 'bad'}">${t}</span>`;
  $('summary').innerHTML =
    `${h.lines.toLocaleString()} lines, estimated ${h.time}; cutting ${h.cut_m.toFixed(1)} m, rapids ${h.rapid_m.toFixed(1)} m; stepover ${h.stepover_mm.toFixed(3)} mm<br>` +
    `simulated gouge ${ok(h.gouge_mm <= 0.001, h.gouge_mm.toFixed(4) + ' mm')}, residual max ${h.residual_mm[0].toFixed(3)} / mean ${h.residual_mm[1].toFixed(4)} mm ` +
    (h.gouge_exact_per_move
      ? `(gouge exact along every move; residual on stock cells ${h.cell_mm.toFixed(3)} mm); `
      : `(stock cells ${h.cell_mm.toFixed(3)} mm; a cut's bottom hides at most ${(h.between_cells_mm * 1000).toFixed(1)} µm between them); `) +
    `rapids through stock: ${ok(!h.rapids_in_stock, h.rapids_in_stock)}, out of travel: ${ok(!h.out_of_travel, h.out_of_travel)}<br>` +
    `${h.engagement}` + (h.notes.length ? '<br>' + h.notes.join('<br>') : '') +
    (h.moves_drawn < h.moves ? `<br>(drawing ${h.moves_drawn.toLocaleString()} of ${h.moves.toLocaleString()} moves)` : '');
}

/// The deviation scale: the largest deviation shown (material left as its
/// mean over a stepover, or the gouge), rounded up to 1, 2 or 5.
function devScale() {
  if (S.job.devMax === undefined) {
    let m = 0;
    for (const d of S.job.arrays.deviation) if (d > m) m = d;
    S.job.devMax = m;
  }
  const m = Math.max(S.job.devMax, S.job.head.gouge_mm, 0.01);
  const e = Math.pow(10, Math.floor(Math.log10(m)));
  for (const k of [1, 2, 5, 10]) if (k * e >= m) return k * e;
  return 10 * e;
}

function legend() {
  const c = $('legend-bar'), g = c.getContext('2d');
  for (let x = 0; x < c.width; x++) {
    const [r, gg, b] = devColour((x / (c.width - 1)) * 2 - 1);
    g.fillStyle = `rgb(${r * 255},${gg * 255},${b * 255})`;
    g.fillRect(x, 0, 1, c.height);
  }
  const s = devScale();
  $('legend-ticks').innerHTML = [-s, -s / 2, 0, s / 2, s]
    .map((v, i) => `<span>${i === 0 ? 'gouge ' : ''}${v === 0 ? '0' : v.toPrecision(2)}${i === 4 ? ' mm left' : ''}</span>`).join('');
}

/// Colour of a deviation over the scale (-1 = gouge, +1 = left), as the
/// shader draws it.
function devColour(t) {
  const grey = [0.78, 0.78, 0.78];
  const end = t < 0 ? [0.85, 0.1, 0.1] : [0.1, 0.25, 0.9];
  const k = Math.min(1, Math.abs(t));
  return grey.map((g, i) => g + (end[i] - g) * k);
}

// ---- drawing ---------------------------------------------------------

const gfx = (() => {
  const canvas = $('scene3d');
  const gl = canvas.getContext('webgl2', { antialias: true, preserveDrawingBuffer: true });
  if (!gl) { status('this browser has no WebGL2: the views cannot be drawn', true); return null; }

  function program(vs, fs) {
    const p = gl.createProgram();
    for (const [type, src] of [[gl.VERTEX_SHADER, vs], [gl.FRAGMENT_SHADER, fs]]) {
      const s = gl.createShader(type);
      gl.shaderSource(s, '#version 300 es\nprecision highp float;\nprecision highp int;\n' + src);
      gl.compileShader(s);
      if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
      gl.attachShader(p, s);
    }
    gl.linkProgram(p);
    if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(p));
    const u = {};
    const n = gl.getProgramParameter(p, gl.ACTIVE_UNIFORMS);
    for (let i = 0; i < n; i++) {
      const name = gl.getActiveUniform(p, i).name;
      u[name] = gl.getUniformLocation(p, name);
    }
    return { p, u };
  }

  // a heightfield: heights (and deviations) in float textures, a grid of
  // vertices that fetches them; the normal per fragment from the full
  // resolution texture, so the light shows every sample
  const field = program(`
    layout(location = 0) in vec2 uv;
    layout(location = 1) in float h;
    uniform mat4 mvp;
    uniform vec4 rect;
    out vec2 vuv;
    out vec3 world;
    void main() {
      world = vec3(rect.x + uv.x * rect.z, rect.y + (1.0 - uv.y) * rect.w, h);
      vuv = uv;
      gl_Position = mvp * vec4(world, 1.0);
    }`, `
    in vec2 vuv;
    in vec3 world;
    uniform sampler2D height;
    uniform sampler2D dev;
    uniform vec4 rect;
    uniform vec3 light;
    uniform vec3 eye;
    uniform int look;
    uniform int mode;
    uniform float scale;
    out vec4 colour;
    float H(ivec2 c, ivec2 n) {
      float h = texelFetch(height, clamp(c, ivec2(0), n - 1), 0).r;
      return isnan(h) ? 0.0 : h;
    }
    void main() {
      ivec2 n = textureSize(height, 0);
      ivec2 c = ivec2(vuv * vec2(n - 1) + 0.5);
      vec2 pitch = rect.zw / vec2(max(n - 1, ivec2(1)));
      float hx = (H(c + ivec2(1, 0), n) - H(c - ivec2(1, 0), n)) / (2.0 * pitch.x);
      float hy = (H(c - ivec2(0, 1), n) - H(c + ivec2(0, 1), n)) / (2.0 * pitch.y);
      vec3 N = normalize(vec3(-hx, -hy, 1.0));
      vec3 V = normalize(eye - world);
      vec3 Hv = normalize(light + V);
      float diff = max(dot(N, light), 0.0);
      vec3 base; float spec = 0.0; float shine = 16.0;
      if (mode == 1) {
        float d = texelFetch(dev, c, 0).r;
        if (isnan(d)) base = vec3(0.35);
        else {
          float t = abs(d) < 0.001 ? 0.0 : clamp(d / scale, -1.0, 1.0);
          vec3 end = t < 0.0 ? vec3(0.85, 0.1, 0.1) : vec3(0.1, 0.25, 0.9);
          base = mix(vec3(0.78), end, abs(t));
        }
        spec = 0.1;
      } else if (look == 0) {
        // fine grain along y, slowly wandering
        float g = sin(world.x * 2.3 + 1.2 * sin(world.y * 0.045) + 0.4 * sin(world.y * 0.19 + world.x * 0.3));
        base = mix(vec3(0.74, 0.56, 0.36), vec3(0.64, 0.46, 0.28), 0.6 * smoothstep(0.55, 1.0, g));
        spec = 0.08;
      } else if (look == 1) {
        float v = sin(world.x * 0.12 + world.y * 0.07 + 3.0 * sin(world.y * 0.05 + 2.0 * sin(world.x * 0.04)));
        base = mix(vec3(0.93, 0.92, 0.89), vec3(0.62, 0.63, 0.66), pow(1.0 - abs(v), 14.0));
        spec = 0.25; shine = 40.0;
      } else {
        base = vec3(0.72, 0.72, 0.74);
        spec = 0.7; shine = 48.0;
        base *= 0.75 + 0.25 * N.z;
      }
      // a raking light darkens a flat panel: shade relative to the flat,
      // as a carver's lamp and eye adapt
      vec3 col = base * clamp(0.15 + 0.8 * diff / max(light.z, 0.25), 0.0, 1.25) + spec * pow(max(dot(N, Hv), 0.0), shine);
      colour = vec4(col, 1.0);
    }`);

  const lines = program(`
    layout(location = 0) in vec4 p;
    uniform mat4 mvp;
    out float kind;
    void main() { kind = p.w; gl_Position = mvp * vec4(p.xyz, 1.0); }`, `
    in float kind;
    out vec4 colour;
    void main() { colour = kind > 0.5 ? vec4(0.05, 0.15, 0.45, 0.3) : vec4(0.95, 0.15, 0.1, 0.2); }`);

  const solid = program(`
    layout(location = 0) in vec3 p;
    uniform mat4 mvp;
    out vec3 q;
    void main() { q = p; gl_Position = mvp * vec4(p, 1.0); }`, `
    in vec3 q;
    uniform vec3 eyeDir;
    out vec4 colour;
    void main() {
      vec3 n = normalize(cross(dFdx(q), dFdy(q)));
      float l = abs(dot(n, eyeDir));
      colour = vec4(vec3(0.8, 0.74, 0.64) * (0.25 + 0.75 * l), 1.0);
    }`);

  const fields = {};
  function texture(w, h, data) {
    const t = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, t);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.R32F, w, h, 0, gl.RED, gl.FLOAT, data);
    for (const k of [gl.TEXTURE_MIN_FILTER, gl.TEXTURE_MAG_FILTER]) gl.texParameteri(gl.TEXTURE_2D, k, gl.NEAREST);
    for (const k of [gl.TEXTURE_WRAP_S, gl.TEXTURE_WRAP_T]) gl.texParameteri(gl.TEXTURE_2D, k, gl.CLAMP_TO_EDGE);
    return t;
  }
  const grids = {};
  /// A grid of gw x gh vertices over the unit square, as triangles (its
  /// buffers shared by every field of that size).
  function grid(gw, gh) {
    const key = gw + 'x' + gh;
    if (grids[key]) return grids[key];
    const uv = new Float32Array(gw * gh * 2);
    for (let y = 0; y < gh; y++) for (let x = 0; x < gw; x++) {
      uv[2 * (y * gw + x)] = x / (gw - 1);
      uv[2 * (y * gw + x) + 1] = y / (gh - 1);
    }
    const idx = new Uint32Array((gw - 1) * (gh - 1) * 6);
    let k = 0;
    for (let y = 0; y + 1 < gh; y++) for (let x = 0; x + 1 < gw; x++) {
      const a = y * gw + x;
      idx.set([a, a + 1, a + gw, a + 1, a + gw + 1, a + gw], k);
      k += 6;
    }
    const b = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, b);
    gl.bufferData(gl.ARRAY_BUFFER, uv, gl.STATIC_DRAW);
    const e = gl.createBuffer();
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, e);
    gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, idx, gl.STATIC_DRAW);
    return (grids[key] = { gw, gh, uv: b, idx: e, count: idx.length });
  }

  /// A field's heights at a grid's vertices (nearest sample; the light
  /// reads every sample from the texture), bound with the grid.
  function fieldMesh(g, w, h, heights) {
    const hv = new Float32Array(g.gw * g.gh);
    for (let y = 0; y < g.gh; y++) {
      const row = Math.round(y * (h - 1) / (g.gh - 1)) * w;
      for (let x = 0; x < g.gw; x++) {
        const v = heights[row + Math.round(x * (w - 1) / (g.gw - 1))];
        hv[y * g.gw + x] = Number.isNaN(v) ? 0 : v;
      }
    }
    const vao = gl.createVertexArray();
    gl.bindVertexArray(vao);
    gl.bindBuffer(gl.ARRAY_BUFFER, g.uv);
    gl.enableVertexAttribArray(0);
    gl.vertexAttribPointer(0, 2, gl.FLOAT, false, 0, 0);
    const hb = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, hb);
    gl.bufferData(gl.ARRAY_BUFFER, hv, gl.STATIC_DRAW);
    gl.enableVertexAttribArray(1);
    gl.vertexAttribPointer(1, 1, gl.FLOAT, false, 0, 0);
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, g.idx);
    gl.bindVertexArray(null);
    return { vao, hb, count: g.count };
  }

  /// A field's coarse mesh is drawn at once; the fine one when the view
  /// rests (software GL takes long over many triangles).
  function setField(name, w, h, heights, dev) {
    const old = fields[name];
    if (old) {
      gl.deleteTexture(old.height);
      if (old.dev) gl.deleteTexture(old.dev);
      for (const m of [old.coarse, old.fine]) if (m) { gl.deleteVertexArray(m.vao); gl.deleteBuffer(m.hb); }
    }
    const side = (n) => { const gw = Math.max(2, Math.min(w, n)); return grid(gw, Math.max(2, Math.round(gw * h / w))); };
    const f = { w, h, heights, height: texture(w, h, heights), dev: dev ? texture(w, h, dev) : null };
    f.coarse = fieldMesh(side(COARSE), w, h, heights);
    f.fine = null;
    f.side = side;
    fields[name] = f;
  }
  /// The detailed mesh: as many vertices as this machine draws in about
  /// 150 ms, judged by how long the coarse mesh took (a GPU takes the
  /// most, software GL on two cores about 1.5x the coarse one's).
  function fine(f) {
    const n = Math.round(Math.min(FINE, COARSE * Math.sqrt(150 / Math.max(S.coarseMs, 1))));
    if (n <= COARSE || (f.w <= COARSE && f.h <= COARSE)) return f.coarse;
    if (!f.fine || f.fine.n !== n) {
      if (f.fine) { gl.deleteVertexArray(f.fine.vao); gl.deleteBuffer(f.fine.hb); }
      f.fine = fieldMesh(f.side(n), f.w, f.h, f.heights);
      f.fine.n = n;
    }
    return f.fine;
  }

  let moves = null;
  function setMoves(m) {
    if (!moves) {
      moves = { vao: gl.createVertexArray(), buf: gl.createBuffer(), count: 0 };
      gl.bindVertexArray(moves.vao);
      gl.bindBuffer(gl.ARRAY_BUFFER, moves.buf);
      gl.enableVertexAttribArray(0);
      gl.vertexAttribPointer(0, 4, gl.FLOAT, false, 0, 0);
      gl.bindVertexArray(null);
    }
    gl.bindBuffer(gl.ARRAY_BUFFER, moves.buf);
    gl.bufferData(gl.ARRAY_BUFFER, m, gl.STATIC_DRAW);
    moves.count = m.length / 4;
  }

  let mesh = null;
  function setMesh(pos, tri) {
    if (mesh) { gl.deleteVertexArray(mesh.vao); gl.deleteBuffer(mesh.b); gl.deleteBuffer(mesh.e); }
    if (!pos) { mesh = null; return; }
    const vao = gl.createVertexArray();
    gl.bindVertexArray(vao);
    const b = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, b);
    gl.bufferData(gl.ARRAY_BUFFER, pos, gl.STATIC_DRAW);
    gl.enableVertexAttribArray(0);
    gl.vertexAttribPointer(0, 3, gl.FLOAT, false, 0, 0);
    const e = gl.createBuffer();
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, e);
    gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, tri, gl.STATIC_DRAW);
    gl.bindVertexArray(null);
    let lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
    for (let i = 0; i < pos.length; i += 3) for (let k = 0; k < 3; k++) {
      lo[k] = Math.min(lo[k], pos[i + k]); hi[k] = Math.max(hi[k], pos[i + k]);
    }
    const c = lo.map((l, k) => (l + hi[k]) / 2);
    let r = 0;
    for (let i = 0; i < pos.length; i += 3) r = Math.max(r, Math.hypot(pos[i] - c[0], pos[i + 1] - c[1], pos[i + 2] - c[2]));
    mesh = { vao, b, e, count: tri.length, c, r };
  }

  function size() {
    const dpr = window.devicePixelRatio || 1;
    const w = Math.round(canvas.clientWidth * dpr), h = Math.round(canvas.clientHeight * dpr);
    if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; }
    gl.viewport(0, 0, w, h);
    return w / Math.max(h, 1);
  }

  function drawField(f, rect, withMoves, detailed) {
    const aspect = size();
    const cx = rect[0] + rect[2] / 2, cy = rect[1] + rect[3] / 2;
    // far enough that the panel fills the view with a margin
    const dist = 1.15 * Math.max(rect[3], rect[2] / aspect) / (2 * Math.tan(15 * D)) / S.orbit.zoom;
    const o = S.orbit;
    const eye = [cx + dist * Math.cos(o.el * D) * Math.sin(o.az * D),
                 cy - dist * Math.cos(o.el * D) * Math.cos(o.az * D),
                 dist * Math.sin(o.el * D)];
    const mvp = mul(perspective(30 * D, aspect, dist / 50, dist * 10), lookAt(eye, [cx, cy, 0], [0, 0, 1]));
    const l = S.light;
    const L = [Math.sin(l.az * D) * Math.cos(l.el * D), Math.cos(l.az * D) * Math.cos(l.el * D), Math.sin(l.el * D)];
    gl.enable(gl.DEPTH_TEST);
    gl.clearColor(0.23, 0.22, 0.21, 1);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    gl.useProgram(field.p);
    gl.uniformMatrix4fv(field.u.mvp, false, mvp);
    gl.uniform4fv(field.u.rect, rect);
    gl.uniform3fv(field.u.light, L);
    gl.uniform3fv(field.u.eye, eye);
    gl.uniform1i(field.u.look, ['wood', 'marble', 'metal'].indexOf($('look').value));
    gl.uniform1i(field.u.mode, f.dev ? 1 : 0);
    gl.uniform1f(field.u.scale, S.job ? devScale() : 1);
    gl.activeTexture(gl.TEXTURE0);
    gl.bindTexture(gl.TEXTURE_2D, f.height);
    gl.uniform1i(field.u.height, 0);
    gl.activeTexture(gl.TEXTURE1);
    gl.bindTexture(gl.TEXTURE_2D, f.dev || f.height);
    gl.uniform1i(field.u.dev, 1);
    const m = detailed ? fine(f) : f.coarse;
    gl.bindVertexArray(m.vao);
    gl.drawElements(gl.TRIANGLES, m.count, gl.UNSIGNED_INT, 0);
    if (withMoves && moves && moves.count) {
      gl.useProgram(lines.p);
      gl.uniformMatrix4fv(lines.u.mvp, false, mvp);
      gl.enable(gl.BLEND);
      gl.blendFunc(gl.SRC_ALPHA, gl.ONE_MINUS_SRC_ALPHA);
      gl.bindVertexArray(moves.vao);
      gl.drawArrays(gl.LINES, 0, moves.count);
      gl.disable(gl.BLEND);
    }
    gl.bindVertexArray(null);
  }

  /// The model as the relief's camera sees it (relievo's own basis).
  function drawMesh(s) {
    const aspect = size();
    gl.enable(gl.DEPTH_TEST);
    gl.clearColor(0.23, 0.22, 0.21, 1);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    if (!mesh) return;
    const [e, r, u] = basis(s);
    const persp = s.fov > 0;
    const dist = persp ? mesh.r / Math.sin(s.fov * D / 2) : mesh.r * 3;
    const view = new Float32Array([r[0], u[0], e[0], 0, r[1], u[1], e[1], 0, r[2], u[2], e[2], 0, 0, 0, 0, 1]);
    const t = mesh.c.map((c, k) => c + e[k] * dist);
    view[12] = -(r[0] * t[0] + r[1] * t[1] + r[2] * t[2]);
    view[13] = -(u[0] * t[0] + u[1] * t[1] + u[2] * t[2]);
    view[14] = -(e[0] * t[0] + e[1] * t[1] + e[2] * t[2]);
    const fit = 1.08 * mesh.r;
    const proj = persp
      ? perspective(2 * Math.asin(Math.min(0.99, fit / dist)) / Math.min(1, aspect), aspect, dist - 2 * mesh.r, dist + 2 * mesh.r)
      : ortho(fit * Math.max(1, aspect), fit * Math.max(1, 1 / aspect), dist - 2 * mesh.r, dist + 2 * mesh.r);
    gl.useProgram(solid.p);
    gl.uniformMatrix4fv(solid.u.mvp, false, mul(proj, view));
    gl.uniform3fv(solid.u.eyeDir, e);
    gl.bindVertexArray(mesh.vao);
    gl.drawElements(gl.TRIANGLES, mesh.count, gl.UNSIGNED_INT, 0);
    gl.bindVertexArray(null);
  }

  return { gl, fields, setField, setMoves, setMesh, drawField, drawMesh, hasMesh: () => !!mesh };
})();

// relievo's camera (src/scene/camera.rs): eye direction, image right and
// up from the preset and yaw/pitch/roll, turned into model coordinates
const PRESETS = { front: [0, 0], back: [180, 0], left: [-90, 0], right: [90, 0], top: [0, 90], bottom: [0, -90] };
const UP_FRAME = {
  y: [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
  z: [[1, 0, 0], [0, 0, -1], [0, 1, 0]],
  '-y': [[-1, 0, 0], [0, -1, 0], [0, 0, 1]],
  '-z': [[1, 0, 0], [0, 0, 1], [0, -1, 0]],
  x: [[0, 1, 0], [-1, 0, 0], [0, 0, 1]],
  '-x': [[0, -1, 0], [1, 0, 0], [0, 0, 1]],
};
function basis(s) {
  const [y0, p0] = PRESETS[s.view];
  const yaw = (y0 + s.yaw) * D, pitch = (p0 + s.pitch) * D;
  const e = [Math.sin(yaw) * Math.cos(pitch), Math.sin(pitch), Math.cos(yaw) * Math.cos(pitch)];
  let r = [Math.cos(yaw), 0, -Math.sin(yaw)];
  let u = cross(e, r);
  const sn = Math.sin(s.roll * D), cs = Math.cos(s.roll * D);
  [r, u] = [r.map((v, k) => v * cs - u[k] * sn), r.map((v, k) => v * sn + u[k] * cs)];
  const up = s.up || (S.model && /\.stl$/i.test(S.model.name) ? 'z' : 'y');
  const F = UP_FRAME[up];
  const m = (v) => F.map((f) => f[0] * v[0] + f[1] * v[1] + f[2] * v[2]);
  return [m(e), m(r), m(u)];
}

function cross(a, b) { return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]; }
function mul(a, b) {
  const o = new Float32Array(16);
  for (let c = 0; c < 4; c++) for (let r = 0; r < 4; r++) {
    let s = 0;
    for (let k = 0; k < 4; k++) s += a[k * 4 + r] * b[c * 4 + k];
    o[c * 4 + r] = s;
  }
  return o;
}
function perspective(fovy, aspect, near, far) {
  const f = 1 / Math.tan(fovy / 2);
  return new Float32Array([f / aspect, 0, 0, 0, 0, f, 0, 0, 0, 0, (far + near) / (near - far), -1, 0, 0, 2 * far * near / (near - far), 0]);
}
function ortho(hw, hh, near, far) {
  return new Float32Array([1 / hw, 0, 0, 0, 0, 1 / hh, 0, 0, 0, 0, -2 / (far - near), 0, 0, 0, -(far + near) / (far - near), 1]);
}
function lookAt(eye, at, up) {
  const z = norm(eye.map((v, k) => v - at[k]));
  const x = norm(cross(up, z));
  const y = cross(z, x);
  const d = (a) => -(a[0] * eye[0] + a[1] * eye[1] + a[2] * eye[2]);
  return new Float32Array([x[0], y[0], z[0], 0, x[1], y[1], z[1], 0, x[2], y[2], z[2], 0, d(x), d(y), d(z), 1]);
}
function norm(v) { const l = Math.hypot(...v) || 1; return v.map((x) => x / l); }

let restTimer = 0;
/// Draw the view now (coarse), and again in detail once nothing changed
/// for a moment.
function draw(detailed) {
  if (!gfx) return;
  clearTimeout(restTimer);
  if (!detailed) restTimer = setTimeout(() => draw(true), 400);
  $('legend').style.display = S.tab === 'job' && S.job ? 'block' : 'none';
  $('look-box').style.display = S.tab === 'relief' ? '' : 'none';
  $('moves-box').style.display = S.tab === 'job' ? '' : 'none';
  const picture = S.tab === 'model' && S.model && S.model.picture;
  $('note').style.display = picture ? 'block' : 'none';
  $('note').textContent = picture ? 'a depth or normal-map picture: its relief is in the Relief view' : '';
  if (S.tab === 'model') {
    gfx.drawMesh(reliefSettings());
  } else if (S.tab === 'relief' && gfx.fields.relief && S.relief) {
    const h = S.relief.head;
    gfx.drawField(gfx.fields.relief, [0, 0, h.width_mm, h.height_mm], false, detailed);
  } else if (S.tab === 'job' && gfx.fields.job && S.job) {
    const st = S.job.head.stock;
    gfx.drawField(gfx.fields.job, [st.x0, st.y0, st.width, st.height], $('show-moves').checked, detailed);
  } else {
    gfx.gl.clearColor(0.23, 0.22, 0.21, 1);
    gfx.gl.clear(gfx.gl.COLOR_BUFFER_BIT);
  }
}

// ---- the controls ----------------------------------------------------

function showValue(el) {
  const o = el.parentElement.querySelector('output');
  if (o) o.textContent = el.value;
}

function reliefChanged() {
  S.inputAt = performance.now();
  askRelief();
}

function wire() {
  for (const el of document.querySelectorAll('[data-k]')) {
    showValue(el);
    el.addEventListener('input', () => {
      S.touched.add(el.dataset.k);
      showValue(el);
      if (el.dataset.opt) $(el.dataset.opt).checked = true;
      if (S.tab === 'model') draw();
      reliefChanged();
    });
  }
  for (const id of ['steps-on', 'smooth-on']) $(id).addEventListener('change', reliefChanged);
  for (const el of document.querySelectorAll('[data-c]')) el.addEventListener('input', () => {
    if (el.id === 'machine') fillTools();
    askJobSoon();
  });
  for (const b of document.querySelectorAll('#tabs button')) b.addEventListener('click', () => tab(b.dataset.tab));
  $('look').addEventListener('input', () => draw());
  $('show-moves').addEventListener('input', () => draw());
  $('demo').addEventListener('click', async () => {
    try { await model(await call('/api/demo', { method: 'POST' })); } catch (e) { status(e.message, true); }
  });
  $('file').addEventListener('change', () => { if ($('file').files[0]) upload($('file').files[0]); });
  document.body.addEventListener('dragover', (e) => { e.preventDefault(); document.body.classList.add('dragging'); });
  document.body.addEventListener('dragleave', () => document.body.classList.remove('dragging'));
  document.body.addEventListener('drop', (e) => {
    e.preventDefault();
    document.body.classList.remove('dragging');
    if (e.dataTransfer.files[0]) upload(e.dataTransfer.files[0]);
  });
  $('copy').addEventListener('click', () => navigator.clipboard && navigator.clipboard.writeText($('command').textContent));
  window.addEventListener('resize', () => draw());
  pointer();
}

/// Drag turns the view (in the model view: the relief's camera); shift or
/// the right button moves the light; the wheel zooms.
function pointer() {
  const c = $('scene3d');
  let last = null, moved = false;
  c.addEventListener('contextmenu', (e) => e.preventDefault());
  c.addEventListener('pointerdown', (e) => { last = [e.clientX, e.clientY, e.shiftKey || e.button === 2]; moved = false; c.setPointerCapture(e.pointerId); });
  c.addEventListener('pointermove', (e) => {
    if (!last) return;
    const dx = e.clientX - last[0], dy = e.clientY - last[1];
    last[0] = e.clientX; last[1] = e.clientY;
    moved = true;
    if (last[2]) {
      S.light.az = (S.light.az + dx * 0.5 + 360) % 360;
      S.light.el = Math.max(2, Math.min(89, S.light.el - dy * 0.3));
    } else if (S.tab === 'model') {
      const yaw = $('yaw'), pitch = $('pitch');
      yaw.value = ((parseFloat(yaw.value) - dx * 0.4 + 540) % 360) - 180;
      pitch.value = Math.max(-89, Math.min(89, parseFloat(pitch.value) + dy * 0.4));
      showValue(yaw); showValue(pitch);
    } else {
      S.orbit.az -= dx * 0.4;
      S.orbit.el = Math.max(5, Math.min(89.9, S.orbit.el + dy * 0.3));
    }
    draw();
  });
  c.addEventListener('pointerup', () => {
    if (last && moved && !last[2] && S.tab === 'model') { S.touched.add('yaw'); reliefChanged(); }
    last = null;
  });
  c.addEventListener('wheel', (e) => {
    e.preventDefault();
    S.orbit.zoom = Math.max(0.3, Math.min(20, S.orbit.zoom * Math.exp(-e.deltaY * 0.001)));
    draw();
  }, { passive: false });
}

function tab(t) {
  S.tab = t;
  for (const b of document.querySelectorAll('#tabs button')) b.classList.toggle('on', b.dataset.tab === t);
  // the Machine panel takes the stage's place
  $('machine-panel').hidden = t !== 'machine';
  $('stage').hidden = $('summary').hidden = t === 'machine';
  draw();
  if (t === 'job') askJob();
}

async function upload(f) {
  const max = S.options ? S.options.max_upload : 128 << 20;
  if (f.size > max) { status(`${f.name}: ${(f.size / 1048576).toFixed(0)} MB, more than the ${(max / 1048576).toFixed(0)} MB the studio takes`, true); return; }
  status(`opening ${f.name}…`);
  try {
    await model(await call('/api/model?name=' + encodeURIComponent(f.name), { method: 'POST', body: f }));
  } catch (e) {
    status(e.message, true);
  }
}

/// A new model on the bench: its name, objects and 3D view, then its relief.
async function model(info) {
  S.model = info;
  S.job = null;
  for (const id of ['dl-nc', 'dl-svg']) $(id).classList.add('off');
  $('model-name').textContent = info.name + (info.triangles ? ` (${info.triangles.toLocaleString()} triangles)` : '');
  $('objects').innerHTML = info.objects.length > 1 ? '<p class="hint">Emphasis per object</p>' : '';
  if (info.objects.length > 1) {
    for (const o of info.objects) {
      const l = document.createElement('label');
      l.textContent = o + ' ';
      const i = document.createElement('input');
      Object.assign(i, { type: 'range', min: 0, max: 4, step: 0.1, value: 1 });
      i.dataset.name = o;
      const out = document.createElement('output');
      out.textContent = '1';
      i.addEventListener('input', () => { out.textContent = i.value; reliefChanged(); });
      l.append(i, out);
      $('objects').append(l);
    }
  }
  if (gfx) {
    if (info.picture) gfx.setMesh(null, null);
    else {
      const m = await call('/api/mesh');
      gfx.setMesh(m.arrays.positions, m.arrays.triangles);
    }
  }
  reliefChanged();
}

function fillTools() {
  const m = S.options.machines.find((x) => x.id === $('machine').value) || { tools: [] };
  const fill = (id, first, extra) => {
    const sel = $(id), keep = sel.value;
    sel.innerHTML = '';
    for (const [v, t] of first.concat(m.tools.map((x) => [x.id, `${x.id} · ${x.name}`]), extra)) {
      const o = document.createElement('option');
      o.value = v; o.textContent = t;
      sel.append(o);
    }
    if ([...sel.options].some((o) => o.value === keep)) sel.value = keep;
  };
  fill('tool', [['ball:3.175', 'ball 3.175 mm']], [['ball:1', 'ball 1 mm'], ['vbit:60:6', 'V-bit 60°']]);
  fill('rough', [['', 'none'], ['flat:3.175', 'flat 3.175 mm']], [['flat:6', 'flat 6 mm']]);
  fill('rest', [['', 'none'], ['ball:1', 'ball 1 mm']], [['ball:0.5', 'ball 0.5 mm']]);
}

async function start() {
  wire();
  try {
    S.options = await call('/api/options');
    for (const m of S.options.machines) $('machine').append(new Option(m.name, m.id));
    for (const m of S.options.materials) $('material').append(new Option(`${m.id} (${m.description})`, m.id));
    fillTools();
    buildMore();
    await model(await call('/api/model'));
  } catch (e) {
    status(e.message, true);
  }
}
start();
