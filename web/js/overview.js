// Overview: identity, mode, safety, who holds control and the queue, RESUME.
import { $, el, replace, setText, toast, fmtTime, fmtDuration } from './dom.js';
import { resume } from './api.js';
import { app, on, roleAtLeast } from './state.js';

function facts(dl, rows) {
  replace(dl, rows.filter(Boolean).map(([k, v, cls]) => [
    el('dt', {}, k),
    el('dd', { class: cls || '' }, v === undefined || v === null || v === '' ? '–' : String(v)),
  ]));
}

export function renderOverview() {
  const s = app.status || {};
  const d = s.discovery || {};
  facts($('#robot-facts'), [
    ['Name', s.name || d.name],
    ['RURI', s.ruri, 'mono'],
    ['RRN', s.rrn || d.rrn, 'mono'],
    ['Model', d.model],
    ['Manufacturer', d.manufacturer],
    ['RCAN', s.rcan_version],
    ['Extensions', Array.isArray(s.extensions) ? s.extensions.join(', ') : ''],
    ['Capabilities', Array.isArray(s.capabilities) ? s.capabilities.join(', ') : ''],
  ]);
  const r = s.robot || {};
  const estop = app.estop;
  facts($('#safety-facts'), [
    ['Mode', s.mode || 'NORMAL', s.mode && s.mode !== 'NORMAL' ? 'warn' : ''],
    ['ESTOP', estop ? 'LATCHED' : 'clear', estop ? 'bad' : 'good'],
    estop && r.estop && ['ESTOP by', r.estop.source],
    estop && r.estop && r.estop.reason && ['ESTOP reason', r.estop.reason],
    estop && r.estop && r.estop.since_ms && ['ESTOP since', fmtTime(r.estop.since_ms)],
    r.state && ['Robot state', r.state],
    r.safe_stop !== undefined && ['Safe stop', r.safe_stop ? 'yes — the next accepted command clears it' : 'no', r.safe_stop ? 'warn' : ''],
    ['Audit log', s.audit_available === false ? 'UNAVAILABLE' : 'recording', s.audit_available === false ? 'bad' : 'good'],
    app.telemetry && typeof app.telemetry.battery_pct === 'number' &&
      ['Battery', `${app.telemetry.battery_pct.toFixed(1)} %`],
  ]);
  const sessions = Array.isArray(s.sessions) ? s.sessions : [];
  const holder = sessions[0];
  facts($('#control-facts'), [
    ['Holder', holder ? `${holder.role || ''} ${holder.user_id || ''}`.trim() : 'nobody — any authorised principal may drive'],
    holder && ['Session', holder.session_id, 'mono'],
    holder && ['Expires in', holder.expires_in === null || holder.expires_in === undefined ? 'no expiry' : fmtDuration(holder.expires_in)],
    ['Active sessions', s.active_sessions],
  ]);
  const queue = Array.isArray(s.queue) ? s.queue : (Array.isArray(s.control_queue) ? s.control_queue : null);
  const q = $('#control-queue');
  if (!queue) replace(q, el('li', { class: 'muted note' }, 'This node does not report a queue.'));
  else if (!queue.length) replace(q, el('li', { class: 'muted note' }, 'Nobody is waiting for control.'));
  else {
    replace(q, queue.map((e) => el('li', {}, e && typeof e === 'object'
      ? [e.role, e.user_id || e.principal, typeof e.waiting_s === 'number' ? `(waiting ${fmtDuration(e.waiting_s)})` : ''].filter(Boolean).join(' ')
      : String(e))));
  }
  const c = app.claims || {};
  facts($('#me-facts'), [
    ['Role', app.role],
    ['Subject', c.sub],
    ['Issuer', c.iss],
    ['Scopes', Array.isArray(c.scope) ? c.scope.join(', ') : (c.scope || c.scopes || '')],
    ['Token expires', typeof c.exp === 'number' ? fmtTime(c.exp * 1000) : ''],
  ]);
  const btn = $('#resume');
  btn.disabled = !roleAtLeast('LEASEE');
  btn.title = btn.disabled ? `RESUME needs LEASEE or above (you are ${app.role || 'unknown'})` : 'Clear the ESTOP latch';
}

export function initOverview() {
  $('#resume').addEventListener('click', async () => {
    try {
      await resume();
      toast('RESUME accepted: ESTOP cleared', 'good');
    } catch (e) {
      toast(`RESUME refused: ${e.code} — ${e.message}`, 'bad');
    }
    app.bus.dispatchEvent(new Event('refresh'));
  });
  on('status', renderOverview);
}
