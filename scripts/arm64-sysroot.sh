#!/usr/bin/env bash
# Prepares the arm64 cross build (make cross-arm64, make test-arm64; docs/ARM64.md):
#   1. Debian's cross toolchain and qemu-user (amd64 packages, installed with apt-get);
#   2. an arm64 sysroot: the project's build dependencies for arm64 and everything they depend
#      on, resolved by a private apt whose only architecture is arm64 and unpacked with dpkg -x
#      into build/arm64-sysroot. Nothing arm64 is installed on the machine: Debian 12's
#      multiarch cannot co-install several of these -dev packages with their amd64 versions
#      (libyaml-cpp-dev, libpq-dev and libjemalloc-dev are not Multi-Arch: same).
# Safe to run repeatedly: it installs only what is missing and unpacks the sysroot once per
# package list (delete build/arm64-sysroot to start again).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
SYSROOT="${ARM64_SYSROOT:-$ROOT/build/arm64-sysroot}"
APTDIR="$SYSROOT.apt"

HOST_PKGS=(crossbuild-essential-arm64 qemu-user-static dpkg-dev)
ARM64_PKGS=(
  libc6-dev libstdc++-12-dev
  libssl-dev
  libboost1.81-dev libboost-json1.81-dev libboost-url1.81-dev
  libyaml-cpp-dev libsqlite3-dev libmosquitto-dev libpq-dev
  libgrpc++-dev libprotobuf-dev
  libgtest-dev libgmock-dev
  libavahi-client-dev libjemalloc-dev
  cyclonedds-dev
)

SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
missing=()
for p in "${HOST_PKGS[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed' || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "arm64-sysroot: installing ${missing[*]}" >&2
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -o DPkg::Lock::Timeout=600 -qq
  $SUDO apt-get install -o DPkg::Lock::Timeout=600 -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

# What each arm64 library package provides, for the arm64 package's Depends
# (cmake/cpack_arm64_depends.cmake; dpkg-shlibdeps knows only the machine's installed
# packages). One line per library in $SYSROOT/.libdeps: its shlibs line ("libssl 3 libssl3
# (>= 3.0.22)"), or, for a package with a symbols file and no shlibs file, "soname=<soname>
# <package> (>= <version>)" from the symbols file's header with the package's own version.
write_libdeps() {
  local out="$SYSROOT/.libdeps" deb version
  : > "$out.tmp"
  for deb in "$APTDIR"/var/cache/apt/archives/*.deb; do
    if dpkg-deb -I "$deb" shlibs >/dev/null 2>&1; then
      dpkg-deb -I "$deb" shlibs | grep -v -e '^#' -e '^udeb:' -e '^[[:space:]]*$' >> "$out.tmp" || true
    elif dpkg-deb -I "$deb" symbols >/dev/null 2>&1; then
      version="$(dpkg-deb -f "$deb" Version)"
      dpkg-deb -I "$deb" symbols | grep -E '^[^[:space:]|*#]' |
        sed -E "s/^([^ ]+) ([^ ]+) #MINVER#.*/soname=\1 \2 (>= $version)/" >> "$out.tmp" || true
    fi
  done
  mv "$out.tmp" "$out"
}

stamp="$SYSROOT/.packages"
if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "${ARM64_PKGS[*]}" ]; then
  [ -f "$SYSROOT/.libdeps" ] || write_libdeps
  exit 0
fi

# A private apt: the machine's Debian sources and keys, arm64 only, an empty dpkg status (so
# every dependency is fetched), its own lists and cache under build/.
rm -rf "$SYSROOT" "$APTDIR"
mkdir -p "$APTDIR"/{etc/apt/sources.list.d,etc/apt/preferences.d,var/lib/apt/lists/partial} \
  "$APTDIR"/var/cache/apt/archives/partial "$APTDIR/var/lib/dpkg" "$SYSROOT"
touch "$APTDIR/var/lib/dpkg/status"
cp /etc/apt/sources.list.d/*.sources "$APTDIR/etc/apt/sources.list.d/" 2>/dev/null || true
[ -f /etc/apt/sources.list ] && cp /etc/apt/sources.list "$APTDIR/etc/apt/"
APT=(-o "Dir=$APTDIR" -o "Dir::State::status=$APTDIR/var/lib/dpkg/status"
  -o "Dir::Etc::trusted=/etc/apt/trusted.gpg" -o "Dir::Etc::trustedparts=/etc/apt/trusted.gpg.d"
  -o APT::Architecture=arm64 -o APT::Architectures::=arm64
  -o APT::Install-Recommends=false -o Debug::NoLocking=true -o APT::Sandbox::User=root)
echo "arm64-sysroot: resolving ${#ARM64_PKGS[@]} arm64 packages and their dependencies" >&2
apt-get "${APT[@]}" update -qq
apt-get "${APT[@]}" install -y -qq --download-only "${ARM64_PKGS[@]}" >/dev/null
n=0
for deb in "$APTDIR"/var/cache/apt/archives/*.deb; do
  dpkg-deb -x "$deb" "$SYSROOT"
  n=$((n + 1))
done
# Debian's -dev symlinks are relative, except a few that point at /lib or /usr/lib: make
# those point inside the sysroot.
find "$SYSROOT" -type l -lname '/*' | while read -r l; do
  t="$(readlink "$l")"
  ln -sfn "$SYSROOT$t" "$l"
done
write_libdeps
echo "${ARM64_PKGS[*]}" > "$stamp"
echo "arm64-sysroot: $n packages unpacked in $SYSROOT ($(du -sh "$SYSROOT" | cut -f1))" >&2
