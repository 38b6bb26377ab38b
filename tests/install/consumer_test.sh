#!/bin/bash
# librcan installed and used (cmake/RcanInstall.cmake): installs the component "devel" of the
# build tree into a temporary prefix, checks what it holds, then builds tests/install/consumer
# against that copy twice, with find_package(rcan CONFIG) and with pkg-config, and runs both.
#   consumer_test.sh BUILD_DIR CONSUMER_SOURCE_DIR
set -euo pipefail
build=$1
consumer=$2
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
prefix=$work/prefix

cmake --install "$build" --prefix "$prefix" --component devel >/dev/null

# What is installed: headers, the archive, the CMake package, rcan.pc; no program, no test.
fail=0
for f in include/rcan/json.h include/rcan/result.h include/rcan/crypto/ed25519.h \
         include/rcan/audit/audit_log.h; do
  [ -f "$prefix/$f" ] || { echo "missing: $f"; fail=1; }
done
for pattern in 'librcan.a' 'librcan_base.a' 'rcanConfig.cmake' 'rcanConfigVersion.cmake' 'rcanTargets.cmake' 'rcan.pc'; do
  [ -n "$(find "$prefix" -name "$pattern")" ] || { echo "missing: $pattern"; fail=1; }
done
others=$(cd "$prefix" && find . -type f ! -path './include/rcan/*' ! -name 'librcan.a' \
         ! -name 'librcan_base.a' \
         ! -name 'rcan*.cmake' ! -name 'rcan.pc' | sort)
if [ -n "$others" ]; then
  echo "installed besides librcan:"; echo "$others"; fail=1
fi
[ ! -e "$prefix/include/rcan/client.h" ] || { echo "client.h (the client library) installed"; fail=1; }
[ "$fail" = 0 ] || exit 1
echo "installed: $(cd "$prefix" && find . -type f | wc -l) files"

expected="ruri: rcan://registry.rcan.dev/acme/robotarm/v2/unit-001
canonical: {\"cmd\":\"move\",\"params\":{\"a\":1,\"b\":2},\"target\":\"x\"}
verify: ok
verify altered: bad
version: $(sed -n 's/.*kSoftwareVersion = "\(.*\)".*/\1/p' "$consumer/../../../include/rcan/version.h")"

check() {  # check NAME PROGRAM
  local got
  got=$("$2")
  if [ "$got" != "$expected" ]; then
    echo "$1: unexpected output:"; echo "$got"; echo "expected:"; echo "$expected"
    exit 1
  fi
  echo "$1: ok"
}

# 1. CMake: find_package(rcan CONFIG REQUIRED), target rcan::rcan.
cmake -S "$consumer" -B "$work/cmake" -G Ninja -DCMAKE_BUILD_TYPE=Release \
      -DCMAKE_PREFIX_PATH="$prefix" >"$work/cmake.log" 2>&1 || { cat "$work/cmake.log"; exit 1; }
cmake --build "$work/cmake" >>"$work/cmake.log" 2>&1 || { cat "$work/cmake.log"; exit 1; }
check find_package "$work/cmake/consumer"

# 2. pkg-config.
pc_dir=$(dirname "$(find "$prefix" -name rcan.pc)")
export PKG_CONFIG_PATH=$pc_dir
flags=$(pkg-config --cflags --libs rcan)
c++ -std=c++20 -O1 -o "$work/consumer-pc" "$consumer/main.cpp" $flags
check pkg-config "$work/consumer-pc"

# 3. Every installed header compiles on its own (none reaches a header left uninstalled).
cflags=$(pkg-config --cflags rcan)
n=0
while IFS= read -r h; do
  echo "#include <${h#./}>" | c++ -std=c++20 -fsyntax-only -x c++ $cflags - ||
    { echo "installed header does not compile alone: $h"; exit 1; }
  n=$((n + 1))
done < <(cd "$prefix/include" && find . -name '*.h' | sort)
echo "headers: $n compile alone"
