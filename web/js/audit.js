// Audit: a table over the node's audit search (paged and filtered on the node, GET /api/audit),
// auto-refresh, the JSONL export, each record's detail, the
// chain's links checked in the browser, the watermark verify form, and the thought behind an AI
// command. Every record field is attacker-influenced text: it is only ever set as text.
import { $, el, replace, setText, toast, fmtTime } from './dom.js';
import { request, ApiError } from './api.js';
import { app, roleAtLeast } from './state.js';
import { verifyLinks } from './chain.js';

const PAGE = 100;
let records = [];        // the page shown, newest first (after the sender filter)
let pageEntries = [];    // the page as the node answered it, oldest first
let cursors = [];        // `before` cursors of the newer pages (for ◀ Newer)
let before = null;       // this page's cursor (null: the newest records)
let nextBefore = null;   // the node's cursor to the next, older page
let chain = null;        // verifyLinks() result
let selectedSeq = null;
let refreshTimer = null;
let typingTimer = null;

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

// The node pages and searches the log (GET /api/audit, docs/NODE.md): one page per request,
// never the whole chain.
function searchParams() {
  const q = new URLSearchParams({ limit: String(PAGE) });
  const text = (id) => $(id).value.trim();
  if (text('#f-event')) q.set('event', text('#f-event').toUpperCase());
  if ($('#f-outcome').value) q.set('outcome', $('#f-outcome').value);
  if (text('#f-principal')) q.set('principal', text('#f-principal'));
  if (text('#f-message')) q.set('message_id', text('#f-message'));
  if (text('#f-text')) q.set('q', text('#f-text'));
  const from = localMs($('#f-from'));
  const to = localMs($('#f-to'));
  if (from !== null) q.set('from', String(from));
  if (to !== null) q.set('to', String(to));
  return q;
}

export async function loadAudit(opts = {}) {
  if (!opts.keepCursor) { cursors = []; before = null; }
  if (!roleAtLeast('OWNER')) {
    // The node refuses (403): the log names every principal and is the owner's to read.
    pageEntries = [];
    nextBefore = null;
    setText($('#audit-source'), 'The audit log names every principal: reading it needs an OWNER token.');
    applyFilter();
    return;
  }
  const q = searchParams();
  if (before !== null) q.set('before', String(before));
  try {
    const data = await request('GET', `/api/audit?${q}`);
    pageEntries = (data && data.entries) || [];
    nextBefore = data && typeof data.next_before === 'number' ? data.next_before : null;
    const bad = (data && Array.isArray(data.unreadable)) ? data.unreadable : [];
    const warn = bad.length ? ` ${bad.length} record(s) failed their check on the node and are not shown (seq ${bad.slice(0, 10).join(', ')}${bad.length > 10 ? ', …' : ''}).` : '';
    const more = data && data.complete === false
      ? ` The node stopped after examining ${data.scanned} records: Older ▶ searches on.` : '';
    setText($('#audit-source'), `${pageEntries.length} record(s) on this page; the log holds seq ${str(data.first_seq)}–${str(data.last_seq)}.${more}${warn}`);
  } catch (e) {
    pageEntries = [];
    nextBefore = null;
    setText($('#audit-source'), `Cannot load the audit log: ${e.code} — ${e.message}`);
  }
  fillFilterChoices();
  applyFilter();
}

function fillFilterChoices() {
  const events = new Set(['COMMAND', 'COMMAND_REJECTED', 'ESTOP', 'RESUME', 'STOP', 'AUTH_FAILED', 'AUDIT_READ']);
  const outcomes = new Set(['ok', 'blocked', 'error', 'degraded']);
  for (const r of pageEntries) { if (r.event) events.add(String(r.event)); if (r.outcome) outcomes.add(String(r.outcome)); }
  replace($('#events-seen'), Array.from(events).sort().map((e) => el('option', { value: e })));
  const sel = $('#f-outcome');
  const keep = sel.value;
  replace(sel, el('option', { value: '' }, 'any'), Array.from(outcomes).sort().map((o) => el('option', { value: o }, o)));
  sel.value = keep;
}

// The sender filter applies to the page shown (the node filters everything else).
function applyFilter() {
  const st = $('#f-sender').value;
  records = pageEntries.filter((r) => !st || str(r.sender_type || 'human') === st).slice().reverse();
  renderTable();
}

function setAutoRefresh(on) {
  if (refreshTimer) { clearInterval(refreshTimer); refreshTimer = null; }
  if (!on) return;
  refreshTimer = setInterval(() => {
    // Only the newest page follows the log; an older page stays where the operator put it.
    if (before === null && !document.hidden && document.querySelector('#view-audit:not([hidden])')) loadAudit().catch(() => {});
  }, 5000);
}

async function exportJsonl() {
  if (!canExport()) {
    toast('The JSONL export needs OWNER with scope config.', 'bad');
    return;
  }
  const q = new URLSearchParams({ format: 'jsonl' });
  const from = localMs($('#f-from'));
  const to = localMs($('#f-to'));
  if (from !== null) q.set('from', String(from));
  if (to !== null) q.set('to', String(to));
  try {
    const text = await request('GET', `/api/v1/audit?${q}`, undefined, { text: true });
    const a = el('a', { href: URL.createObjectURL(new Blob([text], { type: 'application/x-ndjson' })),
      download: `audit-${from ?? 'start'}-${to ?? 'now'}.jsonl` });
    document.body.appendChild(a);
    a.click();
    a.remove();
    setTimeout(() => URL.revokeObjectURL(a.href), 10000);
  } catch (e) {
    toast(`Export failed: ${e.code} — ${e.message}`, 'bad');
  }
}

function chainMark(seq) {
  if (!chain || typeof seq !== 'number') return ['', ''];
  if (chain.intactUpTo !== null && seq >= chain.firstSeq && seq <= chain.intactUpTo) return ['✓', 'good'];
  if (chain.breakAt !== null && seq >= chain.breakAt) return [seq === chain.breakAt ? '✗ break' : '✗', 'bad'];
  return ['', ''];
}

function renderTable() {
  const body = $('#audit-table tbody');
  const rows = records;
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
  const seqs = records.map((r) => r.seq).filter((x) => typeof x === 'number');
  setText($('#page-info'), seqs.length ? `seq ${Math.min(...seqs)}–${Math.max(...seqs)} · page ${cursors.length + 1}` : `page ${cursors.length + 1}`);
  $('#page-prev').disabled = before === null;
  $('#page-next').disabled = nextBefore === null;
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
  const q = new URLSearchParams({ format: 'jsonl' });
  const from = localMs($('#f-from'));
  const to = localMs($('#f-to'));
  if (from !== null) q.set('from', String(from));
  if (to !== null) q.set('to', String(to));
  setText($('#chain-result'), 'Reading the chain…');
  chain = verifyLinks(await request('GET', `/api/v1/audit?${q}`, undefined, { text: true }));
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
  // Typing searches on the node once the operator pauses.
  for (const id of ['#f-event', '#f-principal', '#f-message', '#f-text']) {
    $(id).addEventListener('input', () => { clearTimeout(typingTimer); typingTimer = setTimeout(() => loadAudit(), 350); });
  }
  for (const id of ['#f-outcome', '#f-from', '#f-to']) $(id).addEventListener('change', () => loadAudit());
  $('#f-sender').addEventListener('change', applyFilter);
  $('#page-prev').addEventListener('click', () => {
    if (before === null) return;
    before = cursors.length ? cursors.pop() : null;
    loadAudit({ keepCursor: true });
  });
  $('#page-next').addEventListener('click', () => {
    if (nextBefore === null) return;
    cursors.push(before);
    before = nextBefore;
    loadAudit({ keepCursor: true });
  });
  $('#audit-refresh').addEventListener('change', (e) => setAutoRefresh(e.target.checked));
  $('#audit-export').addEventListener('click', () => exportJsonl());
  $('#verify-chain').addEventListener('click', () => verifyChain().catch((e) => toast(String(e.message), 'bad')));
  $('#wm-form').addEventListener('submit', verifyWatermark);
}

export function setDefaultRrn(rrn) {
  const i = $('#wm-rrn');
  if (i && !i.value && rrn) i.value = String(rrn);
}
