#!/usr/bin/env bash
# The tree is formatted by clang-format (.clang-format): this fails, naming each file, when a
# C++ file is not. `make format` formats them all.
#   scripts/check_format.sh [ROOT]
set -euo pipefail
ROOT="${1:-$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)}"
cd "$ROOT"
if git rev-parse --git-dir >/dev/null 2>&1; then
  mapfile -t files < <(git ls-files --cached --others --exclude-standard '*.cpp' '*.h')
else
  mapfile -t files < <(find src include apps tests bench fuzz -name '*.cpp' -o -name '*.h' | grep -v node_modules)
fi
bad=()
for f in "${files[@]}"; do
  [ -f "$f" ] || continue
  if ! clang-format --dry-run --Werror "$f" >/dev/null 2>&1; then bad+=("$f"); fi
done
if [ ${#bad[@]} -gt 0 ]; then
  printf 'not formatted (run make format): %s\n' "${bad[@]}"
  echo "check_format: ${#files[@]} files, ${#bad[@]} not formatted"
  exit 1
fi
echo "check_format: ${#files[@]} files, all formatted"
