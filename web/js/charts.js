// Canvas drawings: the base's position with its trail, and scrolling time-series charts.
// Colours come from CSS custom properties so the page keeps one palette.

function css(name, fallback) {
  const v = getComputedStyle(document.documentElement).getPropertyValue(name).trim();
  return v || fallback;
}

function fit(canvas) {
  const dpr = window.devicePixelRatio || 1;
  const w = canvas.clientWidth || canvas.width;
  const h = canvas.clientHeight || canvas.height;
  if (canvas.width !== Math.round(w * dpr) || canvas.height !== Math.round(h * dpr)) {
    canvas.width = Math.round(w * dpr);
    canvas.height = Math.round(h * dpr);
  }
  const ctx = canvas.getContext('2d');
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  return { ctx, w, h };
}

export class PositionPlot {
  // fence: the view always holds the workspace fence (when known), not only the trail.
  constructor(canvas, { trail = 600, fence = false } = {}) {
    this.canvas = canvas;
    this.fence = fence;
    this.trail = [];
    this.max = trail;
    this.pose = null;
    this.workspace = null;   // {min_x, max_x, min_y, max_y} when known
    this.draws = 0;
  }

  push(x, y, theta) {
    if (![x, y, theta].every((v) => typeof v === 'number' && isFinite(v))) return;
    const last = this.trail[this.trail.length - 1];
    if (!last || Math.hypot(last[0] - x, last[1] - y) > 0.005) this.trail.push([x, y]);
    if (this.trail.length > this.max) this.trail.shift();
    this.pose = { x, y, theta };
    this.draw();
  }

  clearTrail() {
    this.trail = this.pose ? [[this.pose.x, this.pose.y]] : [];
    this.draw();
  }

  draw() {
    const { ctx, w, h } = fit(this.canvas);
    this.draws += 1;
    ctx.fillStyle = css('--plot-bg', '#0f1720');
    ctx.fillRect(0, 0, w, h);
    // The view: at least ±2 m around the origin, grown to hold the trail and the robot.
    let minX = -2, maxX = 2, minY = -2, maxY = 2;
    for (const [x, y] of this.trail) {
      minX = Math.min(minX, x - 0.5); maxX = Math.max(maxX, x + 0.5);
      minY = Math.min(minY, y - 0.5); maxY = Math.max(maxY, y + 0.5);
    }
    const ws = this.workspace;
    if (this.fence && ws) {
      minX = Math.min(minX, ws.min_x - 0.5); maxX = Math.max(maxX, ws.max_x + 0.5);
      minY = Math.min(minY, ws.min_y - 0.5); maxY = Math.max(maxY, ws.max_y + 0.5);
    }
    const span = Math.max(maxX - minX, maxY - minY);
    const cx = (minX + maxX) / 2, cy = (minY + maxY) / 2;
    const scale = (Math.min(w, h) - 24) / span;
    const X = (x) => w / 2 + (x - cx) * scale;
    const Y = (y) => h / 2 - (y - cy) * scale;
    // Grid, 1 m (or 5 m when zoomed out).
    const step = span > 20 ? 5 : 1;
    ctx.strokeStyle = css('--plot-grid', '#223040');
    ctx.lineWidth = 1;
    ctx.beginPath();
    for (let gx = Math.ceil((cx - span) / step) * step; gx <= cx + span; gx += step) {
      ctx.moveTo(X(gx), 0); ctx.lineTo(X(gx), h);
    }
    for (let gy = Math.ceil((cy - span) / step) * step; gy <= cy + span; gy += step) {
      ctx.moveTo(0, Y(gy)); ctx.lineTo(w, Y(gy));
    }
    ctx.stroke();
    // Axes through the origin.
    ctx.strokeStyle = css('--plot-axis', '#3d5368');
    ctx.beginPath();
    ctx.moveTo(X(0), 0); ctx.lineTo(X(0), h);
    ctx.moveTo(0, Y(0)); ctx.lineTo(w, Y(0));
    ctx.stroke();
    if (ws) {
      ctx.strokeStyle = css('--plot-workspace', '#a36b1f');
      ctx.setLineDash([6, 4]);
      ctx.strokeRect(X(ws.min_x), Y(ws.max_y), (ws.max_x - ws.min_x) * scale, (ws.max_y - ws.min_y) * scale);
      ctx.setLineDash([]);
    }
    ctx.fillStyle = css('--plot-text', '#8aa0b4');
    ctx.font = '11px system-ui, sans-serif';
    ctx.fillText(`grid ${step} m`, 8, h - 8);
    // Trail.
    if (this.trail.length > 1) {
      ctx.strokeStyle = css('--plot-trail', '#3fa7ff');
      ctx.lineWidth = 2;
      ctx.beginPath();
      this.trail.forEach(([x, y], i) => (i ? ctx.lineTo(X(x), Y(y)) : ctx.moveTo(X(x), Y(y))));
      ctx.stroke();
    }
    // The robot: a triangle pointing along theta.
    if (this.pose) {
      const { x, y, theta } = this.pose;
      const r = 10;
      ctx.save();
      ctx.translate(X(x), Y(y));
      ctx.rotate(-theta);
      ctx.fillStyle = css('--plot-robot', '#ffd166');
      ctx.beginPath();
      ctx.moveTo(r * 1.4, 0);
      ctx.lineTo(-r, r * 0.8);
      ctx.lineTo(-r * 0.5, 0);
      ctx.lineTo(-r, -r * 0.8);
      ctx.closePath();
      ctx.fill();
      ctx.restore();
    }
  }
}

// A scrolling chart of a few series over the last `windowS` seconds.
export class TimeChart {
  constructor(canvas, series, { windowS = 30, min = null, max = null, unit = '' } = {}) {
    this.canvas = canvas;
    this.series = series;            // [{name, color}]
    this.points = series.map(() => []);
    this.windowS = windowS;
    this.min = min;
    this.max = max;
    this.unit = unit;
  }

  push(t, values) {
    values.forEach((v, i) => {
      if (typeof v !== 'number' || !isFinite(v) || !this.points[i]) return;
      this.points[i].push([t, v]);
    });
    const cutoff = t - this.windowS * 1000;
    for (const p of this.points) while (p.length && p[0][0] < cutoff) p.shift();
    this.draw(t);
  }

  draw(now) {
    const { ctx, w, h } = fit(this.canvas);
    ctx.fillStyle = css('--plot-bg', '#0f1720');
    ctx.fillRect(0, 0, w, h);
    let lo = this.min, hi = this.max;
    if (lo === null || hi === null) {
      let a = Infinity, b = -Infinity;
      for (const p of this.points) for (const [, v] of p) { a = Math.min(a, v); b = Math.max(b, v); }
      if (!isFinite(a)) { a = -1; b = 1; }
      if (b - a < 0.2) { a -= 0.1; b += 0.1; }
      if (lo === null) lo = a;
      if (hi === null) hi = b;
    }
    const left = 44, right = 8, top = 8, bottom = 18;
    const X = (t) => left + (1 - (now - t) / (this.windowS * 1000)) * (w - left - right);
    const Y = (v) => top + (1 - (v - lo) / (hi - lo)) * (h - top - bottom);
    ctx.strokeStyle = css('--plot-grid', '#223040');
    ctx.fillStyle = css('--plot-text', '#8aa0b4');
    ctx.font = '11px system-ui, sans-serif';
    ctx.lineWidth = 1;
    for (let i = 0; i <= 4; i++) {
      const v = lo + ((hi - lo) * i) / 4;
      ctx.beginPath(); ctx.moveTo(left, Y(v)); ctx.lineTo(w - right, Y(v)); ctx.stroke();
      ctx.fillText(v.toFixed(2), 4, Y(v) + 4);
    }
    ctx.fillText(`last ${this.windowS} s ${this.unit}`, left, h - 4);
    this.series.forEach((s, i) => {
      const p = this.points[i];
      if (p.length < 2) return;
      ctx.strokeStyle = s.color;
      ctx.lineWidth = 1.5;
      ctx.beginPath();
      p.forEach(([t, v], k) => (k ? ctx.lineTo(X(t), Y(v)) : ctx.moveTo(X(t), Y(v))));
      ctx.stroke();
    });
  }
}
