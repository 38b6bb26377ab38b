// The teleop view as an operator's console, in a real browser (Debian's Chromium, headless,
// driven by playwright-core) against a real rcand started here: the live readouts and the
// odometry path beside the drive pad, the gamepad (a stubbed navigator.getGamepads) and the
// on-screen joystick driving proportionally under the same deadman as the pad, and approvals
// that announce themselves (beep, notification) and show what they ask against the robot's
// state. Motion is always judged from the node's status, never from the page. Exit 0 pass,
// 1 fail, 77 skip (no browser or playwright-core).
//
// Environment: RCAND_PATH, RCAN_CLI_PATH (set by CTest), CHROMIUM_PATH (default
// /usr/bin/chromium), DASHBOARD_ARTIFACTS (screenshots; default a temp dir).

import { mkdirSync, mkdtempSync, readFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { randomUUID } from 'node:crypto';
import { checker, http, launchBrowser, loadBrowser, poseProbe, runChecks, spawnRcand, startGatedRcand, tearDown } from './harness.mjs';

const rcandPath = process.env.RCAND_PATH;
const cliPath = process.env.RCAN_CLI_PATH;
const artifacts = process.env.DASHBOARD_ARTIFACTS || mkdtempSync(join(tmpdir(), 'console-artifacts-'));

const { chromium, chromiumPath } = await loadBrowser({ rcandPath, cliPath, needCli: true });

mkdirSync(artifacts, { recursive: true });
const work = mkdtempSync(join(tmpdir(), 'console-test-'));
const failures = [];
const notes = [];
const procs = [];
let browser = null;
const check = checker(failures);
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

function message(type, payload) {
  return { version: '1.0.0', message_id: randomUUID(), type, timestamp_ms: Date.now(), payload };
}

// A gamepad the test holds: navigator.getGamepads() answers with window.__gp while it is
// connected (standard mapping: axes[0] left stick x, axes[1] y, buttons 5 RB and 7 RT).
function gamepadStub() {
  const button = () => ({ pressed: false, touched: false, value: 0 });
  window.__gp = { id: 'Test pad (STANDARD GAMEPAD)', index: 0, connected: false, mapping: 'standard', timestamp: 0,
    axes: [0, 0, 0, 0], buttons: Array.from({ length: 17 }, button) };
  window.__ws = 0;
  const WS = window.WebSocket;
  window.WebSocket = class extends WS { constructor(...a) { super(...a); window.__ws += 1; } };
  navigator.getGamepads = () => (window.__gp.connected ? [window.__gp, null, null, null] : [null, null, null, null]);
}

// Counts what the approvals view announces: oscillators started (beeps), notifications shown,
// and permission prompts.
function announceSpy() {
  window.__beeps = 0;
  window.__notes = [];
  window.__asked = 0;
  const AC = window.AudioContext;
  if (AC) {
    const make = AC.prototype.createOscillator;
    AC.prototype.createOscillator = function createOscillator() { window.__beeps += 1; return make.call(this); };
  }
  const N = window.Notification;
  if (N) {
    const ask = N.requestPermission.bind(N);
    class Counted extends N {
      constructor(title, opts) { super(title, opts); window.__notes.push(`${title}: ${opts && opts.body}`); }
    }
    Counted.requestPermission = (...a) => { window.__asked += 1; return ask(...a); };
    window.Notification = Counted;
  }
}

async function signIn(page, url, token) {
  await page.goto(url + '/', { waitUntil: 'load' });
  await page.waitForSelector('#signin:not([hidden])');
  await page.fill('#token-input', token);
  await page.click('#signin-form button[type=submit]');
  await page.waitForSelector('body[data-stream=open]', { timeout: 10000 });
}

async function main() {
  const dataDir = join(work, 'data');
  const { proc, url } = await spawnRcand(rcandPath, dataDir);
  procs.push(proc);
  const owner = readFileSync(join(dataDir, 'owner.token'), 'utf8').trim();
  const status = async () => (await http(url, 'GET', '/rcan/v1/status', owner)).json;
  const base = async () => (await status()).robot.robot.base;
  const { pose, dist, fmt, waitStopped, waitMoving } = poseProbe(url, owner);
  // After a hold ended: what was already applied runs out within its 0.5 s, then nothing moves.
  async function stays(what) {
    await sleep(800);
    const p1 = await pose();
    await sleep(2500);
    const p2 = await pose();
    check(dist(p1, p2) < 0.005, `${what}: the robot does not move afterwards ${fmt(p1)} → ${fmt(p2)}`);
  }
  // The node's commanded forward speed while a hold runs (the sim's active drive target).
  async function targetSpeed() {
    for (let i = 0; i < 40; i++) {
      const b = await base();
      if (Math.abs(b.target_linear_mps) > 1e-6) return b.target_linear_mps;
      await sleep(50);
    }
    return 0;
  }

  const fence = (await status()).robot.limits.workspace;
  check(fence && fence.enabled && typeof fence.min_x === 'number',
    `the node reports its workspace fence in its status (robot.limits.workspace ${JSON.stringify(fence)})`);

  browser = await launchBrowser(chromium, chromiumPath);
  const context = await browser.newContext({ viewport: { width: 1280, height: 900 } });
  await context.addInitScript(gamepadStub);
  const page = await context.newPage();
  const pageErrors = [];
  page.on('pageerror', (e) => pageErrors.push(String(e)));
  await signIn(page, url, owner);
  await page.click('#tabs button[data-view=teleop]');
  await page.click('#claim');
  await page.waitForFunction(() => /claim: GRANTED/.test(document.querySelector('#teleop-log').textContent));
  // The slider's speed (its maximum is the node's max_linear_mps): the stick scales it.
  const lin = Number(await page.inputValue('#lin-speed'));

  // 1. The readouts beside the pad come from the stream the Live view uses (one WebSocket).
  await page.waitForFunction(() => /m\/s/.test(document.querySelector('#teleop-facts').textContent) &&
    document.querySelector('#teleop-facts').dataset.x !== 'undefined', null, { timeout: 5000 });
  const facts = await page.textContent('#teleop-facts');
  check(/safety\s*running/.test(facts) && /speed/.test(facts) && /joint 6/.test(facts) && /heading/.test(facts),
    `the teleop view shows safety, speed, pose and joints (${facts.replace(/\s+/g, ' ').slice(0, 160)}…)`);
  await page.click('#tabs button[data-view=live]');
  await sleep(500);
  await page.click('#tabs button[data-view=teleop]');
  const sockets = await page.evaluate(() => window.__ws);
  check(sockets === 1, `one WebSocket feeds the Live and Teleop views (${sockets} opened)`);
  const fenceText = await page.textContent('#traj-text');
  check(new RegExp(`fence is x ${fence.min_x.toFixed(1)} to ${fence.max_x.toFixed(1)} m`).test(fenceText),
    `the path's text alternative names the fence (${fenceText})`);

  // 2. Drive with the pad: the readouts and the path follow the robot.
  await waitStopped();
  const points0 = Number(await page.getAttribute('#traj', 'data-points'));
  const x0 = (await pose()).x;
  const fwd = await (await page.$('#pad button[data-drive=fwd]')).boundingBox();
  await page.mouse.move(fwd.x + fwd.width / 2, fwd.y + fwd.height / 2);
  await page.mouse.down();
  await sleep(1500);
  await page.mouse.up();
  await waitStopped();
  const xNode = (await pose()).x;
  await sleep(600);
  const shownX = Number(await page.getAttribute('#teleop-facts', 'data-x'));
  check(Math.abs(xNode - x0) > 0.3 && Math.abs(shownX - xNode) < 0.02,
    `the teleop readouts follow the drive (x ${x0.toFixed(2)} → ${xNode.toFixed(2)} m on the node, ${shownX.toFixed(2)} shown)`);
  const points1 = Number(await page.getAttribute('#traj', 'data-points'));
  check(points1 > points0 + 5, `the trajectory plot gains points as the robot drives (${points0} → ${points1})`);
  check(/Path of \d+ points, [\d.]+ m long/.test(await page.textContent('#traj-text')), 'the path is described in words');

  // 3. The gamepad: RT held is the deadman, the left stick drives in proportion to its deflection.
  await page.evaluate(() => { window.__gp.connected = true; window.dispatchEvent(new Event('gamepadconnected')); });
  await page.waitForFunction(() => /Test pad/.test(document.querySelector('#gamepad-state').textContent));
  check(true, 'the page names the connected gamepad');
  const setPad = (axes, rt) => page.evaluate(([ax, held]) => {
    window.__gp.axes = [ax[0], ax[1], 0, 0];
    window.__gp.buttons[7] = { pressed: held, touched: held, value: held ? 1 : 0 };
  }, [axes, rt]);
  {
    await waitStopped();
    const p0 = await pose();
    await setPad([0, -1], false);            // the stick pushed, no deadman: nothing moves
    await sleep(1200);
    check(dist(await pose(), p0) < 0.005, 'the left stick without the deadman held does not drive');
    await setPad([0, -0.5], true);           // half forward, deadman held
    check(await waitMoving(p0), 'the gamepad drives while RT is held');
    const v = await targetSpeed();
    check(Math.abs(v - lin / 2) < 0.03, `half a stick is half the slider's ${lin} m/s (${v.toFixed(2)} m/s commanded on the node)`);
    await page.screenshot({ path: join(artifacts, 'dashboard-teleop-console.png') });
    await setPad([0, -0.5], false);
    await stays('gamepad: RT released');
  }
  {
    await waitStopped();
    const p0 = await pose();
    await setPad([0, 1], true);               // full back, deadman held
    check(await waitMoving(p0), 'the gamepad drives backwards at full deflection');
    const v = await targetSpeed();
    check(Math.abs(v + lin) < 0.03, `full deflection is the slider's speed, never more (${v.toFixed(2)} m/s)`);
    await page.evaluate(() => { window.__gp.connected = false; window.dispatchEvent(new Event('gamepaddisconnected')); });
    await stays('gamepad: disconnected with RT still held');
  }
  {
    await page.evaluate(() => { window.__gp.connected = true; });
    await setPad([0, 0], false);
    await sleep(200);
    await waitStopped();
    const p0 = await pose();
    await setPad([0.6, 0.8], true);
    check(await waitMoving(p0), 'the gamepad drives again on a fresh press');
    await page.evaluate(() => window.dispatchEvent(new Event('blur')));
    await stays('gamepad: the window lost focus with RT still held (no restart until RT is pressed again)');
    await page.evaluate(() => {
      Object.defineProperty(document, 'visibilityState', { value: 'hidden', configurable: true });
      document.dispatchEvent(new Event('visibilitychange'));
    });
    await setPad([0, -1], false);
    await sleep(200);
    await setPad([0, -1], true);             // a fresh press while the tab is hidden
    const p1 = await pose();
    await sleep(1500);
    check(dist(await pose(), p1) < 0.005, 'a fresh press while the tab is hidden does not drive');
    await setPad([0, 0], false);
    await sleep(200);
    await page.evaluate(() => { delete document.visibilityState; });
    await page.evaluate(() => { document.hasFocus = () => false; });
    await setPad([0, -1], true);             // a fresh press while the window is not focused
    const p2 = await pose();
    await sleep(1500);
    check(dist(await pose(), p2) < 0.005, 'a fresh press while the window is not focused does not drive');
    await setPad([0, 0], false);
    await sleep(200);
    await page.evaluate(() => { delete document.hasFocus; });
    await page.evaluate(() => { window.__gp.connected = false; });
  }

  // 4. The on-screen joystick: a drag drives in proportion, pointercancel and pointerup stop.
  const stick = await (await page.$('#stick')).boundingBox();
  const cx = stick.x + stick.width / 2;
  const cy = stick.y + stick.height / 2;
  const travel = (stick.width / 2) * 0.7;
  {
    await waitStopped();
    const p0 = await pose();
    await page.mouse.move(cx, cy);
    await page.mouse.down();
    await page.mouse.move(cx, cy - travel * 0.5, { steps: 4 });
    check(await waitMoving(p0), 'dragging the joystick forward drives');
    const v = await targetSpeed();
    check(Math.abs(v - lin / 2) < 0.05, `half the joystick's travel is half the slider's speed (${v.toFixed(2)} m/s)`);
    await page.mouse.move(cx, cy - travel * 3, { steps: 4 });   // beyond the rim: clamped
    await sleep(700);
    const vmax = (await base()).target_linear_mps;
    check(vmax <= lin + 1e-6 && vmax > lin * 0.9, `dragging beyond the rim is clamped to the slider's speed (${vmax.toFixed(2)} m/s)`);
    await page.$eval('#stick', (c) => c.dispatchEvent(new PointerEvent('pointercancel', { pointerId: 1, pointerType: 'mouse', bubbles: true })));
    await stays('joystick: pointercancel with the button still down');
    await page.mouse.up();
  }
  {
    await waitStopped();
    const p0 = await pose();
    await page.mouse.move(cx, cy);
    await page.mouse.down();
    await page.mouse.move(cx - travel * 0.8, cy + travel * 0.8, { steps: 4 });
    check(await waitMoving(p0), 'dragging the joystick back and left drives');
    await page.mouse.move(cx + 400, cy + 300, { steps: 4 });    // outside the canvas: capture keeps it
    await sleep(500);
    await page.mouse.up();
    await stays('joystick: pointerup outside the joystick');
  }
  {
    await waitStopped();
    const p0 = await pose();
    await page.mouse.move(cx, cy);
    await page.mouse.down();
    await page.mouse.move(cx, cy + travel, { steps: 4 });
    check(await waitMoving(p0), 'the joystick drives before the release of capture');
    await page.$eval('#stick', (c) => c.releasePointerCapture(1));
    await stays('joystick: lost pointer capture');
    await page.mouse.up();
  }
  check(pageErrors.length === 0, `no page errors (${pageErrors.join('; ')})`);
  await context.close();

  // 5. Approvals that announce themselves and show what they ask against the robot's state.
  const g = await startGatedRcand({ rcandPath, cliPath, dir: join(work, 'gated'), actions: ['arm_move', 'drive'] });
  procs.push(g.proc);
  const ctx2 = await browser.newContext({ viewport: { width: 1280, height: 900 }, permissions: ['notifications'] });
  await ctx2.addInitScript(announceSpy);
  const ap = await ctx2.newPage();
  ap.on('pageerror', (e) => pageErrors.push(String(e)));
  await signIn(ap, g.url, g.owner);
  await ap.click('#tabs button[data-view=approvals]');
  check(!(await ap.isChecked('#sound-approvals')) && !(await ap.isChecked('#notify-approvals')),
    'the beep and the notification are off by default');
  check(await ap.evaluate(() => window.__asked) === 0, 'the page does not ask for notification permission on its own');
  await ap.check('#sound-approvals');
  await ap.check('#notify-approvals');
  check(await ap.evaluate(() => window.__beeps) > 0, 'ticking the beep plays it once (the tick is the gesture a browser wants)');
  await ap.reload({ waitUntil: 'load' });
  await ap.waitForSelector('body[data-stream=open]', { timeout: 10000 });
  await ap.click('#tabs button[data-view=approvals]');
  check(await ap.isChecked('#sound-approvals') && await ap.isChecked('#notify-approvals'),
    'both choices are remembered across a reload (localStorage)');
  const beeps0 = await ap.evaluate(() => window.__beeps);
  const arm = message('COMMAND', { action: 'arm_move', joints: [0.5, 0.25, 0, 0, 0, 0] });
  const held = await http(g.url, 'POST', '/rcan/v1/command', g.leasee, arm);
  check(held.status === 202, `a gated arm_move is parked (${held.status})`);
  await ap.waitForSelector('#approvals-list article.approval', { timeout: 5000 });
  await ap.waitForFunction(() => window.__notes.length > 0 && window.__beeps > 0, null, { timeout: 5000 }).catch(() => {});
  const told = await ap.evaluate(() => ({ beeps: window.__beeps, notes: window.__notes }));
  check(told.beeps > beeps0, `a new request beeps (${told.beeps - beeps0} tone(s))`);
  check(told.notes.length === 1 && /arm_move/.test(told.notes[0]) && /leasee-1/.test(told.notes[0]),
    `a new request raises one browser notification (${JSON.stringify(told.notes)})`);
  await ap.waitForFunction(() => /\d/.test(document.querySelector('#approvals-list td.now[data-path]').textContent));
  const rows = await ap.$$eval('#approvals-list article.approval tbody tr',
    (trs) => trs.map((tr) => [...tr.children].map((td) => [td.textContent, td.className])));
  check(rows.length === 6 && rows[0][0][0] === 'joint 1 (rad)' && rows[0][1][0] === '0.50' && rows[0][2][0] === '0.00 ≠' &&
    /diff/.test(rows[0][2][1]) && rows[2][1][0] === '0.00' && !/diff/.test(rows[2][2][1]),
    `an arm move shows each target joint against the joint now, the changed ones marked (${JSON.stringify(rows.slice(0, 3))})`);
  const drive = message('COMMAND', { action: 'drive', linear: 0.4, angular: 0.2, duration_ms: 500, note: '<b>slow</b>' });
  const held2 = await http(g.url, 'POST', '/rcan/v1/command', g.leasee, drive);
  check(held2.status === 202, `a gated drive is parked (${held2.status})`);
  await ap.waitForFunction(() => document.querySelectorAll('#approvals-list article.approval').length === 2, null, { timeout: 5000 });
  await sleep(500);
  const driveRows = await ap.$$eval('#approvals-list article.approval', (as) => {
    const a = as.find((x) => /^(drive|move)$/.test(x.querySelector('h3').textContent));
    if (!a) return as.map((x) => [x.textContent]);
    return [...a.querySelectorAll('tbody tr')].map((tr) => [...tr.children].map((td) => td.textContent));
  });
  const byName = Object.fromEntries(driveRows.map((r) => [r[0], r.slice(1)]));
  check(byName['linear (m/s)'] && byName['linear (m/s)'][0] === '0.40' && byName['linear (m/s)'][1] === '0.00 ≠' &&
    byName['angular (rad/s)'] && byName['angular (rad/s)'][0] === '0.20',
    `a drive shows the requested speeds against the base's (${JSON.stringify(driveRows)})`);
  check(byName.note && byName.note[0] === '<b>slow</b>' && await ap.$('#approvals-list b') === null,
    'other parameters are a key/value table, as text');
  check(await ap.evaluate(() => window.__notes.length) === 2, 'each new request notifies once');
  await ap.screenshot({ path: join(artifacts, 'dashboard-approvals-compare.png') });
  check(pageErrors.length === 0, `no page errors in the approvals view (${pageErrors.join('; ')})`);
  await ctx2.close();
}

await runChecks('console', main, {
  failures,
  artifacts,
  notes,
  cleanup: () => tearDown(browser, procs, work),
});
