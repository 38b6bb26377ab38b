#!/usr/bin/env bash
# Runs a command beside a PostgreSQL server of its own: a fresh cluster (initdb) in a temporary
# directory, listening on a free loopback port, with empty databases; the command gets their
# URLs in RCAN_REGISTRY_DATABASE (postgresql://rcan@127.0.0.1:<port>/<db>) and
# RCAN_REGISTRY_DATABASE_2…_4. The server and its
# files are removed afterwards; the command's exit status is returned.
# PostgreSQL refuses to run as root: under root the server runs as the `postgres` user.
#
# Usage: scripts/with_postgres.sh COMMAND [ARGS...]      (exit 77 when PostgreSQL is missing)
set -uo pipefail
BIN=""
for d in /usr/lib/postgresql/*/bin; do [ -x "$d/postgres" ] && BIN=$d; done
[ -n "$BIN" ] || { echo "SKIP: PostgreSQL is not installed (scripts/install-deps.sh)" >&2; exit 77; }
WORK=$(mktemp -d "${TMPDIR:-/tmp}/rcan-pg.XXXXXX")
AS=()
if [ "$(id -u)" -eq 0 ]; then
  chown postgres: "$WORK"
  AS=(/usr/bin/setpriv --reuid=postgres --regid=postgres --init-groups)
fi
PORT=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
PID=
cleanup() { [ -n "$PID" ] && kill "$PID" 2>/dev/null && wait "$PID" 2>/dev/null; rm -rf "$WORK"; }
trap cleanup EXIT
"${AS[@]}" "$BIN/initdb" -D "$WORK/data" -A trust -U rcan --no-sync -E UTF8 >"$WORK/initdb.log" 2>&1 ||
  { cat "$WORK/initdb.log" >&2; exit 1; }
"${AS[@]}" "$BIN/postgres" -D "$WORK/data" -p "$PORT" -k "$WORK" -c listen_addresses=127.0.0.1 \
  -c max_connections=200 -c fsync=off >"$WORK/pg.log" 2>&1 &
PID=$!
ready=
for _ in $(seq 1 300); do
  grep -q "ready to accept connections" "$WORK/pg.log" && { ready=1; break; }
  sleep 0.1
done
[ -n "$ready" ] || { cat "$WORK/pg.log" >&2; exit 1; }
for db in rcan rcan_2 rcan_3 rcan_4; do
  "$BIN/psql" "host=127.0.0.1 port=$PORT user=rcan dbname=postgres" -qc "CREATE DATABASE $db" || exit 1
done
export RCAN_REGISTRY_DATABASE="postgresql://rcan@127.0.0.1:$PORT/rcan"
# Three more empty databases on the same server, for tests that run several registries at once
# (a federation's root and its delegated node each have a database of their own).
export RCAN_REGISTRY_DATABASE_2="postgresql://rcan@127.0.0.1:$PORT/rcan_2"
export RCAN_REGISTRY_DATABASE_3="postgresql://rcan@127.0.0.1:$PORT/rcan_3"
export RCAN_REGISTRY_DATABASE_4="postgresql://rcan@127.0.0.1:$PORT/rcan_4"
"$@"
