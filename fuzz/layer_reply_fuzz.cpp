// libFuzzer target: a brain layer's answer (node/layers.h). parse_layer_reply() must never
// crash; when it accepts, building the escalated COMMAND must either fail cleanly or give a
// COMMAND whose ai block says escalated, names the layer, and keeps the original message_id.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string_view>

#include "node/ai/brain_layers.h"
#include "rcan/errors.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace rcan;
  std::string_view body(reinterpret_cast<const char*>(data), size);
  auto reply = node::parse_layer_reply(body);
  if (!reply.ok()) return 0;
  const json::Value* action = reply->command.find("action");
  if (!action || !action->is_string() || action->as_string().empty() || !reply->ai.is_object())
    std::abort();
  Message orig;
  orig.message_id = "6f1c3b5e-2a4d-4f7e-9b1a-0c2d3e4f5a6b";
  orig.timestamp_ms = 1'750'000'000'000;
  auto m = node::escalated_message(orig, *reply, "planner");
  if (!m.ok()) return 0;
  if (!m->ai || !m->ai->escalated || m->ai->layer != "planner" ||
      m->message_id != orig.message_id || m->type != MessageType::kCommand ||
      m->ai->provider.empty() || m->ai->model.empty())
    std::abort();
  if (m->ai->confidence && !(*m->ai->confidence >= 0.0 && *m->ai->confidence <= 1.0)) std::abort();
  return 0;
}
