#!/usr/bin/env bash
# §16 AI accountability, end to end on a simulated robot (docs/AI.md):
#   1. an AI-produced drive command below the nav confidence gate is escalated from the fast
#      layer to the planner layer (the built-in simulated layer, `rcand --sim-layer`), whose
#      command passes the gate and is dispatched with a watermark; a planner command that is
#      still below the gate has no higher layer and is blocked (403 CONFIDENCE_GATE_FAIL);
#   2. three arm commands stopped by a HiTL gate: one approved by the owner from the CLI,
#      one denied, one left to time out;
#   3. the dispatched command's watermark verified over the public endpoint, and the audit
#      chain verified offline with only its secret.
# Usage: scripts/demo-ai.sh [BIN_DIR]   (default build/release/bin; needs curl, python3)
set -euo pipefail

ROOT=$(cd "$(dirname "$0")/.." && pwd)
BIN=${1:-${RCAN_BIN_DIR:-$ROOT/build/release/bin}}
RCAND=$BIN/rcand
RCAN=$BIN/rcan
WORK=$(mktemp -d "${TMPDIR:-/tmp}/rcan-demo-ai.XXXXXX")
PIDS=()
cleanup() {
  for p in "${PIDS[@]}"; do kill "$p" 2>/dev/null || true; done
  wait 2>/dev/null || true
  rm -rf "$WORK"
}
trap cleanup EXIT

say() { printf '\n\033[1m== %s\033[0m\n' "$*"; }
json() { python3 -c "import json,sys; d=json.load(sys.stdin); print(eval(sys.argv[1], {'d': d}))" "$1"; }
fail() { echo "demo-ai: FAILED: $*" >&2; exit 1; }

# Waits for a daemon's "listening" log line and prints its port.
wait_port() {
  local log=$1
  for _ in $(seq 1 300); do
    if grep -q '"event":"listening"' "$log" 2>/dev/null; then
      grep '"event":"listening"' "$log" | head -1 | sed -E 's/.*"url":"[^"]*:([0-9]+)".*/\1/'
      return 0
    fi
    sleep 0.1
  done
  cat "$log" >&2
  return 1
}

say "identity: robot keys, audit chain secret, a token issuer"
mkdir -p "$WORK/data"
"$RCAN" keys generate --dir "$WORK/data/keys" >/dev/null
"$RCAN" audit new-secret --out "$WORK/data/audit.secret" >/dev/null
"$RCAN" keys issuer --dir "$WORK/issuer" --name demo-issuer >/dev/null

say "the planner brain layer (built-in simulated layer)"
"$RCAND" --sim-layer --port 0 --layer planner --confidence 0.93 2>"$WORK/planner.log" &
PIDS+=($!)
PLANNER_PORT=$(wait_port "$WORK/planner.log")
echo "planner layer at http://127.0.0.1:$PLANNER_PORT"

RURI=rcan://local.rcan/acme/demo-rover/0a1b2c3d
cat >"$WORK/robot.rcan.yaml" <<YAML
rcan_version: "1.2"
ruri: $RURI
rrn: RRN-000000000042
robot: {name: demo-rover, manufacturer: acme, model: demo-rover, type: mobile_differential_with_arm}
capabilities: [status, chat, teleop, nav, arm]
safety: {local_safety_wins: true, max_linear_speed_mps: 0.5}
security:
  jwt:
    issuers: [{issuer: demo-issuer, key_file: $WORK/issuer/ed25519.pub.pem}]
agent:
  confidence_gates:
    - {scope: nav, min_confidence: 0.8, on_fail: escalate}
  hitl_gates:
    - action_types: [arm_move]
      require_auth: true
      auth_timeout_ms: 2500
      on_timeout: block
      notify: [ws]
  layers:
    planner: {url: "http://127.0.0.1:$PLANNER_PORT/", timeout_ms: 2000}
YAML
echo "gates: nav >= 0.8 (escalate); arm_move needs OWNER/CREATOR approval within 2.5 s"

say "rcand with that configuration"
"$RCAND" --config "$WORK/robot.rcan.yaml" --data-dir "$WORK/data" --port 0 2>"$WORK/rcand.log" &
RCAND_PID=$!
PIDS+=($RCAND_PID)
PORT=$(wait_port "$WORK/rcand.log")
URL=http://127.0.0.1:$PORT
echo "rcand at $URL"

token() {  # sub role scopes
  "$RCAN" token issue --key "$WORK/issuer/ed25519.seed" --iss demo-issuer --sub "$1" --role "$2" --aud "$RURI" --scope "$3" --ttl 1h
}
token alice owner status,control,config >"$WORK/owner.token"
token agent-bob leasee status,control >"$WORK/agent.token"
chmod 600 "$WORK"/*.token
export RCAN_URL=$URL

send() {  # token-file body → prints "HTTP <status>" then the body
  curl -s -o "$WORK/reply.json" -w '%{http_code}' -X POST "$URL/rcan/v1/command" \
    -H "Authorization: Bearer $(cat "$1")" -H 'Content-Type: application/json' --data-binary "$2"
}
now_ms() { python3 -c 'import time; print(int(time.time()*1000))'; }
uuid() { python3 -c 'import uuid; print(uuid.uuid4())'; }

say "1a. AI drive command at confidence 0.42 from the fast layer: below the nav gate → escalated"
MID=$(uuid)
BODY=$(cat <<JSON
{"version":"1.0.0","message_id":"$MID","type":"COMMAND","timestamp_ms":$(now_ms),
 "payload":{"action":"move","linear":0.3,"duration_ms":300,"instruction":"drive to the charging dock"},
 "ai":{"provider":"sim","model":"sim-fast","layer":"fast","confidence":0.42,"thought_id":"th_demo_fast_1","escalated":false},
 "thought":{"reasoning":"dock is probably ahead; camera is dim","instruction":"drive to the charging dock",
            "context_snapshot":{"battery":0.18}}}
JSON
)
STATUS=$(send "$WORK/agent.token" "$BODY")
echo "HTTP $STATUS"; cat "$WORK/reply.json"; echo
[ "$STATUS" = 200 ] || fail "the escalated command was not dispatched"
WM=$(json 'd["payload"]["watermark_token"]' <"$WORK/reply.json")
echo "dispatched with watermark $WM"
AUDIT=$(curl -s "$URL/api/audit?limit=50" -H "Authorization: Bearer $(cat "$WORK/owner.token")")
echo "$AUDIT" | python3 -c "
import json,sys
for e in json.load(sys.stdin)['entries']:
    if e.get('message_id') == '$MID':
        print('  audit:', e['event'], e['outcome'], 'ai=' + json.dumps({k: e['ai'].get(k) for k in ('layer','confidence','escalated','thought_id')}) if 'ai' in e else '')
"
NEW_THOUGHT=$(echo "$AUDIT" | python3 -c "
import json,sys
print([e for e in json.load(sys.stdin)['entries'] if e.get('message_id')=='$MID' and e['event']=='COMMAND'][0]['ai']['thought_id'])")
echo "the planner's thought (rcan thoughts get $NEW_THOUGHT, owner token):"
"$RCAN" thoughts get "$NEW_THOUGHT" --token-file "$WORK/owner.token"

say "1b. a planner command still below the gate: no higher layer → blocked"
BODY=$(cat <<JSON
{"version":"1.0.0","message_id":"$(uuid)","type":"COMMAND","timestamp_ms":$(now_ms),
 "payload":{"action":"move","linear":0.3,"duration_ms":300},
 "ai":{"provider":"sim","model":"sim-planner","layer":"planner","confidence":0.3,"escalated":false}}
JSON
)
STATUS=$(send "$WORK/agent.token" "$BODY")
echo "HTTP $STATUS"; cat "$WORK/reply.json"; echo
[ "$STATUS" = 403 ] || fail "expected 403 CONFIDENCE_GATE_FAIL"

arm() {  # → message id of a held arm_move
  local id; id=$(uuid)
  local st
  st=$(send "$WORK/agent.token" "{\"version\":\"1.0.0\",\"message_id\":\"$id\",\"type\":\"COMMAND\",\"timestamp_ms\":$(now_ms),\"payload\":{\"action\":\"arm_move\",\"joints\":[0.1,0.2,0.0,0.0,0.0,0.0]},\"ai\":{\"provider\":\"sim\",\"model\":\"sim-planner\",\"layer\":\"planner\",\"confidence\":0.97,\"escalated\":false}}")
  [ "$st" = 202 ] || { cat "$WORK/reply.json" >&2; fail "expected 202 PENDING_AUTH, got $st"; }
  echo "$id"
}

say "2a. arm_move held by the HiTL gate (202 PENDING_AUTH), approved by the owner from the CLI"
A1=$(arm); echo "held $A1"
"$RCAN" pending --token-file "$WORK/owner.token"
"$RCAN" authorize "$A1" --approve --reason "workspace is clear" --token-file "$WORK/owner.token"

say "2b. another arm_move, denied"
A2=$(arm); echo "held $A2"
"$RCAN" authorize "$A2" --deny --reason "a person is next to the arm" --token-file "$WORK/owner.token"

say "2c. a third arm_move, left to time out (2.5 s, on_timeout: block)"
A3=$(arm); echo "held $A3"
"$RCAN" pending --token-file "$WORK/owner.token"
for _ in $(seq 1 100); do
  "$RCAN" pending --token-file "$WORK/owner.token" --json | grep -q "$A3" || break
  sleep 0.1
done
"$RCAN" pending --token-file "$WORK/owner.token"
echo "a LEASEE may not authorize (INSUFFICIENT_PRIVILEGES, audited):"
"$RCAN" authorize "$A3" --approve --token-file "$WORK/agent.token" || true
curl -s "$URL/api/audit?limit=100" -H "Authorization: Bearer $(cat "$WORK/owner.token")" | python3 -c "
import json,sys
ids = {'$A1': 'approved', '$A2': 'denied', '$A3': 'timed out'}
for e in json.load(sys.stdin)['entries']:
    if e.get('message_id') in ids:
        print('  audit [%s]: %s %s%s' % (ids[e['message_id']], e['event'], e['outcome'], ' watermark=' + e['watermark_token'] if 'watermark_token' in e else ''))
"

say "3a. the watermark, verified over the public endpoint (no token)"
RRN=RRN-000000000042
curl -s -w '\nHTTP %{http_code}\n' "$URL/api/v1/watermark/verify?token=$WM&rrn=$RRN"
CODE=$(curl -s -o /dev/null -w '%{http_code}' "$URL/api/v1/watermark/verify?token=$WM&rrn=$RRN")
[ "$CODE" = 200 ] || fail "watermark not verified"
echo "unknown token:"; curl -s -w '  HTTP %{http_code}\n' "$URL/api/v1/watermark/verify?token=rcan-wm-v1:00000000000000000000000000000000&rrn=$RRN"
echo "malformed token:"; curl -s -w '  HTTP %{http_code}\n' "$URL/api/v1/watermark/verify?token=nope&rrn=$RRN"

say "3b. stop rcand and verify the audit chain offline"
kill -TERM "$RCAND_PID"
wait "$RCAND_PID" || true
"$RCAN" audit verify --data-dir "$WORK/data" --secret-file "$WORK/data/audit.secret"
say "demo complete"
