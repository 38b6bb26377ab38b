// The chat and node views, in a real browser (Debian's Chromium, headless, driven by
// playwright-core) against a real rcand started here: a chat round-trip shows what was sent
// and the robot's answer (Enter sends), a GUEST over its chat rate sees the node's refusal in
// words, hostile text stays text; the node view shows the versions, the metrics and, for the
// owner, the node's recent log lines (a line logged after a command appears), while a USER is
// told in words that the log is the owner's and the page does not ask for it. Exit 0 pass,
// 1 fail, 77 skip (no browser or playwright-core).
//
// Environment: RCAND_PATH, RCAN_CLI_PATH (set by CTest), CHROMIUM_PATH (default
// /usr/bin/chromium), DASHBOARD_ARTIFACTS (screenshots; default a temp dir).

import { execFileSync } from 'node:child_process';
import { mkdirSync, mkdtempSync, readFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { randomUUID } from 'node:crypto';
import { checker, http, launchBrowser, loadBrowser, runChecks, spawnRcand, tearDown } from './harness.mjs';

const rcandPath = process.env.RCAND_PATH;
const cliPath = process.env.RCAN_CLI_PATH;
const artifacts = process.env.DASHBOARD_ARTIFACTS || mkdtempSync(join(tmpdir(), 'chat-node-artifacts-'));

const { chromium, chromiumPath } = await loadBrowser({ rcandPath, cliPath, needCli: true });

mkdirSync(artifacts, { recursive: true });
const work = mkdtempSync(join(tmpdir(), 'chat-node-test-'));
const dataDir = join(work, 'data');
const failures = [];
const notes = [];
let rcand = null;
let browser = null;
const check = checker(failures);

function issueToken(ruri, sub, role, scopes) {
  return execFileSync(cliPath, ['token', 'issue', '--key', join(dataDir, 'issuer', 'ed25519.seed'), '--iss', 'rcand-local',
    '--sub', sub, '--role', role, '--aud', ruri, '--scope', scopes, '--ttl', '1h'], { encoding: 'utf8' }).trim();
}

function chat(text) {
  return { version: '1.0.0', message_id: randomUUID(), type: 'COMMAND', timestamp_ms: Date.now(), payload: { action: 'chat', text } };
}

async function signIn(browserRef, url, token, errors) {
  const context = await browserRef.newContext({ viewport: { width: 1280, height: 900 } });
  const page = await context.newPage();
  page.on('pageerror', (e) => errors.push(String(e)));
  page.on('console', (m) => { if (m.type() === 'error') errors.push(m.text()); });
  await page.goto(url + '/', { waitUntil: 'load' });
  await page.waitForSelector('#signin:not([hidden])');
  await page.fill('#token-input', token);
  await page.click('#signin-form button[type=submit]');
  await page.waitForSelector('body[data-stream=open]', { timeout: 10000 });
  return { context, page };
}

const items = (page) => page.$$eval('#chat-log > div', (ls) => ls.map((l) => [l.className, l.textContent]));

async function main() {
  let url;
  ({ proc: rcand, url } = await spawnRcand(rcandPath, dataDir));
  const owner = readFileSync(join(dataDir, 'owner.token'), 'utf8').trim();
  const ruri = (await http(url, 'GET', '/rcan/v1/status')).json.ruri;
  browser = await launchBrowser(chromium, chromiumPath);
  const errors = [];

  // 1. Chat as the owner: Enter sends, the question and the robot's answer are shown.
  const { page } = await signIn(browser, url, owner, errors);
  await page.click('#tabs button[data-view=chat]');
  check(/No messages yet/.test(await page.textContent('#chat-log')), 'an empty conversation says so');
  await page.fill('#chat-input', 'Where are you?');
  await page.press('#chat-input', 'Enter');
  await page.waitForSelector('#chat-log > .robot', { timeout: 5000 });
  let conv = await items(page);
  check(conv.length === 2 && conv[0][0] === 'me' && /Where are you\?/.test(conv[0][1]),
    `what was sent is shown (${JSON.stringify(conv[0])})`);
  const direct = await http(url, 'POST', '/rcan/v1/command', owner, chat('Where are you?'));
  const expected = direct.json.payload.result.reply;
  check(conv[1][0] === 'robot' && conv[1][1].endsWith(expected),
    `the robot's answer is shown as the node gives it ("${conv[1][1].slice(0, 120)}")`);
  check(await page.inputValue('#chat-input') === '', 'the field is emptied after sending');
  // Hostile text is text: it reaches the robot and comes back as characters, creating nothing.
  await page.fill('#chat-input', '<img src=x onerror="window.__pwned=1">');
  await page.press('#chat-input', 'Enter');
  await page.waitForFunction(() => document.querySelectorAll('#chat-log > .robot').length === 2, null, { timeout: 5000 });
  const pwned = await page.evaluate(() => [window.__pwned, document.querySelectorAll('#chat-log img').length]);
  check(pwned[0] === undefined && pwned[1] === 0, 'hostile chat text creates no element and runs nothing');
  await page.screenshot({ path: join(artifacts, 'dashboard-chat.png') });

  // 2. The node view as the owner: versions, metrics, and the recent log lines.
  await page.click('#tabs button[data-view=node]');
  await page.waitForSelector('#log-table tbody tr', { timeout: 5000 });
  const facts = await page.textContent('#node-facts');
  check(/RCAN protocol\s*\S+/.test(facts) && facts.includes(ruri), `the node view shows the protocol version and RURI (${facts.replace(/\s+/g, ' ').slice(0, 200)})`);
  check(/Software\s*rcand \d+\.\d+\.\d+/.test(facts), `the node view shows rcand's own version (${facts.replace(/\s+/g, ' ').slice(0, 200)})`);
  // The safety limits in force, as the node's detailed status gives them.
  const st = (await http(url, 'GET', '/rcan/v1/status', owner)).json;
  const lim = st.robot.limits;
  const shown = await page.textContent('#node-limits');
  check(shown.includes(`Max linear speed${Math.round(lim.max_linear_mps * 1000) / 1000} m/s`) &&
    shown.includes(`Max drive duration${lim.max_drive_duration_ms} ms`) &&
    shown.includes(st.robot.limit_policy === 'clamp' ? 'clamp to the limit' : 'refuse beyond a limit') &&
    /Workspace fence\s*(off|x )/.test(shown),
    `the node view shows the safety limits in force (${shown.replace(/\s+/g, ' ').slice(0, 240)})`);
  await page.waitForFunction(() => /Requests answered\s*\d+/.test(document.querySelector('#node-metrics').textContent), null, { timeout: 5000 });
  const mx = await page.textContent('#node-metrics');
  check(/Audit: last seq\s*\d+/.test(mx), `the node view shows key metrics (${mx.replace(/\s+/g, ' ').slice(0, 200)})`);
  let log = await page.textContent('#log-table tbody');
  check(log.includes('listening'), 'the owner sees the node\'s log lines (the start-up line)');
  check(!log.includes('stop.latency'), 'no stop was logged yet');
  // A SAFETY STOP is logged by the node; a refresh shows the new line first.
  const stop = await http(url, 'POST', '/rcan/v1/command', owner, {
    version: '1.0.0', message_id: randomUUID(), type: 'SAFETY', priority: 'SAFETY', timestamp_ms: Date.now(), payload: { safety_event: 'STOP', reason: 'chat_node test' } });
  check(stop.status === 200, `a SAFETY STOP is accepted (${stop.status})`);
  await page.click('#node-refresh');
  await page.waitForFunction(() => /stop\.latency/.test(document.querySelector('#log-table tbody tr').textContent), null, { timeout: 5000 });
  check(true, 'a line the node logged after a command appears at the top after a refresh');
  check(/recorded in the audit log/.test(await page.textContent('#log-note')), 'the page says the read is recorded');
  await page.screenshot({ path: join(artifacts, 'dashboard-node.png') });
  const reads = await http(url, 'GET', '/api/audit?event=LOG_READ&limit=50', owner);
  check(reads.status === 200 && reads.json.entries.length >= 2, `each log read is recorded as LOG_READ (${reads.json && reads.json.entries.length})`);

  // 3. A USER: no log, a plain-words explanation, and no request for it.
  const user = issueToken(ruri, 'panel-user', 'user', 'status,control,chat');
  const u = await signIn(browser, url, user, errors);
  const asked = [];
  u.page.on('request', (r) => { if (r.url().includes('/api/node/log')) asked.push(r.url()); });
  await u.page.click('#tabs button[data-view=node]');
  await u.page.waitForFunction(() => /only its owner/.test(document.querySelector('#log-note').textContent), null, { timeout: 5000 });
  const userNote = await u.page.textContent('#log-note');
  check(/you are USER/.test(userNote) && (await u.page.$$('#log-table tbody tr')).length === 0 && asked.length === 0,
    `a USER gets no log lines, is told why, and the page does not ask (${userNote})`);
  check(/RCAN protocol/.test(await u.page.textContent('#node-facts')), 'a USER still sees the node facts');
  await u.page.screenshot({ path: join(artifacts, 'dashboard-node-user.png') });
  await u.context.close();

  // 4. A GUEST over its chat rate sees the node's refusal, with its code in words.
  const guest = issueToken(ruri, 'chatty-guest', 'guest', 'status,chat');
  let ok = 0;
  for (let i = 0; i < 12 && ok < 10; i++) if ((await http(url, 'POST', '/rcan/v1/command', guest, chat(`hello ${i}`))).status === 200) ok++;
  check(ok === 10, `the guest's first 10 chats of the minute are answered (${ok})`);
  const g = await signIn(browser, url, guest, errors);
  await g.page.click('#tabs button[data-view=chat]');
  await g.page.fill('#chat-input', 'Are you there?');
  await g.page.press('#chat-input', 'Enter');
  await g.page.waitForSelector('#chat-log > .refused', { timeout: 5000 });
  conv = await items(g.page);
  const refusal = conv[conv.length - 1][1];
  check(/RATE_LIMITED/.test(refusal) && /too many messages/.test(refusal) && /guest chat rate/.test(refusal),
    `a GUEST over its chat rate sees the refusal in words with its code ("${refusal}")`);
  check(await g.page.evaluate(() => document.body.dataset.signedIn === 'yes' && !document.querySelector('#chat-send').disabled),
    'the page stays signed in and the chat stays usable after a refusal');
  await g.page.screenshot({ path: join(artifacts, 'dashboard-chat-guest-limited.png') });
  await g.context.close();

  const unexpected = errors.filter((e) => !/status of 4\d\d/.test(e));
  check(unexpected.length === 0, `no page errors or unexpected console errors (${unexpected.join(' | ') || 'none'})`);
}

await runChecks('chat and node view', main, {
  failures,
  artifacts,
  notes,
  cleanup: () => tearDown(browser, [rcand], work),
});
