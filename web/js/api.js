// The page's only way to the robot: the node's public HTTP endpoints, with the bearer token
// in the Authorization header (never in a URL). The token lives in memory and, if the user
// asks, in this tab's sessionStorage.

const KEY = 'rcan.dashboard.token';
let token = '';

export function setToken(t, remember) {
  token = t || '';
  try {
    if (token && remember) sessionStorage.setItem(KEY, token);
    else sessionStorage.removeItem(KEY);
  } catch (_) { /* storage may be disabled */ }
}

export function restoreToken() {
  try { token = sessionStorage.getItem(KEY) || ''; } catch (_) { token = ''; }
  return token;
}

export function getToken() { return token; }

// Reads the (unverified) claims of a JWT for display only; the node decides what it allows.
export function tokenClaims(t = token) {
  try {
    const part = t.split('.')[1];
    const b64 = part.replace(/-/g, '+').replace(/_/g, '/');
    const json = atob(b64 + '='.repeat((4 - (b64.length % 4)) % 4));
    const bytes = Uint8Array.from(json, (c) => c.charCodeAt(0));
    return JSON.parse(new TextDecoder().decode(bytes));
  } catch (_) {
    return null;
  }
}

export const ROLE_LEVEL = { GUEST: 1, USER: 2, LEASEE: 3, OWNER: 4, CREATOR: 5 };

// crypto.randomUUID needs a secure context; getRandomValues works everywhere.
export function uuid() {
  const b = crypto.getRandomValues(new Uint8Array(16));
  b[6] = (b[6] & 0x0f) | 0x40;
  b[8] = (b[8] & 0x3f) | 0x80;
  const h = Array.from(b, (x) => x.toString(16).padStart(2, '0')).join('');
  return `${h.slice(0, 8)}-${h.slice(8, 12)}-${h.slice(12, 16)}-${h.slice(16, 20)}-${h.slice(20)}`;
}

// The node's clock minus ours, learnt from telemetry, so messages carry the node's time.
let clockOffsetMs = 0;
export function noteServerTime(serverMs) {
  if (typeof serverMs === 'number' && isFinite(serverMs)) clockOffsetMs = serverMs - Date.now();
}
export function serverNow() { return Date.now() + clockOffsetMs; }

export class ApiError extends Error {
  constructor(status, code, message, body) {
    super(message || code || `HTTP ${status}`);
    this.status = status;
    this.code = code || `HTTP_${status}`;
    this.body = body;
  }
}

// Every request gives up after this long unless told otherwise (the network may freeze
// without closing: an answer that never comes must not leave the page waiting).
export const DEFAULT_TIMEOUT_MS = 10000;

// fetch + JSON; an error body (PROFILE §4) becomes an ApiError carrying its error_code. A
// request not answered within `timeoutMs` is aborted (ApiError TIMEOUT).
// `keepalive`: the request outlives the page (sent from pagehide).
export async function request(method, path, body, { auth = true, text = false, timeoutMs = DEFAULT_TIMEOUT_MS, keepalive = false } = {}) {
  const headers = {};
  if (auth && token) headers.Authorization = 'Bearer ' + token;
  const ctl = new AbortController();
  const init = { method, headers, cache: 'no-store', credentials: 'omit', redirect: 'error', signal: ctl.signal, keepalive };
  if (body !== undefined) {
    headers['Content-Type'] = 'application/json';
    init.body = JSON.stringify(body);
  }
  const timer = setTimeout(() => ctl.abort(), timeoutMs);
  let res;
  let raw;
  try {
    res = await fetch(path, init);
    raw = await res.text();
  } catch (e) {
    if (ctl.signal.aborted) throw new ApiError(0, 'TIMEOUT', `no answer within ${(timeoutMs / 1000).toFixed(1)} s`);
    throw new ApiError(0, 'NETWORK', 'the robot cannot be reached');
  } finally {
    clearTimeout(timer);
  }
  if (text && res.ok) return raw;
  let data = null;
  try { data = raw ? JSON.parse(raw) : null; } catch (_) { data = null; }
  if (!res.ok) {
    const p = data && data.payload;
    const code = (p && p.error_code) || (data && (data.code || data.error_code)) || `HTTP_${res.status}`;
    const msg = (p && p.error) || (data && typeof data.error === 'string' && data.error) || res.statusText;
    const err = new ApiError(res.status, code, msg, data);
    err.reason = (p && typeof p.reason === 'string' && p.reason) || '';
    throw err;
  }
  return data;
}

// A refused token in plain words (the parser's own text stays in the error's detail).
export function tokenRefusal(e) {
  const why = {
    expired: 'it has expired',
    not_yet_valid: 'it is not valid yet (check the clocks)',
    token_revoked: 'it has been revoked',
    bad_signature: 'its signature does not verify: not issued by an issuer this robot trusts, or damaged when copied',
  }[e.reason] || (e.code === 'AUTH_REQUIRED' ? 'no token was sent'
    : 'it is not a token this robot accepts: expired, for another robot, from an issuer it does not trust, or damaged when copied');
  return `The node refused this token (${e.code}): ${why}.`;
}

// A COMMAND in the seed shape, through the normal pipeline.
export function commandMessage(action, params = {}, extra = {}) {
  return {
    version: '1.0.0',
    message_id: uuid(),
    type: 'COMMAND',
    priority: 'NORMAL',
    timestamp_ms: Math.round(serverNow()),
    ttl_ms: 5000,
    sender_type: 'human',
    payload: { action, ...params },
    ...extra,
  };
}

// `ttlMs`: the node refuses the command (MESSAGE_STALE) if it arrives later than this after it
// was sent; `timeoutMs`: the page stops waiting for the answer.
export function sendCommand(action, params, { ttlMs = 5000, timeoutMs = DEFAULT_TIMEOUT_MS } = {}) {
  return request('POST', '/rcan/v1/command', commandMessage(action, params, { ttl_ms: ttlMs }), { timeoutMs });
}

// A SAFETY message (STOP, RESUME) with its reason.
function safetyMessage(event, reason, options) {
  return request('POST', '/rcan/v1/command', {
    version: '1.0.0',
    message_id: uuid(),
    type: 'SAFETY',
    priority: 'SAFETY',
    timestamp_ms: Math.round(serverNow()),
    payload: { safety_event: event, reason },
  }, options);
}

// A SAFETY STOP: stops motion without latching; the node never refuses it.
export function safetyStop(reason, timeoutMs = 3000) {
  return safetyMessage('STOP', reason, { timeoutMs });
}

// An ESTOP not answered within this long is shown as not confirmed (and can be sent again).
export const ESTOP_TIMEOUT_MS = 5000;

export function estop() {
  return request('POST', '/api/stop', { reason: 'dashboard ESTOP' }, { timeoutMs: ESTOP_TIMEOUT_MS });
}

export function resume() {
  return safetyMessage('RESUME', 'dashboard RESUME');
}

export function status() {
  return request('GET', '/rcan/v1/status');
}
