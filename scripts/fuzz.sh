#!/usr/bin/env bash
# Runs the libFuzzer targets (clang-14, `make fuzz`) for a given time each and records what
# each run did (docs/FUZZING.md).
#
#   scripts/fuzz.sh [-t SECONDS] [-j N] [--no-build] [--record] [TARGET…]
#   scripts/fuzz.sh SECONDS [TARGET…]          (the older form)
#
#   -t SECONDS   time per target (default 60)
#   -j N         run N targets at once (default 1; each target is one process)
#   --no-build   use the binaries already in build/fuzz/fuzz/
#   --record     also append each target's line, with the commit it fuzzed, to the committed
#                fuzz/campaigns.tsv (the project's record of fuzzing time per target)
#   TARGET       json, http_handler, … or json_fuzz (default: every target)
#
# Each target starts from its committed seeds (fuzz/corpus/<name>/) plus what earlier runs found
# (build/fuzz/corpus/<name>/, where new inputs go). Per run it writes build/fuzz/logs/<name>.log
# and one line of build/fuzz/summary.tsv:
#   target  seconds  executions  exec_per_s  corpus_before  corpus_after  coverage  features  peak_rss_mb  result  artifact
# result is ok, crash, timeout, oom or leak (libFuzzer stops at the first finding). Every line is
# also appended to build/fuzz/history.tsv (with the date), so that the fuzzing time per target
# can be added up over many runs. A finding is minimised into build/fuzz/artifacts/<name>/; copy
# it to fuzz/regressions/<name>/ with the fix — the fuzz_replay tests then run it for ever.
# Exit status: 0 when every target ran clean, 1 otherwise.
set -euo pipefail
cd "$(dirname "$0")/.."

secs=60
jobs=1
build=1
record=0
targets=()
while [ $# -gt 0 ]; do
  case "$1" in
    -t) secs=$2; shift 2 ;;
    -j) jobs=$2; shift 2 ;;
    --no-build) build=0; shift ;;
    --record) record=1; shift ;;
    -h|--help) sed -n '2,28p' "$0"; exit 0 ;;
    -*) echo "fuzz.sh: unknown option $1" >&2; exit 2 ;;
    *)
      if [ ${#targets[@]} -eq 0 ] && [[ "$1" =~ ^[0-9]+$ ]]; then secs=$1; else targets+=("${1%_fuzz}"); fi
      shift ;;
  esac
done
[[ "$secs" =~ ^[0-9]+$ ]] && [ "$secs" -gt 0 ] || { echo "fuzz.sh: SECONDS must be a positive integer" >&2; exit 2; }
[[ "$jobs" =~ ^[0-9]+$ ]] && [ "$jobs" -gt 0 ] || { echo "fuzz.sh: -j needs a positive integer" >&2; exit 2; }

out=build/fuzz
bin=$out/fuzz
if [ "$build" -eq 1 ]; then
  make fuzz >"$out.build.log" 2>&1 || { echo "fuzz.sh: make fuzz failed (see $out.build.log)" >&2; exit 1; }
fi
if [ ${#targets[@]} -eq 0 ]; then
  for t in "$bin"/*_fuzz; do [ -x "$t" ] && targets+=("$(basename "${t%_fuzz}")"); done
fi
[ ${#targets[@]} -gt 0 ] || { echo "fuzz.sh: no targets in $bin (run make fuzz)" >&2; exit 1; }
for t in "${targets[@]}"; do
  [ -x "$bin/${t}_fuzz" ] || { echo "fuzz.sh: no target $bin/${t}_fuzz" >&2; exit 2; }
done
mkdir -p "$out/logs" "$out/corpus" "$out/artifacts"
# The code being fuzzed: the commit at the start (+changes when the code differs from it).
commit=$(git rev-parse --short=12 HEAD 2>/dev/null || echo unknown)
git diff --quiet HEAD -- src include apps fuzz ':!fuzz/campaigns.tsv' 2>/dev/null || commit="$commit+changes"
runs=$(mktemp -d "$out/runs.XXXXXX")  # this invocation's per-target lines
trap 'rm -rf "$runs"' EXIT

count_files() { find "$1" -maxdepth 1 -type f 2>/dev/null | wc -l; }

# One target: run, then write its summary line to $runs/<name>.tsv.
run_one() {
  local name=$1 exe="$bin/${1}_fuzz" work="$out/corpus/$1" art="$out/artifacts/$1/" log="$out/logs/$1.log"
  mkdir -p "$work" "$art"
  local seeds=()
  [ -d "fuzz/corpus/$name" ] && seeds=("fuzz/corpus/$name")
  local before
  before=$(( $(count_files "$work") + $( [ ${#seeds[@]} -gt 0 ] && count_files "${seeds[0]}" || echo 0) ))
  local marker
  marker=$(mktemp)
  local t0 t1
  t0=$(date +%s.%N)
  set +e
  "$exe" -max_total_time="$secs" -max_len=65536 -timeout=25 -rss_limit_mb=2048 -print_final_stats=1 \
    -artifact_prefix="$art" "$work" "${seeds[@]}" >"$log" 2>&1
  local rc=$?
  set -e
  t1=$(date +%s.%N)
  local elapsed execs rss cov ft after result="ok" artifact="-"
  elapsed=$(awk -v a="$t0" -v b="$t1" 'BEGIN { printf "%.0f", b - a }')
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
  rss=$(sed -n 's/^stat::peak_rss_mb: *//p' "$log" | tail -1)
  cov=$(grep -oE 'cov: [0-9]+' "$log" | tail -1 | cut -d' ' -f2)
  ft=$(grep -oE 'ft: [0-9]+' "$log" | tail -1 | cut -d' ' -f2)
  after=$(( $(count_files "$work") + $( [ ${#seeds[@]} -gt 0 ] && count_files "${seeds[0]}" || echo 0) ))
  local found
  found=$(find "${art%/}" -maxdepth 1 -type f -newer "$marker" ! -name 'minimized-*' | head -1)
  rm -f "$marker"
  if [ -n "$found" ] || [ $rc -ne 0 ]; then
    case "$(basename "${found:-crash}")" in
      timeout-*) result=timeout ;;
      oom-*) result=oom ;;
      leak-*) result=leak ;;
      *) result=crash ;;
    esac
    if [ -n "$found" ]; then
      artifact=$found
      if [ "$result" = crash ]; then  # shrink it for fuzz/regressions/
        local min="$art/minimized-$(basename "$found")"
        "$exe" -minimize_crash=1 -max_total_time=60 -timeout=25 -exact_artifact_path="$min" "$found" \
          >"$out/logs/$name.minimize.log" 2>&1 || true
        [ -s "$min" ] && artifact=$min
      fi
    fi
  fi
  local eps=0
  [ -n "$execs" ] && [ "$elapsed" -gt 0 ] && eps=$(( execs / elapsed ))
  printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$name" "$elapsed" "${execs:-0}" "$eps" "$before" "$after" \
    "${cov:-0}" "${ft:-0}" "${rss:-0}" "$result" "$artifact" >"$runs/$name.tsv"
  printf '%-18s %5ss %10s execs %7s/s corpus %5s -> %-5s cov %-6s %s %s\n' "$name" "$elapsed" "${execs:-0}" "$eps" \
    "$before" "$after" "${cov:-0}" "$result" "$( [ "$artifact" = - ] && echo "" || echo "$artifact")"
}

echo "fuzzing ${#targets[@]} target(s) for ${secs}s each, $jobs at a time"
running=0
for t in "${targets[@]}"; do
  if [ "$running" -ge "$jobs" ]; then
    wait -n || true
    running=$((running - 1))
  fi
  run_one "$t" &
  running=$((running + 1))
done
wait || true

summary=$out/summary.tsv
printf 'target\tseconds\texecutions\texec_per_s\tcorpus_before\tcorpus_after\tcoverage\tfeatures\tpeak_rss_mb\tresult\tartifact\n' >"$summary"
status=0
when=$(date -u +%Y-%m-%dT%H:%M:%SZ)
[ -f "$out/history.tsv" ] || printf 'date\ttarget\tseconds\texecutions\texec_per_s\tcorpus_before\tcorpus_after\tcoverage\tfeatures\tpeak_rss_mb\tresult\tartifact\n' >"$out/history.tsv"
campaigns=fuzz/campaigns.tsv
if [ "$record" -eq 1 ] && [ ! -f "$campaigns" ]; then
  printf 'date\tcommit\ttarget\tseconds\texecutions\tcoverage\tresult\n' >"$campaigns"
fi
for t in "${targets[@]}"; do
  line=$(cat "$runs/$t.tsv" 2>/dev/null || printf '%s\t0\t0\t0\t0\t0\t0\t0\t0\tnot-run\t-' "$t")
  printf '%s\n' "$line" >>"$summary"
  printf '%s\t%s\n' "$when" "$line" >>"$out/history.tsv"
  if [ "$record" -eq 1 ]; then
    awk -F'\t' -v OFS='\t' -v w="$when" -v c="$commit" '{ print w, c, $1, $2, $3, $7, $10 }' <<<"$line" >>"$campaigns"
  fi
  [ "$(cut -f10 <<<"$line")" = ok ] || status=1
done
echo "summary: $summary (all runs: $out/history.tsv)"
if [ $status -ne 0 ]; then
  echo "findings (copy the minimised input to fuzz/regressions/<name>/ with the fix):"
  awk -F'\t' 'NR > 1 && $10 != "ok" { print "  " $1 ": " $10 " " $11 }' "$summary"
fi
exit $status
