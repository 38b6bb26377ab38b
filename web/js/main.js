// The dashboard's entry point: sign-in, tabs, the always-visible ESTOP, status polling and the
// stream that feeds the views.
import { $, $all, setText, toast, fmtDuration } from './dom.js';
import * as api from './api.js';
import { Stream } from './stream.js';
import { app, emit, on, safetyState } from './state.js';
import { initOverview, renderOverview } from './overview.js';
import { initLive, onTelemetry, setWorkspace, renderStreamStats } from './live.js';
import { initTeleop, onTelemetryJoints, teleopSignOut, renderControl } from './teleop.js';
import { initApprovals, onPending, onEvent as approvalsEvent, refresh as refreshPending } from './approvals.js';
import { initAudit, loadAudit, setDefaultRrn } from './audit.js';
import { initChat } from './chat.js';
import { initNode } from './nodepanel.js';
import { initRobots } from './robots.js';

let pollTimer = 0;
let auditLoaded = false;

function showSignedIn(yes) {
  $('#signin').hidden = yes;
  $('#tabs').hidden = !yes;
  $('#views').hidden = !yes;
  $('#signout').hidden = !yes;
  document.body.dataset.signedIn = yes ? 'yes' : 'no';
}

function setSafety(estop) {
  app.estop = estop;
  renderSafetyPill();
}

// The safety state as last reported — red ESTOP LATCHED, amber SAFE STOP (reason), green
// running — marked stale while the stream is down.
function renderSafetyPill() {
  const estop = app.estop;
  const live = app.stream && app.stream.state === 'open';
  const pill = $('#safety-pill');
  const { kind, why } = safetyState();
  let text = { unknown: 'status unknown', estop: 'ESTOP LATCHED', safe_stop: `SAFE STOP${why ? ` (${why})` : ''}`, running: 'running' }[kind];
  if (kind !== 'unknown' && !live) text += ' (last known)';
  setText(pill, text);
  pill.className = 'pill ' + { unknown: '', estop: 'bad', safe_stop: 'stopped', running: live ? 'good' : 'warn' }[kind];
  pill.title = live ? 'Safety state from the robot' : 'The stream is down: this is the last state the page saw';
  document.body.dataset.estop = estop ? 'latched' : 'clear';
  document.body.dataset.safety = kind;
  renderBanner();
  emit('safety', estop);
}

// ESTOP and safe-stop as a full-width banner, RESUME beside it (for a latched ESTOP).
function renderBanner() {
  const banner = $('#safety-banner');
  const { kind, why } = safetyState();
  const safeStop = kind === 'safe_stop';
  banner.hidden = !app.estop && !safeStop;
  banner.className = 'banner' + (safeStop ? ' warn' : '');
  document.body.dataset.banner = banner.hidden ? 'none' : kind;
  setText($('#safety-banner-text'), app.estop
    ? 'ESTOP LATCHED — nothing moves until RESUME. Motion controls are disabled.'
    : `SAFE STOP${why ? ` (${why})` : ''} — the robot stopped itself; the next accepted command clears it.`);
  const resumeBtn = $('#banner-resume');
  resumeBtn.hidden = !app.estop;
  resumeBtn.disabled = $('#resume').disabled;
}

async function refreshStatus() {
  const asked = Date.now();
  try {
    const st = await api.status();
    if (asked < app.statusAskedAt) return;   // an older answer overtaken by a newer request
    app.statusAskedAt = asked;
    app.status = st;
    if (st.estop_active === true && estopSend.pressedAt && asked >= estopSend.pressedAt) estopConfirmed();
    setSafety(!!app.status.estop_active);
    renderBanner();
    setText($('#robot-name'), app.status.name || 'RCAN robot');
    setText($('#robot-ruri'), app.status.ruri || '');
    const lim = app.status.robot && app.status.robot.limits;
    if (lim) setWorkspace(lim.workspace);
    setDefaultRrn(app.status.rrn);
    emit('status');
  } catch (e) {
    if (e.status === 401) signOut(api.tokenRefusal(e));
  }
}

async function signIn(token, remember) {
  const t = token.trim();
  if (!t) return;
  api.setToken(t, remember);
  try {
    app.status = await api.status();
  } catch (e) {
    api.setToken('', false);
    showSignedIn(false);
    setText($('#signin-error'), e.status === 401 ? api.tokenRefusal(e) : `Cannot reach the node: ${e.message}`);
    $('#signin-error').title = e.message || '';
    return;
  }
  setText($('#signin-error'), '');
  $('#token-input').value = '';
  app.claims = api.tokenClaims(t) || {};
  expiryWarned = 0;
  app.role = String(app.claims.role || '').toUpperCase();
  setText($('#who'), `${app.claims.sub || 'signed in'} (${app.role || '?'})`);
  showSignedIn(true);
  app.stream = new Stream();
  wireStream(app.stream);
  app.stream.start();
  await refreshStatus();
  refreshPending();
  clearInterval(pollTimer);
  pollTimer = setInterval(() => { refreshStatus(); refreshPending(); renderStreamStats(); warnTokenExpiry(); }, 2000);
}

// The token's expiry, announced 5 minutes and 1 minute ahead (the node signs the page out when
// it refuses the token; a warning lets the operator fetch a new one first).
let expiryWarned = 0;
function warnTokenExpiry() {
  const exp = app.claims && typeof app.claims.exp === 'number' ? app.claims.exp * 1000 : 0;
  if (!exp) return;
  const left = exp - api.serverNow();
  const step = left <= 60000 ? 2 : left <= 300000 ? 1 : 0;
  if (step > expiryWarned) {
    expiryWarned = step;
    toast(`Your token expires in ${fmtDuration(left / 1000)}: get a new one and sign in again before it does.`, 'warn');
  }
}

async function signOut(why) {
  clearInterval(pollTimer);
  await teleopSignOut();      // releases control and leaves the queue while the token works
  if (app.stream) app.stream.stop();
  app.stream = null;
  api.setToken('', false);
  app.role = '';
  app.claims = null;
  auditLoaded = false;
  setEstopStatus('idle');
  setText($('#who'), '');
  setConn('idle');
  showSignedIn(false);
  emit('signed-out');
  setText($('#signin-error'), why || '');
}

function setConn(state, detail) {
  const pill = $('#conn-pill');
  const s = app.stream;
  let text = `stream: ${state}`;
  if (state === 'waiting' && s) text = `stream: reconnecting in ${Math.max(0, Math.round((s.retryAt - Date.now()) / 1000))} s`;
  if (state === 'refused') text = 'stream: refused';
  if (state === 'lost') text = 'connection lost';
  setText(pill, text);
  pill.title = detail ? String(detail) : 'WebSocket stream';
  pill.className = 'pill ' + (state === 'open' ? 'good' : state === 'idle' ? '' : 'warn');
  document.body.dataset.stream = state;
  emit('link', state);
  renderSafetyPill();
  renderStreamStats();
}

function wireStream(s) {
  s.addEventListener('state', (e) => setConn(e.detail.state, e.detail.detail));
  s.addEventListener('connected', (e) => {
    if (e.detail.role) app.role = String(e.detail.role).toUpperCase();
    setText($('#who'), `${(app.claims && app.claims.sub) || 'signed in'} (${app.role})`);
    emit('status');
  });
  s.addEventListener('telemetry', (e) => {
    const f = e.detail;
    api.noteServerTime(f.timestamp_ms);
    app.telemetry = f.payload || {};
    // A frame made after the ESTOP was pressed that shows the latch confirms it.
    if (f.estop_active === true && estopSend.pressedAtNode && f.timestamp_ms >= estopSend.pressedAtNode) estopConfirmed();
    if (typeof f.estop_active === 'boolean' && f.estop_active !== app.estop) {
      setSafety(f.estop_active);
      renderOverview();
    }
    onTelemetry(f);
    onTelemetryJoints(app.telemetry);
  });
  s.addEventListener('pending', (e) => onPending(e.detail));
  s.addEventListener('event', (e) => {
    const m = e.detail;
    const name = m.event || m.type;
    if (m.type === 'ERROR') return;
    emit('stream-event', m);
    if (['ESTOP', 'RESUME', 'STOP', 'PREEMPTED', 'AVAILABLE', 'NETWORK_LOSS_SAFE_STOP'].includes(name)) {
      toast(`Event: ${name}`, name === 'ESTOP' || name === 'PREEMPTED' ? 'bad' : 'info');
      refreshStatus();
    }
    approvalsEvent(m);
  });
  s.addEventListener('refused', (e) => signOut(`The stream refused the token: ${e.detail || ''}`));
}

function showView(name) {
  for (const b of $all('#tabs button')) {
    const on = b.dataset.view === name;
    b.classList.toggle('active', on);
    b.setAttribute('aria-selected', on ? 'true' : 'false');
    b.tabIndex = on ? 0 : -1;
  }
  for (const v of $all('#views .view')) v.hidden = v.id !== `view-${name}`;
  document.body.dataset.view = name;
  emit('view', name);
  if (name === 'audit' && !auditLoaded) { auditLoaded = true; loadAudit(); }
  if (name === 'approvals') refreshPending();
  if (name === 'teleop') renderControl();
}

// An ESTOP is shown as sent at once ("ESTOP sending…"); one the node has not confirmed within
// the request's timeout (a frozen network, a refusal) stays on screen as "ESTOP NOT CONFIRMED"
// with a retry button, until an answer, a telemetry frame or a status read after the press
// shows the latch.
const estopSend = { state: 'idle', seq: 0, pressedAt: 0, pressedAtNode: 0, hideTimer: 0 };

function setEstopStatus(state, detail = '') {
  estopSend.state = state;
  clearTimeout(estopSend.hideTimer);
  if (state === 'idle') { estopSend.pressedAt = 0; estopSend.pressedAtNode = 0; }
  const box = $('#estop-status');
  box.hidden = state === 'idle';
  box.className = `estop-status ${state}`;
  box.dataset.state = state;
  setText($('#estop-status-text'), {
    idle: '',
    sending: 'ESTOP sending…',
    unconfirmed: `ESTOP NOT CONFIRMED — ${detail}. The robot may still be moving: retry, or stop it another way.`,
    confirmed: 'ESTOP confirmed: the robot has latched it.',
  }[state]);
  $('#estop-retry').hidden = state !== 'unconfirmed';
  if (state === 'confirmed') estopSend.hideTimer = setTimeout(() => setEstopStatus('idle'), 4000);
}

function estopConfirmed() {
  if (estopSend.state === 'sending' || estopSend.state === 'unconfirmed') setEstopStatus('confirmed');
}

async function onEstop() {
  if (!api.getToken()) {
    toast('Sign in first — or run `rcan estop` on the robot.', 'bad');
    return;
  }
  emit('estop-pressed');
  const seq = ++estopSend.seq;
  if (estopSend.state !== 'sending' && estopSend.state !== 'unconfirmed') {
    estopSend.pressedAt = Date.now();
    estopSend.pressedAtNode = api.serverNow();
  }
  setEstopStatus('sending');
  try {
    await api.estop();
    estopConfirmed();
    setSafety(true);
    toast('ESTOP latched. RESUME (LEASEE or above) clears it.', 'bad');
  } catch (e) {
    // Only the newest attempt speaks; a confirmation meanwhile has already cleared it.
    if (seq === estopSend.seq && estopSend.state === 'sending') {
      const why = e.code === 'TIMEOUT' ? `no answer within ${(api.ESTOP_TIMEOUT_MS / 1000).toFixed(0)} s` : `${e.code}: ${e.message}`;
      setEstopStatus('unconfirmed', why);
    }
  }
  refreshStatus();
}

function init() {
  initOverview();
  initLive();
  initTeleop();
  initApprovals();
  initAudit();
  initChat();
  initNode();
  initRobots();
  on('refresh', refreshStatus);
  $('#estop').addEventListener('click', onEstop);
  $('#estop-retry').addEventListener('click', onEstop);
  // Escape anywhere on the page is ESTOP (an ESTOP is never harmful: it latches until RESUME).
  document.addEventListener('keydown', (e) => {
    if (e.key === 'Escape' && !e.repeat && !e.ctrlKey && !e.altKey && !e.metaKey) {
      e.preventDefault();
      onEstop();
    }
  });
  $('#banner-resume').addEventListener('click', () => $('#resume').click());
  $('#signout').addEventListener('click', () => signOut(''));
  for (const b of $all('#tabs button')) b.addEventListener('click', () => showView(b.dataset.view));
  // The tab list's keyboard: Left/Right (Home/End) move between tabs and show the view.
  $('#tabs').addEventListener('keydown', (e) => {
    const tabs = $all('#tabs button');
    const i = tabs.indexOf(document.activeElement);
    if (i < 0) return;
    const to = { ArrowRight: i + 1, ArrowLeft: i - 1, Home: 0, End: tabs.length - 1 }[e.key];
    if (to === undefined) return;
    e.preventDefault();
    const t = tabs[(to + tabs.length) % tabs.length];
    t.focus();
    showView(t.dataset.view);
  });
  $('#signin-form').addEventListener('submit', (e) => {
    e.preventDefault();
    signIn($('#token-input').value, $('#remember').checked);
  });
  $('#token-file').addEventListener('change', async (e) => {
    const f = e.target.files && e.target.files[0];
    if (!f) return;
    if (f.size > 16384) { setText($('#signin-error'), 'That file is too large to be a token.'); return; }
    const text = await f.text();
    e.target.value = '';
    signIn(text, $('#remember').checked);
  });
  setSafety(null);
  setConn('idle');
  // Keep the "reconnecting in N s" countdown moving.
  setInterval(() => { if (app.stream && app.stream.state === 'waiting') setConn('waiting', 'retrying'); }, 500);
  showView('overview');
  const saved = api.restoreToken();
  if (saved) signIn(saved, true);
  else showSignedIn(false);
}

init();
