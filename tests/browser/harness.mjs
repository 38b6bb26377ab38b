// What the browser tests share: the skip rule (exit 77, CTest's SKIP_RETURN_CODE, when the
// browser or playwright-core is missing), pass/fail lines, starting an rcand and reading its
// URL from the "listening" log line, and a small JSON-over-HTTP helper.

import { spawn, execFileSync } from 'node:child_process';
import { chmodSync, existsSync, mkdirSync, readFileSync, rmSync, writeFileSync } from 'node:fs';
import { join } from 'node:path';

export const SKIP = 77;

export function skip(why) {
  console.log(`SKIP: ${why}`);
  process.exit(SKIP);
}

// The browser and the binaries the test needs, or a skip. Returns { chromium, chromiumPath }.
export async function loadBrowser({ rcandPath, cliPath, needCli = false }) {
  const chromiumPath = process.env.CHROMIUM_PATH || '/usr/bin/chromium';
  if (!rcandPath || !existsSync(rcandPath)) skip('RCAND_PATH does not name an rcand binary');
  if (needCli && (!cliPath || !existsSync(cliPath))) skip('RCAN_CLI_PATH does not name the rcan CLI');
  if (!existsSync(chromiumPath)) skip(`no browser at ${chromiumPath} (scripts/install-deps.sh installs Debian's chromium)`);
  try {
    const { chromium } = await import('playwright-core');
    return { chromium, chromiumPath };
  } catch (e) {
    return skip(`playwright-core is not installed (scripts/install-deps.sh runs npm ci in tests/browser): ${e.message}`);
  }
}

// check(cond, what): prints ok/FAIL and keeps the failures in `failures`.
export function checker(failures) {
  return (cond, what) => {
    if (cond) console.log(`ok - ${what}`);
    else { console.log(`FAIL - ${what}`); failures.push(what); }
  };
}

// Starts rcand on its embedded default over `dataDir`; resolves { proc, url } once it listens.
export async function spawnRcand(rcandPath, dataDir, port = 0) {
  const proc = spawn(rcandPath, ['--data-dir', dataDir, '--port', String(port)], { stdio: ['ignore', 'ignore', 'pipe'] });
  let log = '';
  const url = await new Promise((resolve, reject) => {
    const timer = setTimeout(() => reject(new Error(`rcand did not start:\n${log}`)), 20000);
    proc.stderr.on('data', (d) => {
      log += d.toString();
      const m = log.match(/"event":"listening"[^\n]*"url":"(http:\/\/[^"]+)"/) || log.match(/"url":"(http:\/\/[^"]+)"[^\n]*listening/);
      if (m) { clearTimeout(timer); resolve(m[1]); }
    });
    proc.on('exit', (code) => { clearTimeout(timer); reject(new Error(`rcand exited ${code}:\n${log}`)); });
  });
  proc.removeAllListeners('exit');
  return { proc, url };
}

// An Ed25519 token issuer in `dir` (openssl): { key, pub } PEM paths, the key 0600.
export function makeIssuer(dir) {
  mkdirSync(dir, { recursive: true, mode: 0o700 });
  const key = join(dir, 'issuer.pem');
  const pub = join(dir, 'issuer.pub.pem');
  execFileSync('openssl', ['genpkey', '-algorithm', 'ed25519', '-out', key]);
  chmodSync(key, 0o600);
  execFileSync('openssl', ['pkey', '-in', key, '-pubout', '-out', pub]);
  return { key, pub };
}

// A token of that issuer (issuer name ops.example) for `aud`.
export function issueToken(cliPath, issuer, { sub, role, aud, scopes = 'status,control' }) {
  return execFileSync(cliPath, ['token', 'issue', '--key', issuer.key, '--iss', 'ops.example',
    '--sub', sub, '--role', role, '--aud', aud, '--scope', scopes, '--ttl', '1h'], { encoding: 'utf8' }).trim();
}

// A configured robot in `dir` (its keys, chain secret and YAML) trusting `issuer`, with
// `extra` YAML lines. Resolves { proc, url }.
export async function startConfiguredRcand({ rcandPath, cliPath, dir, ruri, name, issuer, extra = [] }) {
  const data = join(dir, 'data');
  mkdirSync(data, { recursive: true, mode: 0o700 });
  execFileSync(cliPath, ['keys', 'generate', '--dir', join(data, 'keys')]);
  execFileSync(cliPath, ['audit', 'new-secret', '--out', join(data, 'audit.secret')]);
  const [, manufacturer, model] = /^rcan:\/\/[^/]+\/([^/]+)\/([^/]+)\//.exec(ruri);
  const cfg = join(dir, 'robot.rcan.yaml');
  writeFileSync(cfg, [
    'rcan_version: "1.2"', `ruri: ${ruri}`,
    'robot:', `  name: ${name}`, `  manufacturer: ${manufacturer}`, `  model: ${model}`, '  type: mobile',
    'safety:', '  local_safety_wins: true',
    'security:', '  jwt:', '    issuers:', '      - issuer: ops.example', `        key_file: ${issuer.pub}`,
    ...extra, ''].join('\n'));
  const proc = spawn(rcandPath, ['--config', cfg, '--data-dir', data, '--port', '0'], { stdio: ['ignore', 'ignore', 'pipe'] });
  let log = '';
  const url = await new Promise((resolve, reject) => {
    const timer = setTimeout(() => reject(new Error(`configured rcand did not start:\n${log}`)), 20000);
    proc.stderr.on('data', (d) => {
      log += d.toString();
      const m = log.match(/"event":"listening"[^\n]*"url":"(http:\/\/[^"]+)"/);
      if (m) { clearTimeout(timer); resolve(m[1]); }
    });
    proc.on('exit', (code) => { clearTimeout(timer); reject(new Error(`configured rcand exited ${code}:\n${log}`)); });
  });
  proc.removeAllListeners('exit');
  return { proc, url };
}

// A configured robot whose `actions` wait for a human (agent.hitl_gates), with its own issuer,
// in `dir`. Resolves { proc, url, owner, leasee } (tokens of that issuer).
export async function startGatedRcand({ rcandPath, cliPath, dir, actions = ['arm_move'] }) {
  const issuer = makeIssuer(dir);
  const ruri = 'rcan://local.rcan/acme/rover/0a1b2c3d';
  const { proc, url } = await startConfiguredRcand({ rcandPath, cliPath, dir, ruri, name: 'gated-rover', issuer, extra: [
    'agent:', '  hitl_gates:', `    - action_types: [${actions.join(', ')}]`, '      require_auth: true',
    '      auth_timeout_ms: 60000', '      on_timeout: block', '      notify: [ws]'] });
  const tok = (sub, role, scopes) => issueToken(cliPath, issuer, { sub, role, aud: ruri, scopes });
  return { proc, url, owner: tok('owner-1', 'owner', 'status,control,config'), leasee: tok('leasee-1', 'leasee', 'status,control') };
}

export async function http(base, method, path, token, body) {
  const headers = {};
  if (token) headers.Authorization = `Bearer ${token}`;
  if (body !== undefined) headers['Content-Type'] = 'application/json';
  const res = await fetch(base + path, { method, headers, body: body === undefined ? undefined : JSON.stringify(body) });
  const text = await res.text();
  let json = null;
  try { json = JSON.parse(text); } catch (_) { /* not JSON */ }
  return { status: res.status, json, text, headers: res.headers };
}

// The robot's pose read from the node's own status (never from the page): `pose()`, the
// distance between two poses, how one prints, and waits for the robot to rest or to move.
export function poseProbe(base, token) {
  const sleep = (ms) => new Promise((r) => setTimeout(r, ms));
  const robot = async () => (await http(base, 'GET', '/rcan/v1/status', token)).json.robot.robot;
  const pose = async () => { const r = await robot(); return { x: r.base.x, y: r.base.y, th: r.base.theta }; };
  const dist = (a, b) => Math.hypot(a.x - b.x, a.y - b.y) + Math.abs(a.th - b.th);
  const fmt = (p) => `(${p.x.toFixed(3)}, ${p.y.toFixed(3)}, ${p.th.toFixed(3)})`;
  // At rest: the pose has not changed over 300 ms.
  async function waitStopped() {
    for (let i = 0; i < 40; i++) {
      const a = await pose();
      await sleep(300);
      if (dist(a, await pose()) < 1e-4) return;
    }
    throw new Error('the robot did not come to rest');
  }
  // Moved more than 5 cm (or turned) from `from` within 5 s.
  async function waitMoving(from) {
    for (let i = 0; i < 100; i++) {
      if (dist(await pose(), from) > 0.05) return true;
      await sleep(50);
    }
    return false;
  }
  return { robot, pose, dist, fmt, waitStopped, waitMoving };
}

// What every test does last: closes the browser, stops the processes it started (null ones
// skipped), gives them 300 ms and removes its working directory.
export async function tearDown(browser, procs, work) {
  if (browser) await browser.close().catch(() => {});
  for (const p of procs) if (p) p.kill('SIGTERM');
  await new Promise((r) => setTimeout(r, 300));
  rmSync(work, { recursive: true, force: true });
}

// Runs `main`, then `cleanup` whatever happened; prints the notes and the verdict and exits
// 0 (every check passed) or 1.
export async function runChecks(name, main, { failures, cleanup, artifacts, notes = [] }) {
  try {
    await main();
  } catch (e) {
    failures.push(`exception: ${e.stack || e}`);
    console.log(`FAIL - ${e.stack || e}`);
  } finally {
    await cleanup();
  }
  for (const n of notes) console.log(`note: ${n}`);
  console.log(`artifacts: ${artifacts}`);
  if (failures.length) {
    console.log(`${failures.length} failure(s)`);
    process.exit(1);
  }
  console.log(`all ${name} checks passed`);
  process.exit(0);
}

// Headless Chromium as every browser test runs it. With DASHBOARD_WEB_DIR set (a web/
// directory), every context is served the page's files from there instead of those compiled
// into rcand, with the node's own response headers (CSP and all): a change to the page can be
// tried without rebuilding the node.
export async function launchBrowser(chromium, chromiumPath) {
  const webDir = process.env.DASHBOARD_WEB_DIR;
  const browser = await chromium.launch({
    executablePath: chromiumPath,
    args: ['--headless', '--no-sandbox', '--disable-gpu', '--disable-background-networking',
      '--disable-component-update', '--disable-sync', '--disable-dev-shm-usage',
      // A document the test serves has no address of its own: let it reach the local node.
      ...(webDir ? ['--disable-features=LocalNetworkAccessChecks'] : [])],
  });
  if (webDir) {
    const newContext = browser.newContext.bind(browser);
    browser.newContext = async (options) => {
      const context = await newContext(options);
      await servePageFrom(context, webDir);
      return context;
    };
  }
  return browser;
}

// The page's own files (/, /index.html, /ui/…) from `webDir`; everything else untouched.
async function servePageFrom(context, webDir) {
  const fileOf = (url) => {
    const path = new URL(url).pathname;
    if (path === '/' || path === '/index.html') return join(webDir, 'index.html');
    if (path.startsWith('/ui/') && !path.includes('..')) return join(webDir, path.slice(4));
    return null;
  };
  await context.route((url) => fileOf(url.href) !== null, async (route) => {
    const headers = { ...route.request().headers() };
    delete headers['if-none-match'];
    const response = await route.fetch({ headers });
    const file = fileOf(route.request().url());
    if (response.status() === 200 && existsSync(file)) await route.fulfill({ response, body: readFileSync(file) });
    else await route.fulfill({ response });
  });
}
