// The driver-process frame codec (src/drivers/process/frame.h): framing, the decoder's limits,
// and the strict validation of what a driver process sends.
#include <gtest/gtest.h>

#include <string>

#include "drivers/process/frame.h"
#include "rcan/json.h"

namespace rcan::drivers {
namespace {

std::string frame(const std::string& json) { return encode_frame(json); }

json::Value payload_of(const std::string& f) {
  EXPECT_GE(f.size(), kFrameHeaderBytes);
  auto v = json::parse(f.substr(kFrameHeaderBytes));
  EXPECT_TRUE(v.ok());
  return v.ok() ? *v : json::Value();
}

TEST(ProcessFrame, HeaderIsBigEndianLength) {
  std::string f = encode_frame(std::string(0x0102, 'x'));
  ASSERT_EQ(f.size(), 4u + 0x0102);
  EXPECT_EQ(f[0], 0);
  EXPECT_EQ(f[1], 0);
  EXPECT_EQ(f[2], 1);
  EXPECT_EQ(f[3], 2);
}

TEST(ProcessFrame, OutgoingFramesCarryTypeSeqAndTheLimitedCommand) {
  auto apply = payload_of(encode_apply(7, node::ActuatorCommand::make_drive(0.25, -0.5, 300)));
  EXPECT_EQ(apply.get("type")->as_string(), "apply");
  EXPECT_EQ(apply.get("seq")->as_int(), 7);
  const json::Value* d = apply.get("command")->get("drive");
  ASSERT_NE(d, nullptr);
  EXPECT_DOUBLE_EQ(d->get("linear_mps")->to_double(), 0.25);
  EXPECT_DOUBLE_EQ(d->get("angular_radps")->to_double(), -0.5);
  EXPECT_EQ(d->get("duration_ms")->as_int(), 300);
  EXPECT_EQ(payload_of(encode_stop(8)).get("type")->as_string(), "stop");
  EXPECT_EQ(payload_of(encode_heartbeat(9)).get("seq")->as_int(), 9);
  auto desc = payload_of(encode_describe(1, 100, 500));
  EXPECT_EQ(desc.get("protocol")->as_int(), 1);
  EXPECT_EQ(desc.get("heartbeat_timeout_ms")->as_int(), 500);
}

TEST(ProcessFrame, DecoderReassemblesFramesSplitAnywhere) {
  const std::string stream = frame("{\"a\":1}") + frame("{\"b\":22}") + frame("{}");
  for (size_t cut = 0; cut <= stream.size(); ++cut) {
    FrameDecoder dec;
    std::vector<std::string> got;
    for (const std::string& part : {stream.substr(0, cut), stream.substr(cut)}) {
      dec.feed(part.data(), part.size());
      while (true) {
        auto f = dec.next();
        ASSERT_TRUE(f.ok());
        if (!*f) break;
        got.push_back(**f);
      }
    }
    ASSERT_EQ(got.size(), 3u) << cut;
    EXPECT_EQ(got[1], "{\"b\":22}");
    EXPECT_EQ(dec.buffered(), 0u);
  }
}

TEST(ProcessFrame, ZeroAndOversizeLengthsAreStickyErrors) {
  for (std::string header : {std::string("\0\0\0\0", 4), std::string("\0\x01\0\x01", 4),
                             std::string("\xff\xff\xff\xff", 4)}) {
    FrameDecoder dec;
    dec.feed(header.data(), header.size());  // refused from the header alone
    auto f = dec.next();
    ASSERT_FALSE(f.ok());
    EXPECT_NE(f.error().message.find("frame length"), std::string::npos);
    const std::string more = frame("{}");
    dec.feed(more.data(), more.size());
    EXPECT_FALSE(dec.next().ok());
  }
  FrameDecoder dec;  // exactly the maximum is fine
  std::string big = encode_frame(std::string(kMaxFramePayload, ' '));
  dec.feed(big.data(), big.size());
  auto f = dec.next();
  ASSERT_TRUE(f.ok());
  ASSERT_TRUE(f->has_value());
  EXPECT_EQ((*f)->size(), kMaxFramePayload);
}

TEST(ProcessFrame, ParsesTheProcessMessages) {
  auto d = parse_incoming(
      R"({"type":"describe","protocol":1,"name":"base","max_linear_mps":1.5,"max_angular_radps":3})");
  ASSERT_TRUE(d.ok()) << d.error().message;
  EXPECT_EQ(d->kind, Incoming::Kind::kDescribe);
  EXPECT_EQ(d->name, "base");
  EXPECT_DOUBLE_EQ(d->max_linear_mps.value(), 1.5);
  EXPECT_DOUBLE_EQ(d->max_angular_radps.value(), 3.0);
  auto h = parse_incoming(R"({"type":"heartbeat","seq":4,"fault":"motor hot"})");
  ASSERT_TRUE(h.ok());
  EXPECT_EQ(h->fault, "motor hot");
  auto s = parse_incoming(
      R"({"type":"state","state":{"stopped":false,"base":{"x":1.5,"y":-2,"theta":0.5,)"
      R"("linear_mps":0.2,"target_linear_mps":0.3,"drive_remaining_ms":120},)"
      R"("arm":{"joints_rad":[1,2,3,4,5,6]},"gripper":{"closed":true},"battery_v":12.5}})");
  ASSERT_TRUE(s.ok()) << s.error().message;
  EXPECT_FALSE(s->state.stopped);
  EXPECT_DOUBLE_EQ(s->state.x, 1.5);
  EXPECT_DOUBLE_EQ(s->state.y, -2.0);
  EXPECT_DOUBLE_EQ(s->state.target_linear_mps, 0.3);
  EXPECT_EQ(s->state.drive_remaining_ms, 120);
  EXPECT_DOUBLE_EQ(s->state.joints_rad[5], 6.0);
  EXPECT_TRUE(s->state.gripper_closed);
  EXPECT_TRUE(s->state.battery_known);
  EXPECT_DOUBLE_EQ(s->state.battery_v, 12.5);
}

TEST(ProcessFrame, RefusesWhatIsNotExactlyTheProtocol) {
  const char* bad[] = {
      "not json",
      "[1,2]",
      R"({"seq":1})",
      R"({"type":7})",
      R"({"type":"selfdestruct"})",
      R"({"type":"describe","name":"x"})",
      R"({"type":"describe","protocol":2,"name":"x"})",
      R"({"type":"describe","protocol":1})",
      R"({"type":"describe","protocol":1,"name":""})",
      R"({"type":"describe","protocol":1,"name":"x","max_linear_mps":"fast"})",
      R"({"type":"heartbeat","seq":"one"})",
      R"({"type":"heartbeat","fault":3})",
      R"({"type":"state"})",
      R"({"type":"state","state":[]})",
      R"({"type":"state","state":{"base":{"x":"far"}}})",
      R"({"type":"state","state":{"base":{"x":1e999}}})",
      R"({"type":"state","state":{"base":7}})",
      R"({"type":"state","state":{"stopped":"yes"}})",
      R"({"type":"state","state":{"base":{"drive_remaining_ms":1.5}}})",
      R"({"type":"state","state":{"arm":{"joints_rad":[1,2,3]}}})",
      R"({"type":"state","state":{"arm":{"joints_rad":[1,2,3,4,5,"6"]}}})",
      R"({"type":"state","state":{"gripper":{"closed":1}}})",
      R"({"type":"state","state":{"battery_v":null}})",
      R"({"type":"heartbeat","type":"heartbeat"})",
  };
  for (const char* b : bad) {
    auto r = parse_incoming(b);
    EXPECT_FALSE(r.ok()) << b;
    if (!r.ok()) {
      EXPECT_FALSE(r.error().message.empty()) << b;
    }
  }
  // What the process sent is shown as printable ASCII only.
  auto odd = parse_incoming("{\"type\":\"x\u00e9\\n\"}");
  ASSERT_FALSE(odd.ok());
  EXPECT_NE(odd.error().message.find("\"x???\""), std::string::npos) << odd.error().message;
  // Deeply nested input is refused by depth, not by recursion.
  std::string deep = R"({"type":"state","state":{"base":)" + std::string(5000, '[') + "}}";
  EXPECT_FALSE(parse_incoming(deep).ok());
}

}  // namespace
}  // namespace rcan::drivers
