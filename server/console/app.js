// The operator's page (docs/console.md): the map's segments in tiles, the first traversal, each
// client's last answers fading with age, and the server's live statistics, polled from /api/.
// Plain JS and a canvas: nothing is fetched but this server's API.
'use strict';

const params = new URLSearchParams(location.search);
const token = params.get('token') || '';
const pollMs = Math.max(200, Number(params.get('poll_ms')) || 1000);
const fadeS = Math.max(1, Number(params.get('fade_s')) || 120);
// ?polls=N: stop after N polls (a snapshot: screenshots and tests, with nothing left in flight).
const maxPolls = Number(params.get('polls')) || Infinity;
// ?size=WxH: a canvas of fixed size (screenshots, tests); otherwise the window's.
const fixedSize = /^(\d+)x(\d+)$/.exec(params.get('size') || '');
const kAnswersPerClient = 20;  // the trail drawn per client
const kAnswersListed = 15;
const kMaxClients = 200;       // clients drawn and listed: those heard from last
const kMaxTiles = 600;         // tiles kept in memory; the view holds at most 64
const kColors = {segment: '#3080ff', trajectory: '#8b949e', localized: '#00e676', outside_prior: '#ffb300',
                 not_localized: '#ff1744', error: '#ff1744', background: '#0d1117'};

const state = {map: null, view: null, tiles: new Map(), pending: new Set(), cursor: 0, clients: new Map(),
               answers: [], stats: null, serverOffsetS: 0, lastDrawSegments: 0};
const canvas = document.getElementById('map');
const ctx = canvas.getContext('2d');

// The token of the page's address goes with every API call as a header, not in its URL.
function api(path) {
  const headers = token ? {Authorization: 'Bearer ' + token} : {};
  return fetch(path, {headers, cache: 'no-store'}).then(r => {
    if (!r.ok) return r.json().catch(() => ({})).then(j => { throw new Error(r.status + ' ' + (j.error || r.statusText)); });
    return r.json();
  });
}

function text(id, value) { const e = document.getElementById(id); if (e) e.textContent = value; }

function row(table, cells) {
  const tr = document.createElement('tr');
  for (const c of cells) {
    const td = document.createElement('td');
    td.textContent = c.text;
    if (c.cls) td.className = c.cls;
    tr.appendChild(td);
  }
  table.appendChild(tr);
  return tr;
}

// ---- the view: map metres to canvas pixels (north up) ---------------------------------------
function resize() {
  const host = document.getElementById('view');
  canvas.width = fixedSize ? Number(fixedSize[1]) : host.clientWidth;
  canvas.height = fixedSize ? Number(fixedSize[2]) : host.clientHeight;
}

// Fits the map's segments and trajectory into the canvas with a 24 px margin (or ?view=x0,y0,x1,y1).
function fitView() {
  const b = state.map.bounds;
  let [x0, y0, x1, y1] = [b.min[0], b.min[1], b.max[0], b.max[1]];
  for (const p of state.map.trajectory) x0 = Math.min(x0, p[0]), y0 = Math.min(y0, p[1]), x1 = Math.max(x1, p[0]), y1 = Math.max(y1, p[1]);
  const asked = (params.get('view') || '').split(',').map(Number);
  const viewAsked = asked.length === 4 && asked.every(Number.isFinite);
  if (viewAsked) [x0, y0, x1, y1] = asked;
  const margin = 24;
  // The bounds of a map of one segment are a point: fitted as 1 m. An asked box may be smaller
  // (a covariance ellipse of a few centimetres).
  const least = viewAsked ? 0.01 : 1;
  const w = Math.max(least, x1 - x0), h = Math.max(least, y1 - y0);
  const scale = Math.min((canvas.width - 2 * margin) / w, (canvas.height - 2 * margin) / h);
  state.view = {cx: (x0 + x1) / 2, cy: (y0 + y1) / 2, scale: Math.max(scale, 1e-4)};
  publishView();
}

// The transform in the DOM, for tests and users' tools: px = width/2 + (x - cx) * scale,
// py = height/2 - (y - cy) * scale.
function publishView() {
  const v = state.view;
  canvas.dataset.cx = v.cx, canvas.dataset.cy = v.cy, canvas.dataset.scale = v.scale;
}

function toPx(x, y) {
  const v = state.view;
  return [canvas.width / 2 + (x - v.cx) * v.scale, canvas.height / 2 - (y - v.cy) * v.scale];
}

function toMap(px, py) {
  const v = state.view;
  return [v.cx + (px - canvas.width / 2) / v.scale, v.cy - (py - canvas.height / 2) / v.scale];
}

// ---- tiles -----------------------------------------------------------------------------------
// The level whose tiles are ~512 px on screen, coarser while the view would need over 64 tiles.
function visibleTiles() {
  const t = state.map.tiles;
  let z = Math.round(Math.log2(t.root_m * state.view.scale / 512));
  z = Math.min(t.max_level, Math.max(0, z));
  const [x0, y1] = toMap(0, 0), [x1, y0] = toMap(canvas.width, canvas.height);
  for (;; --z) {
    const size = t.root_m / Math.pow(2, z);
    const tx0 = Math.floor(x0 / size), tx1 = Math.floor(x1 / size), ty0 = Math.floor(y0 / size), ty1 = Math.floor(y1 / size);
    if ((tx1 - tx0 + 1) * (ty1 - ty0 + 1) <= 64 || z === 0) {
      const out = [];
      for (let x = tx0; x <= tx1; ++x) for (let y = ty0; y <= ty1; ++y) out.push(z + '/' + x + '/' + y);
      return out;
    }
  }
}

function loadTiles() {
  for (const key of visibleTiles()) {
    if (state.tiles.has(key) || state.pending.has(key)) continue;
    state.pending.add(key);
    api('api/tiles/' + key).then(tile => {
      state.tiles.set(key, tile.segments);
      if (state.tiles.size > kMaxTiles) state.tiles.delete(state.tiles.keys().next().value);
    }).catch(e => setConnection(false, e.message)).finally(() => { state.pending.delete(key); draw(); });
  }
}

// ---- drawing -----------------------------------------------------------------------------------
function drawSegments() {
  ctx.fillStyle = kColors.segment;
  const r = Math.max(1.5, Math.min(4, state.view.scale * 0.6));
  let n = 0;
  for (const key of visibleTiles()) {
    const segments = state.tiles.get(key);
    if (!segments) continue;
    for (const s of segments) {
      const [px, py] = toPx(s[1], s[2]);
      if (px < -r || py < -r || px > canvas.width + r || py > canvas.height + r) continue;
      ctx.fillRect(px - r, py - r, 2 * r, 2 * r);
      ++n;
    }
  }
  state.lastDrawSegments = n;
}

function drawTrajectory() {
  const t = state.map.trajectory;
  if (t.length < 2) return;
  ctx.strokeStyle = kColors.trajectory;
  ctx.lineWidth = 1.5;
  ctx.globalAlpha = 0.8;
  ctx.beginPath();
  t.forEach((p, i) => { const [x, y] = toPx(p[0], p[1]); if (i) ctx.lineTo(x, y); else ctx.moveTo(x, y); });
  ctx.stroke();
  ctx.globalAlpha = 1;
}

// The 2-sigma ellipse of the horizontal position covariance [xx, xy, yy] (m^2).
function drawEllipse(px, py, cov) {
  const [a, b, c] = cov;
  const mean = (a + c) / 2, d = Math.sqrt(((a - c) / 2) ** 2 + b * b);
  const l1 = mean + d, l2 = Math.max(0, mean - d);
  // The major axis (b, l1 - a) in map axes; the canvas's y points down.
  const theta = b !== 0 ? Math.atan2(l1 - a, b) : (a >= c ? 0 : Math.PI / 2);
  const r1 = 2 * Math.sqrt(l1) * state.view.scale, r2 = 2 * Math.sqrt(l2) * state.view.scale;
  ctx.beginPath();
  ctx.ellipse(px, py, Math.max(r1, 1), Math.max(r2, 1), -theta, 0, 2 * Math.PI);
  ctx.stroke();
}

function drawAnswer(a, nowS, newest) {
  if (!a.pose) return;
  const age = nowS - a.time;
  ctx.globalAlpha = Math.max(0.25, 1 - age / fadeS);
  const color = kColors[a.status] || kColors.error;
  const [px, py] = toPx(a.pose.x, a.pose.y);
  ctx.fillStyle = ctx.strokeStyle = color;
  ctx.lineWidth = 2;
  const r = newest ? 7 : 3;
  ctx.beginPath();
  ctx.arc(px, py, r, 0, 2 * Math.PI);
  if (a.status === 'not_localized') ctx.stroke(); else ctx.fill();
  if (newest && !a.pose.from_prior) {
    ctx.beginPath();  // the heading
    ctx.moveTo(px, py);
    ctx.lineTo(px + 16 * Math.cos(a.pose.yaw), py - 16 * Math.sin(a.pose.yaw));
    ctx.stroke();
    if (a.covariance_xy) drawEllipse(px, py, a.covariance_xy);
  }
  ctx.globalAlpha = 1;
}

function draw() {
  if (!state.view) return;
  ctx.fillStyle = kColors.background;
  ctx.fillRect(0, 0, canvas.width, canvas.height);
  drawTrajectory();
  drawSegments();
  const nowS = Date.now() / 1000 + state.serverOffsetS;
  for (const list of state.clients.values()) list.forEach((a, i) => drawAnswer(a, nowS, i === list.length - 1));
  document.body.dataset.segmentsDrawn = state.lastDrawSegments;
}

// ---- the panel -------------------------------------------------------------------------------
function showMap(m) {
  text('map-name', m.name || '(unnamed map)');
  text('map-schema', m.schema);
  text('map-segments', m.segments.toLocaleString('en'));
  text('map-matcher', m.matcher + (m.fell_back_to_l2 ? ' (fell back: no classifier)' : ''));
  text('map-preset', m.preset + (m.surface_layer ? ', surface layer' : ''));
  text('map-keyframes', m.trajectory_keyframes);
  text('map-built', (m.created_utc || '?') + ' by ' + (m.tool_version || '?'));
  text('map-profile', m.profile || '(none)');
  text('map-parameters', JSON.stringify(m.parameters, null, 1));
  document.title = m.name + ' - segmatch-server console';
}

function fmt(v, digits) { return v === undefined || v === null ? '-' : Number(v).toFixed(digits); }

function showStats(s) {
  const c = s.counters, l = s.localization;
  text('stat-rate', fmt(l.rate_per_s, 1));
  text('stat-rate-window', '(last ' + l.rate_window_s + ' s)');
  const lat = l.latency_ms;
  text('stat-p50', lat.samples ? fmt(lat.p50, 1) : '-');
  text('stat-p90', lat.samples ? fmt(lat.p90, 1) : '-');
  text('stat-p99', lat.samples ? fmt(lat.p99, 1) : '-');
  for (const k of ['localize_requests', 'localized', 'errors', 'timed_out', 'requests', 'connections']) text('stat-' + k, c[k]);
  const refusals = document.getElementById('refusals');
  refusals.textContent = '';
  for (const [reason, n] of Object.entries(l.refusals)) row(refusals, [{text: reason}, {text: n, cls: 'num'}]).id = 'refusal-' + reason;
  const errors = document.getElementById('errors');
  errors.textContent = '';
  for (const [code, n] of Object.entries(l.errors)) row(errors, [{text: 'code ' + code}, {text: n, cls: 'num'}]);
}

function ago(t) {
  const s = Math.max(0, Date.now() / 1000 + state.serverOffsetS - t);
  return s < 90 ? s.toFixed(0) + ' s' : (s / 60).toFixed(0) + ' min';
}

function why(a) {
  if (a.status === 'localized') return a.method ? 'by ' + a.method : '';
  if (a.status === 'error') return 'error ' + a.error_code + ': ' + a.reason;
  return (a.refusal && a.refusal !== 'NONE' ? a.refusal + ': ' : '') + a.reason;
}

function showAnswers() {
  const clients = document.getElementById('clients');
  clients.textContent = '';
  for (const [peer, list] of [...state.clients].reverse().slice(0, 30)) {  // the 30 heard from last
    const a = list[list.length - 1];
    row(clients, [{text: peer}, {text: a.status, cls: 'status-' + a.status}, {text: ago(a.time), cls: 'num'}]);
    row(clients, [{text: why(a), cls: 'reason'}]).firstChild.colSpan = 3;
  }
  const answers = document.getElementById('answers');
  answers.textContent = '';
  for (const a of state.answers.slice(-kAnswersListed).reverse()) {
    const tr = row(answers, [{text: '#' + a.request_id}, {text: a.status, cls: 'status-' + a.status},
                             {text: fmt(a.latency_ms, 0) + ' ms', cls: 'num'}]);
    tr.className = 'answer';
    row(answers, [{text: a.peer + ' ' + a.type + (a.method ? ' (' + a.method + ')' : '') + ' ' + why(a), cls: 'reason'}])
        .firstChild.colSpan = 3;
  }
}

function setConnection(good, message) {
  const e = document.getElementById('connection');
  e.className = good ? 'good' : 'bad';
  e.textContent = good ? 'live' : 'disconnected: ' + message;
}

// ---- polling -----------------------------------------------------------------------------------
function takeAnswers(reply) {
  state.serverOffsetS = reply.now - Date.now() / 1000;
  state.cursor = reply.cursor;
  for (const a of reply.answers) {
    // A client is a connection (the protocol names no vehicle); the most recently heard last.
    const list = state.clients.get(a.peer) || [];
    state.clients.delete(a.peer);
    state.clients.set(a.peer, list);
    list.push(a);
    if (list.length > kAnswersPerClient) list.shift();
    if (state.clients.size > kMaxClients) state.clients.delete(state.clients.keys().next().value);
    state.answers.push(a);
  }
  if (state.answers.length > 200) state.answers.splice(0, state.answers.length - 200);
  return reply.answers.length < 1000;  // drained (the server lists at most 1000 per call by default)
}

function poll() {
  Promise.all([api('api/answers?since=' + state.cursor), api('api/stats')])
      .then(([answers, stats]) => {
        const drained = takeAnswers(answers);
        state.stats = stats;
        showStats(stats);
        showAnswers();
        draw();
        setConnection(true);
        const polls = (Number(document.body.dataset.polls) || 0) + 1;
        document.body.dataset.polls = polls;
        if (polls < maxPolls || !drained) setTimeout(poll, drained ? pollMs : 0);
      })
      .catch(e => { setConnection(false, e.message); setTimeout(poll, pollMs); });
}

// ---- pan and zoom ------------------------------------------------------------------------------
function viewChanged() { publishView(); loadTiles(); draw(); }

canvas.addEventListener('wheel', e => {
  e.preventDefault();
  const [mx, my] = toMap(e.offsetX, e.offsetY);
  state.view.scale *= Math.exp(-e.deltaY * 0.0015);
  const [nx, ny] = toMap(e.offsetX, e.offsetY);
  state.view.cx += mx - nx, state.view.cy += my - ny;
  viewChanged();
}, {passive: false});

let drag = null;
canvas.addEventListener('mousedown', e => { drag = [e.clientX, e.clientY]; canvas.style.cursor = 'grabbing'; });
window.addEventListener('mouseup', () => { drag = null; canvas.style.cursor = 'grab'; });
window.addEventListener('mousemove', e => {
  if (!drag || !state.view) return;
  state.view.cx -= (e.clientX - drag[0]) / state.view.scale;
  state.view.cy += (e.clientY - drag[1]) / state.view.scale;
  drag = [e.clientX, e.clientY];
  viewChanged();
});
window.addEventListener('resize', () => { if (!fixedSize && state.view) { resize(); viewChanged(); } });

function start() {
  resize();
  api('api/map').then(m => {
    state.map = m;
    showMap(m);
    fitView();
    loadTiles();
    draw();
    poll();
  }).catch(e => { setConnection(false, e.message); setTimeout(start, 2000); });
}
start();
