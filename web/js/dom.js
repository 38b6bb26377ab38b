// DOM helpers. Everything that comes from the robot is put into the page as text
// (textContent / createTextNode); this module has no path that parses HTML.

export function $(sel, root = document) {
  return root.querySelector(sel);
}

export function $all(sel, root = document) {
  return Array.from(root.querySelectorAll(sel));
}

// el('div', {class: 'x', dataset: {id: 1}, onclick: fn}, 'text', childNode, …)
export function el(tag, attrs = {}, ...children) {
  const node = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) {
    if (v === undefined || v === null || v === false) continue;
    if (k === 'class') node.className = v;
    else if (k === 'dataset') Object.assign(node.dataset, v);
    else if (k.startsWith('on') && typeof v === 'function') node.addEventListener(k.slice(2), v);
    else if (k === 'text') node.textContent = String(v);
    else if (v === true) node.setAttribute(k, '');
    else node.setAttribute(k, String(v));
  }
  append(node, children);
  return node;
}

function append(node, children) {
  for (const c of children) {
    if (c === undefined || c === null || c === false) continue;
    if (Array.isArray(c)) append(node, c);
    else if (c instanceof Node) node.appendChild(c);
    else node.appendChild(document.createTextNode(String(c)));
  }
}

export function setText(node, value) {
  if (node) node.textContent = value === undefined || value === null ? '' : String(value);
}

export function clear(node) {
  while (node && node.firstChild) node.removeChild(node.firstChild);
}

export function replace(node, ...children) {
  clear(node);
  append(node, children);
}

// A short-lived message at the bottom of the page. A refusal or warning is not replaced by a
// lesser message (an event, a success) within its first 3 s: that one waits its turn.
let toastTimer = 0;
let laterTimer = 0;
let shown = { rank: 0, at: 0 };
const TOAST_RANK = { bad: 2, warn: 1 };
const TOAST_KEEP_MS = 3000;
export function toast(text, kind = 'info') {
  const t = $('#toast');
  if (!t) return;
  const rank = TOAST_RANK[kind] || 0;
  const keep = shown.at + TOAST_KEEP_MS - Date.now();
  clearTimeout(laterTimer);
  if (!t.hidden && rank < shown.rank && keep > 0) {
    laterTimer = setTimeout(() => toast(text, kind), keep);
    return;
  }
  shown = { rank, at: Date.now() };
  t.textContent = String(text);
  t.className = 'toast ' + kind;
  t.hidden = false;
  clearTimeout(toastTimer);
  toastTimer = setTimeout(() => { t.hidden = true; }, 5000);
}

export function fmtTime(ms) {
  if (typeof ms !== 'number' || !isFinite(ms)) return '';
  const d = new Date(ms);
  const pad = (n, w = 2) => String(n).padStart(w, '0');
  return `${d.getFullYear()}-${pad(d.getMonth() + 1)}-${pad(d.getDate())} ` +
    `${pad(d.getHours())}:${pad(d.getMinutes())}:${pad(d.getSeconds())}.${pad(d.getMilliseconds(), 3)}`;
}

// Seconds in words: "7 h 58 min", "12 min 5 s", "45 s".
export function fmtDuration(seconds) {
  if (typeof seconds !== 'number' || !isFinite(seconds)) return '';
  const s = Math.max(0, Math.round(seconds));
  const h = Math.floor(s / 3600);
  const m = Math.floor((s % 3600) / 60);
  if (h) return `${h} h ${m} min`;
  if (m) return `${m} min ${s % 60} s`;
  return `${s} s`;
}

export function fmtNum(v, digits = 2) {
  return typeof v === 'number' && isFinite(v) ? v.toFixed(digits) : '–';
}
