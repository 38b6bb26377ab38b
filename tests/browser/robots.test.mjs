// The Robots view, in a real browser (Debian's Chromium, headless, driven by playwright-core)
// against three real rcand nodes started here. Node A lists B, C and an address where nothing
// listens (dashboard.robots). All three trust one issuer; the operator's token (a USER) names
// acme rovers (A and B) in its audience, not C, an arm of another maker. The view shows each
// robot's state; ESTOP on one row stops that robot alone; ESTOP all stops A and B, and says in
// words that C refused (its own error code) and the dead address was not reached — the robots'
// own status confirms each. Exit 0 pass, 1 fail, 77 skip (no browser or playwright-core).
//
// Environment: RCAND_PATH, RCAN_CLI_PATH (set by CTest), CHROMIUM_PATH (default
// /usr/bin/chromium), DASHBOARD_ARTIFACTS (screenshots; default a temp dir).

import { mkdirSync, mkdtempSync } from 'node:fs';
import { createServer } from 'node:net';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { checker, http, issueToken, launchBrowser, loadBrowser, makeIssuer, runChecks, startConfiguredRcand, tearDown } from './harness.mjs';

const rcandPath = process.env.RCAND_PATH;
const cliPath = process.env.RCAN_CLI_PATH;
const artifacts = process.env.DASHBOARD_ARTIFACTS || mkdtempSync(join(tmpdir(), 'robots-artifacts-'));

const { chromium, chromiumPath } = await loadBrowser({ rcandPath, cliPath, needCli: true });

mkdirSync(artifacts, { recursive: true });
const work = mkdtempSync(join(tmpdir(), 'robots-test-'));
const failures = [];
const procs = [];
let browser = null;
const check = checker(failures);
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

// A loopback port nothing listens on (bound, then closed).
function deadPort() {
  return new Promise((resolve) => {
    const s = createServer();
    s.listen(0, '127.0.0.1', () => { const { port } = s.address(); s.close(() => resolve(port)); });
  });
}

async function node(name, ruri, issuer, extra = []) {
  const dir = join(work, name);
  mkdirSync(dir, { recursive: true });
  const n = await startConfiguredRcand({ rcandPath, cliPath, dir, ruri, name, issuer, extra });
  procs.push(n.proc);
  return { ...n, ruri };
}

const rows = (page) => page.$$eval('#robots-table tbody tr', (trs) => trs.map((tr) => {
  const td = [...tr.querySelectorAll('td')].map((c) => c.textContent.trim());
  return { key: tr.dataset.robot, name: td[0], address: td[1], state: td[2], outcome: td[4] };
}));

async function waitRows(page, pred, what, ms = 10000) {
  for (const end = Date.now() + ms; Date.now() < end; await sleep(100)) {
    const r = await rows(page);
    if (pred(r)) return r;
  }
  const r = await rows(page);
  check(false, `${what} (rows: ${JSON.stringify(r)})`);
  return r;
}

async function main() {
  const issuer = makeIssuer(work);
  const b = await node('rover-b', 'rcan://local.rcan/acme/rover/0000000b', issuer);
  const c = await node('arm-c', 'rcan://local.rcan/other/arm/0000000c', issuer);
  const dead = `http://127.0.0.1:${await deadPort()}`;
  const a = await node('rover-a', 'rcan://local.rcan/acme/rover/0000000a', issuer,
    ['dashboard:', `  robots: [${b.url}, ${c.url}, ${dead}]`, '  poll_ms: 500', '  stop_timeout_ms: 2000']);
  const operator = issueToken(cliPath, issuer, { sub: 'operator-1', role: 'user', aud: 'rcan://local.rcan/acme/rover/*' });
  const ownerOf = (n) => issueToken(cliPath, issuer, { sub: 'owner-1', role: 'owner', aud: n.ruri });
  const latched = async (n) => (await http(n.url, 'GET', '/api/status', ownerOf(n))).json.estop_active === true;
  const resume = async (n) => {
    const r = await http(n.url, 'POST', '/rcan/v1/command', ownerOf(n), { version: '1.0.0', message_id: crypto.randomUUID(),
      type: 'SAFETY', timestamp_ms: Date.now(), payload: { safety_event: 'RESUME' } });
    check(r.status === 200, `RESUME on ${n.ruri} (${r.status} ${r.text.slice(0, 200)})`);
  };

  browser = await launchBrowser(chromium, chromiumPath);
  const errors = [];
  const context = await browser.newContext({ viewport: { width: 1280, height: 900 } });
  const page = await context.newPage();
  page.on('pageerror', (e) => errors.push(String(e)));
  page.on('console', (m) => { if (m.type() === 'error' && !/Failed to load resource/.test(m.text())) errors.push(m.text()); });
  await page.goto(a.url + '/', { waitUntil: 'load' });
  await page.waitForSelector('#signin:not([hidden])');
  await page.fill('#token-input', operator);
  await page.click('#signin-form button[type=submit]');
  await page.waitForSelector('body[data-stream=open]', { timeout: 10000 });
  await page.click('#tabs button[data-view=robots]');

  // 1. The list: this node first, then the configured robots with the state each announces.
  let r = await waitRows(page, (rs) => rs.length === 4 && rs[1].state === 'available' && rs[2].state === 'available' && /unreachable/.test(rs[3].state),
    'the view lists this node, B and C available and the dead address unreachable');
  check(r[0].key === 'self' && /rover-a/.test(r[0].name) && /this node/.test(r[0].name), `this node comes first (${JSON.stringify(r[0])})`);
  check(r[1].name === 'rover-b' && r[1].address === b.url && r[2].name === 'arm-c' && r[3].address === dead,
    `each robot by its name and address (${JSON.stringify(r.slice(1))})`);
  check(/connect/.test(r[3].state), `the unreachable address says why (${r[3].state})`);
  check(/this node's configuration/.test(await page.textContent('#robots-note')), 'the note says where the list comes from');

  // 2. ESTOP on B's row stops B alone.
  await page.click(`#robots-table tr[data-robot="${b.url}"] button`);
  r = await waitRows(page, (rs) => rs[1].outcome === 'confirmed', 'B\'s row says its ESTOP was confirmed');
  check(await latched(b), 'B is latched (its own status)');
  check(!(await latched(a)) && !(await latched(c)), 'A and C are not');
  await waitRows(page, (rs) => rs[1].state === 'ESTOP latched', 'B\'s state becomes "ESTOP latched" at the next read');
  await resume(b);

  // 3. ESTOP all: A (directly) and B confirm; C refuses the token (its audience is acme rovers);
  // the dead address is not reached. The summary names the two that did not confirm.
  await page.click('#robots-estop-all');
  r = await waitRows(page, (rs) => rs.every((x) => x.outcome && x.outcome !== 'sending…'), 'every row has its ESTOP outcome');
  check(r[0].outcome === 'confirmed' && r[1].outcome === 'confirmed', `A and B confirmed (${r[0].outcome}, ${r[1].outcome})`);
  check(/^REFUSED/.test(r[2].outcome) && /AUTH_INVALID/.test(r[2].outcome), `C refused, with its code (${r[2].outcome})`);
  check(/^NOT REACHED/.test(r[3].outcome), `the dead address was not reached (${r[3].outcome})`);
  const summary = await page.textContent('#robots-summary');
  check(/2 of 4 confirmed/.test(summary) && /arm-c \(refused\)/.test(summary) && /unreachable/.test(summary),
    `the summary says who did not confirm ("${summary}")`);
  check(await latched(a) && await latched(b), 'A and B are latched (their own status)');
  check(!(await latched(c)), 'C is not: it refused the token');
  await page.waitForSelector('#safety-banner:not([hidden])', { timeout: 5000 });
  await page.screenshot({ path: join(artifacts, 'robots-estop-all.png'), fullPage: true });

  // 4. Hostile-looking failures stay text; nothing went wrong in the page.
  check(errors.length === 0, `no console or page errors (${errors.join(' | ')})`);
  await context.close();
}

await runChecks('robots view', main, { failures, cleanup: () => tearDown(browser, procs, work), artifacts });
