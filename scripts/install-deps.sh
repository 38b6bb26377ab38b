#!/usr/bin/env bash
# Installs every build, test and benchmark dependency of the project from Debian 12's
# apt repositories. Safe to run repeatedly: it installs only what is missing.
# Boost comes from the 1.81 packages; the 1.74 libboost-dev/libboost-all-dev conflict and
# must never be installed.
set -euo pipefail

PKGS=(
  build-essential cmake ninja-build ccache lld pkg-config git
  libssl-dev openssl
  libboost1.81-dev libboost-json1.81-dev libboost-url1.81-dev
  libyaml-cpp-dev libsqlite3-dev
  mosquitto libmosquitto-dev nats-server
  postgresql libpq-dev
  libgrpc++-dev libprotobuf-dev protobuf-compiler protobuf-compiler-grpc
  libgtest-dev libgmock-dev googletest libbenchmark-dev
  clang-14 libclang-rt-14-dev clang-format
  python3 curl python3-grpcio python3-protobuf python3-cryptography python3-httpx
  chromium fonts-dejavu-core nodejs
  avahi-daemon dbus libavahi-client-dev iproute2
  faketime e2fsprogs
  libjemalloc-dev
  cyclonedds-dev cyclonedds-tools
  help2man dpkg-dev systemd
)

missing=()
for p in "${PKGS[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed'; then
    missing+=("$p")
  fi
done
# npm ships inside some Node.js builds; Debian packages it separately.
if ! command -v npm >/dev/null 2>&1; then missing+=(npm); fi

SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
if [ ${#missing[@]} -gt 0 ]; then
  echo "install-deps: installing ${missing[*]}" >&2
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -o DPkg::Lock::Timeout=600 -qq
  $SUDO apt-get install -o DPkg::Lock::Timeout=600 -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

# The dashboard's browser test drives Debian's chromium with playwright-core and checks
# accessibility with axe-core, both pinned in tests/browser/package-lock.json (no browser
# download: it uses /usr/bin/chromium).
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
B="$ROOT/tests/browser"
stale=""
for dep in playwright-core axe-core; do
  want="$(node -p "require('$B/package.json').dependencies['$dep']")"
  have="$(node -p "require('$B/node_modules/$dep/package.json').version" 2>/dev/null || true)"
  if [ "$want" != "$have" ]; then stale="$stale $dep@$want"; fi
done
if [ -n "$stale" ]; then
  echo "install-deps: npm ci in tests/browser ($stale )" >&2
  (cd "$B" && PLAYWRIGHT_SKIP_BROWSER_DOWNLOAD=1 npm ci --no-audit --no-fund --loglevel=error >/dev/null)
fi

# The SDK client tests (tests/sdk) run rcan-ts 3.4.2, copied in third_party/rcan-ts and
# built here with its own lockfile: npm ci (no install scripts), then tsup into dist/. Skipped
# when dist/ is newer than the lockfile and the sources.
T="$ROOT/third_party/rcan-ts"
if [ ! -f "$T/dist/index.mjs" ] || [ -n "$(find "$T/package-lock.json" "$T/package.json" "$T/src" "$T/tsup.config.ts" -newer "$T/dist/index.mjs" 2>/dev/null | head -1)" ]; then
  echo "install-deps: npm ci + tsup in third_party/rcan-ts" >&2
  # tsup's output (warnings about rcan-ts's own config) is shown only when the build fails.
  (cd "$T" && npm ci --ignore-scripts --no-audit --no-fund --loglevel=error >/dev/null &&
    { out="$(npx --no-install tsup 2>&1)" || { echo "$out" >&2; exit 1; }; })
fi
