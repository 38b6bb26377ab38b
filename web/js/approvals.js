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
    params: paramsOf(ocp && Object.keys(ocp).length ? ocp : oc),
    raw: p,
  };
}

// What the command would do, without the fields already shown.
function paramsOf(cmd) {
  if (!cmd || typeof cmd !== 'object') return '';
  const rest = {};
  for (const [k, v] of Object.entries(cmd)) {
    if (!['action', 'action_type', 'command', 'cmd', 'ai', 'thought', 'watermark_token'].includes(k)) rest[k] = v;
  }
  return Object.keys(rest).length ? JSON.stringify(rest) : '';
}

// A new request announces itself beyond the tab badge: the window title counts what waits,
// and with the operator's consent ("Notify me") a browser notification names the action.
const BASE_TITLE = document.title;
const reasons = new Map();   // item key → the reason typed so far (kept across refreshes)
let renderedKeys = '';

function announce(it) {
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
    available = true;
    const list = Array.isArray(data) ? data : (data && (data.pending || data.items || data.entries)) || [];
    const seen = new Set();
    for (const m of list) {
      const it = normalise(m);
      if (!it.key) continue;
      seen.add(it.key);
      items.set(it.key, it);
    }
    // Drop what the node no longer lists, unless it was pushed after this list was asked for.
    for (const [k, it] of Array.from(items.entries())) if (!seen.has(k) && !(it.pushedAt > asked)) items.delete(k);
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
      el('dl', { class: 'facts' },
        el('dt', {}, 'Parameters'), el('dd', { class: 'mono' }, it.params || '–'),
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
}

function countdown() {
  for (const c of document.querySelectorAll('#approvals-list .countdown')) {
    const exp = Number(c.dataset.expires);
    if (!exp) continue;
    const left = Math.max(0, exp - serverNow());
    setText(c, left > 0 ? `${Math.ceil(left / 1000)} s left` : 'timed out');
  }
}

export function initApprovals() {
  const box = $('#notify-approvals');
  if (box) {
    if (typeof Notification === 'undefined') box.disabled = true;
    box.addEventListener('change', async () => {
      if (box.checked && Notification.permission !== 'granted') {
        const got = await Notification.requestPermission().catch(() => 'denied');
        if (got !== 'granted') { box.checked = false; toast('The browser did not allow notifications.', 'warn'); }
      }
    });
  }
  clearInterval(tick);
  tick = setInterval(countdown, 250);
  render();
}

export function pendingCount() { return items.size; }
