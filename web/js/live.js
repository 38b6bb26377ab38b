// Live view: telemetry from the stream drawn as the base's position with its trail, speed and
// joint angles as scrolling charts, and the stream's connection state.
import { $, el, replace, setText, fmtNum } from './dom.js';
import { PositionPlot, TimeChart } from './charts.js';
import { app } from './state.js';

const JOINT_COLOURS = ['#3fa7ff', '#ffd166', '#06d6a0', '#ef476f', '#c77dff', '#f4a261'];
let plot, speed, joints;
let lastDraw = 0;
let rateWindow = [];

export function initLive() {
  plot = new PositionPlot($('#plot'));
  speed = new TimeChart($('#speed-chart'), [{ name: 'linear', color: '#3fa7ff' }, { name: 'angular', color: '#ffd166' }], { unit: '' });
  joints = new TimeChart($('#joint-chart'), JOINT_COLOURS.map((c, i) => ({ name: `j${i + 1}`, color: c })), { min: -3.2, max: 3.2 });
  replace($('#joint-legend'), JOINT_COLOURS.map((c, i) => [el('span', { class: `sw j${i}` }), `j${i + 1} `]));
  $('#clear-trail').addEventListener('click', () => plot.clearTrail());
  plot.draw();
  window.addEventListener('resize', () => plot.draw());
}

export function setWorkspace(ws) {
  if (plot && ws && [ws.min_x, ws.max_x, ws.min_y, ws.max_y].every((v) => typeof v === 'number' && isFinite(v) && Math.abs(v) < 1e6)) {
    plot.workspace = ws;
  }
}

export function onTelemetry(frame) {
  const t = frame.payload || {};
  const b = t.base || {};
  const now = Date.now();
  rateWindow.push(now);
  while (rateWindow.length && rateWindow[0] < now - 5000) rateWindow.shift();
  plot.push(b.x, b.y, b.theta);
  speed.push(now, [b.linear_mps, b.angular_radps]);
  const j = (t.arm && Array.isArray(t.arm.joints_rad)) ? t.arm.joints_rad : [];
  joints.push(now, j);
  lastDraw = now;
  const lf = $('#live-facts');
  replace(lf, [
    ['x', `${fmtNum(b.x)} m`], ['y', `${fmtNum(b.y)} m`], ['heading', `${fmtNum((b.theta || 0) * 180 / Math.PI, 0)}°`],
    ['speed', `${fmtNum(b.linear_mps)} m/s`], ['turn', `${fmtNum(b.angular_radps)} rad/s`],
    ['odometry', `${fmtNum(b.odometry_m)} m`],
    ['battery', typeof t.battery_pct === 'number' ? `${t.battery_pct.toFixed(1)} %` : '–'],
    ['state', frame.estop_active ? 'ESTOP' : (t.stopped ? 'stopped' : 'moving')],
  ].map(([k, v]) => [el('dt', {}, k), el('dd', {}, v)]));
  lf.dataset.x = String(b.x);
  lf.dataset.y = String(b.y);
  renderStreamStats();
}

export function renderStreamStats() {
  const s = app.stream;
  if (!s) return;
  const hz = rateWindow.length > 1 ? ((rateWindow.length - 1) * 1000) / (rateWindow[rateWindow.length - 1] - rateWindow[0]) : 0;
  setText($('#stream-stats'), `stream ${s.state}; ${s.frames} telemetry frames, ${hz.toFixed(1)} Hz; ` +
    `${s.reconnects} reconnects; last frame ${lastDraw ? Math.round((Date.now() - lastDraw) / 100) / 10 + ' s ago' : 'never'}`);
}

export function plotDraws() { return plot ? plot.draws : 0; }
