#!/usr/bin/env bash
# Builds the libFuzzer targets (clang-14) and runs each for the given number of seconds,
# starting from the committed seed corpora under fuzz/corpus/<name>/ (targets named
# <name>_fuzz; a target without a seed directory starts empty). New inputs go to
# build/fuzz/corpus-<name>/; crashes to build/fuzz/artifacts/.
#   scripts/fuzz.sh [SECONDS_PER_TARGET] [TARGET…]
set -euo pipefail
cd "$(dirname "$0")/.."
secs=${1:-60}
shift || true
make fuzz >/dev/null
mkdir -p build/fuzz/artifacts
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
  for t in build/fuzz/fuzz/*_fuzz; do targets+=("$(basename "$t")"); done
fi
status=0
for t in "${targets[@]}"; do
  name=${t%_fuzz}
  work=build/fuzz/corpus-$name
  mkdir -p "$work"
  seeds=()
  [ -d "fuzz/corpus/$name" ] && seeds=("fuzz/corpus/$name")
  echo "== $t for ${secs}s"
  if ! "build/fuzz/fuzz/$t" -max_total_time="$secs" -max_len=65536 -timeout=10 -rss_limit_mb=2048 \
      -artifact_prefix=build/fuzz/artifacts/"$name"- -print_final_stats=1 "$work" "${seeds[@]}" \
      2> "build/fuzz/$name.log"; then
    echo "   FAILED: see build/fuzz/$name.log"; status=1
  fi
  grep -E 'stat::number_of_executed_units|stat::peak_rss_mb' "build/fuzz/$name.log" | sed 's/^/   /'
done
exit $status
