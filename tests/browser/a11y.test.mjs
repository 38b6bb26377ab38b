// Accessibility of the operator dashboard (WCAG 2.1 AA), checked by axe-core (pinned in
// package-lock.json) in Debian's headless Chromium against a real rcand: every view — sign-in,
// overview, live, teleop, approvals, audit, chat (with a conversation), node, and the ESTOP
// banner — at a desktop (1280×800) and
// a phone (390×844) width. Any violation axe rates serious or critical fails the test; the
// others are printed. At the phone's width it also checks the layout: no text squeezed to about
// one character per line, the Live readouts at least four characters wide, every tab in view,
// the audit table's outcome column in view. Exit 0 pass, 1 fail, 77 skip (no browser,
// playwright-core or axe-core).
//
// Environment: RCAND_PATH (set by CTest), CHROMIUM_PATH (default /usr/bin/chromium),
// DASHBOARD_ARTIFACTS (screenshots; default a temp dir).

import { existsSync, mkdirSync, mkdtempSync, readFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join, dirname } from 'node:path';
import { fileURLToPath } from 'node:url';
import { checker, http, launchBrowser, loadBrowser, runChecks, skip, spawnRcand, tearDown } from './harness.mjs';

const here = dirname(fileURLToPath(import.meta.url));
const rcandPath = process.env.RCAND_PATH;
const artifacts = process.env.DASHBOARD_ARTIFACTS || mkdtempSync(join(tmpdir(), 'a11y-artifacts-'));
const axePath = join(here, 'node_modules', 'axe-core', 'axe.min.js');

const { chromium, chromiumPath } = await loadBrowser({ rcandPath });
if (!existsSync(axePath)) skip('axe-core is not installed (scripts/install-deps.sh runs npm ci in tests/browser)');

mkdirSync(artifacts, { recursive: true });
const work = mkdtempSync(join(tmpdir(), 'a11y-test-'));
const dataDir = join(work, 'data');
const failures = [];
const notes = [];
const check = checker(failures);
let rcand = null;
let browser = null;

// WCAG 2.0/2.1 A and AA rules (axe's tags), run on the whole document as it is shown.
async function audit(page, what) {
  await page.addScriptTag({ path: axePath });
  const res = await page.evaluate(() => window.axe.run(document, {
    runOnly: { type: 'tag', values: ['wcag2a', 'wcag2aa', 'wcag21a', 'wcag21aa'] },
    resultTypes: ['violations'],
  }));
  const bad = res.violations.filter((v) => v.impact === 'serious' || v.impact === 'critical');
  for (const v of res.violations) {
    const where = v.nodes.slice(0, 3).map((n) => n.target.join(' ')).join(', ');
    const line = `${what}: ${v.impact} ${v.id} (${v.nodes.length}×: ${where}) — ${v.help}`;
    if (bad.includes(v)) console.log(`  ${line}`);
    else notes.push(line);
  }
  check(bad.length === 0, `${what}: no serious or critical axe violation (${bad.map((v) => v.id).join(', ') || 'none'})`);
}

// At a phone's width, what an operator must be able to read: text of three characters or more
// is never squeezed to under three characters a line (a readout wrapping "0.", "00", "m"), the
// page does not scroll sideways, and per view the readouts, the tabs and the audit's outcome.
async function phoneLayout(page, view) {
  const r = await page.evaluate((view) => {
    const vw = innerWidth;
    const inView = (e) => { const b = e.getBoundingClientRect(); return b.width > 0 && b.left >= -0.5 && b.right <= vw + 0.5; };
    const squeezed = [];
    for (const root of [document.querySelector('header'), document.querySelector('#tabs'), document.querySelector(`#view-${view}`)]) {
      const walk = document.createTreeWalker(root, NodeFilter.SHOW_TEXT);
      for (let n = walk.nextNode(); n; n = walk.nextNode()) {
        const chars = n.textContent.replace(/\s+/g, '').length;
        if (chars < 3) continue;
        const range = document.createRange();
        range.selectNodeContents(n);
        const lines = new Set([...range.getClientRects()].filter((q) => q.width > 0).map((q) => Math.round(q.top))).size;
        if (lines >= 2 && chars / lines < 3) squeezed.push(`${n.parentElement.tagName.toLowerCase()}${n.parentElement.id ? '#' + n.parentElement.id : ''} "${n.textContent.trim().slice(0, 16)}" on ${lines} lines`);
      }
    }
    // A readout narrower than four characters of its own font.
    const ctx = document.createElement('canvas').getContext('2d');
    const narrow = [...document.querySelectorAll(`#view-${view} #live-facts dd, #view-${view} #teleop-facts dd`)].filter((e) => {
      const b = e.getBoundingClientRect();
      if (!b.width) return false;
      ctx.font = getComputedStyle(e).font;
      return b.width < ctx.measureText('0000').width - 0.5;
    }).map((e) => `${e.tagName.toLowerCase()} "${e.textContent}"`);
    const tabs = [...document.querySelectorAll('#tabs button')];
    const bar = document.querySelector('#tabs');
    const outcome = [...document.querySelectorAll('#audit-table th:nth-child(4), #audit-table tbody td:nth-child(4)')];
    const wrap = document.querySelector('#audit-table').closest('.table-wrap');
    return {
      squeezed, narrow,
      readouts: document.querySelectorAll(`#view-${view} #live-facts dd`).length,
      pageWidth: document.documentElement.scrollWidth, vw,
      tabsOut: tabs.filter((b) => !inView(b)).map((b) => b.textContent.trim()),
      tabsScroll: bar.scrollWidth > bar.clientWidth + 1,
      outcome: outcome.length,
      outcomeOut: outcome.filter((c) => !inView(c) || c.getBoundingClientRect().right > wrap.getBoundingClientRect().right + 0.5).length,
      auditScroll: wrap.scrollWidth > wrap.clientWidth + 1,
    };
  }, view);
  check(r.squeezed.length === 0, `phone ${view}: no text wraps to about one character per line (${r.squeezed.slice(0, 4).join('; ') || 'none'})`);
  check(r.pageWidth <= r.vw, `phone ${view}: the page does not scroll sideways (${r.pageWidth} px in ${r.vw})`);
  if (view === 'live') {
    check(r.readouts >= 8 && r.narrow.length === 0, `phone live: ${r.readouts} readouts, none narrower than four characters (${r.narrow.slice(0, 4).join('; ') || 'none'})`);
  }
  if (view === 'overview') {
    check(r.tabsOut.length === 0 && !r.tabsScroll, `phone: every tab is within the viewport, none scrolled out of the tab bar (${r.tabsOut.join(', ') || 'all in view'})`);
  }
  if (view === 'audit') {
    check(r.outcome >= 2 && r.outcomeOut === 0 && !r.auditScroll,
      `phone audit: the outcome column's ${r.outcome} cells are inside the viewport, the table does not scroll sideways (${r.outcomeOut} outside)`);
  }
}

async function main() {
  let url;
  ({ proc: rcand, url } = await spawnRcand(rcandPath, dataDir));
  const owner = readFileSync(join(dataDir, 'owner.token'), 'utf8').trim();
  browser = await launchBrowser(chromium, chromiumPath);
  for (const [label, viewport] of [['desktop', { width: 1280, height: 800 }], ['phone', { width: 390, height: 844 }]]) {
    // The page's CSP allows only its own scripts; the test context lets axe in.
    const context = await browser.newContext({ viewport, bypassCSP: true });
    const page = await context.newPage();
    await page.goto(url + '/', { waitUntil: 'load' });
    await page.waitForSelector('#signin:not([hidden])');
    await audit(page, `${label} sign-in`);
    await page.fill('#token-input', owner);
    await page.click('#signin-form button[type=submit]');
    await page.waitForSelector('body[data-stream=open]', { timeout: 10000 });
    for (const view of ['overview', 'live', 'teleop', 'approvals', 'audit', 'chat', 'node', 'robots']) {
      await page.click(`#tabs button[data-view=${view}]`);
      if (view === 'chat') {
        await page.fill('#chat-input', 'Where are you?');
        await page.press('#chat-input', 'Enter');
        await page.waitForSelector('#chat-log > .robot', { timeout: 5000 });
      }
      if (view === 'node') await page.waitForSelector('#log-table tbody tr', { timeout: 5000 });
      if (view === 'robots') await page.waitForSelector('#robots-table tbody tr', { timeout: 5000 });
      await page.waitForTimeout(view === 'audit' ? 1500 : 600);
      await audit(page, `${label} ${view}`);
      if (label === 'phone') await phoneLayout(page, view);
      await page.screenshot({ path: join(artifacts, `a11y-${label}-${view}.png`), fullPage: true });
    }
    // Semantics axe cannot judge by itself: the tabs as a tab list (roles, the selected tab,
    // arrow keys), the safety state as a live region, the charts named.
    const sem = await page.evaluate(() => ({
      tablist: document.querySelector('#tabs').getAttribute('role'),
      tabs: [...document.querySelectorAll('#tabs button')].map((b) => [b.getAttribute('role'), b.getAttribute('aria-selected')]),
      panel: document.querySelector('#view-audit').getAttribute('role'),
      pill: document.querySelector('#safety-pill').getAttribute('aria-live'),
      chatLog: [document.querySelector('#chat-log').getAttribute('role'), document.querySelector('#chat-log').getAttribute('aria-live')],
      chatLabel: document.querySelector('#chat-input').labels.length,
      charts: [...document.querySelectorAll('canvas')].map((c) => [c.getAttribute('role'), c.getAttribute('aria-label') || '']),
    }));
    check(sem.tablist === 'tablist' && sem.tabs.every(([r]) => r === 'tab') && sem.panel === 'tabpanel',
      `${label}: the tabs are a tablist of tabs controlling tabpanels`);
    check(sem.tabs.filter(([, sel]) => sel === 'true').length === 1 && sem.tabs[sem.tabs.length - 1][1] === 'true',
      `${label}: exactly the shown view's tab is aria-selected (${JSON.stringify(sem.tabs.map(([, x]) => x))})`);
    check(sem.pill === 'polite', `${label}: the safety state is a live region`);
    check(sem.chatLog[0] === 'log' && sem.chatLog[1] === 'polite' && sem.chatLabel === 1,
      `${label}: the conversation is a polite live log and the message field has its label (${JSON.stringify(sem.chatLog)})`);
    check(sem.charts.length >= 3 && sem.charts.every(([r, l]) => r === 'img' && l.length > 10),
      `${label}: every chart is an image with a name`);
    await page.focus('#tabs button[data-view=robots]');
    await page.keyboard.press('ArrowRight');
    check(await page.evaluate(() => document.body.dataset.view === 'overview' && document.activeElement.dataset.view === 'overview'),
      `${label}: ArrowRight on the last tab wraps to the first and shows its view`);
    await page.keyboard.press('ArrowRight');
    check(await page.evaluate(() => document.body.dataset.view === 'live'), `${label}: ArrowRight shows the next view`);

    // The ESTOP banner and its RESUME, as an operator meets them.
    const e = await http(url, 'POST', '/api/stop', owner, { reason: 'a11y test' });
    check(e.status === 200, `${label}: ESTOP latched (${e.status})`);
    await page.waitForSelector('#safety-banner:not([hidden])', { timeout: 5000 });
    await audit(page, `${label} ESTOP banner`);
    await page.click('#banner-resume');
    await page.waitForSelector('#safety-banner', { state: 'hidden', timeout: 5000 });
    await context.close();
  }
}

await runChecks('accessibility', main, {
  failures,
  artifacts,
  notes,
  cleanup: () => tearDown(browser, [rcand], work),
});
