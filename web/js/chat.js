// Chat: the robot's `chat` capability (docs/NODE.md, "chat"). Each message is a seed-shape
// COMMAND `chat` with `text`, sent like every other command (api.sendCommand), so the node
// authenticates, rate-limits (a GUEST's chat_rate) and audits it; the answer is the ACK's
// `payload.result.reply`, a refusal is shown with its code in plain words. The conversation
// lives in this page only, and everything in it is text.
import { $, el, setText } from './dom.js';
import { sendCommand } from './api.js';
import { app, on } from './state.js';

const MAX_ITEMS = 200;   // the oldest go first
const MAX_TEXT = 500;

// What a refusal means, in words; the node's own message follows it.
const WORDS = {
  RATE_LIMITED: 'too many messages: the node allows only so many a minute (for a GUEST, the guest chat rate); wait a little and send again',
  INSUFFICIENT_PRIVILEGES: 'your token may not chat with this robot (it needs the scope chat)',
  AUTH_REQUIRED: 'you are not signed in',
  AUTH_INVALID: 'the node no longer accepts your token: sign in again',
  SESSION_EXPIRED: 'your session has expired: sign in again',
  MESSAGE_STALE: 'the message arrived too late (check the clocks or the connection)',
  COMMAND_REJECTED: 'the robot refused the message',
  AUDIT_UNAVAILABLE: 'the audit log cannot record now, so the robot takes no messages',
  TIMEOUT: 'the robot did not answer in time',
  NETWORK: 'the robot cannot be reached',
};

export function refusalWords(e) {
  const why = WORDS[e.code] || 'the node refused it';
  const detail = e.message && e.message !== e.code ? ` (${e.message})` : '';
  return `Not sent: ${why} — ${e.code}${e.reason ? ' / ' + e.reason : ''}${detail}.`;
}

function add(kind, who, text) {
  const list = $('#chat-log');
  const note = list.querySelector('.note');
  if (note) note.remove();
  const item = el('div', { class: kind },
    el('span', { class: 'who' }, `${who} · ${new Date().toLocaleTimeString()}`), text);
  list.appendChild(item);
  while (list.children.length > MAX_ITEMS) list.removeChild(list.firstChild);
  list.scrollTop = list.scrollHeight;
  return item;
}

function robotName() {
  return (app.status && app.status.name) || 'Robot';
}

async function send(text) {
  add('me', 'You', text);
  const btn = $('#chat-send');
  btn.disabled = true;
  try {
    const res = await sendCommand('chat', { text });
    const result = (res && res.payload && res.payload.result) || {};
    const reply = typeof result.reply === 'string' ? result.reply : JSON.stringify(result);
    add('robot', robotName(), reply);
  } catch (e) {
    add('refused', `Refused by ${robotName()}`, refusalWords(e));
  } finally {
    btn.disabled = false;
  }
}

function reset() {
  const list = $('#chat-log');
  while (list.firstChild) list.removeChild(list.firstChild);
  list.appendChild(el('p', { class: 'note' }, 'No messages yet. Type one below and press Enter.'));
}

export function initChat() {
  reset();
  $('#chat-form').addEventListener('submit', (e) => {
    e.preventDefault();
    const input = $('#chat-input');
    const text = input.value.trim().slice(0, MAX_TEXT);
    if (!text) return;
    input.value = '';
    send(text);
  });
  on('signed-out', reset);
  on('status', () => setText($('#chat-input').labels[0], `Message to ${robotName()}`));
}
