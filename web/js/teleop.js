// Teleop: claim/release control, drive (pad and arrow keys), arm joints, gripper. Every action is
// an ordinary RCAN message through the node's pipeline, so refusals come back with their code.
import { $, el, setText, toast, fmtNum } from './dom.js';
import { request, sendCommand, safetyStop, uuid, serverNow, getToken } from './api.js';
import { app, emit, on, roleAtLeast, safetyState, staleWhy } from './state.js';

const DEFAULT_MIN = [-3.1, -2.0, -2.5, -3.1, -2.0, -3.1];
const DEFAULT_MAX = [3.1, 2.0, 2.5, 3.1, 2.0, 3.1];
let heartbeatTimer = 0;

// Hold-to-drive is a deadman. A hold repeats a short drive (DRIVE_MS on the robot) every
// REPEAT_MS while the operator holds a pad button or an arrow key; every way a hold can end
// (release, pointer cancel or lost capture, leaving the button, the button losing focus, the
// window losing focus, the tab hidden, the stream going silent, a drive unanswered or refused,
// an ESTOP) ends it at once and sends a SAFETY STOP if a drive of it may have gone through.
// A drive is never sent while the previous one is unanswered or the stream is not live, and it
// carries a short ttl_ms, so the node refuses (MESSAGE_STALE) one that a frozen network
// delivers late.
const DRIVE_MS = 500;
const REPEAT_MS = 300;
const DRIVE_TIMEOUT_MS = 800;
const DRIVE_TTL_MS = 1000;
const STREAM_SILENCE_MS = 1000;   // telemetry runs at 5 Hz: five frames missed
// The joystick and the gamepad's left stick are proportional: a deflection in [-1, 1] times the
// slider's speed; inside DEADZONE the stick is centred and the robot is stopped.
const DEADZONE = 0.15;
let hold = null;                  // {dir, key, timer, moved, vec}
let driveInFlight = false;
// After an ESTOP the node refuses our session's drives until it is re-armed (docs/NODE.md,
// "Re-arm after ESTOP"); the page re-arms on the operator's next press, never from a hold.
let needRearm = false;

// `kind`: true (done), false (refused or failed) or 'warn' (done, but not as asked). The newest
// result is also the status line beside the pad (a polite live region), and a refusal is a
// toast as well: the log itself may be below the fold (on a phone it always is). `quiet`: a
// success that goes to the log only (the automatic stop after a hold, which would otherwise
// hide the refusal that ended it).
function log(text, kind, quiet = false) {
  const list = $('#teleop-log');
  const cls = kind === 'warn' ? 'warn' : kind ? 'good' : 'bad';
  list.insertBefore(el('li', { class: cls }, `${new Date().toLocaleTimeString()}  ${text}`), list.firstChild);
  while (list.children.length > 30) list.removeChild(list.lastChild);
  if (quiet && kind === true) return;
  const line = $('#teleop-status');
  setText(line, text);
  line.className = `teleop-status ${cls}`;
  if (!kind) toast(text, 'bad');
}

// A command the safety core limited (clamped to a limit, shortened or stopped at the workspace
// fence) is accepted but not done as asked: a warning with the node's reason, never a green ACK.
function limitedNote(label, res) {
  const p = (res && res.payload) || {};
  if (!p.clamped) return false;
  const why = typeof p.clamped === 'string' ? p.clamped : 'a safety limit';
  log(`${label}: limited — ${why}`, 'warn');
  toast(`${label} limited: ${why}`, 'warn');
  return true;
}

let lastSent = 0;

// An accepted command clears a safe stop on the node: read the status now rather than at the
// next poll, so the header stops saying SAFE STOP at once.
function accepted() {
  if (safetyState().kind === 'safe_stop') emit('refresh');
}

async function act(label, fn, quiet = false) {
  lastSent = Date.now();
  try {
    const res = await fn();
    if (!limitedNote(label, res)) log(`${label}: ${res && (res.type || res.message_type) || 'OK'}`, true, quiet);
    accepted();
    return res;
  } catch (e) {
    log(`${label}: ${e.code}${e.reason ? ' / ' + e.reason : ''} — ${e.message}`, false);
    if (e.reason === 'rearm_required') needRearm = true;
    return null;
  }
}

export function streamLive() {
  const s = app.stream;
  return !!s && s.state === 'open' && Date.now() - (s.lastFrameAt || 0) < STREAM_SILENCE_MS;
}

// `quiet` unless the operator asked for this stop (■): see log().
function sendStop(why, quiet = true) {
  lastSent = Date.now();
  return act(`stop (${why})`, () => safetyStop(`dashboard: ${why}`), quiet);
}

async function rearm() {
  if (!app.session) { needRearm = false; return true; }
  const res = await act('re-arm after ESTOP', () => request('POST', '/rcan/v1/auth/renew',
    { session_id: app.session.session_id, rearm: true }, { timeoutMs: 3000 }));
  if (res && res.payload && res.payload.rearmed) { needRearm = false; return true; }
  return false;
}

async function driveOnce(h) {
  if (hold !== h) return;
  if (!streamLive()) { endHold('the stream is silent'); return; }
  if (driveInFlight) return;   // never queue a drive behind an unanswered one
  const lin = parseFloat($('#lin-speed').value);
  const ang = parseFloat($('#ang-speed').value);
  let m;
  if (h.vec) {
    const clamp = (v) => Math.max(-1, Math.min(1, Number(v) || 0));
    const [fl, fa] = h.vec().map(clamp);
    if (Math.abs(fl) < DEADZONE && Math.abs(fa) < DEADZONE) {
      // Centred: the robot stands still (one STOP if the last drive may have moved it).
      if (h.moved) { h.moved = false; sendStop(`${h.dir} centred`); }
      return;
    }
    const r = (v) => Math.round(v * 100) / 100;
    m = [r(fl * lin), r(fa * ang)];
  } else {
    m = { fwd: [lin, 0], back: [-lin, 0], left: [0, ang], right: [0, -ang] }[h.dir];
  }
  driveInFlight = true;
  h.moved = true;              // until the node says otherwise, this drive may move the robot
  lastSent = Date.now();
  try {
    const res = await sendCommand('drive', { linear: m[0], angular: m[1], duration_ms: DRIVE_MS },
      { ttlMs: DRIVE_TTL_MS, timeoutMs: DRIVE_TIMEOUT_MS });
    // One line per hold, and one warning the first time the hold is limited.
    if (!h.warned && limitedNote(`drive ${h.dir}`, res)) h.warned = true;
    else if (!h.logged) log(`drive ${h.dir}: ${res && (res.type || res.message_type) || 'OK'}`, true);
    if (!h.logged) accepted();
    h.logged = true;
  } catch (e) {
    const rearmHint = e.reason === 'rearm_required' ? ' (an ESTOP since this session was armed: let go and press again to re-arm)' : '';
    log(`drive ${h.dir}: ${e.code}${e.reason ? ' / ' + e.reason : ''} — ${e.message}${rearmHint}`, false);
    if (e.reason === 'rearm_required') needRearm = true;
    endHold(e.status ? 'refused' : 'no answer');
  } finally {
    driveInFlight = false;
  }
}

// `vec` (the joystick, the gamepad): a function giving the deflection [forward, left] in
// [-1, 1] at each repeat; without it the hold drives one pad direction at the sliders' speeds.
async function startHold(dir, key, vec = null) {
  if (dir === 'stop') { endHold('■'); sendStop('■', false); return; }
  if (hold && hold.dir === dir && hold.key === key) return;
  endHold('another direction');
  if (!streamLive()) { log(`drive ${dir}: not sent — the stream is not live`, false); return; }
  const h = { dir, key, vec, timer: 0, moved: false, logged: false, warned: false };
  hold = h;
  if (needRearm && !(await rearm())) { if (hold === h) hold = null; return; }
  if (hold !== h) return;      // let go while re-arming
  driveOnce(h);
  h.timer = setInterval(() => driveOnce(h), REPEAT_MS);
}

function endHold(why) {
  const h = hold;
  if (!h) return;
  hold = null;
  clearInterval(h.timer);
  if (h.moved || driveInFlight) sendStop(why);
  if (h.dir === 'stick') { stickVec = [0, 0]; drawStick(); }
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
  else if (app.queued) text = `You are number ${app.queued} in the queue for control${holder ? ` (held by ${holder.role || '?'} ${holder.user_id || ''})` : ''}. This page takes over and starts heart-beating when the node promotes you; closing it leaves the queue.`;
  else if (holder) text = `Held by ${holder.role || '?'} ${holder.user_id || ''}. Your motion commands are refused (CONTROL_CONFLICT) unless your role pre-empts theirs when you claim.`;
  else text = 'Nobody holds control: any authorised principal may drive. Claim it to keep others off.';
  // Without a live stream, who holds control may have changed since: say it is the last known.
  const stale = staleWhy();
  const box = $('#control-state');
  setText(box, stale ? `Last known (${stale}): ${text}` : text);
  box.classList.toggle('stale', !!stale);
  const rel = $('#release');
  rel.disabled = !app.session && !app.queued;
  setText(rel, !app.session && app.queued ? 'Leave queue' : 'Release');
}

// This page holds the session from now on: heartbeats keep the deadman fed.
function takeSession(p) {
  app.session = { session_id: p.session_id, heartbeat_timeout_ms: p.heartbeat_timeout_ms, since: Date.now() };
  app.queued = 0;
  needRearm = false;
  startHeartbeat(p.heartbeat_timeout_ms);
}

async function claim() {
  // A claim is the operator's own action: it also re-arms a session armed before an ESTOP.
  lastSent = Date.now();
  try {
    const res = await request('POST', '/rcan/v1/auth/claim', { source_ruri: 'rcan://local/dashboard', rearm: true });
    const p = (res && res.payload) || {};
    log(`claim: ${res && (res.type || res.message_type) || 'OK'}`, true);
    if (p.session_id) takeSession(p);
  } catch (e) {
    const p = (e.body && e.body.payload) || {};
    if (p.queued) {
      app.queued = p.queue_position || 1;
      log(`claim: queued at position ${app.queued} — this page is told when control passes to you`, 'warn');
    } else {
      log(`claim: ${e.code}${e.reason ? ' / ' + e.reason : ''} — ${e.message}`, false);
    }
  }
  renderControl();
  emit('refresh');
}

async function releaseOrLeave() {
  if (app.session) {
    endHold('release');
    const sid = app.session.session_id;
    const res = await act('release', () => request('DELETE', '/rcan/v1/auth/release', { session_id: sid }));
    if (res) { app.session = null; stopHeartbeat(); }
  } else if (app.queued) {
    const res = await act('leave queue', () => request('DELETE', '/rcan/v1/auth/queue'));
    if (res) app.queued = 0;
  }
  renderControl();
  emit('refresh');
}

// The node's word on our place: promoted (we hold control now) or dropped from the queue.
function onControlEvent(m) {
  if (m.event === 'PROMOTED' && m.session_id) {
    takeSession(m);
    log(`promoted from the queue: you hold control (session ${String(m.session_id).slice(0, 8)}…)`, true);
    toast('You now hold control of the robot.', 'good');
    renderControl();
    emit('refresh');
  } else if (m.event === 'CLAIM_DROPPED' && app.queued) {
    app.queued = 0;
    log(`left the queue: ${m.reason || 'dropped by the node'}`, 'warn');
    renderControl();
  }
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

// The arm sliders start at the arm's pose and follow it until the operator moves one; "Move
// arm" then changes only the joints the operator touched and holds the others where the arm
// is commanded to be.
const touched = new Set();

function buildJoints() {
  const box = $('#joints');
  const lim = (app.status && app.status.robot && app.status.robot.limits) || {};
  const mins = Array.isArray(lim.joint_min_rad) ? lim.joint_min_rad : DEFAULT_MIN;
  const maxs = Array.isArray(lim.joint_max_rad) ? lim.joint_max_rad : DEFAULT_MAX;
  for (let i = 0; i < 6; i++) {
    const out = el('output', { id: `j${i}-out` }, '…');
    const input = el('input', { type: 'range', id: `j${i}`, min: mins[i], max: maxs[i], step: 0.01, value: 0, disabled: '' });
    input.addEventListener('input', () => { touched.add(i); setText(out, Number(input.value).toFixed(2)); });
    box.appendChild(el('label', { class: 'slider' }, `Joint ${i + 1}`, input, out, el('span', { class: 'muted small', id: `j${i}-now` })));
  }
}

function armOf(t) {
  const a = t && t.arm;
  if (!a || !Array.isArray(a.joints_rad) || a.joints_rad.length !== 6) return null;
  return { joints: a.joints_rad, targets: Array.isArray(a.targets_rad) && a.targets_rad.length === 6 ? a.targets_rad : a.joints_rad };
}

export function onTelemetryJoints(t) {
  const arm = armOf(t);
  if (!arm) return;
  arm.joints.forEach((v, i) => {
    setText($(`#j${i}-now`), `now ${fmtNum(v)}`);
    const input = $(`#j${i}`);
    input.disabled = false;
    if (!touched.has(i)) { input.value = String(v); setText($(`#j${i}-out`), Number(v).toFixed(2)); }
  });
}

function sendArm() {
  const arm = armOf(app.telemetry) || armOf(app.status && app.status.robot && app.status.robot.robot);
  if (!arm) { log('arm_move: not sent — the arm\'s pose is not known yet', false); return; }
  if (!touched.size) { log('arm_move: no joint changed', false); return; }
  const joints = arm.targets.map((v, i) => (touched.has(i) ? Number($(`#j${i}`).value) : v));
  const what = [...touched].sort().map((i) => `J${i + 1} → ${joints[i].toFixed(2)}`).join(', ');
  log(`arm_move sends ${what}; the other joints stay where they are`, true);
  act('arm_move', () => sendCommand('arm_move', { joints })).then((res) => { if (res) touched.clear(); });
}

// The on-screen joystick: a canvas the pointer drags (pointer capture keeps the drag while the
// pointer leaves it); pointerup, pointercancel and lost capture end the hold.
let stickVec = [0, 0];       // [forward, left] in [-1, 1]
let motionOk = false;

function drawStick() {
  const c = $('#stick');
  const ctx = c.getContext('2d');
  const w = c.width, r = w / 2;
  const cs = getComputedStyle(document.documentElement);
  ctx.clearRect(0, 0, w, w);
  ctx.fillStyle = cs.getPropertyValue('--plot-bg').trim() || '#0f1720';
  ctx.strokeStyle = cs.getPropertyValue('--control-line').trim() || '#6b7f93';
  ctx.lineWidth = 2;
  ctx.beginPath(); ctx.arc(r, r, r - 2, 0, 2 * Math.PI); ctx.fill(); ctx.stroke();
  ctx.beginPath(); ctx.arc(r, r, (r - 2) * DEADZONE, 0, 2 * Math.PI); ctx.stroke();
  ctx.beginPath(); ctx.moveTo(r, 8); ctx.lineTo(r, w - 8); ctx.moveTo(8, r); ctx.lineTo(w - 8, r); ctx.stroke();
  const travel = r * 0.7;
  ctx.fillStyle = hold && hold.dir === 'stick' ? (cs.getPropertyValue('--plot-robot').trim() || '#ffd166') : '#8aa0b4';
  ctx.beginPath(); ctx.arc(r - stickVec[1] * travel, r - stickVec[0] * travel, r * 0.24, 0, 2 * Math.PI); ctx.fill();
}

function setStick(c, e) {
  const b = c.getBoundingClientRect();
  const travel = (b.width / 2) * 0.7;
  let dx = (e.clientX - (b.left + b.width / 2)) / travel;
  let dy = (e.clientY - (b.top + b.height / 2)) / travel;
  const n = Math.hypot(dx, dy);
  if (n > 1) { dx /= n; dy /= n; }
  stickVec = [-dy, -dx];
  drawStick();
}

function initStick() {
  const c = $('#stick');
  const mine = (e) => hold && hold.key === `joy${e.pointerId}`;
  c.addEventListener('pointerdown', (e) => {
    e.preventDefault();
    if (!motionOk) return;
    try { c.setPointerCapture(e.pointerId); } catch (_) { /* not an active pointer */ }
    setStick(c, e);
    startHold('stick', `joy${e.pointerId}`, () => stickVec);
  });
  c.addEventListener('pointermove', (e) => { if (mine(e)) setStick(c, e); });
  for (const ev of ['pointerup', 'pointercancel', 'lostpointercapture']) {
    c.addEventListener(ev, () => {
      stickVec = [0, 0];
      if (hold && hold.key.startsWith('joy')) endHold(ev);
      drawStick();
    });
  }
  drawStick();
}

// The gamepad (standard mapping): the left stick drives while RB or RT is held — the deadman.
// Letting go, the gamepad disconnecting, and everything that ends any other hold end it; a
// deadman still held when a hold ended another way must be released and pressed again.
const DEADMAN_BUTTONS = [5, 7];
let padVec = [0, 0];
let padArmed = true;
let padSeen = '';

function firstGamepad() {
  const list = navigator.getGamepads ? Array.from(navigator.getGamepads() || []) : [];
  return list.find((g) => g && g.connected) || null;
}

function pollGamepad() {
  const gp = firstGamepad();
  const id = gp ? String(gp.id || 'gamepad').slice(0, 60) : '';
  const driving = hold && hold.key === 'gamepad';
  const say = gp ? `Gamepad: ${id} — ${driving ? 'driving (let go of RB/RT to stop)' : 'hold RB or RT (the right bumper or trigger) and use the left stick to drive'}.`
    : 'Gamepad: none connected. Connect one and press a button: the left stick drives while RB or RT (the right bumper or trigger) is held.';
  if (say !== padSeen) { padSeen = say; setText($('#gamepad-state'), say); }
  if (!gp) { if (driving) endHold('gamepad gone'); return; }
  const axes = gp.axes || [];
  padVec = [-(Number(axes[1]) || 0), -(Number(axes[0]) || 0)];
  const btn = (i) => gp.buttons && gp.buttons[i] && (gp.buttons[i].pressed || gp.buttons[i].value > 0.5);
  if (!DEADMAN_BUTTONS.some(btn)) {
    padArmed = true;
    if (driving) endHold('deadman released');
    return;
  }
  if (driving || !padArmed) return;
  if (!motionOk || document.visibilityState !== 'visible' || !document.hasFocus() ||
      document.body.dataset.view !== 'teleop') return;
  padArmed = false;
  startHold('gamepad', 'gamepad', () => padVec);
}

const PAD_KEYS = { ArrowUp: 'fwd', ArrowDown: 'back', ArrowLeft: 'left', ArrowRight: 'right' };

export function initTeleop() {
  buildJoints();
  $('#lin-speed').addEventListener('input', (e) => setText($('#lin-out'), `${Number(e.target.value).toFixed(1)} m/s`));
  $('#ang-speed').addEventListener('input', (e) => setText($('#ang-out'), `${Number(e.target.value).toFixed(1)} rad/s`));
  $('#claim').addEventListener('click', claim);
  $('#release').addEventListener('click', releaseOrLeave);
  // Closing or leaving the page gives control back and leaves the queue (the request outlives
  // the page); the node also drops a queued claim whose last stream closed.
  window.addEventListener('pagehide', () => {
    const token = getToken();
    if (!token) return;
    if (app.session) {
      request('DELETE', '/rcan/v1/auth/release', { session_id: app.session.session_id }, { keepalive: true }).catch(() => {});
    } else if (app.queued) {
      request('DELETE', '/rcan/v1/auth/queue', undefined, { keepalive: true }).catch(() => {});
    }
  });
  // The pad: pressing a button (pointer, Enter or Space) or an arrow key while the pad has
  // focus starts a hold; every way it can end stops the robot.
  const pad = $('#pad');
  for (const b of pad.querySelectorAll('button')) {
    const dir = b.dataset.drive;
    b.addEventListener('pointerdown', (e) => {
      e.preventDefault();
      b.focus();
      startHold(dir, `pointer${e.pointerId}`);
    });
    for (const ev of ['pointerup', 'pointercancel', 'pointerleave', 'lostpointercapture']) {
      b.addEventListener(ev, () => { if (hold && hold.key.startsWith('pointer')) endHold(ev); });
    }
    b.addEventListener('keydown', (e) => {
      if (e.key !== 'Enter' && e.key !== ' ') return;
      e.preventDefault();
      if (!e.repeat) startHold(dir, e.key);
    });
    b.addEventListener('keyup', (e) => { if (hold && hold.key === e.key) endHold('key released'); });
    b.addEventListener('blur', () => endHold('the pad lost focus'));
  }
  // Arrow keys drive only while a pad button has focus; on a speed slider they change the speed.
  pad.addEventListener('keydown', (e) => {
    const dir = PAD_KEYS[e.key];
    if (!dir) return;
    e.preventDefault();
    if (e.repeat) return;      // the hold repeats by itself
    const target = pad.querySelector(`button[data-drive=${dir}]`);
    if (target && document.activeElement !== target) target.focus();
    startHold(dir, e.key);
  });
  pad.addEventListener('keyup', (e) => { if (hold && hold.key === e.key) endHold('key released'); });
  initStick();
  setInterval(pollGamepad, 50);
  window.addEventListener('gamepaddisconnected', () => { if (hold && hold.key === 'gamepad') endHold('gamepad disconnected'); pollGamepad(); });
  window.addEventListener('gamepadconnected', pollGamepad);
  on('view', (name) => { if (name !== 'teleop') endHold('left the teleop view'); });
  window.addEventListener('blur', () => endHold('the window lost focus'));
  document.addEventListener('visibilitychange', () => { if (document.visibilityState !== 'visible') endHold('the tab was hidden'); });
  // The stream falling silent ends a hold even between repeats.
  setInterval(() => { if (hold && !streamLive()) endHold('the stream is silent'); }, 200);
  on('stream-event', (m) => {
    const name = m && (m.event || m.type);
    if (name === 'ESTOP') { needRearm = true; endHold('ESTOP'); }
    onControlEvent(m);
    if (name === 'PREEMPTED' || name === 'SESSION_EXPIRED' || name === 'SESSION_REVOKED' || name === 'NETWORK_LOSS_SAFE_STOP') endHold(name);
  });
  on('estop-pressed', () => { needRearm = true; endHold('ESTOP'); });
  // Motion controls work only while the stream is live (stream.js: liveness watchdog).
  // and no ESTOP is latched.
  let linkState = 'idle';
  // A GUEST may watch but neither claim nor drive (seed §6.3): its controls are disabled and
  // say why, instead of answering every press with a refusal.
  const motionControls = () => {
    const mayDrive = roleAtLeast('USER');
    const ok = linkState === 'open' && app.estop !== true && mayDrive;
    motionOk = ok;
    $('#stick').setAttribute('aria-disabled', ok ? 'false' : 'true');
    for (const b of document.querySelectorAll('#pad button, #arm-send, #arm-home, #grip-open, #grip-close')) {
      b.disabled = !ok;
      b.title = mayDrive ? '' : `Driving needs USER or above (you are ${app.role || 'unknown'})`;
    }
    const claim = $('#claim');
    claim.disabled = !mayDrive;
    claim.title = mayDrive ? '' : `Claiming control needs USER or above (you are ${app.role || 'unknown'})`;
  };
  on('status', motionControls);
  on('link', (state) => {
    linkState = state;
    if (state !== 'open') endHold(`stream ${state}`);
    motionControls();
    renderControl();
  });
  on('safety', (estop) => {
    if (estop) endHold('ESTOP');
    motionControls();
  });
  $('#arm-send').addEventListener('click', sendArm);
  $('#arm-home').addEventListener('click', () => {
    touched.clear();
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
      endHold('control session ended');
      log('control session ended (released, pre-empted or expired)', false);
    }
    if (!app.telemetry) onTelemetryJoints(s.robot && s.robot.robot);
    applyLimits();
    renderControl();
  });
}

// Signing out gives control back and leaves the queue first, while the token still works.
export async function teleopSignOut() {
  endHold('signed out');
  stopHeartbeat();
  const sid = app.session && app.session.session_id;
  const queued = app.queued;
  app.session = null;
  app.queued = 0;
  try {
    if (sid) await request('DELETE', '/rcan/v1/auth/release', { session_id: sid }, { timeoutMs: 3000 });
    else if (queued) await request('DELETE', '/rcan/v1/auth/queue', undefined, { timeoutMs: 3000 });
  } catch (_) { /* the token may already be refused; the node's timers end what is left */ }
}
