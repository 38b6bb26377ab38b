#!/usr/bin/env bash
# The soak (docs/SOAK.md): a run of MINUTES (default 60) at 64 clients with mixed traffic —
# HTTP COMMANDs, GET status, WebSocket streams with telemetry, §16 gate traffic — against a
# real rcand, sampled every minute and judged at the end (no error; no growth of RSS, file
# descriptors or threads beyond the stated bound; the audit log grows and its chain verifies).
#
#   scripts/soak.sh [MINUTES] [soak options…]     e.g. scripts/soak.sh 60 --data-root /var/tmp
#
# Builds what it needs, then writes the per-minute table to $SOAK_OUT (default
# build/release/soak) as soak-<UTC time>.tsv and the whole report (the table in markdown and
# the judgement) as soak-<UTC time>.md. Exit status 0 when every judgement holds.
set -euo pipefail
cd "$(dirname "$0")/.."
MINUTES=${1:-60}
[ $# -gt 0 ] && shift
BUILD_DIR=${BUILD_DIR:-build/release}
OUT=${SOAK_OUT:-$BUILD_DIR/soak}
JOBS=${JOBS:-$(nproc)}
if [ ! -f "$BUILD_DIR/build.ninja" ]; then
  cmake -S . -B "$BUILD_DIR" -G Ninja -DCMAKE_BUILD_TYPE=Release
fi
cmake --build "$BUILD_DIR" -j "$JOBS" --target soak rcand rcan_cli
mkdir -p "$OUT"
stamp=$(date -u +%Y%m%dT%H%M%SZ)
echo "soak: $MINUTES minutes; report in $OUT/soak-$stamp.md"
set +e
"$BUILD_DIR/bench/soak" --minutes "$MINUTES" --rcand "$BUILD_DIR/bin/rcand" --rcan "$BUILD_DIR/bin/rcan" \
  --tsv "$OUT/soak-$stamp.tsv" "$@" | tee "$OUT/soak-$stamp.md"
status=${PIPESTATUS[0]}
exit "$status"
