// rcan-ts 3.4.2 (third_party/rcan-ts, built by scripts/install-deps.sh) as a real client of a live rcand.
// Messages are built with the SDK's RCANMessage / RobotURI and signed with its own functions
// (signMessage with MLDSAKeyPair, signBody, signHybrid over canonicalJson); they go to rcand over
// HTTP (POST /rcan/v1/command) and over the WebSocket stream (/rcan/v1/stream), and every answer
// is checked against docs/PROTOCOL.md — including the replay identity rcand derives for rcan-ts
// messages, which carry no msg_id. rcan-ts has no Ed25519-only message signature: Ed25519 is
// checked as the half of the hybrid forms.
//
// Exit 0 pass, 1 fail, 77 skip (CTest SKIP_RETURN_CODE): RCAND_PATH / RCAN_CLI_PATH missing, or
// the SDK not built (dist/index.mjs).

import { execFileSync, spawn } from 'node:child_process';
import { createHash, generateKeyPairSync, randomBytes, webcrypto } from 'node:crypto';
import { chmodSync, existsSync, mkdirSync, mkdtempSync, rmSync, writeFileSync } from 'node:fs';
import net from 'node:net';
import { tmpdir } from 'node:os';
import { dirname, join } from 'node:path';
import { fileURLToPath } from 'node:url';

// Node 18 (Debian 12's nodejs) has no global Web Crypto unless asked; the SDK's ML-DSA library
// (@noble/post-quantum) draws its key seeds from globalThis.crypto.getRandomValues.
if (!globalThis.crypto) globalThis.crypto = webcrypto;

const SKIP = 77;
const here = dirname(fileURLToPath(import.meta.url));
const sdkDist = join(here, '..', '..', 'third_party', 'rcan-ts', 'dist', 'index.mjs');
const rcandPath = process.env.RCAND_PATH;
const cliPath = process.env.RCAN_CLI_PATH;

function skip(why) {
  console.log(`SKIP: ${why}`);
  process.exit(SKIP);
}
if (!rcandPath || !existsSync(rcandPath)) skip('RCAND_PATH does not name an rcand binary');
if (!cliPath || !existsSync(cliPath)) skip('RCAN_CLI_PATH does not name the rcan CLI');
if (!existsSync(sdkDist)) skip('rcan-ts is not built (scripts/install-deps.sh runs npm ci + tsup in third_party/rcan-ts)');
const sdk = await import(sdkDist);
const { RCANMessage, MessageType, RobotURI, MLDSAKeyPair, signMessage, verifyMessage, signBody, verifyBody, signHybrid, canonicalJson } = sdk;

const failures = [];
const notes = [];
function check(cond, what) {
  console.log(`${cond ? 'ok' : 'FAIL'} - ${what}`);
  if (!cond) failures.push(what);
}

const RURI = 'rcan://local.rcan/acme/rover/0a1b2c3d';

function ed25519Key() {
  const { privateKey, publicKey } = generateKeyPairSync('ed25519');
  const jwk = privateKey.export({ format: 'jwk' });
  return { seed: Buffer.from(jwk.d, 'base64url'), pub: Buffer.from(jwk.x, 'base64url'), privateKey, publicKey };
}

async function startRcand(work, operator, operatorEd, peer, peerEd) {
  const data = join(work, 'data');
  mkdirSync(data, { recursive: true, mode: 0o700 });
  execFileSync(cliPath, ['keys', 'generate', '--dir', join(data, 'keys')]);
  execFileSync(cliPath, ['audit', 'new-secret', '--out', join(data, 'audit.secret')]);
  const key = join(work, 'issuer.pem');
  const pub = join(work, 'issuer.pub.pem');
  execFileSync('openssl', ['genpkey', '-algorithm', 'ed25519', '-out', key]);
  chmodSync(key, 0o600);
  execFileSync('openssl', ['pkey', '-in', key, '-pubout', '-out', pub]);
  writeFileSync(join(work, 'operator.mldsa65.pub'), operator.publicKey);
  writeFileSync(join(work, 'operator.ed25519.pub'), operatorEd.pub);
  writeFileSync(join(work, 'peer.mldsa65.pub'), peer.publicKey);
  writeFileSync(join(work, 'peer.ed25519.pub'), peerEd.pub);
  const cfg = join(work, 'robot.rcan.yaml');
  writeFileSync(cfg, [
    'rcan_version: "1.2"', `ruri: ${RURI}`,
    'robot:', '  name: sdk-rover', '  manufacturer: acme', '  model: rover', '  type: mobile',
    'safety:', '  local_safety_wins: true',
    'security:', '  jwt:', '    issuers:', '      - issuer: ops.example', `        key_file: ${pub}`,
    '  trusted_signer_keys:',
    `    - {name: operator, mldsa65_pub_file: ${work}/operator.mldsa65.pub, ed25519_pub_file: ${work}/operator.ed25519.pub}`,
    '  trusted_robot_keys:',
    `    - {name: peer, mldsa65_pub_file: ${work}/peer.mldsa65.pub, ed25519_pub_file: ${work}/peer.ed25519.pub}`,
    ''].join('\n'));
  const proc = spawn(rcandPath, ['--config', cfg, '--data-dir', data, '--port', '0'], { stdio: ['ignore', 'ignore', 'pipe'] });
  let log = '';
  const url = await new Promise((resolve, reject) => {
    const timer = setTimeout(() => reject(new Error(`rcand did not start:\n${log}`)), 20000);
    proc.stderr.on('data', (d) => {
      log += d.toString();
      const m = log.match(/"event":"listening"[^\n]*"url":"(http:\/\/[^"]+)"/);
      if (m) { clearTimeout(timer); resolve(m[1]); }
    });
    proc.on('exit', (code) => { clearTimeout(timer); reject(new Error(`rcand exited ${code}:\n${log}`)); });
  });
  proc.removeAllListeners('exit');
  const token = execFileSync(cliPath, ['token', 'issue', '--key', key, '--iss', 'ops.example', '--sub', 'operator-1',
    '--role', 'user', '--aud', RURI, '--scope', 'status,control', '--ttl', '1h'], { encoding: 'utf8' }).trim();
  const ownerToken = execFileSync(cliPath, ['token', 'issue', '--key', key, '--iss', 'ops.example', '--sub', 'auditor',
    '--role', 'owner', '--aud', RURI, '--scope', 'status', '--ttl', '1h'], { encoding: 'utf8' }).trim();
  return { proc, url, token, ownerToken };
}

async function post(base, token, body) {
  const res = await fetch(`${base}/rcan/v1/command`, {
    method: 'POST',
    headers: { Authorization: `Bearer ${token}`, 'Content-Type': 'application/json' },
    body: typeof body === 'string' ? body : JSON.stringify(body),
  });
  const text = await res.text();
  let json = null;
  try { json = JSON.parse(text); } catch (_) { json = { raw: text }; }
  return { status: res.status, json };
}
const codeOf = (b) => b?.payload?.error_code ?? null;

// A minimal WebSocket client (RFC 6455 text frames, client masking) — Node 18/20 have none built in.
class Ws {
  static open(base, path) {
    const { hostname, port } = new URL(base);
    return new Promise((resolve, reject) => {
      const sock = net.connect(Number(port), hostname);
      const ws = new Ws(sock);
      let head = Buffer.alloc(0);
      const onData = (d) => {
        head = Buffer.concat([head, d]);
        const end = head.indexOf('\r\n\r\n');
        if (end < 0) return;
        sock.off('data', onData);
        if (!/^HTTP\/1\.1 101/.test(head.toString('latin1'))) return reject(new Error(`handshake refused: ${head}`));
        sock.on('data', (x) => ws.#feed(x));
        ws.#feed(head.subarray(end + 4));
        resolve(ws);
      };
      sock.on('data', onData);
      sock.on('error', reject);
      sock.write(`GET ${path} HTTP/1.1\r\nHost: ${hostname}:${port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n` +
        `Sec-WebSocket-Key: ${randomBytes(16).toString('base64')}\r\nSec-WebSocket-Version: 13\r\n\r\n`);
    });
  }
  #buf = Buffer.alloc(0);
  #frames = [];
  #waiters = [];
  constructor(sock) { this.sock = sock; }
  #feed(d) {
    this.#buf = Buffer.concat([this.#buf, d]);
    for (;;) {
      if (this.#buf.length < 2) return;
      let n = this.#buf[1] & 0x7f;
      let off = 2;
      if (n === 126) { if (this.#buf.length < 4) return; n = this.#buf.readUInt16BE(2); off = 4; }
      else if (n === 127) { if (this.#buf.length < 10) return; n = Number(this.#buf.readBigUInt64BE(2)); off = 10; }
      if (this.#buf.length < off + n) return;
      const op = this.#buf[0] & 0x0f;
      const payload = this.#buf.subarray(off, off + n);
      this.#buf = this.#buf.subarray(off + n);
      if (op === 1) {
        const f = JSON.parse(payload.toString('utf8'));
        const w = this.#waiters.shift();
        if (w) w(f); else this.#frames.push(f);
      }
    }
  }
  send(obj) {
    const data = Buffer.from(typeof obj === 'string' ? obj : JSON.stringify(obj), 'utf8');
    const mask = randomBytes(4);
    let hdr;
    if (data.length < 126) hdr = Buffer.from([0x81, 0x80 | data.length]);
    else if (data.length < 65536) { hdr = Buffer.alloc(4); hdr[0] = 0x81; hdr[1] = 0x80 | 126; hdr.writeUInt16BE(data.length, 2); }
    else { hdr = Buffer.alloc(10); hdr[0] = 0x81; hdr[1] = 0x80 | 127; hdr.writeBigUInt64BE(BigInt(data.length), 2); }
    const masked = Buffer.alloc(data.length);
    for (let i = 0; i < data.length; i++) masked[i] = data[i] ^ mask[i % 4];
    this.sock.write(Buffer.concat([hdr, mask, masked]));
  }
  recv(timeoutMs = 10000) {
    if (this.#frames.length) return Promise.resolve(this.#frames.shift());
    return new Promise((resolve, reject) => {
      const t = setTimeout(() => reject(new Error('no frame on the stream')), timeoutMs);
      this.#waiters.push((f) => { clearTimeout(t); resolve(f); });
    });
  }
  // The ACK or ERROR answering a message (pushed events skipped).
  async answer() {
    for (;;) {
      const f = await this.recv();
      if (f.type === 'ACK' || f.type === 'ERROR') return f;
    }
  }
  close() { this.sock.destroy(); }
}

async function main() {
  const work = mkdtempSync(join(tmpdir(), 'rcants-sdk-'));
  let proc = null;
  try {
    const operator = await MLDSAKeyPair.generate();
    const operatorKp = { privateKey: operator.secretKey, publicKey: operator.publicKey }; // signBody's key shape
    const operatorEd = ed25519Key();
    const stranger = await MLDSAKeyPair.generate();
    const strangerEd = ed25519Key();
    const peer = await MLDSAKeyPair.generate(); // a peer robot's keys (security.trusted_robot_keys)
    const peerEd = ed25519Key();
    let base, token, ownerToken;
    ({ proc, url: base, token, ownerToken } = await startRcand(work, operator, operatorEd, peer, peerEd));
    console.log(`rcand at ${base}`);

    // The robot's identity as the SDK writes it, copied from status and the ANNOUNCE answer.
    const status = await (await fetch(`${base}/rcan/v1/status`)).json();
    check(status.ruri === RURI && status.ruri_sdk === 'rcan://local.rcan/acme/rover/v1/0a1b2c3d',
      `status advertises both RURI forms (${status.ruri}, ${status.ruri_sdk})`);
    const target = RobotURI.parse(status.ruri_sdk);
    check(target.toString() === status.ruri_sdk && target.deviceId === '0a1b2c3d',
      'rcan-ts RobotURI.parse reads status\'s ruri_sdk as the robot\'s identity');
    const announce = await (await fetch(`${base}/rcan/v1/discover`, { method: 'POST' })).json();
    check(announce?.payload?.ruri_sdk === status.ruri_sdk, 'the DISCOVER answer (ANNOUNCE) carries ruri_sdk');
    let n = 0; // distinct params per message: rcan-ts timestamps have millisecond resolution
    const move = (extra = {}) => new RCANMessage({ cmd: 'move', target, params: { linear: 0.1, duration_ms: 100 + (n++) }, ...extra });
    const hybridBody = async (msg, kp = operatorKp, ed = operatorEd) =>
      signBody(kp, msg.toJSON(), { ed25519Secret: ed.seed, ed25519Public: ed.pub });

    // --- HTTP -----------------------------------------------------------------------------
    const plain = move();
    const plainWire = plain.toJSONString();
    check(!('msg_id' in JSON.parse(plainWire)) && typeof JSON.parse(plainWire).timestamp === 'string',
      'rcan-ts toJSONString has no msg_id and an ISO-string timestamp');
    let r = await post(base, token, plainWire);
    check(r.status === 200 && r.json?.type === 'ACK', `HTTP: unsigned rcan-ts message + token is ACKed (${r.status} ${codeOf(r.json)})`);
    r = await post(base, token, plainWire);
    check(r.status === 409 && codeOf(r.json) === 'REPLAY_DETECTED', `HTTP: the same rcan-ts message again (no msg_id) is 409 REPLAY_DETECTED (${r.status} ${codeOf(r.json)})`);

    const signed = await signMessage(move(), operator);
    check(signed.signature?.alg === 'ml-dsa-65', 'rcan-ts signMessage wrote an ml-dsa-65 signature block');
    await verifyMessage(signed, [operator]); // the SDK's own check passes (throws otherwise)
    const signedWire = signed.toJSONString();
    r = await post(base, token, signedWire);
    check(r.status === 200 && r.json?.type === 'ACK', `HTTP: ML-DSA-65-signed (signMessage) is ACKed (${r.status} ${codeOf(r.json)})`);
    r = await post(base, token, signedWire);
    check(r.status === 409 && codeOf(r.json) === 'REPLAY_DETECTED', `HTTP: the same signed message again is 409 REPLAY_DETECTED (${r.status} ${codeOf(r.json)})`);
    const reconf = JSON.parse(signedWire);
    reconf.confidence = 0.5; // outside rcan-ts's signature: must not make the message new
    r = await post(base, token, reconf);
    check(r.status === 409 && codeOf(r.json) === 'REPLAY_DETECTED', `HTTP: the signed message with an unsigned field added is still a replay (${r.status} ${codeOf(r.json)})`);

    const tampered = JSON.parse((await signMessage(move(), operator)).toJSONString());
    tampered.params.linear = 0.5;
    r = await post(base, token, tampered);
    check(r.status === 401 && codeOf(r.json) === 'SIGNATURE_INVALID', `HTTP: params changed after signMessage is 401 SIGNATURE_INVALID (${r.status} ${codeOf(r.json)})`);
    r = await post(base, token, (await signMessage(move(), stranger)).toJSONString());
    check(r.status === 401 && codeOf(r.json) === 'SIGNATURE_INVALID', `HTTP: signed by an untrusted ML-DSA-65 key is 401 SIGNATURE_INVALID (${r.status} ${codeOf(r.json)})`);

    const hb = await hybridBody(move());
    check(await verifyBody(hb, operator.publicKey), 'rcan-ts verifyBody accepts its own signBody output');
    r = await post(base, token, hb);
    check(r.status === 200 && r.json?.type === 'ACK', `HTTP: hybrid-signed (signBody) is ACKed (${r.status} ${codeOf(r.json)})`);
    r = await post(base, token, hb);
    check(r.status === 409 && codeOf(r.json) === 'REPLAY_DETECTED', `HTTP: the same hybrid body again is 409 REPLAY_DETECTED (${r.status} ${codeOf(r.json)})`);
    const hbt = structuredClone(await hybridBody(move()));
    hbt.params.linear = 0.5;
    check(!(await verifyBody(hbt, operator.publicKey)), 'rcan-ts verifyBody refuses the tampered body');
    r = await post(base, token, hbt);
    check(r.status === 401 && codeOf(r.json) === 'SIGNATURE_INVALID', `HTTP: hybrid body changed after signing is 401 SIGNATURE_INVALID (${r.status} ${codeOf(r.json)})`);
    r = await post(base, token, await hybridBody(move(), operatorKp, strangerEd));
    check(r.status === 401 && codeOf(r.json) === 'SIGNATURE_INVALID', `HTTP: hybrid with an untrusted Ed25519 key is 401 SIGNATURE_INVALID (${r.status} ${codeOf(r.json)})`);
    r = await post(base, token, await hybridBody(move(), { privateKey: stranger.secretKey, publicKey: stranger.publicKey }));
    check(r.status === 401 && codeOf(r.json) === 'SIGNATURE_INVALID', `HTTP: hybrid with an untrusted ML-DSA-65 key is 401 SIGNATURE_INVALID (${r.status} ${codeOf(r.json)})`);

    // A peer robot's key (security.trusted_robot_keys) verifies the rcan-ts forms too; the audit
    // record names the robot key that signed (kid: first 8 hex of SHA-256 of the raw public key).
    const kidOf = (pk) => createHash('sha256').update(pk).digest('hex').slice(0, 8);
    const recordOf = async (msgId) => {
      for (let i = 0; i < 50; i++) {
        const res = await fetch(`${base}/api/audit?limit=1000`, { headers: { Authorization: `Bearer ${ownerToken}` } });
        const rec = (await res.json()).entries?.find((e) => e.message_id === msgId);
        if (rec) return rec;
        await new Promise((res) => setTimeout(res, 100));
      }
      return null;
    };
    // A robot sender says so and names the human it acts for (§8.5), in rcan-ts's own camelCase.
    const asRobot = () => move({ senderType: 'robot', delegationChain: [{ issuerRuri: RURI, humanSubject: 'operator-1',
      timestamp: new Date().toISOString(), scope: 'control', signature: '' }] });
    r = await post(base, token, (await signMessage(asRobot(), operator)).toJSONString());
    check(r.status === 401 && codeOf(r.json) === 'AUTH_INVALID', `HTTP: senderType robot signed by an operator's key is 401 AUTH_INVALID (${r.status} ${codeOf(r.json)})`);
    for (const [form, body] of [['signMessage', (await signMessage(asRobot(), peer)).toJSONString()],
      ['signBody', await hybridBody(asRobot(), { privateKey: peer.secretKey, publicKey: peer.publicKey }, peerEd)]]) {
      r = await post(base, token, body);
      check(r.status === 200 && r.json?.type === 'ACK', `HTTP: ${form} by a trusted robot key is ACKed (${r.status} ${codeOf(r.json)} ${JSON.stringify(r.json?.payload)})`);
      const rec = r.json?.msg_id ? await recordOf(r.json.msg_id) : null;
      check(rec?.detail?.sig_kid === kidOf(peer.publicKey) && rec?.sender_type === 'robot',
        `HTTP: the audit record of the ${form} message names the robot key and a robot sender (${rec?.detail?.sig_kid} ${rec?.sender_type})`);
    }

    // signHybrid (the bytes-level primitive) over canonicalJson, carried in the signBody form.
    const sh = { ...move().toJSON(), pq_signing_pub: Buffer.from(operator.publicKey).toString('base64'), pq_kid: operator.keyId };
    const hs = signHybrid(operatorEd.seed, operator.secretKey, canonicalJson(sh));
    check(hs.profile === 'pqc-hybrid-v1', 'rcan-ts signHybrid made a pqc-hybrid-v1 signature');
    const shBody = { ...sh, sig: { ml_dsa: Buffer.from(hs.mlDsaSig).toString('base64'), ed25519: Buffer.from(hs.ed25519Sig).toString('base64'), ed25519_pub: operatorEd.pub.toString('base64') } };
    r = await post(base, token, shBody);
    check(r.status === 200 && r.json?.type === 'ACK', `HTTP: signHybrid over canonicalJson (signBody form) is ACKed (${r.status} ${codeOf(r.json)})`);
    const shBad = structuredClone(shBody);
    shBad.sig.ed25519 = Buffer.from(signHybrid(strangerEd.seed, operator.secretKey, canonicalJson(sh)).ed25519Sig).toString('base64');
    r = await post(base, token, { ...shBad, params: { ...shBad.params, duration_ms: 1 } });
    check(r.status === 401 && codeOf(r.json) === 'SIGNATURE_INVALID', `HTTP: signHybrid with a wrong Ed25519 half is 401 SIGNATURE_INVALID (${r.status} ${codeOf(r.json)})`);

    // --- INVOKE (skills): rcan-ts has MessageType.INVOKE but no type member on RCANMessage ---
    r = await post(base, token, new RCANMessage({ cmd: 'scan_environment', target, params: { duration_ms: 100 + (n++) } }).toJSONString());
    check(r.status === 200 && r.json?.type === 'ACK', `HTTP: the simulator's skill scan_environment is ACKed (${r.status} ${codeOf(r.json)})`);
    const inv = { ...new RCANMessage({ cmd: 'juggle', target, params: { n: n++ } }).toJSON(), type: MessageType.INVOKE };
    r = await post(base, token, inv);
    check(r.status === 404 && r.json?.type === 'ERROR' && codeOf(r.json) === 'NOT_FOUND' && r.json?.payload?.reason === 'unknown_skill',
      `HTTP: INVOKE (type ${MessageType.INVOKE}) of an unknown skill is 404 NOT_FOUND/unknown_skill (${r.status} ${codeOf(r.json)})`);

    // --- WebSocket ------------------------------------------------------------------------
    const ws = await Ws.open(base, '/rcan/v1/stream');
    try {
      ws.send({ type: 'CONNECT', token });
      const ack = await ws.recv();
      check(ack.type === 'CONNECT_ACK', `WS: CONNECT with the token is CONNECT_ACKed (${ack.type})`);
      const u = move().toJSONString();
      ws.send(u);
      let a = await ws.answer();
      check(a.type === 'ACK', `WS: unsigned rcan-ts message is ACKed (${a.type} ${codeOf(a)})`);
      ws.send(u);
      a = await ws.answer();
      check(codeOf(a) === 'REPLAY_DETECTED', `WS: the same rcan-ts message again is REPLAY_DETECTED (${codeOf(a)})`);
      ws.send((await signMessage(move(), operator)).toJSONString());
      a = await ws.answer();
      check(a.type === 'ACK', `WS: ML-DSA-65-signed is ACKed (${a.type} ${codeOf(a)})`);
      ws.send(await hybridBody(move()));
      a = await ws.answer();
      check(a.type === 'ACK', `WS: hybrid-signed (signBody) is ACKed (${a.type} ${codeOf(a)})`);
      const t = JSON.parse((await signMessage(move(), operator)).toJSONString());
      t.cmd = 'rotate';
      ws.send(t);
      a = await ws.answer();
      check(codeOf(a) === 'SIGNATURE_INVALID', `WS: cmd changed after signing is SIGNATURE_INVALID (${codeOf(a)})`);
      ws.send((await signMessage(move(), stranger)).toJSONString());
      a = await ws.answer();
      check(codeOf(a) === 'SIGNATURE_INVALID', `WS: an untrusted key is SIGNATURE_INVALID (${codeOf(a)})`);
      ws.send(await hybridBody(move(), operatorKp, strangerEd));
      a = await ws.answer();
      check(codeOf(a) === 'SIGNATURE_INVALID', `WS: hybrid with an untrusted Ed25519 key is SIGNATURE_INVALID (${codeOf(a)})`);
    } finally {
      ws.close();
    }
    notes.push('rcan-ts RCANMessage.toJSON never writes pqSig ("field 16"): only `signature` reaches the wire');
  } catch (e) {
    failures.push(`exception: ${e.stack || e}`);
    console.log(`FAIL - ${e.stack || e}`);
  } finally {
    if (proc) {
      const stopped = new Promise((res) => proc.once('exit', res));
      proc.kill('SIGTERM');
      await Promise.race([stopped, new Promise((res) => setTimeout(res, 10000))]);
      if (proc.exitCode === null) proc.kill('SIGKILL');
    }
    rmSync(work, { recursive: true, force: true });
  }
  for (const note of notes) console.log(`note: ${note}`);
  if (failures.length) {
    console.log(`${failures.length} failure(s)`);
    process.exit(1);
  }
  console.log('all rcan-ts client checks passed');
  process.exit(0);
}

await main();
