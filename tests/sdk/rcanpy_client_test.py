#!/usr/bin/env python3
"""rcan-py 3.4.1 (third_party/rcan-py) as a real client of a live rcand.

Messages are built with the SDK's RCANMessage / RobotURI and signed with its own functions
(rcan.signing.sign_message with MLDSAKeyPair, rcan.hybrid.sign_body); they go to rcand over HTTP
(POST /rcan/v1/command) and over the WebSocket stream (/rcan/v1/stream), and every answer is
checked against docs/PROTOCOL.md. rcan-py 3.4.1 has no Ed25519 message signer (its KeyPair
raises); the Ed25519 case signs the SDK's own pre-image (rcan.signing._canonical_message_bytes)
with an Ed25519 key, as older rcan-py's KeyPair did.

Exit 0 pass, 1 fail, 77 skip (CTest SKIP_RETURN_CODE): RCAND_PATH / RCAN_CLI_PATH missing, or
no `cryptography` with Ed25519.
"""
import base64
import copy
import hashlib
import json
import os
import re
import shutil
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
import uuid
import urllib.error
import urllib.request

SKIP = 77
HERE = os.path.dirname(os.path.abspath(__file__))
THIRD_PARTY = os.path.join(os.path.dirname(os.path.dirname(HERE)), "third_party")
sys.path.insert(0, os.path.join(THIRD_PARTY, "rcan-py"))
sys.path.insert(0, os.path.join(THIRD_PARTY, "dilithium-py", "src"))


def skip(why):
    print(f"SKIP: {why}")
    sys.exit(SKIP)


RCAND = os.environ.get("RCAND_PATH", "")
CLI = os.environ.get("RCAN_CLI_PATH", "")
if not os.path.isfile(RCAND):
    skip("RCAND_PATH does not name an rcand binary")
if not os.path.isfile(CLI):
    skip("RCAN_CLI_PATH does not name the rcan CLI")
try:
    from cryptography.hazmat.primitives import serialization
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey
except ImportError as e:  # Debian: python3-cryptography (scripts/install-deps.sh)
    skip(f"python3 has no cryptography with Ed25519: {e}")
if not shutil.which("openssl"):
    skip("no openssl to make the token issuer's key")

import rcan  # noqa: E402  (the SDK under test)
from rcan import RCANMessage, RobotURI  # noqa: E402
from rcan.crypto import MlDsaKeyPair  # noqa: E402
from rcan.hybrid import sign_body, verify_body  # noqa: E402
from rcan.message import MessageType, RCANResponse  # noqa: E402
from rcan.signing import KeyPair, MLDSAKeyPair, _canonical_message_bytes, sign_message  # noqa: E402

failures = []
notes = []


def check(cond, what):
    print(f"{'ok' if cond else 'FAIL'} - {what}")
    if not cond:
        failures.append(what)


# ---------------------------------------------------------------------------------------------
# rcand on a temp data dir, with the SDK's keys as trusted signer keys.

RURI = "rcan://local.rcan/acme/rover/0a1b2c3d"


class Ed25519Key:
    def __init__(self):
        self.priv = Ed25519PrivateKey.generate()
        self.seed = self.priv.private_bytes(serialization.Encoding.Raw, serialization.PrivateFormat.Raw,
                                            serialization.NoEncryption())
        self.pub = self.priv.public_key().public_bytes(serialization.Encoding.Raw, serialization.PublicFormat.Raw)
        pem = self.priv.public_key().public_bytes(serialization.Encoding.PEM,
                                                  serialization.PublicFormat.SubjectPublicKeyInfo)
        self.kid = hashlib.sha256(pem).hexdigest()[:8]  # older rcan-py KeyPair.key_id


def start_rcand(work, operator, operator_ed):
    data = os.path.join(work, "data")
    os.makedirs(data, mode=0o700)
    subprocess.run([CLI, "keys", "generate", "--dir", os.path.join(data, "keys")], check=True, capture_output=True)
    subprocess.run([CLI, "audit", "new-secret", "--out", os.path.join(data, "audit.secret")], check=True,
                   capture_output=True)
    key, pub = os.path.join(work, "issuer.pem"), os.path.join(work, "issuer.pub.pem")
    subprocess.run(["openssl", "genpkey", "-algorithm", "ed25519", "-out", key], check=True, capture_output=True)
    os.chmod(key, 0o600)
    subprocess.run(["openssl", "pkey", "-in", key, "-pubout", "-out", pub], check=True, capture_output=True)
    with open(os.path.join(work, "operator.mldsa65.pub"), "wb") as f:
        f.write(operator.public_key)
    with open(os.path.join(work, "operator.ed25519.pub"), "wb") as f:
        f.write(operator_ed.pub)
    cfg = os.path.join(work, "robot.rcan.yaml")
    with open(cfg, "w") as f:
        f.write("\n".join([
            'rcan_version: "1.2"', f"ruri: {RURI}",
            "robot:", "  name: sdk-rover", "  manufacturer: acme", "  model: rover", "  type: mobile",
            "safety:", "  local_safety_wins: true",
            "security:", "  jwt:", "    issuers:", "      - issuer: ops.example", f"        key_file: {pub}",
            "  trusted_signer_keys:",
            f"    - {{name: operator, mldsa65_pub_file: {work}/operator.mldsa65.pub, "
            f"ed25519_pub_file: {work}/operator.ed25519.pub}}", ""]))
    proc = subprocess.Popen([RCAND, "--config", cfg, "--data-dir", data, "--port", "0"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    log, url = [], [None]
    ready = threading.Event()

    def pump():
        for line in proc.stderr:
            log.append(line)
            m = re.search(r'"event":"listening".*"url":"(http://[^"]+)"', line)
            if m and not ready.is_set():
                url[0] = m.group(1)
                ready.set()
        ready.set()

    threading.Thread(target=pump, daemon=True).start()
    ready.wait(20)
    if not url[0]:
        proc.kill()
        raise RuntimeError("rcand did not start:\n" + "".join(log))
    token = subprocess.run([CLI, "token", "issue", "--key", key, "--iss", "ops.example", "--sub", "operator-1",
                            "--role", "user", "--aud", RURI, "--scope", "status,control", "--ttl", "1h"],
                           check=True, capture_output=True, text=True).stdout.strip()
    return proc, url[0], token


def post(base, token, body):
    data = body if isinstance(body, bytes) else json.dumps(body).encode()
    req = urllib.request.Request(base + "/rcan/v1/command", data=data, method="POST",
                                 headers={"Authorization": f"Bearer {token}", "Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(req, timeout=10) as r:
            return r.status, json.loads(r.read() or b"null")
    except urllib.error.HTTPError as e:
        text = e.read()
        try:
            return e.code, json.loads(text)
        except ValueError:
            return e.code, {"raw": text.decode(errors="replace")}


def get(base, path, token):
    req = urllib.request.Request(base + path, headers={"Authorization": f"Bearer {token}"} if token else {})
    with urllib.request.urlopen(req, timeout=10) as r:
        return r.status, json.loads(r.read())


def code_of(body):
    try:
        return body["payload"]["error_code"]
    except (KeyError, TypeError):
        return None


# ---------------------------------------------------------------------------------------------
# A minimal WebSocket client (RFC 6455, text frames, client masking) for the node's stream.

class WebSocket:
    def __init__(self, base, path):
        host, port = re.match(r"http://([^:/]+):(\d+)", base).groups()
        self.sock = socket.create_connection((host, int(port)), timeout=10)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall((f"GET {path} HTTP/1.1\r\nHost: {host}:{port}\r\nUpgrade: websocket\r\n"
                           f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n").encode())
        head = b""
        while b"\r\n\r\n" not in head:
            chunk = self.sock.recv(1)
            if not chunk:
                raise RuntimeError("WebSocket handshake: connection closed")
            head += chunk
        if b" 101 " not in head.split(b"\r\n")[0]:
            raise RuntimeError(f"WebSocket handshake refused: {head!r}")

    def send(self, obj):
        data = (obj if isinstance(obj, str) else json.dumps(obj)).encode()
        mask = os.urandom(4)
        n = len(data)
        hdr = bytes([0x81]) + (bytes([0x80 | n]) if n < 126 else
                               bytes([0x80 | 126]) + struct.pack(">H", n) if n < 65536 else
                               bytes([0x80 | 127]) + struct.pack(">Q", n))
        self.sock.sendall(hdr + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(data)))

    def _exact(self, n):
        out = b""
        while len(out) < n:
            chunk = self.sock.recv(n - len(out))
            if not chunk:
                raise RuntimeError("WebSocket closed")
            out += chunk
        return out

    def recv(self):
        """The next text frame as JSON (events and telemetry included)."""
        while True:
            b0, b1 = self._exact(2)
            n = b1 & 0x7F
            if n == 126:
                n = struct.unpack(">H", self._exact(2))[0]
            elif n == 127:
                n = struct.unpack(">Q", self._exact(8))[0]
            payload = self._exact(n)
            if b0 & 0x0F == 0x1:
                return json.loads(payload)
            if b0 & 0x0F == 0x8:
                raise RuntimeError(f"WebSocket closed by the node: {payload!r}")

    def answer_to(self, msg_id=None):
        """The ACK or ERROR answering a message (skipping pushed events)."""
        deadline = time.time() + 10
        while time.time() < deadline:
            f = self.recv()
            if f.get("type") in ("ACK", "ERROR"):
                return f
        raise RuntimeError("no answer on the stream")

    def close(self):
        try:
            self.sock.close()
        except OSError:
            pass


# ---------------------------------------------------------------------------------------------

def main():
    work = tempfile.mkdtemp(prefix="rcanpy-sdk-")
    proc = None
    try:
        operator = MLDSAKeyPair.generate()          # rcan.signing (message signing)
        operator_pq = MlDsaKeyPair(key_id=operator.key_id, public_key_bytes=operator.public_key,
                                   _secret_key=operator._secret_key)  # rcan.crypto (hybrid bodies)
        operator_ed = Ed25519Key()
        stranger = MLDSAKeyPair.generate()
        stranger_ed = Ed25519Key()
        proc, base, token = start_rcand(work, operator, operator_ed)
        print(f"rcand at {base}, rcan-py {rcan.__version__}")

        # The robot's identity as the SDK writes it, copied from status and discovery.
        st, status = get(base, "/rcan/v1/status", None)
        sdk_ruri = status.get("ruri_sdk", "")
        check(status.get("ruri") == RURI and sdk_ruri == "rcan://local.rcan/acme/rover/v1/0a1b2c3d",
              f"status advertises both RURI forms ({status.get('ruri')}, {sdk_ruri})")
        target = RobotURI.parse(sdk_ruri)
        check(str(target) == sdk_ruri and target.device_id == "0a1b2c3d",
              "rcan-py RobotURI.parse reads status's ruri_sdk as the robot's identity")
        st, disc = get(base, "/api/discovery", None)
        check(disc.get("txt_record", {}).get("ruri_sdk") == sdk_ruri, "discovery's TXT record carries ruri_sdk")

        def move(linear=0.1):
            return RCANMessage(cmd="move", target=target, params={"linear": linear, "duration_ms": 100})

        def hybrid(msg, kp=operator_pq, ed=operator_ed):
            return sign_body(kp, msg.to_dict(), ed25519_secret=ed.seed, ed25519_public=ed.pub)

        def ed25519_signed(msg, ed):  # rcan-py's own pre-image, an Ed25519 sig block
            sig = ed.priv.sign(_canonical_message_bytes(msg))
            msg.signature = {"alg": "ed25519", "kid": ed.kid, "value": base64.urlsafe_b64encode(sig).decode()}
            return msg

        # --- HTTP -------------------------------------------------------------------------------
        st, body = post(base, token, move().to_dict())
        check(st == 200 and body.get("type") == "ACK", f"HTTP: unsigned rcan-py message + token is ACKed ({st})")
        sent = move()
        st, body = post(base, token, sent.to_dict())
        resp = RCANResponse.from_dict(body or {})
        check(st == 200 and resp.ok and resp.msg_id == sent.msg_id and resp.safety_approved
              and resp.result.get("applied", {}).get("drive", {}).get("linear_mps") == 0.1,
              f"rcan-py RCANResponse.from_dict reads rcand's ACK as ok for its msg_id, with the result "
              f"({resp.status}, {resp.msg_id}, {resp.result})")

        signed = sign_message(move(), operator)
        check(signed.to_dict()["sig"]["alg"] == "ml-dsa-65", "rcan-py sign_message wrote an ml-dsa-65 sig block")
        wire = json.dumps(signed.to_dict()).encode()
        st, body = post(base, token, wire)
        check(st == 200 and body.get("type") == "ACK", f"HTTP: ML-DSA-65-signed (sign_message) is ACKed ({st} {code_of(body)})")
        st, body = post(base, token, wire)
        check(st == 409 and code_of(body) == "REPLAY_DETECTED", f"HTTP: the same signed message again is 409 REPLAY_DETECTED ({st} {code_of(body)})")
        resp = RCANResponse.from_dict(body or {})
        check(not resp.ok and resp.status == "error" and resp.msg_id == signed.msg_id and "already used" in resp.message,
              f"rcan-py RCANResponse.from_dict reads the refusal as an error for its msg_id ({resp.status}: {resp.message})")

        tampered = signed.to_dict()
        tampered["params"] = {"linear": 0.5, "duration_ms": 100}
        st, body = post(base, token, tampered)
        check(st == 401 and code_of(body) == "SIGNATURE_INVALID", f"HTTP: params changed after signing is 401 SIGNATURE_INVALID ({st} {code_of(body)})")

        # Signed by a trusted operator for another robot (same fleet, next device id): the
        # signature is good, the target is not this robot.
        other = RobotURI.parse("rcan://local.rcan/acme/rover/v1/0a1b2c3e")
        st, body = post(base, token, sign_message(RCANMessage(cmd="move", target=other, params={"linear": 0.1, "duration_ms": 100}), operator).to_dict())
        check(st == 422 and code_of(body) == "COMMAND_REJECTED" and "0a1b2c3e" in json.dumps(body),
              f"HTTP: a signed message addressed to another robot is 422 COMMAND_REJECTED ({st} {code_of(body)})")

        st, body = post(base, token, sign_message(move(), stranger).to_dict())
        check(st == 401 and code_of(body) == "SIGNATURE_INVALID", f"HTTP: signed by an untrusted ML-DSA-65 key is 401 SIGNATURE_INVALID ({st} {code_of(body)})")

        try:
            KeyPair()
            notes.append("rcan-py KeyPair() constructed (expected its DeprecationWarning)")
        except DeprecationWarning:
            notes.append("rcan-py 3.4.1 KeyPair (Ed25519) raises DeprecationWarning: the Ed25519 case signs "
                         "rcan-py's pre-image with an Ed25519 key directly")
        st, body = post(base, token, ed25519_signed(move(), operator_ed).to_dict())
        check(st == 200 and body.get("type") == "ACK", f"HTTP: Ed25519-signed (rcan-py pre-image) is ACKed ({st} {code_of(body)})")
        st, body = post(base, token, ed25519_signed(move(), stranger_ed).to_dict())
        check(st == 401 and code_of(body) == "SIGNATURE_INVALID", f"HTTP: Ed25519 by an untrusted key is 401 SIGNATURE_INVALID ({st} {code_of(body)})")

        hb = hybrid(move())
        check(verify_body(hb, operator.public_key), "rcan-py verify_body accepts its own hybrid body")
        st, body = post(base, token, hb)
        check(st == 200 and body.get("type") == "ACK", f"HTTP: hybrid-signed (hybrid.sign_body) is ACKed ({st} {code_of(body)})")
        st, body = post(base, token, hb)
        check(st == 409 and code_of(body) == "REPLAY_DETECTED", f"HTTP: the same hybrid body again is 409 REPLAY_DETECTED ({st} {code_of(body)})")
        hbt = copy.deepcopy(hybrid(move()))
        hbt["params"]["linear"] = 0.5
        check(not verify_body(hbt, operator.public_key), "rcan-py verify_body refuses the tampered hybrid body")
        st, body = post(base, token, hbt)
        check(st == 401 and code_of(body) == "SIGNATURE_INVALID", f"HTTP: hybrid body changed after signing is 401 SIGNATURE_INVALID ({st} {code_of(body)})")
        st, body = post(base, token, hybrid(move(), ed=stranger_ed))
        check(st == 401 and code_of(body) == "SIGNATURE_INVALID", f"HTTP: hybrid with an untrusted Ed25519 key is 401 SIGNATURE_INVALID ({st} {code_of(body)})")
        stranger_pq = MlDsaKeyPair(key_id=stranger.key_id, public_key_bytes=stranger.public_key,
                                   _secret_key=stranger._secret_key)
        st, body = post(base, token, hybrid(move(), kp=stranger_pq))
        check(st == 401 and code_of(body) == "SIGNATURE_INVALID", f"HTTP: hybrid with an untrusted ML-DSA-65 key is 401 SIGNATURE_INVALID ({st} {code_of(body)})")

        # --- INVOKE (skills) ----------------------------------------------------------------------
        def invoke(skill, **params):
            return RCANMessage(type=MessageType.INVOKE, cmd=skill, target=target, params=params)

        inv = invoke("scan_environment", duration_ms=200)
        if "type" not in inv.to_dict():
            notes.append("rcan-py RCANMessage.to_dict() drops type=INVOKE: an SDK INVOKE is a COMMAND on the "
                         "wire unless the sender adds \"type\": 11")
        st, body = post(base, token, inv.to_dict())
        check(st == 200 and body.get("type") == "ACK", f"HTTP: the simulator's skill scan_environment is ACKed ({st} {code_of(body)})")
        typed = sign_message(invoke("scan_environment", duration_ms=150), operator).to_dict()
        typed["type"] = int(MessageType.INVOKE)
        st, body = post(base, token, typed)
        check(st == 200 and body.get("type") == "ACK", f"HTTP: a signed INVOKE (type 11) of scan_environment is ACKed ({st} {code_of(body)})")
        for skill in ("juggle", "dock"):  # not a skill at all / a skill the simulator does not offer
            d = {**invoke(skill, speed=1).to_dict(), "type": int(MessageType.INVOKE)}
            st, body = post(base, token, d)
            p = (body or {}).get("payload") or {}
            check(st == 404 and body.get("type") == "ERROR" and p.get("error_code") == "NOT_FOUND"
                  and p.get("reason") == "unknown_skill" and (p.get("detail") or {}).get("field") == "payload.skill",
                  f"HTTP: INVOKE of {skill} is 404 NOT_FOUND/unknown_skill with the error body ({st} {code_of(body)})")
        st, body = post(base, token, invoke("juggle").to_dict())
        check(st == 422 and code_of(body) == "COMMAND_REJECTED", f"HTTP: the same name as a plain COMMAND is 422 COMMAND_REJECTED ({st} {code_of(body)})")

        # --- WebSocket --------------------------------------------------------------------------
        ws = WebSocket(base, "/rcan/v1/stream")
        try:
            ws.send({"type": "CONNECT", "token": token})
            ack = ws.recv()
            check(ack.get("type") == "CONNECT_ACK", f"WS: CONNECT with the token is CONNECT_ACKed ({ack.get('type')})")
            ws.send(move().to_dict())
            a = ws.answer_to()
            check(a.get("type") == "ACK", f"WS: unsigned rcan-py message is ACKed ({a.get('type')} {code_of(a)})")
            wire = json.dumps(sign_message(move(), operator).to_dict())
            ws.send(wire)
            a = ws.answer_to()
            check(a.get("type") == "ACK", f"WS: ML-DSA-65-signed is ACKed ({a.get('type')} {code_of(a)})")
            ws.send(wire)
            a = ws.answer_to()
            check(code_of(a) == "REPLAY_DETECTED", f"WS: the same message again is REPLAY_DETECTED ({code_of(a)})")
            ws.send(ed25519_signed(move(), operator_ed).to_dict())
            a = ws.answer_to()
            check(a.get("type") == "ACK", f"WS: Ed25519-signed is ACKed ({a.get('type')} {code_of(a)})")
            ws.send(hybrid(move()))
            a = ws.answer_to()
            check(a.get("type") == "ACK", f"WS: hybrid-signed is ACKed ({a.get('type')} {code_of(a)})")
            t = sign_message(move(), operator).to_dict()
            t["cmd"] = "rotate"
            ws.send(t)
            a = ws.answer_to()
            check(code_of(a) == "SIGNATURE_INVALID", f"WS: cmd changed after signing is SIGNATURE_INVALID ({code_of(a)})")
            ws.send(sign_message(move(), stranger).to_dict())
            a = ws.answer_to()
            check(code_of(a) == "SIGNATURE_INVALID", f"WS: an untrusted key is SIGNATURE_INVALID ({code_of(a)})")
            ws.send({**invoke("juggle").to_dict(), "type": int(MessageType.INVOKE)})
            a = ws.answer_to()
            check(code_of(a) == "NOT_FOUND", f"WS: INVOKE of an unknown skill is NOT_FOUND ({code_of(a)})")
        finally:
            ws.close()

        # --- A safety refusal as rcan-py reads it (last: the ESTOP stays latched) ----------------
        st, body = post(base, token, {"version": "1.0.0", "message_id": str(uuid.uuid4()), "type": "SAFETY",
                                      "timestamp_ms": int(time.time() * 1000), "payload": {"safety_event": "ESTOP"}})
        check(st == 200 and body.get("type") == "ACK", f"HTTP: ESTOP is ACKed ({st} {code_of(body)})")
        sent = move()
        st, body = post(base, token, sent.to_dict())
        resp = RCANResponse.from_dict(body or {})
        check(st == 423 and resp.blocked and not resp.safety_approved and resp.safety_reason == "estop_active"
              and resp.msg_id == sent.msg_id,
              f"rcan-py RCANResponse.from_dict reads a move during ESTOP as blocked by safety "
              f"({st} {resp.status} {resp.safety_approved} {resp.safety_reason})")
    except Exception as e:  # an exception is a failure, never a pass
        import traceback
        traceback.print_exc()
        failures.append(f"exception: {e}")
    finally:
        if proc:
            proc.terminate()
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                proc.kill()
        shutil.rmtree(work, ignore_errors=True)
    for n in notes:
        print(f"note: {n}")
    if failures:
        print(f"{len(failures)} failure(s)")
        return 1
    print("all rcan-py client checks passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
