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
