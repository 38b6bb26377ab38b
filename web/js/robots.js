// Robots: this node and the robots its configuration lists (dashboard.robots), with their state
// as the node last read it (GET /api/robots, each robot's public discovery answer), and ESTOP
// for each and for all. Robots the node found by mDNS (dashboard.mdns) are listed with the
// state they announce and a link to their own page, never sent a stop from here. This node's own ESTOP goes straight to it (POST /api/stop, as the
// header's button); the others' through the node (POST /api/robots/estop), which sends each
// robot POST /api/stop with the operator's own token and says which ones confirmed. Every value
// is put into the page as text.
import { $, el, replace, setText, toast } from './dom.js';
import * as api from './api.js';
import { app, on } from './state.js';

const POLL_MS = 2000;
const SELF = 'self';
let robots = [];            // the last GET /api/robots: [{key, name, url, status, …}]
const outcomes = new Map(); // key → {result, detail, at} of the last ESTOP sent from this page
let timer = 0;
let loading = false;

const STATE_WORDS = {
  available: ['available', 'good'],
  claimed: ['claimed', 'good'],
  estop: ['ESTOP latched', 'bad'],
  unreachable: ['unreachable', 'warn'],
  unknown: ['not read yet', ''],
};
const RESULT_WORDS = {
  confirmed: ['confirmed', 'good'],
  refused: ['REFUSED', 'bad'],
  unreachable: ['NOT REACHED', 'bad'],
  timeout: ['NO ANSWER', 'bad'],
  sending: ['sending…', 'warn'],
};

function ago(ms) {
  if (!ms) return '';
  const s = Math.max(0, Math.round((api.serverNow() - ms) / 1000));
  return s < 2 ? 'just now' : `${s} s ago`;
}

function row(r) {
  const [word, cls] = STATE_WORDS[r.status] || [String(r.status || '?'), ''];
  const out = outcomes.get(r.key);
  const [oword, ocls] = out ? RESULT_WORDS[out.result] || [out.result, ''] : ['', ''];
  let action;
  if (r.discovered) {
    action = el('a', { href: r.url + '/', target: '_blank', rel: 'noopener noreferrer' }, 'its page');
  } else {
    action = el('button', { type: 'button', class: 'estop small', 'aria-label': `ESTOP ${r.name || r.url}` }, 'ESTOP');
    action.addEventListener('click', () => estop([r.key]));
  }
  const outcome = r.discovered
    ? el('td', { class: 'outcome muted small' }, 'found by mDNS: not stopped from here (not in dashboard.robots)')
    : el('td', { class: 'outcome ' + ocls, title: out && out.detail ? out.detail : '' }, oword,
      out && out.detail ? el('div', { class: 'muted small' }, out.detail) : '');
  return el('tr', { 'data-robot': r.key },
    el('td', {}, r.name || r.url || '–', r.key === SELF ? el('span', { class: 'muted small' }, ' (this node)') : ''),
    el('td', { class: 'mono small' }, r.key === SELF ? location.host : r.url),
    el('td', { class: 'state ' + cls, title: r.error || '' }, word,
      r.error ? el('div', { class: 'muted small' }, r.error) : ''),
    el('td', { class: 'small nowrap' }, r.key === SELF || r.discovered ? '' : ago(r.checked_ms)),
    outcome,
    el('td', {}, action));
}

function render() {
  replace($('#robots-table tbody'), robots.map(row));
}

async function load() {
  if (loading) return;
  loading = true;
  try {
    const res = await api.request('GET', '/api/robots');
    const self = res.self || {};
    const found = Array.isArray(res.discovered) ? res.discovered : [];
    robots = [{ key: SELF, name: self.name, status: app.estop ? 'estop' : self.status }]
      .concat((Array.isArray(res.robots) ? res.robots : []).map((r) => ({ ...r, key: r.url })))
      .concat(found.map((r) => ({ ...r, key: r.url, discovered: true })));
    const plural = (n, w) => `${n} ${w}${n === 1 ? '' : 's'}`;
    const mdns = res.mdns === 'on' ? ` ${plural(found.length, 'more robot')} found by mDNS.`
      : res.mdns && res.mdns !== 'off' ? ` mDNS: ${res.mdns}.` : '';
    setText($('#robots-note'), (res.configured
      ? `${plural(res.configured, 'other robot')} from this node's configuration (dashboard.robots), read every few seconds by the node.`
      : 'This node lists no other robot: add their addresses to dashboard.robots in its configuration (docs/DASHBOARD.md, Robots).') + mdns);
    render();
  } catch (e) {
    setText($('#robots-note'), `The robots could not be read: ${e.code} — ${e.message}`);
  } finally {
    loading = false;
  }
}

function summarise(keys, all) {
  const named = (k) => { const r = robots.find((x) => x.key === k); return (r && (r.name || r.url)) || k; };
  const done = keys.map((k) => [k, outcomes.get(k)]);
  const ok = done.filter(([, o]) => o && o.result === 'confirmed').length;
  const bad = done.filter(([, o]) => !o || o.result !== 'confirmed');
  const left = all ? robots.filter((r) => r.discovered) : [];
  const warn = bad.length > 0 || left.length > 0;
  let text = bad.length
    ? `${ok} of ${keys.length} confirmed the ESTOP. NOT confirmed: ${bad.map(([k, o]) => `${named(k)} (${o ? o.result : 'no answer'})`).join(', ')}.`
    : `All ${keys.length} confirmed the ESTOP.`;
  if (left.length) {
    text += ` Found by mDNS and NOT sent a stop: ${left.map((r) => r.name || r.url).join(', ')} (stop them from their own page).`;
  }
  const s = $('#robots-summary');
  setText(s, text);
  s.className = warn ? 'bad' : 'good';
  toast(text, warn ? 'bad' : 'info');
}

async function estopSelf() {
  try {
    await api.estop();
    outcomes.set(SELF, { result: 'confirmed', at: Date.now() });
  } catch (e) {
    outcomes.set(SELF, { result: e.status ? 'refused' : 'unreachable', detail: `${e.code} — ${e.message}`, at: Date.now() });
  }
}

async function estopOthers(urls) {
  try {
    const res = await api.request('POST', '/api/robots/estop', { robots: urls });
    for (const r of res.results || []) {
      const detail = r.result === 'confirmed' ? '' : [r.error_code, r.detail].filter(Boolean).join(' — ');
      outcomes.set(r.url, { result: r.result, detail, at: Date.now() });
    }
  } catch (e) {
    for (const u of urls) outcomes.set(u, { result: 'unreachable', detail: `this node did not relay it: ${e.code} — ${e.message}`, at: Date.now() });
  }
}

// ESTOP `keys` (SELF and robot URLs) at once; each row shows its own answer as it comes.
// `everyone`: the ESTOP all button (the summary then names the robots it could not stop).
async function estop(keys, everyone = false) {
  for (const k of keys) outcomes.set(k, { result: 'sending', at: Date.now() });
  render();
  const others = keys.filter((k) => k !== SELF);
  await Promise.all([
    keys.includes(SELF) ? estopSelf() : null,
    others.length ? estopOthers(others) : null,
  ]);
  render();
  summarise(keys, everyone);
  load();
}

function schedule(visible) {
  clearInterval(timer);
  timer = 0;
  if (visible) {
    load();
    timer = setInterval(load, POLL_MS);
  }
}

export function initRobots() {
  $('#robots-refresh').addEventListener('click', load);
  $('#robots-estop-all').addEventListener('click', () =>
    estop(robots.length ? robots.filter((r) => !r.discovered).map((r) => r.key) : [SELF], true));
  on('view', (name) => schedule(name === 'robots'));
  on('signed-out', () => { schedule(false); robots = []; outcomes.clear(); render(); setText($('#robots-summary'), ''); });
}
