#!/usr/bin/env bash
# registry_bench on PostgreSQL: one rcan-registry instance, then two on the same database
# (docs/REGISTRY.md §Performance). Starts its own PostgreSQL cluster (initdb) on a free
# loopback port in a temporary directory and removes it afterwards.
#
# Usage: bench/registry_pg_bench.sh BUILD_DIR [registry_bench options: --robots N --clients C --seconds S]
set -euo pipefail
BUILD=${1:?build dir}; shift
BIN=""
for d in /usr/lib/postgresql/*/bin; do [ -x "$d/postgres" ] && BIN=$d; done
[ -n "$BIN" ] || { echo "PostgreSQL is not installed (scripts/install-deps.sh)" >&2; exit 2; }
WORK=$(mktemp -d "${TMPDIR:-/tmp}/registry-pg-bench.XXXXXX")
AS=()
if [ "$(id -u)" -eq 0 ]; then  # PostgreSQL refuses to run as root
  chown postgres: "$WORK"
  AS=(/usr/bin/setpriv --reuid=postgres --regid=postgres --init-groups)
fi
PORT=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
PID=
cleanup() { [ -n "$PID" ] && kill "$PID" 2>/dev/null && wait "$PID" 2>/dev/null; rm -rf "$WORK"; }
trap cleanup EXIT
"${AS[@]}" "$BIN/initdb" -D "$WORK/data" -A trust -U rcan --no-sync -E UTF8 >"$WORK/initdb.log" 2>&1
"${AS[@]}" "$BIN/postgres" -D "$WORK/data" -p "$PORT" -k "$WORK" -c listen_addresses=127.0.0.1 \
  -c max_connections=200 >"$WORK/pg.log" 2>&1 &
PID=$!
for _ in $(seq 1 100); do grep -q "ready to accept connections" "$WORK/pg.log" && break; sleep 0.1; done
for n in 1 2; do
  db=bench$n
  "$BIN/psql" "host=127.0.0.1 port=$PORT user=rcan dbname=postgres" -qc "CREATE DATABASE $db"
  echo "== $n instance(s) on one PostgreSQL database"
  "$BUILD/bench/registry_bench" --registry "$BUILD/bin/rcan-registry" \
    --database "postgresql://rcan@127.0.0.1:$PORT/$db" --instances "$n" "$@"
done
