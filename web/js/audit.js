// Audit: a paged, filterable table over the node's audit endpoints, each record's detail, the
// chain's links checked in the browser, the watermark verify form, and the thought behind an AI
// command. Every record field is attacker-influenced text: it is only ever set as text.
import { $, el, replace, setText, toast, fmtTime } from './dom.js';
import { request, ApiError } from './api.js';
import { app, roleAtLeast } from './state.js';
import { verifyLinks } from './chain.js';

const PAGE = 50;
let records = [];        // newest first, after filtering
let all = [];            // as loaded, oldest first
let rawJsonl = '';       // the export text, when we have it (needed to check links)
let page = 0;
let chain = null;        // verifyLinks() result
let selectedSeq = null;

function str(v) { return v === undefined || v === null ? '' : (typeof v === 'object' ? JSON.stringify(v) : String(v)); }

function localMs(input) {
  const v = input.value;
  if (!v) return null;
  const t = new Date(v).getTime();
  return isFinite(t) ? t : null;
}

function canExport() {
  const c = app.claims || {};
  const scopes = [].concat(c.scope || [], c.scopes || [], c.rcan_scopes || []).flatMap((s) => String(s).split(/[ ,]/));
  return roleAtLeast('OWNER') && scopes.includes('config');
}

export async function loadAudit() {
  const from = localMs($('#f-from'));
  const to = localMs($('#f-to'));
  chain = null;
  setText($('#chain-result'), '');
  try {
    if (canExport()) {
      const q = new URLSearchParams({ format: 'jsonl' });
      if (from !== null) q.set('from', String(from));
      if (to !== null) q.set('to', String(to));
      rawJsonl = await request('GET', `/api/v1/audit?${q}`, undefined, { text: true });
      all = rawJsonl.split('\n').filter((l) => l.trim()).map((l) => { try { return JSON.parse(l); } catch (_) { return { event: '(unreadable line)' }; } });
      setText($('#audit-source'), `${all.length} records from the chain export (GET /api/v1/audit?format=jsonl).`);
    } else if (!roleAtLeast('OWNER')) {
      // The node refuses (403): the log names every principal and is the owner's to read.
      all = [];
      rawJsonl = '';
      setText($('#audit-source'), 'The audit log names every principal: reading it needs an OWNER token.');
    } else {
      const data = await request('GET', '/api/audit?limit=1000');
      all = (data && data.entries) || [];
      rawJsonl = '';
      const bad = (data && Array.isArray(data.unreadable)) ? data.unreadable : [];
      const warn = bad.length ? ` ${bad.length} record(s) failed their check on the node and are not shown (seq ${bad.slice(0, 10).join(', ')}${bad.length > 10 ? ', …' : ''}).` : '';
      setText($('#audit-source'), `The latest ${all.length} records (GET /api/audit). The full export and the chain check need OWNER with scope config.${warn}`);
    }
  } catch (e) {
    all = [];
    setText($('#audit-source'), `Cannot load the audit log: ${e.code} — ${e.message}`);
  }
  fillFilterChoices();
  applyFilter();
}

function fillFilterChoices() {
  const events = new Set(), outcomes = new Set();
  for (const r of all) { if (r.event) events.add(String(r.event)); if (r.outcome) outcomes.add(String(r.outcome)); }
  replace($('#events-seen'), Array.from(events).sort().map((e) => el('option', { value: e })));
  const sel = $('#f-outcome');
  const keep = sel.value;
  replace(sel, el('option', { value: '' }, 'any'), Array.from(outcomes).sort().map((o) => el('option', { value: o }, o)));
  sel.value = keep;
}

function applyFilter() {
  const ev = $('#f-event').value.trim().toLowerCase();
  const oc = $('#f-outcome').value;
  const pr = $('#f-principal').value.trim().toLowerCase();
  const st = $('#f-sender').value;
  const from = localMs($('#f-from'));
  const to = localMs($('#f-to'));
  records = all.filter((r) =>
    (!ev || str(r.event).toLowerCase().includes(ev)) &&
    (!oc || str(r.outcome) === oc) &&
    (!pr || str(r.principal).toLowerCase().includes(pr) || str(r.sub).toLowerCase().includes(pr)) &&
    (!st || str(r.sender_type || 'human') === st) &&
    (from === null || (r.timestamp_ms || 0) >= from) &&
    (to === null || (r.timestamp_ms || 0) <= to)).reverse();
  page = 0;
  renderTable();
}

function chainMark(seq) {
  if (!chain || typeof seq !== 'number') return ['', ''];
  if (chain.intactUpTo !== null && seq >= chain.firstSeq && seq <= chain.intactUpTo) return ['✓', 'good'];
  if (chain.breakAt !== null && seq >= chain.breakAt) return [seq === chain.breakAt ? '✗ break' : '✗', 'bad'];
  return ['', ''];
}

function renderTable() {
  const body = $('#audit-table tbody');
  const start = page * PAGE;
  const rows = records.slice(start, start + PAGE);
  replace(body, rows.map((r) => {
    const [mark, cls] = chainMark(r.seq);
    const tr = el('tr', { class: r.seq === selectedSeq ? 'selected' : '', tabindex: 0, dataset: { seq: str(r.seq) } },
      el('td', { class: 'num' }, str(r.seq)),
      el('td', { class: 'nowrap' }, fmtTime(r.timestamp_ms)),
      el('td', {}, str(r.event)),
      el('td', { class: /ok|success|accepted/i.test(str(r.outcome)) ? 'good' : (/block|fail|denied|refused|error/i.test(str(r.outcome)) ? 'bad' : '') }, str(r.outcome)),
      el('td', { class: 'trunc' }, str(r.principal)),
      el('td', {}, str(r.sender_type)),
      el('td', { class: 'trunc' }, str(r.action)),
      el('td', { class: 'trunc' }, str(r.reason)),
      el('td', { class: cls }, mark));
    tr.addEventListener('click', () => showRecord(r));
    tr.addEventListener('keydown', (e) => { if (e.key === 'Enter') showRecord(r); });
    return tr;
  }));
  if (!rows.length) replace(body, el('tr', {}, el('td', { colspan: 9, class: 'muted' }, 'No records match.')));
  const pages = Math.max(1, Math.ceil(records.length / PAGE));
  setText($('#page-info'), `page ${page + 1} of ${pages} · ${records.length} records`);
  $('#page-prev').disabled = page === 0;
  $('#page-next').disabled = page + 1 >= pages;
}

function showRecord(r) {
  selectedSeq = r.seq;
  for (const tr of document.querySelectorAll('#audit-table tbody tr')) tr.classList.toggle('selected', tr.dataset.seq === str(r.seq));
  setText($('#record-hint'), `Record seq ${str(r.seq)}`);
  setText($('#record-detail'), JSON.stringify(r, null, 2));
  const box = $('#thought');
  clear(box);
  const tid = r.ai && typeof r.ai === 'object' ? r.ai.thought_id : null;
  if (tid) {
    box.appendChild(el('button', { type: 'button', onclick: () => showThought(String(tid)) }, `Show the thought behind it (${String(tid)})`));
  }
  if (r.watermark_token) {
    $('#wm-token').value = String(r.watermark_token);
  }
}

function clear(n) { replace(n); }

async function showThought(id) {
  const box = $('#thought');
  try {
    const t = await request('GET', `/api/thoughts/${encodeURIComponent(id)}`);
    const rows = [['Model', t.model], ['Provider', t.provider], ['Layer', t.layer], ['Instruction', t.instruction],
      ['Action', t.action && JSON.stringify(t.action)], ['Confidence', t.confidence],
      ['Reasoning', 'reasoning' in t ? t.reasoning : '(shown only to callers with scope config)'],
      ['Escalated from', t.escalated_from]];
    replace(box, el('h3', {}, 'Thought'), el('dl', { class: 'facts' }, rows.map(([k, v]) => [el('dt', {}, k), el('dd', {}, str(v) || '–')])));
  } catch (e) {
    replace(box, el('p', { class: 'bad' }, `No thought: ${e.code} — ${e.message}`));
  }
}

async function verifyChain() {
  if (!canExport()) {
    setText($('#chain-result'), 'Checking the chain needs the export: sign in as OWNER with scope config, or run `rcan audit verify` on the robot.');
    return;
  }
  if (!rawJsonl) await loadAudit();
  chain = verifyLinks(rawJsonl);
  const res = $('#chain-result');
  if (!chain.checked && chain.breakAt === null) {
    setText(res, 'Nothing to check.');
  } else if (chain.breakAt === null) {
    setText(res, `Chain links intact: ${chain.checked} records, seq ${chain.firstSeq}–${chain.lastSeq} (prev_hash and seq checked in this browser). ` +
      'The HMACs need the chain secret, which stays on the robot: `rcan audit verify` checks them.');
    res.className = 'small good';
  } else {
    setText(res, `Chain broken at seq ${chain.breakAt}: ${chain.reason}. Intact before it: ` +
      (chain.intactUpTo === null ? 'nothing' : `seq ${chain.firstSeq}–${chain.intactUpTo}`) + '.');
    res.className = 'small bad';
  }
  renderTable();
}

async function verifyWatermark(e) {
  e.preventDefault();
  const token = $('#wm-token').value.trim();
  const rrn = $('#wm-rrn').value.trim();
  const q = new URLSearchParams({ token });
  if (rrn) q.set('rrn', rrn);
  const out = $('#wm-result');
  setText($('#wm-detail'), '');
  try {
    const r = await request('GET', `/api/v1/watermark/verify?${q}`, undefined, { auth: false });
    setText(out, r && r.valid ? `Valid: issued by ${str(r.rrn)} — the audit record is below.` : 'Not valid.');
    out.className = r && r.valid ? 'good' : 'bad';
    setText($('#wm-detail'), JSON.stringify(r && r.audit_entry, null, 2));
  } catch (err) {
    const msg = err instanceof ApiError && err.body && err.body.error ? err.body.error : err.message;
    setText(out, `Not verified (${err.status === 404 && !err.body ? 'this node has no watermark endpoint' : msg}).`);
    out.className = 'bad';
  }
}

export function initAudit() {
  $('#audit-filter').addEventListener('submit', (e) => { e.preventDefault(); loadAudit(); });
  for (const id of ['#f-event', '#f-principal']) $(id).addEventListener('input', applyFilter);
  for (const id of ['#f-outcome', '#f-sender']) $(id).addEventListener('change', applyFilter);
  $('#page-prev').addEventListener('click', () => { if (page > 0) { page--; renderTable(); } });
  $('#page-next').addEventListener('click', () => { if ((page + 1) * PAGE < records.length) { page++; renderTable(); } });
  $('#verify-chain').addEventListener('click', () => verifyChain().catch((e) => toast(String(e.message), 'bad')));
  $('#wm-form').addEventListener('submit', verifyWatermark);
}

export function setDefaultRrn(rrn) {
  const i = $('#wm-rrn');
  if (i && !i.value && rrn) i.value = String(rrn);
}
