#!/usr/bin/env bash
# Runs one GoogleTest suite for CTest (tests/CMakeLists.txt registers one CTest test per suite):
#   run_gtest_suite.sh PROGRAM [ARGS...]      e.g. PROGRAM --gtest_filter='Suite.*:*/Suite.*'
# The program's output passes through unchanged. The exit status is the program's when it
# failed (a failed test fails the suite even if others skipped); 77, which CTest reports as
# skipped (SKIP_RETURN_CODE), when tests ran and every one of them skipped (GTEST_SKIP); 1 when
# the filter matched no test (the suite was renamed or removed and the tree not reconfigured).
set -o pipefail
log=$(mktemp)
trap 'rm -f "$log"' EXIT
"$@" 2>&1 | tee "$log"
rc=${PIPESTATUS[0]}
[ "$rc" -ne 0 ] && exit "$rc"
# gtest's closing lines: "[==========] N tests from M test suites ran." and "[  PASSED  ] P tests."
ran=$(sed -n 's/^\[==========\] \([0-9][0-9]*\) tests\{0,1\} from .* ran\..*/\1/p' "$log" | tail -n 1)
passed=$(sed -n 's/^\[  PASSED  \] \([0-9][0-9]*\) tests\{0,1\}\..*/\1/p' "$log" | tail -n 1)
if [ -z "$ran" ] || [ "$ran" -eq 0 ]; then
  echo "run_gtest_suite: no test matched ($*)" >&2
  exit 1
fi
[ "${passed:-0}" -eq 0 ] && exit 77
exit 0
