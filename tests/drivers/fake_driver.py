#!/usr/bin/env python3
"""A driver process that misbehaves on purpose, for process_driver_test.

  fake_driver.py MODE [--after-ms N] [--record FILE]

It answers describe and heartbeats correctly, and after --after-ms (default 300) does what
MODE says: good (nothing), garbage (a frame that is not JSON), oversize (a length over the
maximum), badtype (a state with a string where a number belongs), unknown (an unknown frame
type), silent (stops answering but stays alive), exit (exits with status 3), fault (reports a
fault in its heartbeats), narrow (describes a narrower envelope than rcand's). With --record,
every frame received is appended to FILE as one JSON line.
"""
import json
import os
import socket
import struct
import sys
import time

mode = sys.argv[1]
after = 0.3
record = None
for i, a in enumerate(sys.argv):
    if a == "--after-ms":
        after = int(sys.argv[i + 1]) / 1000.0
    if a == "--record":
        record = open(sys.argv[i + 1], "a", buffering=1)

sock = socket.socket(fileno=int(os.environ["RCAN_DRIVER_FD"]))
sock.settimeout(0.02)
start = time.monotonic()
buf = b""
done = False


def send(obj):
    data = obj if isinstance(obj, bytes) else json.dumps(obj).encode()
    sock.sendall(struct.pack(">I", len(data)) + data)


def serve():
    global buf, done
    while True:
        try:
            chunk = sock.recv(65536)
            if not chunk:
                sys.exit(0)
            buf += chunk
        except socket.timeout:
            pass
        late = time.monotonic() - start > after
        while len(buf) >= 4:
            (n,) = struct.unpack(">I", buf[:4])
            if len(buf) < 4 + n:
                break
            f = json.loads(buf[4:4 + n])
            buf = buf[4 + n:]
            if record:
                record.write(json.dumps(f) + "\n")
            if late and mode == "silent":
                continue
            if f["type"] == "describe":
                send({"type": "describe", "protocol": 1, "name": "fake-" + mode,
                      "max_linear_mps": 0.1 if mode == "narrow" else 5.0})
            elif f["type"] == "heartbeat":
                hb = {"type": "heartbeat", "seq": f["seq"]}
                if late and mode == "fault":
                    hb["fault"] = "motor overheated"
                send(hb)
        if late and not done:
            done = True
            if mode == "garbage":
                send(b"hello, not json")
            elif mode == "oversize":
                sock.sendall(struct.pack(">I", 1 << 24))
            elif mode == "badtype":
                send({"type": "state", "state": {"base": {"x": "far"}}})
            elif mode == "unknown":
                send({"type": "selfdestruct"})
            elif mode == "exit":
                sys.exit(3)


try:
    serve()
except (OSError, ValueError):
    sys.exit(0)
