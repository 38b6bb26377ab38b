// The WebSocket stream (/rcan/v1/stream): CONNECT with the token in the first frame (never in
// the URL), SUBSCRIBE to telemetry at 5 Hz, then telemetry, events and PENDING_AUTH pushes.
// Reconnects with backoff 1, 2, 4, 8, 16, 30 s (±0.5 s jitter), as the WebSocket binding says.

import { getToken, uuid } from './api.js';

const BACKOFF_S = [1, 2, 4, 8, 16, 30];
// Liveness: telemetry arrives every TELEMETRY_PERIOD_MS; an open stream that brings nothing for
// three periods is "lost" (a frozen network closes nothing) until a message arrives again.
export const TELEMETRY_HZ = 5;
export const TELEMETRY_PERIOD_MS = 1000 / TELEMETRY_HZ;
export const LIVENESS_MS = 3 * TELEMETRY_PERIOD_MS;

export class Stream extends EventTarget {
  constructor() {
    super();
    this.ws = null;
    this.state = 'idle';       // idle | connecting | open | lost | waiting | refused
    this.watchdog = 0;
    this.attempt = 0;
    this.reconnects = 0;
    this.retryAt = 0;
    this.role = '';
    this.sessionId = '';
    this.frames = 0;
    this.timer = 0;
    this.stopped = true;
    this.lastFrameAt = 0;
    this.pending = new Map();  // message_id → resolve, for messages sent over the stream
  }

  start() {
    this.stopped = false;
    clearInterval(this.watchdog);
    this.watchdog = setInterval(() => {
      if (this.state === 'open' && Date.now() - this.lastFrameAt > LIVENESS_MS) {
        this.setState('lost', `no message for ${Math.round((Date.now() - this.lastFrameAt) / 100) / 10} s`);
      }
    }, 100);
    this.connect();
  }

  stop() {
    this.stopped = true;
    clearInterval(this.watchdog);
    clearTimeout(this.timer);
    if (this.ws) this.ws.close(1000, 'signed out');
    this.ws = null;
    this.setState('idle');
  }

  setState(s, detail = '') {
    this.state = s;
    this.dispatchEvent(new CustomEvent('state', { detail: { state: s, detail } }));
  }

  connect() {
    if (this.stopped) return;
    const scheme = location.protocol === 'https:' ? 'wss:' : 'ws:';
    let ws;
    try {
      ws = new WebSocket(`${scheme}//${location.host}/rcan/v1/stream`);
    } catch (e) {
      this.scheduleReconnect('cannot open the stream');
      return;
    }
    this.ws = ws;
    this.setState('connecting');
    ws.onopen = () => {
      ws.send(JSON.stringify({ type: 'CONNECT', token: getToken(), version: '1.0.0' }));
    };
    ws.onmessage = (ev) => {
      if (typeof ev.data !== 'string') return;
      let msg;
      try { msg = JSON.parse(ev.data); } catch (_) { return; }
      if (!msg || typeof msg !== 'object') return;
      this.lastFrameAt = Date.now();
      if (this.state === 'lost') this.setState('open');
      this.handle(msg);
    };
    ws.onclose = (ev) => {
      if (this.ws !== ws) return;
      this.ws = null;
      if (ev.code === 4001) {
        // The token was refused: retrying with the same token cannot succeed.
        this.setState('refused', ev.reason || 'token refused');
        this.dispatchEvent(new CustomEvent('refused', { detail: ev.reason }));
        return;
      }
      this.scheduleReconnect(`closed (${ev.code})`);
    };
    ws.onerror = () => { /* onclose follows */ };
  }

  scheduleReconnect(why) {
    if (this.stopped) return;
    const base = BACKOFF_S[Math.min(this.attempt, BACKOFF_S.length - 1)] * 1000;
    const delay = Math.max(200, base + (Math.random() * 1000 - 500));
    this.attempt += 1;
    this.retryAt = Date.now() + delay;
    this.setState('waiting', why);
    clearTimeout(this.timer);
    this.timer = setTimeout(() => { this.reconnects += 1; this.connect(); }, delay);
  }

  handle(msg) {
    const type = msg.type || msg.message_type;
    if (type === 'CONNECT_ACK') {
      this.attempt = 0;
      this.role = msg.role || '';
      this.sessionId = msg.session_id || '';
      this.setState('open');
      this.ws.send(JSON.stringify({ type: 'SUBSCRIBE', topics: ['telemetry'], hz: TELEMETRY_HZ }));
      this.dispatchEvent(new CustomEvent('connected', { detail: msg }));
      return;
    }
    if (type === 'STREAM' && msg.topic === 'telemetry') {
      this.frames += 1;
      this.dispatchEvent(new CustomEvent('telemetry', { detail: msg }));
      return;
    }
    if (msg.reply_to && this.pending.has(msg.reply_to)) {
      const resolve = this.pending.get(msg.reply_to);
      this.pending.delete(msg.reply_to);
      resolve(msg);
      return;
    }
    if (type === 'PENDING_AUTH' || (msg.payload && msg.payload.type === 'PENDING_AUTH')) {
      this.dispatchEvent(new CustomEvent('pending', { detail: msg }));
    }
    this.dispatchEvent(new CustomEvent('event', { detail: msg }));
  }

  // Sends an RCAN message on the stream; resolves with its answer (or null after 5 s).
  send(message) {
    return new Promise((resolve) => {
      if (!this.ws || this.state !== 'open') { resolve(null); return; }
      if (!message.message_id) message.message_id = uuid();
      this.pending.set(message.message_id, resolve);
      setTimeout(() => {
        if (this.pending.delete(message.message_id)) resolve(null);
      }, 5000);
      this.ws.send(JSON.stringify(message));
    });
  }
}
