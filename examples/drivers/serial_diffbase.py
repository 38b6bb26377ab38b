#!/usr/bin/env python3
"""Reference rcand driver process: a differential-drive base on a serial port.

Python standard library only. rcand starts it (driver.type: process, driver.process.command)
and hands it a connected Unix stream socket as file descriptor 3 (RCAN_DRIVER_FD=3); with
--listen PATH it instead listens on a Unix socket (mode 0600) for an rcand configured with
driver.process.socket. The protocol is documented in docs/DRIVERS.md (§Driver processes):
frames of a 4-byte big-endian length and one JSON object.

The base speaks a line protocol (ASCII, one command per line, '\\n'-terminated):

  driver -> base   V <left_mps> <right_mps>    wheel surface speeds, m/s, 3 decimals
                                               ("V 0.000 0.000" is the stop)
  base -> driver   O <left_m> <right_m>        cumulative wheel travel (encoders), m
                   E <text>                    the base reports a fault (E alone clears it)

The driver converts rcand's unicycle command (linear m/s, angular rad/s) into wheel speeds
with the wheel base (left = v - w*b/2, right = v + w*b/2, both scaled down together when one
exceeds --max-wheel-mps), holds them for the command's duration_ms, then stops the base. It
stops the base at once on a stop frame, an apply with "stop", when rcand falls silent for the
heartbeat timeout rcand announced, on SIGTERM/SIGINT and when the socket closes (then it exits).
It integrates the odometry lines into a pose and pushes state frames to rcand.

  serial_diffbase.py --port /dev/ttyUSB0 [--baud 115200] [--wheel-base 0.30]
                     [--max-wheel-mps 1.0] [--state-hz 20] [--listen PATH]
"""
import argparse
import errno
import json
import math
import os
import selectors
import signal
import socket
import struct
import sys
import termios
import time
import tty

PROTOCOL = 1
MAX_FRAME = 65536
BAUDS = {9600: termios.B9600, 19200: termios.B19200, 38400: termios.B38400,
         57600: termios.B57600, 115200: termios.B115200, 230400: termios.B230400}


def log(msg):
    sys.stderr.write("serial_diffbase: %s\n" % msg)
    sys.stderr.flush()


class Link:
    """The framed connection to rcand."""

    def __init__(self, sock):
        self.sock = sock
        self.buf = b""

    def send(self, obj):
        data = json.dumps(obj, separators=(",", ":")).encode()
        self.sock.sendall(struct.pack(">I", len(data)) + data)

    def receive(self):
        """Frames that arrived (a list of dicts); None when rcand closed the connection."""
        try:
            chunk = self.sock.recv(65536)
        except BlockingIOError:
            return []
        if not chunk:
            return None
        self.buf += chunk
        out = []
        while len(self.buf) >= 4:
            (n,) = struct.unpack(">I", self.buf[:4])
            if n == 0 or n > MAX_FRAME:
                raise ValueError("bad frame length %d" % n)
            if len(self.buf) < 4 + n:
                break
            out.append(json.loads(self.buf[4:4 + n]))
            self.buf = self.buf[4 + n:]
        return out


class Base:
    """The serial port and the base's line protocol."""

    def __init__(self, path, baud):
        self.path, self.baud = path, baud
        self.fd = -1
        self.rx = b""
        self.port_fault = ""   # the serial port itself (cleared by the next good write)
        self.base_fault = ""   # what the base reported with E lines

    @property
    def fault(self):
        return self.port_fault or self.base_fault

    def open(self):
        try:
            self.fd = os.open(self.path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
            tty.setraw(self.fd)
            attrs = termios.tcgetattr(self.fd)
            attrs[4] = attrs[5] = BAUDS.get(self.baud, termios.B115200)
            termios.tcsetattr(self.fd, termios.TCSANOW, attrs)
            self.port_fault = ""
        except (OSError, termios.error) as e:
            if self.fd >= 0:
                os.close(self.fd)
            self.fd = -1
            self.port_fault = "serial port %s: %s" % (self.path, e.args[-1])
        return self.fd >= 0

    def write_line(self, line):
        if self.fd < 0 and not self.open():
            return False
        data = (line + "\n").encode()
        deadline = time.monotonic() + 0.05
        while data:
            try:
                n = os.write(self.fd, data)
                data = data[n:]
            except BlockingIOError:
                if time.monotonic() > deadline:
                    self.port_fault = "serial port %s does not accept writes" % self.path
                    return False
                time.sleep(0.001)
            except OSError as e:
                self.port_fault = "serial port %s: %s" % (self.path, e.strerror)
                os.close(self.fd)
                self.fd = -1
                return False
        self.port_fault = ""
        return True

    def read_lines(self):
        try:
            chunk = os.read(self.fd, 4096)
        except BlockingIOError:
            return []
        except OSError as e:
            if e.errno == errno.EIO:  # a pty whose other side is closed: nothing to read yet
                return []
            raise
        self.rx += chunk
        lines = self.rx.split(b"\n")
        self.rx = lines.pop()[-4096:]
        return [ln.decode("ascii", "replace").strip() for ln in lines]


class Driver:
    def __init__(self, args, link, base):
        self.a, self.link, self.base = args, link, base
        self.x = self.y = self.theta = self.odometry = 0.0
        self.v = self.w = 0.0              # measured from the encoders
        self.target_v = self.target_w = 0.0
        self.deadline = None               # monotonic end of the active drive
        self.enc = None                    # last (left_m, right_m, t)
        self.last_rx = time.monotonic()
        self.hb_timeout = 0.5
        self.stale_stopped = False
        self.next_state = 0.0

    # -- the base
    def set_wheels(self, v, w):
        half = w * self.a.wheel_base / 2.0
        left, right = v - half, v + half
        peak = max(abs(left), abs(right))
        if peak > self.a.max_wheel_mps:
            scale = self.a.max_wheel_mps / peak
            left, right, v, w = left * scale, right * scale, v * scale, w * scale
        self.target_v, self.target_w = v, w
        self.base.write_line("V %.3f %.3f" % (left, right))

    def stop(self):
        self.deadline = None
        self.target_v = self.target_w = 0.0
        self.base.write_line("V 0.000 0.000")

    def on_odometry(self, left, right):
        now = time.monotonic()
        if self.enc is not None:
            dl, dr, dt = left - self.enc[0], right - self.enc[1], now - self.enc[2]
            d, dth = (dl + dr) / 2.0, (dr - dl) / self.a.wheel_base
            self.x += d * math.cos(self.theta + dth / 2.0)
            self.y += d * math.sin(self.theta + dth / 2.0)
            self.theta = math.remainder(self.theta + dth, 2.0 * math.pi)
            self.odometry += abs(d)
            if dt > 0:
                self.v, self.w = d / dt, dth / dt
        self.enc = (left, right, now)

    # -- rcand
    def on_frame(self, f):
        self.last_rx = time.monotonic()
        self.stale_stopped = False
        kind = f.get("type")
        if kind == "describe":
            self.hb_timeout = f.get("heartbeat_timeout_ms", 500) / 1000.0
            wmax = self.a.max_wheel_mps
            self.link.send({"type": "describe", "protocol": PROTOCOL, "name": "serial_diffbase",
                            "max_linear_mps": wmax,
                            "max_angular_radps": 2.0 * wmax / self.a.wheel_base})
        elif kind == "heartbeat":
            reply = {"type": "heartbeat", "seq": f.get("seq", 0)}
            if self.base.fault:
                reply["fault"] = self.base.fault
            self.link.send(reply)
        elif kind == "stop":
            self.stop()
            self.push_state()
        elif kind == "apply":
            cmd = f.get("command", {})
            if cmd.get("stop"):
                self.stop()
            elif "drive" in cmd:
                d = cmd["drive"]
                self.set_wheels(float(d["linear_mps"]), float(d["angular_radps"]))
                self.deadline = time.monotonic() + max(0, int(d["duration_ms"])) / 1000.0
            self.push_state()

    def push_state(self):
        remaining = 0
        if self.deadline is not None:
            remaining = max(0, int((self.deadline - time.monotonic()) * 1000))
        moving = self.target_v != 0.0 or self.target_w != 0.0
        self.link.send({"type": "state", "state": {
            "stopped": not moving and abs(self.v) < 1e-3 and abs(self.w) < 1e-3,
            "base": {"x": self.x, "y": self.y, "theta": self.theta,
                     "linear_mps": self.v, "angular_radps": self.w,
                     "target_linear_mps": self.target_v, "target_angular_radps": self.target_w,
                     "drive_remaining_ms": remaining, "odometry_m": self.odometry}}})
        self.next_state = time.monotonic() + 1.0 / self.a.state_hz

    def timers(self):
        now = time.monotonic()
        if self.deadline is not None and now >= self.deadline:
            self.stop()
            self.push_state()
        if not self.stale_stopped and now - self.last_rx > self.hb_timeout:
            log("rcand silent for %.0f ms: stopping the base" % ((now - self.last_rx) * 1000))
            self.stop()
            self.stale_stopped = True
        if now >= self.next_state:
            self.push_state()

    def timeout(self):
        t = self.next_state
        if self.deadline is not None:
            t = min(t, self.deadline)
        return max(0.0, min(t - time.monotonic(), 0.05))

    def run(self):
        sel = selectors.DefaultSelector()
        sel.register(self.link.sock, selectors.EVENT_READ, "link")
        watched = -1  # the serial fd being read (the port may be reopened)
        self.stop()
        while True:
            if self.base.fd != watched:
                if watched >= 0:
                    try:
                        sel.unregister(watched)
                    except (KeyError, ValueError):
                        pass
                watched = self.base.fd
                if watched >= 0:
                    sel.register(watched, selectors.EVENT_READ, "base")
            for key, _ in sel.select(self.timeout()):
                if key.data == "link":
                    frames = self.link.receive()
                    if frames is None:
                        return
                    for f in frames:
                        self.on_frame(f)
                else:
                    for line in self.base.read_lines():
                        self.on_line(line)
            self.timers()

    def on_line(self, line):
        parts = line.split()
        if not parts:
            return
        if parts[0] == "O" and len(parts) == 3:
            try:
                self.on_odometry(float(parts[1]), float(parts[2]))
            except ValueError:
                pass
        elif parts[0] == "E":
            self.base.base_fault = " ".join(parts[1:])


def connect(args):
    fd = os.environ.get("RCAN_DRIVER_FD")
    if not args.listen and fd:
        return [socket.socket(fileno=int(fd))]
    if not args.listen:
        sys.exit("serial_diffbase: no RCAN_DRIVER_FD and no --listen PATH")
    try:
        os.unlink(args.listen)
    except FileNotFoundError:
        pass
    srv = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    old = os.umask(0o177)
    srv.bind(args.listen)
    os.umask(old)
    srv.listen(1)
    return srv


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--port", required=True)
    ap.add_argument("--baud", type=int, default=115200)
    ap.add_argument("--wheel-base", type=float, default=0.30)
    ap.add_argument("--max-wheel-mps", type=float, default=1.0)
    ap.add_argument("--state-hz", type=float, default=20.0)
    ap.add_argument("--listen", default="")
    args = ap.parse_args()
    base = Base(args.port, args.baud)
    if not base.open():
        log(base.fault)

    state = {"driver": None}

    def terminate(signum, _frame):
        if state["driver"]:
            state["driver"].stop()
        else:
            base.write_line("V 0.000 0.000")
        sys.exit(0)

    signal.signal(signal.SIGTERM, terminate)
    signal.signal(signal.SIGINT, terminate)
    conn = connect(args)
    while True:
        sock = conn[0] if isinstance(conn, list) else conn.accept()[0]
        drv = Driver(args, Link(sock), base)
        state["driver"] = drv
        try:
            drv.run()
        except (OSError, ValueError, KeyError, TypeError) as e:
            log("connection: %s" % e)
        drv.stop()
        sock.close()
        if isinstance(conn, list):
            return


if __name__ == "__main__":
    main()
