// Node: what the node says about itself — its identity and versions (the detailed status),
// key figures from GET /metrics (public, Prometheus text), and the newest lines of its log
// (GET /api/node/log: OWNER with scope `config`; each read is recorded as LOG_READ). Every
// value is put into the page as text.
import { $, el, replace, setText } from './dom.js';
import { request } from './api.js';
import { app, on, roleAtLeast } from './state.js';

const LOG_LIMIT = 200;

function facts(dl, rows) {
  replace(dl, rows.filter(Boolean).map(([k, v, cls]) => [
    el('dt', {}, k),
    el('dd', { class: cls || '' }, v === undefined || v === null || v === '' ? '–' : String(v)),
  ]));
}

const list = (v) => (Array.isArray(v) ? v.join(', ') : '');

function driverWords(d) {
  if (typeof d !== 'object') return String(d);
  const parts = [d.name || d.type || '?'];
  if (d.simulated) parts.push('(simulated)');
  const has = [d.has_base && 'base', d.has_arm && `arm (${d.arm_joints || '?'} joints)`, d.has_gripper && 'gripper'].filter(Boolean);
  if (has.length) parts.push('— ' + has.join(', '));
  return parts.join(' ');
}

function renderFacts() {
  const s = app.status || {};
  const d = s.discovery || {};
  const r = s.robot || {};
  const reg = s.registry && typeof s.registry === 'object' ? s.registry : null;
  facts($('#node-facts'), [
    ['Robot name', s.name || d.name],
    ['Model', [d.manufacturer, d.model].filter(Boolean).join(' ')],
    r.driver && ['Driver', driverWords(r.driver)],
    ['RURI', s.ruri, 'mono'],
    s.ruri_sdk && ['RURI (SDK form)', s.ruri_sdk, 'mono'],
    ['RRN', s.rrn || d.rrn, 'mono'],
    s.software && ['Software', `${s.software.name || 'rcand'} ${s.software.version || ''}`.trim()],
    ['RCAN protocol', s.rcan_version || d.rcan_version],
    ['Extensions', list(s.extensions)],
    ['Capabilities', list(s.capabilities)],
    ['HTTP port', d.port],
    ['Transports', transports(s)],
    reg && ['Registry', reg.url || reg.state || reg.status || 'linked'],
    ['Audit log', s.audit_available === false ? 'UNAVAILABLE' : 'recording', s.audit_available === false ? 'bad' : 'good'],
  ]);
  renderLimits();
}

// The safety core's limits as it enforces them (the detailed status's robot.limits: the
// configuration's safety block met with the driver's envelope), and its limit policy.
const num = (v, unit) => (typeof v === 'number' && isFinite(v) ? `${Math.round(v * 1000) / 1000} ${unit}` : undefined);
function joints(lo, hi) {
  if (!Array.isArray(lo) || !Array.isArray(hi)) return undefined;
  return lo.map((l, i) => `J${i + 1} ${num(l, '')}…${num(hi[i], 'rad')}`.replace(/ +…/, '…')).join(', ');
}
function renderLimits() {
  const r = (app.status || {}).robot || {};
  const l = r.limits;
  if (!l || typeof l !== 'object') {
    facts($('#node-limits'), [['Limits', 'shown to a signed-in user (the detailed status)']]);
    return;
  }
  const w = l.workspace || {};
  const fence = w.enabled
    ? `x ${num(w.min_x, 'm')} … ${num(w.max_x, 'm')}, y ${num(w.min_y, 'm')} … ${num(w.max_y, 'm')}`
    : 'off';
  const policy = { clamp: 'clamp to the limit', reject: 'refuse beyond a limit' }[r.limit_policy] || r.limit_policy;
  facts($('#node-limits'), [
    ['Beyond a limit', policy],
    ['Max linear speed', num(l.max_linear_mps, 'm/s')],
    ['Max turn rate', num(l.max_angular_radps, 'rad/s')],
    ['Max drive duration', num(l.max_drive_duration_ms, 'ms')],
    r.driver && r.driver.has_arm && ['Max joint speed', num(l.max_joint_speed_radps, 'rad/s')],
    r.driver && r.driver.has_arm && ['Joint ranges', joints(l.joint_min_rad, l.joint_max_rad)],
    ['Workspace fence', fence],
  ]);
}

// The transports the page can see: HTTP (it is talking to it) and the WebSocket stream, plus
// those the node's log says it started (gRPC, UDP, MQTT; the owner's view only) or its metrics
// name.
const seenTransports = new Set();
function transports() {
  return ['HTTP', 'WebSocket stream', ...seenTransports].join(', ');
}

const STARTED = { 'grpc.listening': 'gRPC', 'udp.listening': 'UDP', mqtt_started: 'MQTT' };

// Prometheus text → { name: [{labels, value}] } (names and values only; the page shows a few).
export function parseMetrics(text) {
  const out = {};
  for (const line of String(text).split('\n')) {
    if (!line || line[0] === '#') continue;
    const m = /^([a-zA-Z_:][a-zA-Z0-9_:]*)(\{[^}]*\})?\s+(\S+)/.exec(line);
    if (!m) continue;
    const v = Number(m[3]);
    if (!isFinite(v)) continue;
    (out[m[1]] = out[m[1]] || []).push({ labels: m[2] || '', value: v });
  }
  return out;
}

const one = (mx, name) => (mx[name] && mx[name].length ? mx[name][0].value : undefined);
const sum = (mx, name, pred = () => true) =>
  (mx[name] ? mx[name].filter((s) => pred(s.labels)).reduce((a, s) => a + s.value, 0) : undefined);

function renderMetrics(mx) {
  const reqs = sum(mx, 'rcan_requests_total');
  const refused = sum(mx, 'rcan_requests_total', (l) => /status="[45]\d\d"/.test(l));
  for (const [t, name] of [['gRPC', 'grpc'], ['MQTT', 'mqtt'], ['UDP', 'udp']]) {
    if (Object.keys(mx).some((k) => k.includes(`_${name}_`))) seenTransports.add(t);
  }
  facts($('#node-metrics'), [
    ['ESTOP', one(mx, 'rcan_estop_active') === 1 ? 'LATCHED' : 'clear', one(mx, 'rcan_estop_active') === 1 ? 'bad' : 'good'],
    ['Requests answered', reqs],
    ['Refused (4xx/5xx)', refused],
    ['Streams open', one(mx, 'rcan_streams_open')],
    ['Control sessions', one(mx, 'rcan_control_sessions')],
    ['Waiting for control', one(mx, 'rcan_control_queue')],
    ['Leases running', one(mx, 'rcan_leases_active')],
    ['Audit: last seq', one(mx, 'rcan_audit_last_seq')],
    ['Audit: queue depth', one(mx, 'rcan_audit_queue_depth')],
    ['Audit: failures', one(mx, 'rcan_audit_failures_total')],
  ]);
  renderFacts();
}

function logRow(line) {
  const o = line && typeof line === 'object' ? line : { event: String(line) };
  const rest = Object.entries(o)
    .filter(([k]) => k !== 'ts' && k !== 'level' && k !== 'event')
    .map(([k, v]) => `${k}=${typeof v === 'string' ? v : JSON.stringify(v)}`)
    .join('  ');
  const level = String(o.level || '');
  return el('tr', {},
    el('td', { class: 'nowrap mono' }, String(o.ts || '')),
    el('td', { class: level === 'error' ? 'bad' : level === 'warn' ? 'warn' : '' }, level),
    el('td', { class: 'mono' }, String(o.event || '')),
    el('td', { class: 'details' }, rest));
}

async function loadLog() {
  const body = $('#log-table tbody');
  const wrap = $('#log-table').parentElement;
  wrap.hidden = false;
  if (!roleAtLeast('OWNER')) {
    replace(body);
    wrap.hidden = true;
    setText($('#log-note'), `The node's log names addresses, files and principals, so only its owner (OWNER with scope config) may read it; you are ${app.role || 'not signed in'}. The page did not ask for it.`);
    return;
  }
  try {
    const res = await request('GET', `/api/node/log?limit=${LOG_LIMIT}`);
    const lines = Array.isArray(res && res.lines) ? res.lines : [];
    for (const l of lines) if (l && STARTED[l.event]) seenTransports.add(STARTED[l.event]);
    renderFacts();
    replace(body, lines.slice().reverse().map(logRow));
    setText($('#log-note'), `The newest ${lines.length} of the ${res.written} lines the node has written since it started (it keeps the last ${res.capacity}), newest first; URLs are cut to their host. This read is recorded in the audit log (LOG_READ).`);
  } catch (e) {
    replace(body);
    wrap.hidden = true;
    setText($('#log-note'), e.status === 403
      ? `The node keeps its log for its owner with scope config; your token does not have it (${e.code}).`
      : `The log could not be read: ${e.code} — ${e.message}`);
  }
}

async function loadMetrics() {
  try {
    renderMetrics(parseMetrics(await request('GET', '/metrics', undefined, { text: true })));
    setText($('#metrics-note'), `From GET /metrics (public, Prometheus text), read at ${new Date().toLocaleTimeString()}.`);
  } catch (e) {
    setText($('#metrics-note'), `The metrics could not be read: ${e.code} — ${e.message}`);
  }
}

export function loadNode() {
  renderFacts();
  loadMetrics();
  loadLog();
}

export function initNode() {
  $('#node-refresh').addEventListener('click', loadNode);
  on('view', (name) => { if (name === 'node') loadNode(); });
  on('status', () => { if (document.body.dataset.view === 'node') renderFacts(); });
}
