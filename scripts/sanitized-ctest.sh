#!/usr/bin/env bash
# Runs one sanitizer tree's CTest suite (docs/TESTING.md "Sanitizers").
#   scripts/sanitized-ctest.sh asan|tsan BUILD_DIR [JOBS] [extra ctest args...]
# Every sanitizer report — from a test program or from an rcand / rcan it started — goes to
# BUILD_DIR/sanitizer-logs/<kind>.<pid>; the run fails when any report exists, even if the
# test that caused it passed (a daemon's leak or race shows only in its own process).
set -uo pipefail
kind=${1:?asan or tsan}
dir=${2:?build directory}
jobs=${3:-2}
shift $(( $# < 3 ? $# : 3 ))
root=$(cd "$(dirname "$0")/.." && pwd)
logs="$(cd "$dir" && pwd)/sanitizer-logs"
supp="$root/tests/sanitizers"
rm -rf "$logs" "$logs.tracer"
mkdir -p "$logs"

case "$kind" in
  asan)
    export ASAN_OPTIONS="halt_on_error=1:detect_leaks=1:strict_string_checks=1:check_initialization_order=1:strict_init_order=1:detect_stack_use_after_return=0:intercept_tls_get_addr=0:log_exe_name=1:log_path=$logs/asan"
    export UBSAN_OPTIONS="halt_on_error=1:print_stacktrace=1:report_error_type=1:log_exe_name=1:log_path=$logs/ubsan"
    export LSAN_OPTIONS="suppressions=$supp/lsan.supp:print_suppressions=0"
    ;;
  tsan)
    export TSAN_OPTIONS="halt_on_error=1:second_deadlock_stack=1:history_size=3:suppressions=$supp/tsan.supp:log_exe_name=1:log_path=$logs/tsan"
    ;;
  *) echo "unknown sanitizer '$kind'" >&2; exit 2 ;;
esac

ctest --test-dir "$dir" --output-on-failure -j "$jobs" "$@"
rc=$?

# LeakSanitizer's own tracer can fail while it stops a process's threads at exit: it crashes
# ("Tracer caught signal") or cannot read a thread's registers ("Unable to get registers from
# thread"). The crash is a fault of the GCC 12 runtime's __tls_get_addr interceptor, which takes
# a malloc'd TLS block at a 4096-byte offset for an old glibc header; intercept_tls_get_addr=0
# (above) turns that interceptor off, so the crash should no longer happen, but should it:
# Such a file holds no finding about our code — only those lines and LeakSanitizer's
# fatal-error lines — so it is shown and set aside; any other line in it (a leak, an ASan or
# UBSan error) counts.
for f in $(find "$logs" -type f | sort); do
  if grep -q -e 'Tracer caught signal' -e 'Unable to get registers from thread' "$f" &&
     ! grep -v -e 'Tracer caught signal' -e 'Unable to get registers from thread [0-9]*\.$' \
         -e 'LeakSanitizer has encountered a fatal error' \
         -e '^==[^=]*==\([0-9]*==\)\{0,1\}HINT: ' -e '^[[:space:]]*$' "$f" | grep -q .; then
    echo "== $kind: LeakSanitizer's tracer failed in $(basename "$f") (no finding; that process's leak check is lost or incomplete):"
    cat "$f"
    mkdir -p "$logs.tracer"
    mv "$f" "$logs.tracer/"
  fi
done

reports=$(find "$logs" -type f | sort)
if [ -n "$reports" ]; then
  n=$(echo "$reports" | wc -l)
  echo "== $kind: $n sanitizer report(s) in $logs"
  for f in $reports; do
    echo "---- $f"
    cat "$f"
  done
  [ $rc -eq 0 ] && rc=1
fi
exit $rc
