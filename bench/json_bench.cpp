// JSON micro-benchmarks: the JSON work the node does for every COMMAND.
//
//   BM_Parse_Command            the request body (json::parse)
//   BM_Dump_AckEnvelope         the answer (json::dump of the ACK envelope)
//   BM_Canonical_AuditDetail    the audit record's `detail` member, canonical(Object)
//   BM_Canonical_AuditDetail_ValueCopy   the same through canonical(Value(detail)): the copy the
//                               audit path made before canonical(Object) existed
//   BM_AuditPrepare             the whole record's member fragments, off the writer thread
//                               (audit::internal::prepare)
//   BM_Parse_FleetEstop         a fleet ESTOP as a robot receives it over MQTT: a 7,514-byte
//                               token and a 4,412-byte signature (ML-DSA-65 sizes), base64url
//   BM_CanonicalWithout_FleetEstop   its signature's preimage (canonical_without "sig")
#include <benchmark/benchmark.h>

#include <cstdint>
#include <string>
#include <utility>

#include "audit/fast_seal.h"
#include "rcan/audit/record.h"
#include "rcan/json.h"

namespace {

using rcan::json::Array;
using rcan::json::Object;
using rcan::json::Value;

const std::string kCommand =
    R"({"version":"1.0.0","message_id":"3f0c8a52-9d7e-4b6a-8f1e-2c4d6e8a0b1c","type":"COMMAND",)"
    R"("timestamp_ms":1795000000123,"payload":{"action":"move","linear":0.2,"duration_ms":100}})";

Object applied() {
  return Object{
      {"action", "move"}, {"linear", 0.2}, {"angular", 0.0}, {"duration_ms", int64_t{100}}};
}

Object detail() {
  Object d{{"transport", "http"}, {"route", "/rcan/v1/command"}};
  d.set("applied", applied());
  return d;
}

Value envelope() {
  Object payload{
      {"command", "move"},
      {"result",
       Object{{"accepted", true}, {"odometry_m", 12.25}, {"pose", Array{1.5, -0.25, 0.7853}}}}};
  Object o;
  o.set("version", "1.2");
  o.set("message_id", "9b2e4c6a-1d3f-4a5b-8c7d-0e1f2a3b4c5d");
  o.set("source_ruri", "rcan://local.rcan/rcan/sim-rover/0fee043e");
  o.set("type", "ACK");
  o.set("message_type", "ACK");
  o.set("reply_to", "3f0c8a52-9d7e-4b6a-8f1e-2c4d6e8a0b1c");
  o.set("timestamp_ms", int64_t{1795000000456});
  o.set("payload", std::move(payload));
  return o;
}

// base64url text of `n` characters, a fixed pseudo-random sequence.
std::string base64url_text(size_t n) {
  static const char* abc = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789-_";
  std::string s;
  uint32_t x = 12345;
  for (size_t i = 0; i < n; ++i) {
    x = x * 1103515245 + 12345;
    s.push_back(abc[(x >> 16) & 63]);
  }
  return s;
}

const std::string& fleet_estop() {
  static const std::string text = rcan::json::dump(Value(Object{
      {"version", "1.0.0"},
      {"message_id", "3f0c8a52-9d7e-4b6a-8f1e-2c4d6e8a0b1c"},
      {"type", "SAFETY"},
      {"timestamp_ms", int64_t{1795000000123}},
      {"source_ruri", "rcan://local.rcan/rcan/coordinator/0fee043e"},
      {"target_ruri", "broadcast"},
      {"auth_token", base64url_text(2600) + "." + base64url_text(500) + "." + base64url_text(4412)},
      {"payload", Object{{"safety_event", "ESTOP"}, {"reason", "fleet stop"}}},
      {"sig",
       Object{{"alg", "ml-dsa-65"}, {"kid", "coordinator-1"}, {"value", base64url_text(4412)}}},
  }));
  return text;
}

void BM_Parse_FleetEstop(benchmark::State& state) {
  if (!rcan::json::parse(fleet_estop()).ok()) {
    state.SkipWithError("the fleet ESTOP does not parse");
    return;
  }
  for (auto _ : state) benchmark::DoNotOptimize(rcan::json::parse(fleet_estop()));
  state.SetBytesProcessed(static_cast<int64_t>(state.iterations() * fleet_estop().size()));
}
BENCHMARK(BM_Parse_FleetEstop);

void BM_CanonicalWithout_FleetEstop(benchmark::State& state) {
  auto parsed = rcan::json::parse(fleet_estop());
  if (!parsed.ok()) {
    state.SkipWithError("the fleet ESTOP does not parse");
    return;
  }
  const Value v = std::move(parsed).value();
  for (auto _ : state)
    benchmark::DoNotOptimize(rcan::json::canonical_without(v.as_object(), "sig"));
}
BENCHMARK(BM_CanonicalWithout_FleetEstop);

void BM_Parse_Command(benchmark::State& state) {
  for (auto _ : state) benchmark::DoNotOptimize(rcan::json::parse(kCommand));
}
BENCHMARK(BM_Parse_Command);

void BM_Dump_AckEnvelope(benchmark::State& state) {
  const Value v = envelope();
  for (auto _ : state) benchmark::DoNotOptimize(rcan::json::dump(v));
}
BENCHMARK(BM_Dump_AckEnvelope);

void BM_Canonical_AuditDetail(benchmark::State& state) {
  const Object d = detail();
  for (auto _ : state) benchmark::DoNotOptimize(rcan::json::canonical(d));
}
BENCHMARK(BM_Canonical_AuditDetail);

void BM_Canonical_AuditDetail_ValueCopy(benchmark::State& state) {
  const Object d = detail();
  for (auto _ : state) benchmark::DoNotOptimize(rcan::json::canonical(Value(d)));
}
BENCHMARK(BM_Canonical_AuditDetail_ValueCopy);

void BM_AuditPrepare(benchmark::State& state) {
  rcan::audit::AuditEntry e;
  e.principal = "user-1@rcan://local.rcan/rcan/sim-rover/0fee043e";
  e.ruri = "rcan://local.rcan/rcan/sim-rover/0fee043e";
  e.timestamp_ms = 1795000000123;
  e.message_id = "3f0c8a52-9d7e-4b6a-8f1e-2c4d6e8a0b1c";
  e.event = "COMMAND";
  e.outcome = "ok";
  e.sender_type = "operator";
  e.sub = "user-1";
  e.action = "move";
  e.detail = detail();
  for (auto _ : state) benchmark::DoNotOptimize(rcan::audit::internal::prepare(e));
}
BENCHMARK(BM_AuditPrepare);

}  // namespace

BENCHMARK_MAIN();
