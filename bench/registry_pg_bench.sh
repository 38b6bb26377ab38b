#!/usr/bin/env bash
# registry_bench on PostgreSQL: one rcan-registry instance, then two on one database
# (docs/REGISTRY.md §Performance), each run beside a fresh PostgreSQL of its own
# (scripts/with_postgres.sh).
#
# Usage: bench/registry_pg_bench.sh BUILD_DIR [registry_bench options: --robots N --clients C --seconds S]
set -euo pipefail
BUILD=${1:?build dir}; shift
HERE=$(cd "$(dirname "$0")" && pwd)
for n in 1 2; do
  echo "== $n instance(s) on one PostgreSQL database"
  "$HERE/../scripts/with_postgres.sh" bash -c \
    '"$0/bench/registry_bench" --registry "$0/bin/rcan-registry" --database "$RCAN_REGISTRY_DATABASE" --instances "$1" "${@:2}"' \
    "$BUILD" "$n" "$@"
done
