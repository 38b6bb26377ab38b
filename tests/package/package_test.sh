#!/usr/bin/env bash
# The Debian package, built and inspected without installing it on this machine: cpack builds
# the .deb from the release tree; dpkg-deb unpacks it into a temporary root; the files, modes,
# dependencies and maintainer scripts are checked; systemd-analyze verifies the unit and scores
# its hardening; the postinst's `rcand init` and the unit's ExecStart run with their paths
# redirected into the root, and the node answers /healthz. Exit 0 pass, 1 fail, 77 skip.
#
# Usage: package_test.sh BUILD_DIR
# A cross build's tree (make cross-arm64, docs/ARM64.md) sets RCAN_PACKAGE_RUN to its emulator
# ("qemu-aarch64-static -L <sysroot>"), RCAN_PACKAGE_MACHINE to the ELF machine its programs
# must be ("AArch64") and RCAN_PACKAGE_ARCH to the package's ("arm64"): the packaged programs
# then run under the emulator.
set -uo pipefail
BUILD=${1:?build dir}
RUN=${RCAN_PACKAGE_RUN:-}
MACHINE=${RCAN_PACKAGE_MACHINE:-}
for t in cpack dpkg-deb systemd-analyze curl; do
  command -v "$t" >/dev/null || { echo "SKIP: $t is not installed (scripts/install-deps.sh)"; exit 77; }
done
WORK=$(mktemp -d "${TMPDIR:-/tmp}/rcan-package.XXXXXX")
PID=
cleanup() { [ -n "$PID" ] && kill "$PID" 2>/dev/null; wait 2>/dev/null; rm -rf "$WORK"; }
trap cleanup EXIT
fails=0
ok() { echo "ok - $*"; }
bad() { echo "FAIL - $*"; fails=$((fails + 1)); }
check() { local what=$1; shift; if "$@"; then ok "$what"; else bad "$what"; fi; }

# 1. Build the package (into this test's own directory).
( cd "$BUILD" && cpack -G DEB -B "$WORK/out" ) >"$WORK/cpack.log" 2>&1 || { cat "$WORK/cpack.log"; bad "cpack builds the .deb"; exit 1; }
DEB=$(ls "$WORK"/out/rcan_*.deb 2>/dev/null | head -1)
check "cpack builds the .deb ($(basename "${DEB:-none}"))" test -f "$DEB"
ROOT=$WORK/root CTRL=$WORK/control
dpkg-deb -x "$DEB" "$ROOT" && dpkg-deb -e "$DEB" "$CTRL"

# 2. Files, modes, metadata.
for f in usr/bin/rcand usr/bin/rcan usr/bin/rcan-registry; do check "$f is an executable" test -x "$ROOT/$f"; done
for f in usr/lib/rcan/librcand_grpc.so usr/lib/systemd/system/rcand.service \
         usr/lib/systemd/system/rcan-registry.service usr/share/man/man1/rcan-registry.1.gz \
         usr/share/man/man1/rcand.1.gz usr/share/man/man1/rcan.1.gz \
         usr/share/bash-completion/completions/rcan usr/share/doc/rcan/examples/sim-robot.rcan.yaml; do
  check "$f is packaged" test -s "$ROOT/$f"
done
if [ -n "$MACHINE" ]; then
  for f in usr/bin/rcand usr/bin/rcan usr/bin/rcan-registry usr/lib/rcan/librcand_grpc.so; do
    check "$f is built for $MACHINE" bash -c "readelf -h '$ROOT/$f' | grep -Eq 'Machine:[[:space:]]+$MACHINE'"
  done
  check "the control file says Architecture: ${RCAN_PACKAGE_ARCH:-?}" \
    grep -q "^Architecture: ${RCAN_PACKAGE_ARCH:-?}\$" "$CTRL/control"
fi
check "the man pages hold the --help text" bash -c "zcat '$ROOT/usr/share/man/man1/rcand.1.gz' | grep -q 'rcand init'"
check "the man pages keep the help's UTF-8 (no ???)" bash -c "! zcat '$ROOT/usr/share/man/man1/rcand.1.gz' | grep -q '???'"
check "the completion completes rcan's verbs" grep -q "fleet" "$ROOT/usr/share/bash-completion/completions/rcan"
check "no file is group- or world-writable" test -z "$(find "$ROOT" -perm /022 ! -type l)"
check "no file is setuid or setgid" test -z "$(find "$ROOT" -perm /6000)"
check "the package depends on adduser and the shared libraries" grep -Eq '^Depends: .*adduser.*libssl3' "$CTRL/control"
for s in postinst prerm postrm; do
  check "$s is an executable sh script" bash -c "test -x '$CTRL/$s' && head -1 '$CTRL/$s' | grep -q '^#!/bin/sh' && sh -n '$CTRL/$s'"
done
check "postinst creates the rcand system user" grep -q 'gecos "RCAN robot node" rcand$' "$CTRL/postinst"
check "postinst creates the rcan-registry system user" \
  grep -q 'gecos "RCAN robot registry" rcan-registry$' "$CTRL/postinst"
check "postinst enables and starts no service" bash -c "! grep -Eq '^[[:space:]]*systemctl (enable|start)' '$CTRL/postinst'"
check "postinst makes the robot with rcand init, never over an existing config" \
  grep -q 'if \[ ! -e /etc/rcan/robot.rcan.yaml \]' "$CTRL/postinst"
check "postrm removes the audit log on purge only" bash -c "grep -B2 'rm -rf /var/lib/rcand' '$CTRL/postrm' | grep -q purge"

# 3. The unit: systemd's own verifier and hardening score.
UNIT=$ROOT/usr/lib/systemd/system/rcand.service
# The verifier resolves the unit's dependencies (sysinit.target…) in the root: give it this
# machine's system units beside the package's. Its Documentation= check runs man(1), which a
# build machine may lack: only those lines are set aside.
VROOT=$WORK/verify-root
cp -a "$ROOT" "$VROOT" && cp -rn /usr/lib/systemd/system/. "$VROOT/usr/lib/systemd/system/"
for u in rcand rcan-registry; do
  verify=$(systemd-analyze verify --root="$VROOT" "$VROOT/usr/lib/systemd/system/$u.service" 2>&1 |
           grep -v "Command 'man " || true)
  check "systemd-analyze verify accepts $u.service${verify:+ ($verify)}" test -z "$verify"
  score=$(systemd-analyze security --offline=true "$ROOT/usr/lib/systemd/system/$u.service" 2>/dev/null |
          sed -n "s/.*Overall exposure level for $u.service: \([0-9.]*\).*/\1/p")
  echo "note: systemd-analyze security $u: exposure ${score:-?} (0 safest, 10 unsafe)"
  check "the $u exposure score is at most 2.0 (${score:-none})" awk -v s="${score:-99}" 'BEGIN { exit !(s <= 2.0) }'
done
for k in 'Type=notify' 'WatchdogSec=' 'User=rcand' 'ProtectSystem=strict' 'ProtectHome=true' \
         'NoNewPrivileges=true' 'PrivateTmp=true' 'ReadWritePaths=/var/lib/rcand' \
         'CapabilityBoundingSet=$' 'RestrictAddressFamilies=' 'SystemCallFilter=@system-service'; do
  check "the unit sets $k" grep -Eq "^$k" "$UNIT"
done

# 4. What postinst does, into the root: a configured robot in /var/lib/rcand, /etc/rcan.
PORT=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
$RUN "$ROOT/usr/bin/rcand" init --dir "$ROOT/var/lib/rcand" --config "$ROOT/etc/rcan/robot.rcan.yaml" \
  --yes --port "$PORT" >"$WORK/init.log" 2>&1
check "rcand init (postinst's step) makes the configured robot" test -s "$ROOT/var/lib/rcand/owner.token"

# 4b. The postinst itself, in a sandbox: its paths redirected into a root of its own, the
# commands that need root or the system's users stubbed (runuser runs the command as it is:
# this machine has no rcand user). The rcand user owns /var/lib/rcand: a link it planted there
# (init.log → a file of root's) must not be followed by root. Before: root's shell redirected
# rcand init's output through it.
SB=$WORK/sandbox STUBS=$WORK/stubs
mkdir -p "$SB/var/lib/rcand" "$SB/etc" "$STUBS"
for c in getent addgroup adduser systemctl; do printf '#!/bin/sh\nexit 0\n' >"$STUBS/$c"; done
printf '#!/bin/sh\necho "chown $*" >>"%s"\n' "$WORK/stub.log" >"$STUBS/chown"
# install: as asked, less the owner and group (the users do not exist here).
cat >"$STUBS/install" <<'EOF_STUB'
#!/bin/sh
args=
while [ $# -gt 0 ]; do
  case $1 in -o|-g) shift 2 ;; *) args="$args $1"; shift ;; esac
done
exec /usr/bin/install $args
EOF_STUB
cat >"$STUBS/runuser" <<EOF_STUB
#!/bin/sh
[ "\$1" = "-u" ] && [ "\$3" = "--" ] || { echo "runuser: unexpected \$*" >&2; exit 2; }
echo "runuser \$*" >>"$WORK/stub.log"
shift 3
exec "\$@"
EOF_STUB
chmod +x "$STUBS"/*
ln -s "$WORK/root-only" "$SB/var/lib/rcand/init.log"
sed -e "s|/var/lib/rcand|$SB/var/lib/rcand|g" -e "s|/etc/rcan|$SB/etc/rcan|g" \
    -e "s|/usr/bin/rcand|${RUN:+$RUN }$ROOT/usr/bin/rcand|g" "$CTRL/postinst" >"$WORK/postinst"
PATH="$STUBS:$PATH" sh "$WORK/postinst" configure >"$WORK/postinst.log" 2>&1
rc=$?
check "postinst configure succeeds in the sandbox (exit $rc)" test "$rc" -eq 0
check "postinst writes nothing through a link the rcand user planted in its directory" \
  test ! -e "$WORK/root-only"
check "postinst runs rcand init as the rcand user" grep -q -- "^runuser -u rcand -- .*usr/bin/rcand init" "$WORK/stub.log"
check "postinst redirects nothing into /var/lib/rcand" \
  bash -c "! grep -Eq '>[[:space:]]*\"?/var/lib/rcand' '$CTRL/postinst'"
check "postinst made the robot (owner token, configuration naming its own path)" bash -c \
  "test -s '$SB/var/lib/rcand/owner.token' && grep -q 'rcand --config $SB/etc/rcan/robot.rcan.yaml' '$SB/etc/rcan/robot.rcan.yaml'"
check "the configuration is 0644 and no staging directory is left" bash -c \
  "test \"\$(stat -c %a '$SB/etc/rcan/robot.rcan.yaml')\" = 644 && test -z \"\$(ls -A '$SB/etc/rcan' | grep -v '^robot.rcan.yaml\$')\""
[ "$rc" -eq 0 ] || cat "$WORK/postinst.log"

# 5. The unit's ExecStart, its paths redirected into the root: the node serves.
exec_start=$(sed -n 's/^ExecStart=//p' "$UNIT")
cmd=${exec_start//\/usr\/bin\//$ROOT/usr/bin/}
cmd=${cmd//\/etc\/rcan/$ROOT/etc/rcan}
cmd=${cmd//\/var\/lib\/rcand/$ROOT/var/lib/rcand}
echo "note: starting: ${cmd#$ROOT}"
$RUN $cmd 2>"$WORK/rcand.log" &
PID=$!
healthy=
for _ in $(seq 1 100); do
  if curl -fsS "http://127.0.0.1:$PORT/healthz" >"$WORK/health" 2>/dev/null; then healthy=1; break; fi
  sleep 0.1
done
check "rcand started by the unit's command line answers /healthz" test -n "$healthy"
check "the packaged CLI drives it with the OWNER token" bash -c \
  "RCAN_URL=http://127.0.0.1:$PORT RCAN_TOKEN_FILE='$ROOT/var/lib/rcand/owner.token' $RUN '$ROOT/usr/bin/rcan' status >/dev/null"
check "the packaged gRPC module is the one it would load" test -f "$ROOT/usr/lib/rcan/librcand_grpc.so"
kill -TERM "$PID"; wait "$PID"; rc=$?; PID=
check "SIGTERM stops it cleanly (exit $rc)" test "$rc" -eq 0

# 6. The registry's unit: its ExecStart, paths redirected into the root and on a free port.
RUNIT=$ROOT/usr/lib/systemd/system/rcan-registry.service
RPORT=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
rcmd=$(sed -n 's/^ExecStart=//p' "$RUNIT")
rcmd=${rcmd//\/usr\/bin\//$ROOT/usr/bin/}
rcmd=${rcmd//\/var\/lib\/rcan-registry/$ROOT/var/lib/rcan-registry}
rcmd=${rcmd//--port 8090/--port $RPORT}
echo "note: starting: ${rcmd#$ROOT}"
$RUN $rcmd 2>"$WORK/registry.log" &
PID=$!
healthy=
for _ in $(seq 1 100); do
  if curl -fsS "http://127.0.0.1:$RPORT/healthz" >/dev/null 2>&1; then healthy=1; break; fi
  sleep 0.1
done
check "rcan-registry started by its unit's command line answers /healthz" test -n "$healthy"
check "its first start wrote the admin key 0600" \
  test "$(stat -c %a "$ROOT/var/lib/rcan-registry/admin.key" 2>/dev/null)" = 600
check "the packaged CLI lists robots with it" bash -c \
  "RCAN_REGISTRY=http://127.0.0.1:$RPORT $RUN '$ROOT/usr/bin/rcan' registry list >/dev/null"
kill -TERM "$PID"; wait "$PID"; rc=$?; PID=
check "SIGTERM stops rcan-registry cleanly (exit $rc)" test "$rc" -eq 0

if [ "$fails" -gt 0 ]; then
  echo "$fails failure(s)"; tail -20 "$WORK/rcand.log"; tail -20 "$WORK/registry.log" 2>/dev/null; exit 1
fi
echo "all package checks passed"
