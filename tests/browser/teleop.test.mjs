// Teleop that cannot run away, in a real browser (Debian's Chromium, headless, driven by
// playwright-core) against a real rcand started here. The page reaches the node through a small
// TCP proxy that this test can freeze (it stops forwarding without closing anything), as a
// stalled Wi-Fi link would; the robot's pose is read from the node directly, never through the
// page. Each scenario starts a hold, ends it in one of the ways an operator's hold really ends —
// pointer cancelled, window blurred, Tab away while Space is held, tab hidden, network frozen,
// ESTOP then RESUME by someone else — and checks that the robot's pose does not change after
// the hold ended. Exit 0 pass, 1 fail, 77 skip (no browser or playwright-core).
//
// Environment: RCAND_PATH, RCAN_CLI_PATH (set by CTest), CHROMIUM_PATH (default
// /usr/bin/chromium), DASHBOARD_ARTIFACTS (screenshots; default a temp dir).

import { existsSync, mkdirSync, mkdtempSync, readFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { randomUUID } from 'node:crypto';
import { execFileSync } from 'node:child_process';
import { createServer, connect } from 'node:net';
import { checker, http, launchBrowser, loadBrowser, poseProbe, runChecks, spawnRcand, tearDown } from './harness.mjs';

const rcandPath = process.env.RCAND_PATH;
const cliPath = process.env.RCAN_CLI_PATH;
const artifacts = process.env.DASHBOARD_ARTIFACTS || mkdtempSync(join(tmpdir(), 'teleop-artifacts-'));

const { chromium, chromiumPath } = await loadBrowser({ rcandPath, cliPath, needCli: true });

mkdirSync(artifacts, { recursive: true });
const work = mkdtempSync(join(tmpdir(), 'teleop-test-'));
const dataDir = join(work, 'data');
const failures = [];
let rcand = null;
let browser = null;
let proxy = null;

const check = checker(failures);

const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

async function startRcand() {
  let url;
  ({ proc: rcand, url } = await spawnRcand(rcandPath, dataDir));
  return url;
}

// A TCP proxy to the node. freeze(): nothing more is forwarded either way and nothing is
// closed (bytes are held, as a stalled link holds them); thaw(): everything held is delivered.
async function startProxy(targetPort) {
  let frozen = false;
  const held = [];   // [socket, chunk | null (end)]
  const deliver = (sock, chunk) => {
    if (frozen) { held.push([sock, chunk]); return; }
    if (sock.destroyed) return;
    if (chunk === null) sock.end(); else sock.write(chunk);
  };
  const server = createServer((client) => {
    const upstream = connect(targetPort, '127.0.0.1');
    client.on('data', (c) => deliver(upstream, c));
    upstream.on('data', (c) => deliver(client, c));
    client.on('end', () => deliver(upstream, null));
    upstream.on('end', () => deliver(client, null));
    client.on('error', () => upstream.destroy());
    upstream.on('error', () => client.destroy());
  });
  await new Promise((r) => server.listen(0, '127.0.0.1', r));
  return {
    port: server.address().port,
    freeze() { frozen = true; },
    thaw() {
      frozen = false;
      for (const [sock, chunk] of held.splice(0)) deliver(sock, chunk);
    },
    close() { server.close(); },
  };
}

function issueToken(ruri, sub, role, scopes) {
  return execFileSync(cliPath, ['token', 'issue', '--key', join(dataDir, 'issuer', 'ed25519.seed'), '--iss', 'rcand-local',
    '--sub', sub, '--role', role, '--aud', ruri, '--scope', scopes, '--ttl', '1h'], { encoding: 'utf8' }).trim();
}

function message(type, payload) {
  return { version: '1.0.0', message_id: randomUUID(), type, timestamp_ms: Date.now(), payload };
}

async function main() {
  const node = await startRcand();
  const owner = readFileSync(join(dataDir, 'owner.token'), 'utf8').trim();
  proxy = await startProxy(Number(new URL(node).port));
  const viaProxy = `http://127.0.0.1:${proxy.port}`;
  console.log(`rcand at ${node}, the page reaches it through ${viaProxy}`);

  const { robot, pose, dist, fmt, waitStopped, waitMoving } = poseProbe(node, owner);

  browser = await launchBrowser(chromium, chromiumPath);
  const context = await browser.newContext({ viewport: { width: 1280, height: 860 } });
  const page = await context.newPage();
  const pageErrors = [];
  page.on('pageerror', (e) => pageErrors.push(String(e)));
  await page.goto(viaProxy + '/', { waitUntil: 'load' });
  await page.waitForSelector('#signin:not([hidden])');
  await page.fill('#token-input', owner);
  await page.click('#signin-form button[type=submit]');
  await page.waitForSelector('body[data-stream=open]', { timeout: 10000 });
  await page.click('#tabs button[data-view=teleop]');
  await page.click('#claim');
  await page.waitForFunction(() => /claim: GRANTED/.test(document.querySelector('#teleop-log').textContent));
  await page.waitForFunction(() => !document.querySelector('#j0').disabled, null, { timeout: 10000 });

  const center = async (dir) => {
    const b = await (await page.$(`#pad button[data-drive=${dir}]`)).boundingBox();
    return [b.x + b.width / 2, b.y + b.height / 2];
  };
  async function pointerHold(dir) {
    const [x, y] = await center(dir);
    await page.mouse.move(x, y);
    await page.mouse.down();
  }

  // One runaway scenario: start a hold, end it the given way, then the robot must not move.
  async function scenario(name, begin, end, cleanup) {
    await waitStopped();
    const p0 = await pose();
    await begin();
    const moving = await waitMoving(p0);
    check(moving, `${name}: the hold drives the robot`);
    await end();
    await sleep(800);                       // a drive already applied ends within its 0.5 s
    const p1 = await pose();
    await sleep(2500);                      // an unstopped hold repeats every 0.3 s
    const p2 = await pose();
    check(dist(p1, p2) < 0.005, `${name}: the robot does not move after the hold ended ${fmt(p1)} → ${fmt(p2)}`);
    await cleanup();
    await sleep(300);
  }

  // 1. A touch the browser cancels (pointercancel), the button still pressed.
  await scenario('pointercancel',
    () => pointerHold('fwd'),
    () => page.$eval('#pad button[data-drive=fwd]', (b) => b.dispatchEvent(new PointerEvent('pointercancel', { pointerId: 1, pointerType: 'mouse', bubbles: true }))),
    () => page.mouse.up());

  // 2. The window loses focus while the button is held.
  await scenario('window blur',
    () => pointerHold('back'),
    () => page.evaluate(() => window.dispatchEvent(new Event('blur'))),
    () => page.mouse.up());

  // 3. Space held on ▼, Tab moves the focus away, Space released elsewhere.
  await scenario('Tab away while Space is held',
    async () => { await page.focus('#pad button[data-drive=back]'); await page.keyboard.down(' '); },
    () => page.keyboard.press('Tab'),
    () => page.keyboard.up(' '));
  check(await page.evaluate(() => document.activeElement && document.activeElement.id) === 'lin-speed',
    'after Tab the focus is on the speed slider');

  // 4. The tab is hidden (switching apps on a phone) while the button is held.
  await scenario('hidden tab',
    () => pointerHold('fwd'),
    () => page.evaluate(() => {
      Object.defineProperty(document, 'visibilityState', { value: 'hidden', configurable: true });
      Object.defineProperty(document, 'hidden', { value: true, configurable: true });
      document.dispatchEvent(new Event('visibilitychange'));
    }),
    async () => {
      await page.evaluate(() => { delete document.visibilityState; delete document.hidden; });
      await page.mouse.up();
    });

  // 5. The network freezes while the button is held; the operator lets go during the freeze;
  // the network comes back. Nothing the page sent may move the robot after it let go.
  {
    await waitStopped();
    const p0 = await pose();
    await pointerHold('fwd');
    check(await waitMoving(p0), 'frozen network: the hold drives the robot');
    proxy.freeze();
    await sleep(1500);                      // still holding, nothing gets through
    await page.mouse.up();
    const letGo = Date.now();
    await sleep(800);
    const p1 = await pose();
    await sleep(2000);
    proxy.thaw();                           // ~3 s after letting go, everything held arrives
    await sleep(2500);
    const p2 = await pose();
    check(dist(p1, p2) < 0.005,
      `frozen network: nothing sent before letting go moves the robot when the network returns ${((Date.now() - letGo) / 1000).toFixed(1)} s later ${fmt(p1)} → ${fmt(p2)}`);
    await page.waitForSelector('body[data-stream=open]', { timeout: 15000 });
    await page.waitForFunction(() => {
      const s = document.querySelector('#conn-pill');
      return s && /open/.test(s.textContent);
    }, null, { timeout: 15000 });
    await sleep(500);
  }

  // 6. A hold stuck down, ESTOP and RESUME by another client; nobody touches anything.
  {
    await waitStopped();
    const p0 = await pose();
    await pointerHold('fwd');
    check(await waitMoving(p0), 'ESTOP→RESUME: the hold drives the robot');
    const e = await http(node, 'POST', '/api/stop', owner, { reason: 'test ESTOP' });
    check(e.status === 200, `ESTOP by another client (${e.status})`);
    await sleep(500);
    const r = await http(node, 'POST', '/rcan/v1/command', owner, message('SAFETY', { safety_event: 'RESUME' }));
    check(r.status === 200, `RESUME by another client (${r.status})`);
    await sleep(300);
    const p1 = await pose();
    await sleep(2500);
    const p2 = await pose();
    check(dist(p1, p2) < 0.005, `ESTOP→RESUME: the stuck hold does not drive again ${fmt(p1)} → ${fmt(p2)}`);
    await page.mouse.up();
    // A fresh press re-arms the session and drives.
    await waitStopped();
    const p3 = await pose();
    await pointerHold('fwd');
    check(await waitMoving(p3), 'ESTOP→RESUME: a fresh press re-arms and drives');
    await page.mouse.up();
    check(/re-arm after ESTOP: GRANTED/.test(await page.textContent('#teleop-log')), 'the page re-armed on the fresh press');
  }

  // 7. Arrow keys on a focused speed slider change the speed, they do not drive; on the pad
  // they drive while held and stop when released.
  {
    await waitStopped();
    const p0 = await pose();
    await page.focus('#lin-speed');
    const before = await page.inputValue('#lin-speed');
    await page.keyboard.press('ArrowDown');   // the slider may already be at its maximum
    await sleep(800);
    const after = await page.inputValue('#lin-speed');
    check(after !== before, `ArrowDown on the speed slider changes the speed (${before} → ${after})`);
    const pa = await pose();
    check(dist(pa, p0) < 0.005, `ArrowDown on the speed slider does not drive (backwards) ${fmt(p0)} → ${fmt(pa)}`);
    await page.focus('#pad button[data-drive=fwd]');
    await page.keyboard.down('ArrowUp');
    check(await waitMoving(p0), 'ArrowUp held on the pad drives');
    await page.keyboard.up('ArrowUp');
    await sleep(800);
    const p1 = await pose();
    await sleep(1500);
    check(dist(p1, await pose()) < 0.005, 'releasing ArrowUp stops the robot');
  }

  // 8. Move arm: the sliders start at the arm's pose; only the joint the operator changed moves.
  {
    const pose6 = [0, 1.2, -0.8, 0, 0.5, 0];
    const a = await http(node, 'POST', '/rcan/v1/command', owner, message('COMMAND', { action: 'arm_move', joints: pose6 }));
    check(a.status === 200, `the arm is moved to ${JSON.stringify(pose6)} by another client (${a.status})`);
    await page.waitForFunction(() => Math.abs(Number(document.querySelector('#j1').value) - 1.2) < 0.02 &&
      Math.abs(Number(document.querySelector('#j2').value) + 0.8) < 0.02, null, { timeout: 10000 });
    check(true, 'the arm sliders follow the arm\'s pose');
    await page.fill('#j0', '0.8');
    await page.click('#arm-send');
    await page.waitForFunction(() => /arm_move: ACK/.test(document.querySelector('#teleop-log').textContent));
    const targets = (await robot()).arm.targets_rad;
    const want = [0.8, 1.2, -0.8, 0, 0.5, 0];
    check(targets.every((v, i) => Math.abs(v - want[i]) < 1e-6), `Move arm changes only joint 1: targets ${JSON.stringify(targets)}`);
  }
  await page.screenshot({ path: join(artifacts, 'dashboard-teleop-deadman.png') });

  // 9. A frozen connection (nothing closed): within three telemetry periods (5 Hz: 600 ms) the
  // page says "connection lost" and disables motion; when the network returns, it recovers.
  {
    const frozenAt = Date.now();
    proxy.freeze();
    await page.waitForFunction(() => document.body.dataset.stream === 'lost' &&
      /connection lost/.test(document.querySelector('#conn-pill').textContent) &&
      document.querySelector('#pad button[data-drive=fwd]').disabled &&
      document.querySelector('#arm-send').disabled, null, { timeout: 5000, polling: 20 });
    const shownMs = Date.now() - frozenAt;
    // The last frame came at most one period before the freeze; the watchdog looks every 0.1 s.
    check(shownMs <= 600 + 100 + 100, `frozen connection: "connection lost" and motion disabled ${shownMs} ms after the freeze`);
    // What the page shows from the stream no longer looks live: the readouts beside the pad, the
    // Live view's and the control text are amber and say "last known".
    const staleView = () => page.evaluate(() => {
      const q = (sel) => document.querySelector(sel);
      const dd = (box, key) => {
        const dt = [...document.querySelectorAll(`${box} dt`)].find((d) => d.textContent === key);
        const v = dt && dt.nextElementSibling;
        return v ? [v.textContent, getComputedStyle(v).color] : ['', ''];
      };
      const note = (sel) => (q(sel) && !q(sel).hidden ? q(sel).textContent : '');
      return {
        teleop: q('#teleop-facts').classList.contains('stale'), teleopNote: note('#teleop-stale'),
        motion: dd('#teleop-facts', 'motion'), speed: dd('#teleop-facts', 'speed'),
        live: q('#live-facts').classList.contains('stale'), liveNote: note('#live-stale'),
        liveState: dd('#live-facts', 'state'), liveSpeed: dd('#live-facts', 'speed'),
        control: [q('#control-state').textContent, getComputedStyle(q('#control-state')).color],
        warn: getComputedStyle(document.documentElement).getPropertyValue('--warn').trim(),
      };
    });
    const amber = 'rgb(245, 165, 36)';
    const lost = await staleView();
    check(lost.teleop && /last known, connection lost/.test(lost.teleopNote) &&
      /\(last known\)/.test(lost.motion[0]) && /\(last known\)/.test(lost.speed[0]) &&
      lost.motion[1] === amber && lost.speed[1] === amber,
    `frozen connection: the readouts beside the pad are amber and "last known" (${lost.teleopNote} motion "${lost.motion[0]}", speed "${lost.speed[0]}", ${lost.motion[1]})`);
    check(lost.live && /last known, connection lost/.test(lost.liveNote) && /\(last known\)/.test(lost.liveState[0]) &&
      /\(last known\)/.test(lost.liveSpeed[0]) && lost.liveState[1] === amber,
    `frozen connection: the Live view's readouts are amber and "last known" (${lost.liveNote} state "${lost.liveState[0]}")`);
    check(/^Last known \(connection lost\): You hold control/.test(lost.control[0]) && lost.control[1] === amber,
      `frozen connection: the control text says it is the last known (${lost.control[0].slice(0, 60)}…, ${lost.control[1]})`);
    await page.screenshot({ path: join(artifacts, 'dashboard-connection-lost.png') });
    proxy.thaw();
    await page.waitForFunction(() => document.body.dataset.stream === 'open' &&
      !document.querySelector('#pad button[data-drive=fwd]').disabled, null, { timeout: 10000 });
    check(true, 'when the network returns the stream is live again and motion is enabled');
    const back = await staleView();
    check(!back.teleop && !back.live && !back.teleopNote && !back.liveNote && !/last known/i.test(back.motion[0] + back.liveState[0] + back.control[0]),
      'when the network returns the readouts and the control text are live again (no "last known")');
  }

  // 9b. Safe stop: the network stays frozen longer than the deadman (heartbeat_timeout_ms 2 s),
  // so the node stops the robot itself (NETWORK_LOSS_SAFE_STOP). The header's pill says SAFE
  // STOP with the reason, in amber, never "running"; the banner says so too; the next accepted
  // command clears it.
  {
    proxy.freeze();
    await sleep(3500);
    proxy.thaw();
    const st = (await http(node, 'GET', '/rcan/v1/status', owner)).json;
    check(st.robot.state === 'safe_stop' && st.robot.safe_stop_detail && st.robot.safe_stop_detail.reason === 'NETWORK_LOSS_SAFE_STOP',
      `the node safe-stopped while the network was frozen (robot.state ${st.robot.state})`);
    const shown = await page.waitForFunction(() => /SAFE STOP \(NETWORK_LOSS_SAFE_STOP\)/.test(document.querySelector('#safety-pill').textContent) &&
      document.body.dataset.stream === 'open', null, { timeout: 8000 }).then(() => true, () => false);
    const pill = await page.evaluate(() => {
      const p = document.querySelector('#safety-pill');
      const b = document.querySelector('#safety-banner');
      return { text: p.textContent, cls: p.className, bg: getComputedStyle(p).backgroundColor,
        banner: b.hidden ? '' : b.textContent, bannerCls: b.className };
    });
    check(shown && !/running/.test(pill.text) && pill.bg === 'rgb(245, 165, 36)',
      `safe stop: the header pill reads "${pill.text}" on amber (${pill.bg}), not "running"`);
    check(/SAFE STOP \(NETWORK_LOSS_SAFE_STOP\)/.test(pill.banner) && /warn/.test(pill.bannerCls),
      `safe stop: the amber banner says so with the reason (${pill.banner.trim().slice(0, 60)}…)`);
    await page.screenshot({ path: join(artifacts, 'dashboard-safe-stop.png') });
    await page.click('#grip-open');
    const cleared = await page.waitForFunction(() => document.querySelector('#safety-pill').textContent === 'running' &&
      document.querySelector('#safety-banner').hidden, null, { timeout: 8000 }).then(() => true, () => false);
    check(cleared, `an accepted command clears the safe stop and the pill reads "running" again (${await page.textContent('#safety-pill')})`);
  }

  // 9c. ESTOP pressed while the network is frozen: "ESTOP sending…" at once; not confirmed
  // within the request's timeout (5 s), "ESTOP NOT CONFIRMED" with a retry button, which stays
  // until the latch is seen; the network back, the latch is confirmed.
  {
    const estopView = () => page.evaluate(() => {
      const box = document.querySelector('#estop-status');
      const retry = document.querySelector('#estop-retry');
      const text = document.querySelector('#estop-status-text');
      return { shown: !!box && !box.hidden, text: text ? text.textContent.trim() : '', retry: !!retry && !retry.hidden && !retry.disabled };
    });
    proxy.freeze();
    const pressed = Date.now();
    await page.click('#estop');
    const sending = await estopView();
    check(sending.shown && /^ESTOP sending…/.test(sending.text) && !sending.retry, `ESTOP on a frozen network: "${sending.text}" at once`);
    const unconfirmed = await page.waitForFunction(() => /ESTOP NOT CONFIRMED/.test((document.querySelector('#estop-status') || {}).textContent || ''),
      null, { timeout: 9000 }).then(() => true, () => false);
    const after = Date.now() - pressed;
    let v = await estopView();
    check(unconfirmed && v.shown && v.retry && after >= 4500 && after <= 7000,
      `ESTOP on a frozen network: "${v.text.slice(0, 60)}…" with a retry button ${after} ms after the press`);
    await page.screenshot({ path: join(artifacts, 'dashboard-estop-not-confirmed.png') });
    await sleep(2000);
    v = await estopView();
    check(v.shown && /ESTOP NOT CONFIRMED/.test(v.text) && v.retry, 'ESTOP NOT CONFIRMED stays on screen while nothing confirms it');
    if (v.retry) await page.click('#estop-retry');
    v = await estopView();
    check(/^ESTOP sending…/.test(v.text), `the retry sends the ESTOP again ("${v.text}")`);
    proxy.thaw();
    const confirmed = await page.waitForFunction(() => {
      const box = document.querySelector('#estop-status');
      return box && (box.hidden || box.dataset.state === 'confirmed') && document.body.dataset.estop === 'latched';
    }, null, { timeout: 10000 }).then(() => true, () => false);
    const st = (await http(node, 'GET', '/rcan/v1/status', owner)).json;
    check(confirmed && st.estop_active === true,
      `the network back, the latch is confirmed and "NOT CONFIRMED" is gone (${(await estopView()).text || 'hidden'}; status estop_active ${st.estop_active})`);
    const r = await http(node, 'POST', '/rcan/v1/command', owner, message('SAFETY', { safety_event: 'RESUME' }));
    check(r.status === 200, `RESUME after the frozen-network ESTOP (${r.status})`);
    await page.waitForSelector('body[data-estop=clear]', { timeout: 5000 });
  }

  // 9d. On a phone (390×844) a refusal is seen where the operator is: a USER's drive while the
  // owner holds control is refused, and the refusal with its code is in the status line beside
  // the pad and in a toast; a refused gripper command (far below the pad) in a toast.
  {
    const ruri = (await http(node, 'GET', '/rcan/v1/status', owner)).json.ruri;
    const ctx = await browser.newContext({ viewport: { width: 390, height: 844 } });
    const p = await ctx.newPage();
    p.on('pageerror', (e) => pageErrors.push(`phone: ${e}`));
    await p.goto(node + '/', { waitUntil: 'load' });
    await p.fill('#token-input', issueToken(ruri, 'phone-op', 'user', 'status,control'));
    await p.click('#signin-form button[type=submit]');
    await p.waitForSelector('body[data-stream=open]', { timeout: 10000 });
    await p.click('#tabs button[data-view=teleop]');
    await p.waitForFunction(() => /Held by OWNER/.test(document.querySelector('#control-state').textContent), null, { timeout: 5000 });
    const inView = (sel) => p.evaluate((s) => {
      const e = document.querySelector(s);
      if (!e || e.hidden || !e.textContent.trim()) return null;
      const r = e.getBoundingClientRect();
      const visible = r.width > 0 && r.height > 0 && r.top >= 0 && r.bottom <= innerHeight && r.left >= 0 && r.right <= innerWidth;
      return { visible, text: e.textContent.trim(), role: e.getAttribute('role'), live: e.getAttribute('aria-live') };
    }, sel);
    const fwd = await p.$('#pad button[data-drive=fwd]');
    await fwd.scrollIntoViewIfNeeded();
    const bb = await fwd.boundingBox();
    await p.mouse.move(bb.x + bb.width / 2, bb.y + bb.height / 2);
    await p.mouse.down();
    await p.waitForFunction(() => /drive fwd: [A-Z_]+/.test(document.querySelector('#teleop-log').textContent), null, { timeout: 5000 }).catch(() => {});
    const line = await inView('#teleop-status');
    const toastShown = await inView('#toast');
    await p.mouse.up();
    check(!!line && line.visible && /drive fwd: [A-Z_]{4,}/.test(line.text) && line.role === 'status' && line.live === 'polite',
      `phone: the drive's refusal is in the status line beside the pad, in view (${line ? line.text.slice(0, 70) : 'nothing shown'})`);
    check(!!toastShown && toastShown.visible && /drive fwd: [A-Z_]{4,}/.test(toastShown.text),
      `phone: and in a toast in view (${toastShown ? toastShown.text.slice(0, 70) : 'no toast'})`);
    await sleep(5500);                       // the drive's toast goes
    const grip = await p.$('#grip-open');
    await grip.scrollIntoViewIfNeeded();
    await grip.click();
    await p.waitForFunction(() => /gripper_open: [A-Z_]+/.test(document.querySelector('#teleop-log').textContent), null, { timeout: 5000 }).catch(() => {});
    const gripToast = await inView('#toast');
    const gripLog = await p.evaluate(() => document.querySelector('#teleop-log li') ? document.querySelector('#teleop-log li').className : '');
    check(gripLog === 'bad' && !!gripToast && gripToast.visible && /gripper_open: [A-Z_]{4,}/.test(gripToast.text),
      `phone: the gripper's refusal is a toast in view (${gripToast ? gripToast.text.slice(0, 70) : 'no toast'})`);
    await p.screenshot({ path: join(artifacts, 'dashboard-phone-refusal.png') });
    await ctx.close();
  }
  // 10. Control follows the operator: sign-out releases control, the queued operator's page is
  // told it was promoted and keeps the deadman fed, a closed tab leaves the queue, and a drive
  // the safety core limits shows as a warning with its reason.
  {
    await page.click('#release');
    await page.waitForFunction(() => /release: RELEASED/.test(document.querySelector('#teleop-log').textContent));
    const ruri = (await http(node, 'GET', '/rcan/v1/status', owner)).json.ruri;
    const operator = async (sub) => {
      const ctx = await browser.newContext({ viewport: { width: 1280, height: 860 } });
      const p = await ctx.newPage();
      p.on('pageerror', (e) => pageErrors.push(`${sub}: ${e}`));
      await p.goto(node + '/', { waitUntil: 'load' });
      await p.fill('#token-input', issueToken(ruri, sub, 'user', 'status,control'));
      await p.click('#signin-form button[type=submit]');
      await p.waitForSelector('body[data-stream=open]', { timeout: 10000 });
      await p.click('#tabs button[data-view=teleop]');
      await p.click('#claim');
      return p;
    };
    const queue = async () => ((await http(node, 'GET', '/rcan/v1/auth/queue', owner)).json.queue || []).map((q) => q.user_id);
    const safeStops = async () => ((await http(node, 'GET', '/api/audit?limit=1000', owner)).json.entries || [])
      .filter((r) => r.event === 'NETWORK_LOSS_SAFE_STOP').length;

    const a = await operator('op-a');
    await a.waitForFunction(() => /claim: GRANTED/.test(document.querySelector('#teleop-log').textContent));
    const b = await operator('op-b');
    await b.waitForFunction(() => /number 1 in the queue/.test(document.querySelector('#control-state').textContent));
    check(await b.textContent('#release') === 'Leave queue', 'a queued operator sees its place and a "Leave queue" button');
    const stopsBefore = await safeStops();
    await a.click('#signout');
    await b.waitForFunction(() => /You hold control/.test(document.querySelector('#control-state').textContent), null, { timeout: 5000 });
    check(/promoted from the queue/.test(await b.textContent('#teleop-log')), 'sign-out released control and the queued operator\'s page was told it was promoted');
    await sleep(3500);                     // heartbeat_timeout_ms is 2 s: an unfed deadman would fire
    const st = (await http(node, 'GET', '/rcan/v1/status', owner)).json;
    check(st.control === 'HELD' && st.sessions && st.sessions[0] && st.sessions[0].user_id === 'op-b',
      `the promoted operator holds control (${st.control}, ${st.sessions && st.sessions[0] && st.sessions[0].user_id})`);
    check(await safeStops() === stopsBefore, 'the promoted page feeds the deadman: no NETWORK_LOSS_SAFE_STOP after the promotion');

    const c = await operator('op-c');
    await c.waitForFunction(() => /number 1 in the queue/.test(document.querySelector('#control-state').textContent));
    check((await queue()).includes('op-c'), 'a third operator is queued');
    await c.context().close();
    const closedAt = Date.now();
    while (Date.now() - closedAt < 10000 && (await queue()).includes('op-c')) await sleep(200);
    check(!(await queue()).includes('op-c'), `a closed tab leaves the queue (${Date.now() - closedAt} ms)`);

    // Drive into the workspace fence (±5 m): the node shortens, then refuses to move, and says so.
    const [x, y] = await (async () => {
      const bb = await (await b.$('#pad button[data-drive=fwd]')).boundingBox();
      return [bb.x + bb.width / 2, bb.y + bb.height / 2];
    })();
    await b.mouse.move(x, y);
    await b.mouse.down();
    await b.waitForFunction(() => /limited — .*workspace/.test(document.querySelector('#teleop-log').textContent), null, { timeout: 20000 })
      .catch(() => {});
    await b.mouse.up();
    const lines = await b.$$eval('#teleop-log li', (ls) => ls.map((l) => [l.className, l.textContent]));
    const limited = lines.find(([, t]) => /limited — .*workspace/.test(t));
    check(!!limited && limited[0] === 'warn', `a drive limited at the workspace fence is a warning with its reason (${limited ? limited[1] : 'none'})`);
    check(!lines.some(([cls, t]) => cls === 'good' && /clamped/.test(t)), 'no green "clamped" ACK');
    await b.screenshot({ path: join(artifacts, 'dashboard-teleop-promoted-limited.png') });
    await b.context().close();
    await a.context().close();
  }
  check(pageErrors.length === 0, `no page errors (${pageErrors.join('; ')})`);
  await page.close();
}

await runChecks('teleop', main, {
  failures,
  artifacts,
  async cleanup() {
    if (proxy) proxy.close();
    await tearDown(browser, [rcand], work);
  },
});
