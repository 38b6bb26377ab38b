// Teleop: claim/release control, drive (pad and arrow keys), arm joints, gripper. Every action is
// an ordinary RCAN message through the node's pipeline, so refusals come back with their code.
import { $, el, setText, toast, fmtNum } from './dom.js';
import { request, sendCommand, uuid, serverNow } from './api.js';
import { app, emit, on } from './state.js';

const DEFAULT_MIN = [-3.1, -2.0, -2.5, -3.1, -2.0, -3.1];
const DEFAULT_MAX = [3.1, 2.0, 2.5, 3.1, 2.0, 3.1];
let heartbeatTimer = 0;
let lastDrive = 0;
let held = null;

function log(text, ok) {
  const list = $('#teleop-log');
  list.insertBefore(el('li', { class: ok ? 'good' : 'bad' }, `${new Date().toLocaleTimeString()}  ${text}`), list.firstChild);
  while (list.children.length > 30) list.removeChild(list.lastChild);
}

let lastSent = 0;

async function act(label, fn) {
  lastSent = Date.now();
  try {
    const res = await fn();
    const p = (res && res.payload) || {};
    log(`${label}: ${res && (res.type || res.message_type) || 'OK'}${p.clamped ? ' (clamped)' : ''}`, true);
    return res;
  } catch (e) {
    log(`${label}: ${e.code} — ${e.message}`, false);
    if (e.status === 401) toast(`${label}: ${e.code}`, 'bad');
    return null;
  }
}

function drive(dir) {
  const lin = parseFloat($('#lin-speed').value);
  const ang = parseFloat($('#ang-speed').value);
  const m = { fwd: [lin, 0], back: [-lin, 0], left: [0, ang], right: [0, -ang], stop: [0, 0] }[dir];
  if (!m) return;
  lastDrive = Date.now();
  if (dir === 'stop') return act('stop', () => sendCommand('drive', { linear: 0, angular: 0, duration_ms: 1 }));
  return act(`drive ${dir}`, () => sendCommand('drive', { linear: m[0], angular: m[1], duration_ms: 500 }));
}

function startHeartbeat(timeoutMs) {
  stopHeartbeat();
  const every = Math.max(250, Math.floor((timeoutMs || 2000) / 3));
  heartbeatTimer = setInterval(() => {
    // Commands from the holder feed the deadman too; a heartbeat is only needed when idle
    // (this also keeps a USER within its rate limit while driving).
    if (Date.now() - lastSent < every) return;
    lastSent = Date.now();
    const msg = {
      version: '1.0.0', message_id: uuid(), type: 'HEARTBEAT', timestamp_ms: Math.round(serverNow()),
      payload: { session_id: app.session && app.session.session_id },
    };
    if (app.stream && app.stream.state === 'open') app.stream.send(msg);
    else request('POST', '/rcan/v1/command', msg).catch(() => {});
  }, every);
}

function stopHeartbeat() {
  clearInterval(heartbeatTimer);
  heartbeatTimer = 0;
}

export function renderControl() {
  const s = app.status || {};
  const holder = Array.isArray(s.sessions) ? s.sessions[0] : null;
  let text;
  if (app.session) text = `You hold control (session ${app.session.session_id.slice(0, 8)}…). The deadman needs a heartbeat: this page sends one while it is open.`;
  else if (holder) text = `Held by ${holder.role || '?'} ${holder.user_id || ''}. Your motion commands are refused (CONTROL_CONFLICT) unless your role pre-empts theirs when you claim.`;
  else text = 'Nobody holds control: any authorised principal may drive. Claim it to keep others off.';
  setText($('#control-state'), text);
  $('#release').disabled = !app.session;
}

// The speed sliders follow the safety core's limits (faster requests would only be clamped).
export function applyLimits() {
  const lim = (app.status && app.status.robot && app.status.robot.limits) || {};
  for (const [id, max, unit] of [['#lin-speed', lim.max_linear_mps, 'm/s'], ['#ang-speed', lim.max_angular_radps, 'rad/s']]) {
    const input = $(id);
    if (typeof max !== 'number' || !(max > 0) || Number(input.max) === max) continue;
    input.max = String(max);
    if (Number(input.value) > max) input.value = String(max);
    setText($(id.replace('speed', 'out')), `${Number(input.value).toFixed(1)} ${unit}`);
  }
}

function buildJoints() {
  const box = $('#joints');
  const lim = (app.status && app.status.robot && app.status.robot.limits) || {};
  const mins = Array.isArray(lim.joint_min_rad) ? lim.joint_min_rad : DEFAULT_MIN;
  const maxs = Array.isArray(lim.joint_max_rad) ? lim.joint_max_rad : DEFAULT_MAX;
  for (let i = 0; i < 6; i++) {
    const out = el('output', { id: `j${i}-out` }, '0.00');
    const input = el('input', { type: 'range', id: `j${i}`, min: mins[i], max: maxs[i], step: 0.01, value: 0 });
    input.addEventListener('input', () => setText(out, Number(input.value).toFixed(2)));
    box.appendChild(el('label', { class: 'slider' }, `Joint ${i + 1}`, input, out, el('span', { class: 'muted small', id: `j${i}-now` })));
  }
}

export function onTelemetryJoints(t) {
  const j = t && t.arm && Array.isArray(t.arm.joints_rad) ? t.arm.joints_rad : null;
  if (!j) return;
  j.forEach((v, i) => setText($(`#j${i}-now`), `now ${fmtNum(v)}`));
}

export function initTeleop() {
  buildJoints();
  $('#lin-speed').addEventListener('input', (e) => setText($('#lin-out'), `${Number(e.target.value).toFixed(1)} m/s`));
  $('#ang-speed').addEventListener('input', (e) => setText($('#ang-out'), `${Number(e.target.value).toFixed(1)} rad/s`));
  $('#claim').addEventListener('click', async () => {
    const res = await act('claim', () => request('POST', '/rcan/v1/auth/claim', { source_ruri: 'rcan://local/dashboard' }));
    if (res && res.payload && res.payload.session_id) {
      app.session = { session_id: res.payload.session_id, heartbeat_timeout_ms: res.payload.heartbeat_timeout_ms, since: Date.now() };
      startHeartbeat(res.payload.heartbeat_timeout_ms);
    }
    renderControl();
    emit('refresh');
  });
  $('#release').addEventListener('click', async () => {
    if (!app.session) return;
    const sid = app.session.session_id;
    const res = await act('release', () => request('DELETE', '/rcan/v1/auth/release', { session_id: sid }));
    if (res) { app.session = null; stopHeartbeat(); }
    renderControl();
    emit('refresh');
  });
  // The pad: a press drives, holding repeats every 300 ms, letting go stops.
  for (const b of document.querySelectorAll('#pad button')) {
    const dir = b.dataset.drive;
    const startHold = (e) => {
      e.preventDefault();
      drive(dir);
      clearInterval(held);
      if (dir !== 'stop') held = setInterval(() => drive(dir), 300);
    };
    const endHold = () => {
      if (held) { clearInterval(held); held = null; }
    };
    b.addEventListener('pointerdown', startHold);
    b.addEventListener('pointerup', endHold);
    b.addEventListener('pointerleave', endHold);
    b.addEventListener('keydown', (e) => { if (e.key === 'Enter' || e.key === ' ') startHold(e); });
    b.addEventListener('keyup', endHold);
  }
  document.addEventListener('keydown', (e) => {
    if ($('#view-teleop').hidden) return;
    const tag = (e.target && e.target.tagName) || '';
    if (tag === 'INPUT' || tag === 'TEXTAREA' || tag === 'SELECT') return;
    const dir = { ArrowUp: 'fwd', ArrowDown: 'back', ArrowLeft: 'left', ArrowRight: 'right' }[e.key];
    if (!dir) return;
    e.preventDefault();
    if (Date.now() - lastDrive < 200) return;   // key auto-repeat is faster than we need
    drive(dir);
  });
  $('#arm-send').addEventListener('click', () => {
    const joints = [0, 1, 2, 3, 4, 5].map((i) => Number($(`#j${i}`).value));
    act('arm_move', () => sendCommand('arm_move', { joints }));
  });
  $('#arm-home').addEventListener('click', () => {
    for (let i = 0; i < 6; i++) { $(`#j${i}`).value = 0; setText($(`#j${i}-out`), '0.00'); }
    act('arm_home', () => sendCommand('arm_home', {}));
  });
  $('#grip-open').addEventListener('click', () => act('gripper_open', () => sendCommand('gripper_open', {})));
  $('#grip-close').addEventListener('click', () => act('gripper_close', () => sendCommand('gripper_close', {})));
  on('status', () => {
    // A session we held may have been pre-empted or expired.
    const s = app.status || {};
    const holder = Array.isArray(s.sessions) ? s.sessions[0] : null;
    if (app.session && app.statusAskedAt > app.session.since &&
        (!holder || !app.session.session_id.startsWith(holder.session_id))) {
      app.session = null;
      stopHeartbeat();
      log('control session ended (released, pre-empted or expired)', false);
    }
    applyLimits();
    renderControl();
  });
}

export function teleopSignedOut() {
  stopHeartbeat();
  app.session = null;
}
