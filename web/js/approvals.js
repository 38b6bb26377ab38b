// Approvals: HiTL items waiting for a human (PROFILE §8, seed §16.4). Pushed on the stream as
// PENDING_AUTH and listed by GET /rcan/v1/pending; approve/deny by POST /rcan/v1/authorize
// (OWNER or CREATOR; everyone else sees them read-only).
import { $, el, replace, setText, toast, fmtTime } from './dom.js';
import { request, uuid, serverNow } from './api.js';
import { app, roleAtLeast } from './state.js';

const items = new Map();   // key → item
let available = null;      // null unknown, true, false (the node has no pending endpoint)
let tick = 0;

function keyOf(p) {
  return p.pending_id || p.ref_message_id || p.message_id || p.thought_id;
}

// A PENDING_AUTH may arrive as the message itself or wrapped in an envelope's payload.
function normalise(msg) {
  const p = msg && msg.payload && typeof msg.payload === 'object' && (msg.payload.action_type || msg.payload.pending_id || msg.payload.ref_message_id)
    ? { ...msg.payload } : { ...msg };
  const oc = p.original_command && typeof p.original_command === 'object' ? p.original_command : {};
  const ocp = oc.payload && typeof oc.payload === 'object' ? oc.payload : {};
  const ai = (oc.ai && typeof oc.ai === 'object') ? oc.ai : {};
  const ref = p.ref_message_id || oc.message_id || oc.msg_id || p.message_id;
  let expires = typeof p.expires_at_ms === 'number' ? p.expires_at_ms : null;
  if (expires === null && typeof p.timeout_remaining_ms === 'number') expires = serverNow() + p.timeout_remaining_ms;
  if (expires === null && typeof p.auth_timeout_ms === 'number') expires = serverNow() + p.auth_timeout_ms;
  return {
    key: keyOf({ ...p, ref_message_id: ref }),
    ref,
    pending_id: p.pending_id,
    thought_id: p.thought_id,
    action: p.action_type || ocp.action || ocp.command || oc.cmd || '',
    description: p.description || '',
    requester: [p.requester || p.principal || p.requested_by || oc.principal || oc.source_ruri || '', p.requested_role ? `(${p.requested_role})` : '']
      .filter(Boolean).join(' '),
    sender_type: p.sender_type || oc.sender_type || '',
    model: p.model_id || ai.model || p.model || '',
    confidence: typeof p.confidence === 'number' ? p.confidence : (typeof ai.confidence === 'number' ? ai.confidence : null),
    expires,
    timeout: p.auth_timeout_ms,
    args: argsOf(ocp && Object.keys(ocp).length ? ocp : oc),
    raw: p,
  };
}

// What the command would do, without the fields already shown.
function argsOf(cmd) {
  const rest = {};
  if (!cmd || typeof cmd !== 'object') return rest;
  for (const [k, v] of Object.entries(cmd)) {
    if (!['action', 'action_type', 'command', 'cmd', 'ai', 'thought', 'watermark_token'].includes(k)) rest[k] = v;
  }
  return rest;
}

// The parameters against the robot's state now: rows [name, requested, telemetry path or ''].
// An arm move shows each target joint against the joint now, a drive its speeds against the
// base's; anything else is a key/value table.
function paramRows(it) {
  const a = it.args;
  const text = (v) => String(typeof v === 'string' ? v : JSON.stringify(v)).slice(0, 200);
  const num = (v) => (typeof v === 'number' && isFinite(v) ? v.toFixed(2) : text(v));
  const rows = [];
  const done = new Set();
  if (/arm_move/.test(it.action) && Array.isArray(a.joints)) {
    a.joints.slice(0, 12).forEach((v, i) => rows.push([`joint ${i + 1} (rad)`, num(v), `arm.joints_rad.${i}`]));
    done.add('joints');
  } else if (/drive|move/.test(it.action) && ('linear' in a || 'angular' in a)) {
    for (const [k, path, unit] of [['linear', 'base.linear_mps', 'm/s'], ['angular', 'base.angular_radps', 'rad/s']]) {
      if (k in a) { rows.push([`${k} (${unit})`, num(a[k]), path]); done.add(k); }
    }
  }
  for (const [k, v] of Object.entries(a)) if (!done.has(k)) rows.push([k, text(v), '']);
  return rows;
}

function valueAt(path) {
  let v = app.telemetry;
  for (const k of path.split('.')) v = v && typeof v === 'object' ? v[k] : undefined;
  return typeof v === 'number' && isFinite(v) ? v : null;
}

function paramTable(it) {
  const rows = paramRows(it);
  if (!rows.length) return el('p', { class: 'muted small' }, 'No parameters.');
  const withNow = rows.some((r) => r[2]);
  return el('table', { class: 'params' },
    el('thead', {}, el('tr', {}, el('th', { scope: 'col' }, 'parameter'), el('th', { scope: 'col' }, 'requested'),
      withNow && el('th', { scope: 'col' }, 'robot now'))),
    el('tbody', {}, rows.map(([k, v, path]) => el('tr', {},
      el('td', {}, k), el('td', { class: 'mono' }, v),
      withNow && el('td', { class: 'mono now', dataset: path ? { path, want: v } : {} }, path ? '…' : '')))));
}

// The "robot now" cells follow the telemetry; a value away from the request is marked.
function renderNow() {
  for (const td of document.querySelectorAll('#approvals-list td.now[data-path]')) {
    const v = valueAt(td.dataset.path);
    const differs = v !== null && Math.abs(v - Number(td.dataset.want)) > 0.005;
    setText(td, v === null ? 'unknown' : `${v.toFixed(2)}${differs ? ' ≠' : ''}`);
    td.classList.toggle('diff', differs);
    td.title = differs ? 'differs from the request' : '';
  }
}

// A new request announces itself beyond the tab badge: the window title counts what waits,
// and with the operator's consent ("Notify me") a browser notification names the action.
const BASE_TITLE = document.title;
const reasons = new Map();   // item key → the reason typed so far (kept across refreshes)
let renderedKeys = '';

// Both announcements are off until the operator ticks them; the choice is remembered in this
// browser (localStorage). The browser is asked for notification permission only on the tick.
const SOUND_KEY = 'rcan-dashboard.approval-sound';
const NOTIFY_KEY = 'rcan-dashboard.approval-notify';
let audio = null;

function remember(key, on) {
  try { localStorage.setItem(key, on ? 'on' : 'off'); } catch (_) { /* storage may be off */ }
}

function remembered(key) {
  try { return localStorage.getItem(key) === 'on'; } catch (_) { return false; }
}

// A short two-tone beep (WebAudio; no sound file). A browser may hold sound back until the page
// has been clicked once since it loaded.
function beep() {
  const AC = window.AudioContext || window.webkitAudioContext;
  if (!AC || !$('#sound-approvals').checked) return;
  try {
    audio = audio || new AC();
    if (audio.state === 'suspended') audio.resume().catch(() => {});
    const t = audio.currentTime;
    const g = audio.createGain();
    g.gain.value = 0.12;
    g.connect(audio.destination);
    [[880, 0], [660, 0.16]].forEach(([f, at]) => {
      const o = audio.createOscillator();
      o.frequency.value = f;
      o.connect(g);
      o.start(t + at);
      o.stop(t + at + 0.14);
    });
  } catch (_) { /* no audio output */ }
}

function announce(it) {
  beep();
  if (typeof Notification === 'undefined' || Notification.permission !== 'granted') return;
  if (!$('#notify-approvals') || !$('#notify-approvals').checked) return;
  try {
    new Notification('Approval needed', { body: `${it.action || 'a command'} from ${it.requester || 'someone'}`, tag: it.key });
  } catch (_) { /* some browsers allow notifications only from a service worker */ }
}

export function onPending(msg) {
  const it = normalise(msg);
  if (!it.key) return;
  it.pushedAt = Date.now();
  if (!items.has(it.key)) announce(it);
  items.set(it.key, it);
  render();
}

// Resolution events (AUTHORIZE decided, timeout): drop the item if we can tell which.
export function onEvent(msg) {
  const t = msg.type || msg.event || '';
  const p = msg.payload || msg;
  if (/AUTHORI[SZ]E|HITL|PENDING_(RESOLVED|EXPIRED)/i.test(t) || /HITL/i.test(msg.event || '')) {
    for (const k of [p.ref_message_id, p.pending_id, p.message_id, p.thought_id]) if (k) items.delete(k);
    render();
    refresh();
  }
}

export async function refresh() {
  const asked = Date.now();
  try {
    const data = await request('GET', '/rcan/v1/pending');
    const list = Array.isArray(data) ? data : (data && (data.pending || data.items || data.entries)) || [];
    const seen = new Set();
    const first = available !== true;
    for (const m of list) {
      const it = normalise(m);
      if (!it.key) continue;
      seen.add(it.key);
      // A request the stream did not push (or not yet) announces itself too, except in the
      // list found on signing in.
      if (!items.has(it.key) && !first) announce(it);
      items.set(it.key, it);
    }
    // Drop what the node no longer lists, unless it was pushed after this list was asked for.
    for (const [k, it] of Array.from(items.entries())) if (!seen.has(k) && !(it.pushedAt > asked)) items.delete(k);
    available = true;
  } catch (e) {
    if (e.status === 404 || e.status === 405) available = false;
  }
  render();
}

async function decide(it, decision) {
  const body = {
    version: '1.0.0',
    message_id: uuid(),
    type: 'AUTHORIZE',
    timestamp_ms: Math.round(serverNow()),
    payload: {
      message_id: it.ref, ref_message_id: it.ref, pending_id: it.pending_id, thought_id: it.thought_id, decision,
      reason: (reasons.get(it.key) || '').trim() || `${decision} from the dashboard`,
    },
  };
  try {
    await request('POST', '/rcan/v1/authorize', body);
    toast(`${decision === 'approve' ? 'Approved' : 'Denied'}: ${it.action}`, 'good');
    items.delete(it.key);
    reasons.delete(it.key);
  } catch (e) {
    toast(`AUTHORIZE refused: ${e.code} — ${e.message}`, 'bad');
  }
  refresh();
}

function render() {
  const list = $('#approvals-list');
  const canDecide = roleAtLeast('OWNER');
  const note = available === false
    ? 'This node does not offer HiTL approvals (no /rcan/v1/pending).'
    : canDecide ? 'Approve or deny each item before its countdown runs out.'
      : `Read-only: only OWNER or CREATOR may approve (you are ${app.role || 'unknown'}).`;
  setText($('#approvals-note'), note);
  const badge = $('#pending-count');
  badge.hidden = items.size === 0;
  setText(badge, items.size);
  document.title = items.size ? `(${items.size}) waiting for approval — ${BASE_TITLE}` : BASE_TITLE;
  // The list is rebuilt only when its items change, so a reason being typed keeps its focus.
  const keys = `${canDecide}|${Array.from(items.keys()).join('|')}`;
  if (keys === renderedKeys && items.size) return;
  renderedKeys = keys;
  if (!items.size) {
    replace(list, el('p', { class: 'muted' }, 'Nothing is waiting.'));
    return;
  }
  replace(list, Array.from(items.values()).map((it) => {
    const left = it.expires === null ? null : Math.max(0, it.expires - serverNow());
    const count = el('span', { class: 'countdown', dataset: { expires: it.expires ?? '' } }, left === null ? '' : `${(left / 1000).toFixed(0)} s left`);
    return el('article', { class: 'approval', dataset: { key: it.key } },
      el('h3', {}, it.action || '(no action type)'),
      el('p', { class: 'desc' }, it.description),
      paramTable(it),
      el('dl', { class: 'facts' },
        el('dt', {}, 'Requester'), el('dd', {}, it.requester || '–'),
        it.sender_type && [el('dt', {}, 'Sender'), el('dd', {}, it.sender_type)],
        el('dt', {}, 'Model'), el('dd', {}, it.model || '–'),
        el('dt', {}, 'Confidence'), el('dd', {}, it.confidence === null ? 'unknown' : it.confidence.toFixed(2)),
        el('dt', {}, 'Message'), el('dd', { class: 'mono' }, it.ref || '–'),
        el('dt', {}, 'Expires'), el('dd', {}, it.expires ? fmtTime(it.expires) : '–')),
      el('label', { class: 'reason' }, 'Reason (recorded in the audit log)',
        el('input', { type: 'text', class: 'reason-input', maxlength: 200, disabled: !canDecide, value: reasons.get(it.key) || '',
          placeholder: 'why you approve or deny', oninput: (e) => reasons.set(it.key, e.target.value) })),
      el('div', { class: 'row' },
        count,
        el('button', { type: 'button', class: 'primary approve', disabled: !canDecide, onclick: () => decide(it, 'approve') }, 'Approve'),
        el('button', { type: 'button', class: 'danger deny', disabled: !canDecide, onclick: () => decide(it, 'deny') }, 'Deny')));
  }));
  renderNow();
}

function countdown() {
  renderNow();
  for (const c of document.querySelectorAll('#approvals-list .countdown')) {
    const exp = Number(c.dataset.expires);
    if (!exp) continue;
    const left = Math.max(0, exp - serverNow());
    setText(c, left > 0 ? `${Math.ceil(left / 1000)} s left` : 'timed out');
  }
}

export function initApprovals() {
  const sound = $('#sound-approvals');
  sound.checked = remembered(SOUND_KEY);
  if (!(window.AudioContext || window.webkitAudioContext)) sound.disabled = true;
  sound.addEventListener('change', () => {
    remember(SOUND_KEY, sound.checked);
    if (sound.checked) beep();       // the tick is a user gesture: the browser lets the sound play
  });
  const box = $('#notify-approvals');
  if (typeof Notification === 'undefined') box.disabled = true;
  else box.checked = remembered(NOTIFY_KEY) && Notification.permission === 'granted';
  box.addEventListener('change', async () => {
    if (box.checked && Notification.permission !== 'granted') {
      const got = await Notification.requestPermission().catch(() => 'denied');
      if (got !== 'granted') { box.checked = false; toast('The browser did not allow notifications.', 'warn'); }
    }
    remember(NOTIFY_KEY, box.checked);
  });
  clearInterval(tick);
  tick = setInterval(countdown, 250);
  render();
}

export function pendingCount() { return items.size; }
