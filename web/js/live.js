// Live view: telemetry from the stream drawn as the base's position with its trail, speed and
// joint angles as scrolling charts, and the stream's connection state.
import { $, el, replace, setText, fmtNum } from './dom.js';
import { PositionPlot, TimeChart } from './charts.js';
import { app, on, safetyState, staleWhy } from './state.js';

const JOINT_COLOURS = ['#3fa7ff', '#ffd166', '#06d6a0', '#ef476f', '#c77dff', '#f4a261'];
let plot, speed, joints, traj;
let lastDraw = 0;
let rateWindow = [];
let lastFrame = null;       // the newest telemetry frame, for the readouts

export function initLive() {
  plot = new PositionPlot($('#plot'));
  speed = new TimeChart($('#speed-chart'), [{ name: 'linear', color: '#3fa7ff' }, { name: 'angular', color: '#ffd166' }], { unit: '' });
  joints = new TimeChart($('#joint-chart'), JOINT_COLOURS.map((c, i) => ({ name: `j${i + 1}`, color: c })), { min: -3.2, max: 3.2 });
  replace($('#joint-legend'), JOINT_COLOURS.map((c, i) => [el('span', { class: `sw j${i}` }), `j${i + 1} `]));
  $('#clear-trail').addEventListener('click', () => plot.clearTrail());
  plot.draw();
  // Beside the drive pad: the same frames as readouts and the odometry path inside the fence.
  traj = new PositionPlot($('#traj'), { trail: 2000, fence: true });
  $('#clear-path').addEventListener('click', () => { traj.clearTrail(); describePath(); });
  traj.draw();
  describePath();
  renderTeleopFacts();
  for (const ev of ['link', 'safety', 'status']) on(ev, renderTeleopFacts);
  on('link', renderLiveFacts);
  on('signed-out', () => { lastFrame = null; renderLiveFacts(); });
  window.addEventListener('resize', () => { plot.draw(); traj.draw(); });
}

// The path's text alternative: what the plot shows, in words.
function describePath() {
  const c = $('#traj');
  const tr = traj.trail;
  const ws = traj.workspace;
  const fence = ws ? `the workspace fence is x ${fmtNum(ws.min_x, 1)} to ${fmtNum(ws.max_x, 1)} m, y ${fmtNum(ws.min_y, 1)} to ${fmtNum(ws.max_y, 1)} m`
    : 'no workspace fence is in force';
  let text;
  if (!tr.length) text = `No path yet; ${fence}.`;
  else {
    let len = 0;
    for (let i = 1; i < tr.length; i++) len += Math.hypot(tr[i][0] - tr[i - 1][0], tr[i][1] - tr[i - 1][1]);
    const [x0, y0] = tr[0];
    const [x1, y1] = tr[tr.length - 1];
    text = `Path of ${tr.length} points, ${fmtNum(len)} m long, from (${fmtNum(x0)}, ${fmtNum(y0)}) to (${fmtNum(x1)}, ${fmtNum(y1)}) m; ${fence}.`;
  }
  setText($('#traj-text'), text);
  c.dataset.points = String(tr.length);
}

// The safety state in words, marked when the stream is not live (the last state seen).
function safetyWords() {
  const live = app.stream && app.stream.state === 'open';
  const { kind, why } = safetyState();
  let s = { unknown: 'unknown', estop: 'ESTOP latched', safe_stop: `safe stop${why ? ` (${why})` : ''}`, running: 'running' }[kind];
  if (!live && kind !== 'unknown') s += ' (last known)';
  return s;
}

// Readouts from the stream are marked when it is not live: a class on their container (amber)
// and the words "last known", so a frozen page never looks like a moving robot's live state.
function markStale(box, note, what) {
  const why = staleWhy();
  box.classList.toggle('stale', !!why);
  box.dataset.stale = why ? 'yes' : 'no';
  note.hidden = !why;
  setText(note, why ? `${what} (last known, ${why}): not live.` : '');
  return why ? ' (last known)' : '';
}

export function renderTeleopFacts() {
  const t = app.telemetry || {};
  const b = t.base || {};
  const j = (t.arm && Array.isArray(t.arm.joints_rad)) ? t.arm.joints_rad : [];
  const box = $('#teleop-facts');
  const old = markStale(box, $('#teleop-stale'), 'Telemetry as last received');
  replace(box, [
    ['safety', safetyWords()], ['motion', app.telemetry ? (t.stopped ? 'stopped' : 'moving') + old : '–'],
    ['speed', `${fmtNum(b.linear_mps)} m/s${old}`], ['turn', `${fmtNum(b.angular_radps)} rad/s${old}`],
    ['x', `${fmtNum(b.x)} m`], ['y', `${fmtNum(b.y)} m`], ['heading', `${fmtNum((b.theta || 0) * 180 / Math.PI, 0)}°`],
    ...[0, 1, 2, 3, 4, 5].map((i) => [`joint ${i + 1}`, `${fmtNum(j[i])} rad`]),
  ].map(([k, v]) => el('div', {}, el('dt', {}, k), el('dd', {}, v))));
  box.dataset.x = String(b.x);
  box.dataset.speed = String(b.linear_mps);
}

// The safety core's workspace fence (status robot.limits.workspace); none when it is off.
export function setWorkspace(ws) {
  const ok = ws && ws.enabled !== false &&
    [ws.min_x, ws.max_x, ws.min_y, ws.max_y].every((v) => typeof v === 'number' && isFinite(v) && Math.abs(v) < 1e6);
  const fence = ok ? { min_x: ws.min_x, max_x: ws.max_x, min_y: ws.min_y, max_y: ws.max_y } : null;
  if (!plot || JSON.stringify(fence) === JSON.stringify(traj.workspace)) return;
  plot.workspace = fence;
  traj.workspace = fence;
  plot.draw();
  traj.draw();
  describePath();
}

export function onTelemetry(frame) {
  const t = frame.payload || {};
  const b = t.base || {};
  const now = Date.now();
  rateWindow.push(now);
  while (rateWindow.length && rateWindow[0] < now - 5000) rateWindow.shift();
  plot.push(b.x, b.y, b.theta);
  traj.push(b.x, b.y, b.theta);
  describePath();
  renderTeleopFacts();
  speed.push(now, [b.linear_mps, b.angular_radps]);
  const j = (t.arm && Array.isArray(t.arm.joints_rad)) ? t.arm.joints_rad : [];
  joints.push(now, j);
  lastDraw = now;
  lastFrame = frame;
  renderLiveFacts();
  renderStreamStats();
}

// The Live view's readouts from the newest frame, marked "last known" while the stream is not live.
function renderLiveFacts() {
  const lf = $('#live-facts');
  const old = markStale(lf, $('#live-stale'), 'Readouts as last received');
  if (!lastFrame) { replace(lf); return; }
  const t = lastFrame.payload || {};
  const b = t.base || {};
  replace(lf, [
    ['x', `${fmtNum(b.x)} m`], ['y', `${fmtNum(b.y)} m`], ['heading', `${fmtNum((b.theta || 0) * 180 / Math.PI, 0)}°`],
    ['speed', `${fmtNum(b.linear_mps)} m/s${old}`], ['turn', `${fmtNum(b.angular_radps)} rad/s${old}`],
    ['odometry', `${fmtNum(b.odometry_m)} m`],
    ['battery', typeof t.battery_pct === 'number' ? `${t.battery_pct.toFixed(1)} %` : '–'],
    ['state', (lastFrame.estop_active ? 'ESTOP' : (t.stopped ? 'stopped' : 'moving')) + old],
  ].map(([k, v]) => [el('dt', {}, k), el('dd', {}, v)]));
  lf.dataset.x = String(b.x);
  lf.dataset.y = String(b.y);
}

export function renderStreamStats() {
  const s = app.stream;
  if (!s) return;
  const hz = rateWindow.length > 1 ? ((rateWindow.length - 1) * 1000) / (rateWindow[rateWindow.length - 1] - rateWindow[0]) : 0;
  setText($('#stream-stats'), `stream ${s.state}; ${s.frames} telemetry frames, ${hz.toFixed(1)} Hz; ` +
    `${s.reconnects} reconnects; last frame ${lastDraw ? Math.round((Date.now() - lastDraw) / 100) / 10 + ' s ago' : 'never'}`);
}

export function plotDraws() { return plot ? plot.draws : 0; }
