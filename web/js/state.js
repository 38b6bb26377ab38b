// What the views share: the stream, the latest status, who we are.
import { ROLE_LEVEL } from './api.js';

export const app = {
  stream: null,
  status: null,        // last GET /rcan/v1/status
  statusAskedAt: 0,    // when the request behind `status` was sent (Date.now())
  role: '',            // from the stream's CONNECT_ACK (the node's word), else the token's claim
  claims: null,        // the token's claims (display only)
  telemetry: null,     // last telemetry payload
  estop: null,         // last known ESTOP state
  session: null,       // our control session {session_id, heartbeat_timeout_ms, since} while we hold it
  queued: 0,           // our place in the control queue (1-based) while our claim waits
  bus: new EventTarget(),
};

export function roleAtLeast(role) {
  return (ROLE_LEVEL[app.role] || 0) >= (ROLE_LEVEL[role] || 99);
}

export function emit(name, detail) {
  app.bus.dispatchEvent(new CustomEvent(name, { detail }));
}

export function on(name, fn) {
  app.bus.addEventListener(name, (e) => fn(e.detail));
}

// The robot's safety state as the page last saw it: ESTOP from the stream and the status,
// safe stop (the robot stopped itself; the next accepted command clears it) from the status.
// kind: unknown | estop | safe_stop | running; `why` names a safe stop's reason.
export function safetyState() {
  const robot = (app.status && app.status.robot) || {};
  if (app.estop === null) return { kind: 'unknown', why: '' };
  if (app.estop) return { kind: 'estop', why: '' };
  if (robot.safe_stop === true || robot.state === 'safe_stop') {
    const d = robot.safe_stop_detail;
    return { kind: 'safe_stop', why: d && d.reason ? String(d.reason) : '' };
  }
  return { kind: 'running', why: '' };
}

// Why what the page shows from the stream is not live ('' while it is): the liveness watchdog
// found the connection silent, or the stream is down and reconnecting.
export function staleWhy() {
  const s = app.stream;
  if (!s || s.state === 'open' || s.state === 'idle') return '';
  if (s.state === 'connecting' && !s.reconnects) return '';   // the first connection: nothing shown from it yet
  return { lost: 'connection lost', refused: 'stream refused', connecting: 'stream connecting' }[s.state] || 'stream reconnecting';
}
