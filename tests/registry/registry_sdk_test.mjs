// rcan-ts 3.4.2 (third_party/rcan-ts, built by scripts/install-deps.sh) as a real client of a live
// rcan-registry (docs/REGISTRY.md): RegistryClient get/list/search/patch/delete and NodeClient
// getNodeManifest/verifyNode/listNodes/discover/resolve. rcan-ts's register() sends no
// Authorization header, so the registry refuses it (401, shown as RCANRegistryError) unless it
// runs with --open-registration (then it registers a community robot, as rcan.dev does); robots
// are registered with the admin key over fetch and then handled through the SDK with their own
// key.
//
// Exit 0 pass, 1 fail, 77 skip (CTest SKIP_RETURN_CODE): RCAN_REGISTRY_PATH missing, or the SDK
// not built (dist/index.mjs).
import { spawn } from 'node:child_process';
import { existsSync, mkdtempSync, readFileSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { dirname, join } from 'node:path';
import { fileURLToPath } from 'node:url';

const SKIP = 77;
const here = dirname(fileURLToPath(import.meta.url));
const sdkDist = join(here, '..', '..', 'third_party', 'rcan-ts', 'dist', 'index.mjs');
const REGISTRY = process.env.RCAN_REGISTRY_PATH ?? '';
// With RCAN_REGISTRY_DATABASE (scripts/with_postgres.sh sets it and _2…_4) every registry of the
// test runs on a PostgreSQL database of its own; without it, on SQLite.
const onDatabase = (suffix = '') => {
  const url = process.env[`RCAN_REGISTRY_DATABASE${suffix}`] ?? '';
  return url ? ['--database', url] : [];
};
function skip(why) {
  console.log(`SKIP: ${why}`);
  process.exit(SKIP);
}
if (!existsSync(REGISTRY)) skip('RCAN_REGISTRY_PATH does not name rcan-registry');
if (!existsSync(sdkDist)) skip('rcan-ts is not built (scripts/install-deps.sh runs npm ci + tsup in third_party/rcan-ts)');
const sdk = await import(sdkDist);

const failures = [];
function check(cond, what) {
  console.log(`${cond ? 'ok  ' : 'FAIL'} ${what}`);
  if (!cond) failures.push(what);
}

async function start(extra = []) {
  const dir = mkdtempSync(join(tmpdir(), 'rcan-registry-ts-'));
  const proc = spawn(REGISTRY, ['--data-dir', dir, '--port', '0', ...extra], { stdio: ['ignore', 'ignore', 'pipe'] });
  let buf = '';
  const url = await new Promise((resolve, reject) => {
    const timer = setTimeout(() => reject(new Error('rcan-registry did not start')), 30000);
    proc.stderr.on('data', (d) => {
      buf += d.toString();
      const m = buf.match(/\{[^\n]*"event":"listening"[^\n]*\}/);
      if (m) {
        clearTimeout(timer);
        resolve(JSON.parse(m[0]).url);
      }
    });
    proc.on('exit', () => reject(new Error(`rcan-registry exited:\n${buf}`)));
  });
  const admin = readFileSync(join(dir, 'admin.key'), 'utf8');
  const exited = new Promise((resolve) => proc.on('exit', resolve));
  // SIGTERM, wait for the exit, remove the data directory.
  const stop = async () => {
    proc.kill('SIGTERM');
    await exited;
    rmSync(dir, { recursive: true, force: true });
  };
  return { proc, url, admin, stop };
}

async function post(reg, path, body, key) {
  const r = await fetch(reg.url + path, {
    method: 'POST',
    headers: { 'Content-Type': 'application/json', Authorization: `Bearer ${key}` },
    body: JSON.stringify(body),
  });
  return { status: r.status, body: await r.json() };
}

async function registryClient(reg) {
  const anon = new sdk.RegistryClient({ baseUrl: reg.url });
  try {
    await anon.register({ manufacturer: 'acme', model: 'arm', version: 'v2', device_id: 'ts-0' });
    check(false, 'RegistryClient.register without a key is refused');
  } catch (e) {
    check(e instanceof sdk.RCANRegistryError && /Authorization required/.test(e.message),
      'RegistryClient.register without a key is refused (401 → RCANRegistryError)');
  }
  const made = [];
  for (const device of ['ts-1', 'ts-2', 'ts-3']) {
    const r = await post(reg, '/api/v1/robots', { manufacturer: 'acme', model: 'arm', version: 'v2', device_id: device, description: `robot ${device}` }, reg.admin);
    check(r.status === 201, `register ${device} → 201`);
    made.push(r.body);
  }
  const rc = new sdk.RegistryClient({ baseUrl: reg.url, apiKey: made[0].api_key });
  const got = await rc.get(made[0].rrn);
  check(got.rrn === made[0].rrn && got.status === 'active' && got.description === 'robot ts-1', 'RegistryClient.get');
  const list = await rc.list({ limit: 2, offset: 0 });
  check(list.total === 3 && list.robots.length === 2 && list.limit === 2 && list.offset === 0, 'RegistryClient.list (limit/offset)');
  const found = await rc.search({ q: 'acme' });
  check(found.length === 3, 'RegistryClient.search (q)');
  const byModel = await rc.search({ model: 'arm' });
  check(byModel.length === 3, 'RegistryClient.search (model)');
  const patched = await rc.patch(made[0].rrn, { description: 'patched by rcan-ts' });
  check(patched.description === 'patched by rcan-ts', 'RegistryClient.patch with the robot key');
  try {
    await rc.patch(made[1].rrn, { description: 'not mine' });
    check(false, "RegistryClient.patch of another robot is refused");
  } catch (e) {
    check(e instanceof sdk.RCANRegistryError && /Invalid API key/.test(e.message), "RegistryClient.patch of another robot is refused (403)");
  }
  await rc.delete(made[0].rrn);
  try {
    await rc.get(made[0].rrn);
    check(false, 'get after delete is 404');
  } catch (e) {
    check(/Robot not found/.test(e.message), 'RegistryClient.delete, then get → not found');
  }
  return made[1].rrn;
}

async function nodeClient(reg, rrn) {
  const nc = new sdk.NodeClient(reg.url, 5000);
  const manifest = await nc.getNodeManifest(reg.url);
  check(manifest.node_type === 'root' && manifest.public_key.startsWith('ed25519:'), 'NodeClient.getNodeManifest');
  check(nc.verifyNode(manifest), 'NodeClient.verifyNode with --public-url https://…');
  const nodes = await nc.listNodes();
  check(nodes.length === 1 && nodes[0].node_type === 'root', 'NodeClient.listNodes');
  const res = await nc.resolve(rrn);
  check(res.rrn === rrn && res.record.rrn === rrn && res.namespace === 'root', 'NodeClient.resolve');
  const r = await post(reg, '/api/v1/nodes', { prefix: 'EU', operator: 'EU robots', node_url: 'https://eu.example' }, reg.admin);
  check(r.status === 201, 'delegate EU → 201');
  const eu = await nc.discover('RRN-EU-00000007');
  check(eu.node_url === 'https://eu.example' && eu.api_base === 'https://eu.example/api/v1', 'NodeClient.discover (delegated)');
}

// A root delegating BD to a second rcan-registry (--prefix BD): resolve at the root follows
// the root's 307 to the authoritative node.
async function federation() {
  const bd = await start(['--prefix', 'BD', ...onDatabase('_2')]);
  const root = await start(['--allow-http-node-urls', ...onDatabase('_3')]);
  try {
    const made = await post(bd, '/api/v1/robots', { manufacturer: 'bd', model: 'spot', version: 'v1', device_id: 'f-1' }, bd.admin);
    check(made.status === 201 && made.body.rrn.startsWith('RRN-BD-'), 'the BD node mints RRN-BD-…');
    const d = await post(root, '/api/v1/nodes', { prefix: 'BD', operator: 'BD robots', node_url: bd.url }, root.admin);
    check(d.status === 201, 'the root delegates BD to the second node');
    const nc = new sdk.NodeClient(root.url, 5000);
    const res = await nc.resolve(made.body.rrn);
    check(res.resolved_by === bd.url && res.record.rrn === made.body.rrn, 'NodeClient.resolve at the root follows federation to the BD node');
    const node = await nc.discover(made.body.rrn);
    check(node.node_url === bd.url, 'NodeClient.discover → the BD node');
  } finally {
    await bd.stop();
    await root.stop();
  }
}

// --open-registration: RegistryClient.register without a key registers a community robot and
// returns its key. On SQLite in both runs (the four PostgreSQL databases are the others').
async function openRegistration() {
  const reg = await start(['--open-registration']);
  try {
    const anon = new sdk.RegistryClient({ baseUrl: reg.url });
    const r = await anon.register({ manufacturer: 'acme', model: 'arm', version: 'v2', device_id: 'ts-open' });
    check(/^RRN-/.test(r.rrn) && /^rcan_/.test(r.api_key) && r.verification_tier === 'community',
      'with --open-registration, RegistryClient.register without a key → a community robot and its key');
    const mine = new sdk.RegistryClient({ baseUrl: reg.url, apiKey: r.api_key });
    const patched = await mine.patch(r.rrn, { description: 'registered by rcan-ts' });
    check(patched.description === 'registered by rcan-ts', 'the anonymously registered robot patches itself with its key');
  } finally {
    await reg.stop();
  }
}

try {
  await federation();
} catch (e) {
  check(false, `federation: ${e.stack ?? e}`);
}
try {
  await openRegistration();
} catch (e) {
  check(false, `open registration: ${e.stack ?? e}`);
}
const database = process.env.RCAN_REGISTRY_DATABASE ?? '';
const insecure = await start(onDatabase());
console.log(`registry database: ${database ? 'PostgreSQL' : 'SQLite'}`);
const secure = await start(['--public-url', 'https://registry.example', ...onDatabase('_4')]);
try {
  await registryClient(insecure);
  const r = await post(secure, '/api/v1/robots', { manufacturer: 'acme', model: 'arm', version: 'v2', device_id: 'n-1' }, secure.admin);
  await nodeClient(secure, r.body.rrn);
  const nc = new sdk.NodeClient(insecure.url, 5000);
  try {
    await nc.getNodeManifest(insecure.url);
    check(false, 'an http:// api_base fails getNodeManifest');
  } catch (e) {
    check(e instanceof sdk.RCANNodeTrustError, 'an http:// api_base fails getNodeManifest (RCANNodeTrustError)');
  }
} catch (e) {
  check(false, `unexpected: ${e.stack ?? e}`);
} finally {
  await insecure.stop();
  await secure.stop();
}
console.log(`${failures.length} failure(s)`);
process.exit(failures.length ? 1 : 0);
