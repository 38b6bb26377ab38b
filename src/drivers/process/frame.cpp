#include "drivers/process/frame.h"

#include <cmath>

#include "rcan/json.h"

namespace rcan::drivers {
namespace {

constexpr size_t kMaxNameBytes = 128;
constexpr size_t kMaxFaultBytes = 512;

Error bad(std::string msg, std::string field = {}) {
  return Error(ErrorCode::kSchemaValidationFailed, std::move(msg), std::move(field),
               "driver_protocol");
}

std::string frame_of(const json::Object& o) { return encode_frame(json::dump(json::Value(o))); }

// Reads optional members of `o` into out-parameters, remembering the first type error.
class Reader {
 public:
  Reader(const json::Value& o, std::string path) : o_(o), path_(std::move(path)) {}

  void num(std::string_view key, double& out) {
    const json::Value* v = o_.get(key);
    if (!v) return;
    if (!v->is_number() || !std::isfinite(v->to_double())) return fail(key, "a finite number");
    out = v->to_double();
  }
  void opt_num(std::string_view key, std::optional<double>& out) {
    if (!o_.get(key)) return;
    double d = 0;
    num(key, d);
    if (!err_) out = d;
  }
  void integer(std::string_view key, int64_t& out) {
    const json::Value* v = o_.get(key);
    if (!v) return;
    if (!v->is_int()) return fail(key, "an integer");
    out = v->as_int();
  }
  void boolean(std::string_view key, bool& out) {
    const json::Value* v = o_.get(key);
    if (!v) return;
    if (!v->is_bool()) return fail(key, "a boolean");
    out = v->as_bool();
  }
  void str(std::string_view key, std::string& out, size_t max) {
    const json::Value* v = o_.get(key);
    if (!v) return;
    if (!v->is_string() || v->as_string().size() > max)
      return fail(key, "a string of at most " + std::to_string(max) + " bytes");
    out = v->as_string();
  }
  void joints(std::string_view key, node::JointArray& out) {
    const json::Value* v = o_.get(key);
    if (!v) return;
    if (!v->is_array() || v->as_array().size() != out.size())
      return fail(key, "an array of " + std::to_string(out.size()) + " numbers");
    for (size_t i = 0; i < out.size(); ++i) {
      const json::Value& e = v->as_array()[i];
      if (!e.is_number() || !std::isfinite(e.to_double()))
        return fail(key, "an array of finite numbers");
      out[i] = e.to_double();
    }
  }
  // A nested object (absent: nullopt; present and not an object: an error).
  const json::Value* object(std::string_view key) {
    const json::Value* v = o_.get(key);
    if (!v) return nullptr;
    if (!v->is_object()) {
      fail(key, "an object");
      return nullptr;
    }
    return v;
  }
  void merge(const Reader& inner) {
    if (!err_ && inner.err_) err_ = inner.err_;
  }
  const std::optional<Error>& error() const { return err_; }
  const std::string& path() const { return path_; }

 private:
  void fail(std::string_view key, const std::string& what) {
    if (err_) return;
    std::string f = path_.empty() ? std::string(key) : path_ + "." + std::string(key);
    err_ = bad(f + " must be " + what, f);
  }
  const json::Value& o_;
  std::string path_;
  std::optional<Error> err_;
};

std::optional<Error> read_state(const json::Value& s, node::RobotState& st) {
  Reader r(s, "state");
  r.boolean("stopped", st.stopped);
  if (const json::Value* b = r.object("base")) {
    Reader rb(*b, "state.base");
    rb.num("x", st.x);
    rb.num("y", st.y);
    rb.num("theta", st.theta);
    rb.num("linear_mps", st.linear_mps);
    rb.num("angular_radps", st.angular_radps);
    rb.num("target_linear_mps", st.target_linear_mps);
    rb.num("target_angular_radps", st.target_angular_radps);
    rb.integer("drive_remaining_ms", st.drive_remaining_ms);
    rb.num("odometry_m", st.odometry_m);
    r.merge(rb);
  }
  if (const json::Value* a = r.object("arm")) {
    Reader ra(*a, "state.arm");
    ra.joints("joints_rad", st.joints_rad);
    ra.joints("targets_rad", st.joint_targets_rad);
    ra.num("joint_speed_radps", st.joint_speed_radps);
    r.merge(ra);
  }
  if (const json::Value* g = r.object("gripper")) {
    Reader rg(*g, "state.gripper");
    rg.boolean("closed", st.gripper_closed);
    r.merge(rg);
  }
  std::optional<double> bv, bp;
  r.opt_num("battery_v", bv);
  r.opt_num("battery_pct", bp);
  if (bv || bp) {
    st.battery_known = true;
    st.battery_v = bv.value_or(0.0);
    st.battery_pct = bp.value_or(0.0);
  }
  return r.error();
}

}  // namespace

std::string encode_frame(std::string_view payload) {
  std::string out;
  out.reserve(kFrameHeaderBytes + payload.size());
  const auto n = static_cast<uint32_t>(payload.size());
  out.push_back(static_cast<char>((n >> 24) & 0xff));
  out.push_back(static_cast<char>((n >> 16) & 0xff));
  out.push_back(static_cast<char>((n >> 8) & 0xff));
  out.push_back(static_cast<char>(n & 0xff));
  out.append(payload);
  return out;
}

std::string encode_describe(uint64_t seq, uint32_t heartbeat_ms, uint32_t heartbeat_timeout_ms) {
  return frame_of(
      json::Object{{"type", "describe"},
                   {"seq", static_cast<int64_t>(seq)},
                   {"protocol", static_cast<int64_t>(kProtocolVersion)},
                   {"heartbeat_ms", static_cast<int64_t>(heartbeat_ms)},
                   {"heartbeat_timeout_ms", static_cast<int64_t>(heartbeat_timeout_ms)}});
}

std::string encode_apply(uint64_t seq, const node::ActuatorCommand& cmd) {
  return frame_of(json::Object{
      {"type", "apply"}, {"seq", static_cast<int64_t>(seq)}, {"command", cmd.to_json()}});
}

std::string encode_stop(uint64_t seq) {
  return frame_of(json::Object{{"type", "stop"}, {"seq", static_cast<int64_t>(seq)}});
}

std::string encode_heartbeat(uint64_t seq) {
  return frame_of(json::Object{{"type", "heartbeat"}, {"seq", static_cast<int64_t>(seq)}});
}

void FrameDecoder::feed(const char* data, size_t n) {
  if (err_ || n == 0) return;
  if (off_ > 0 && off_ == buf_.size()) {
    buf_.clear();
    off_ = 0;
  } else if (off_ > 4096 && off_ * 2 > buf_.size()) {
    buf_.erase(0, off_);
    off_ = 0;
  }
  buf_.append(data, n);
}

Result<std::optional<std::string>> FrameDecoder::next() {
  if (err_) return *err_;
  if (buffered() < kFrameHeaderBytes) return std::optional<std::string>();
  const auto* p = reinterpret_cast<const unsigned char*>(buf_.data() + off_);
  const uint32_t n =
      (uint32_t{p[0]} << 24) | (uint32_t{p[1]} << 16) | (uint32_t{p[2]} << 8) | uint32_t{p[3]};
  if (n == 0 || n > max_) {
    err_ = bad("frame length " + std::to_string(n) + " is outside 1.." + std::to_string(max_));
    return *err_;
  }
  if (buffered() < kFrameHeaderBytes + n) return std::optional<std::string>();
  std::string payload = buf_.substr(off_ + kFrameHeaderBytes, n);
  off_ += kFrameHeaderBytes + n;
  return std::optional<std::string>(std::move(payload));
}

Result<Incoming> parse_incoming(std::string_view payload) {
  auto v = json::parse(payload, {.max_depth = 8, .max_bytes = kMaxFramePayload});
  if (!v.ok()) return bad("frame is not JSON: " + v.error().message);
  if (!v->is_object()) return bad("frame is not a JSON object");
  const json::Value* type = v->get("type");
  if (!type || !type->is_string()) return bad("frame has no string \"type\"", "type");
  Incoming in;
  Reader r(*v, "");
  const std::string& t = type->as_string();
  if (t == "describe") {
    in.kind = Incoming::Kind::kDescribe;
    const json::Value* proto = v->get("protocol");
    if (!proto || !proto->is_int())
      return bad("describe needs an integer \"protocol\"", "protocol");
    if (proto->as_int() != kProtocolVersion)
      return bad("protocol " + std::to_string(proto->as_int()) +
                     " is not supported (rcand speaks " + std::to_string(kProtocolVersion) + ")",
                 "protocol");
    in.protocol = kProtocolVersion;
    const json::Value* name = v->get("name");
    if (!name || !name->is_string() || name->as_string().empty())
      return bad("describe needs a non-empty string \"name\"", "name");
    r.str("name", in.name, kMaxNameBytes);
    r.opt_num("max_linear_mps", in.max_linear_mps);
    r.opt_num("max_angular_radps", in.max_angular_radps);
  } else if (t == "heartbeat") {
    in.kind = Incoming::Kind::kHeartbeat;
    int64_t seq = 0;
    r.integer("seq", seq);
    r.str("fault", in.fault, kMaxFaultBytes);
  } else if (t == "state") {
    in.kind = Incoming::Kind::kState;
    const json::Value* s = r.object("state");
    if (!s && !r.error()) return bad("state frame needs an object \"state\"", "state");
    if (s) {
      if (auto e = read_state(*s, in.state)) return *e;
    }
  } else {
    std::string shown;  // printable ASCII only: the text goes to the log and the audit record
    for (char c : t.substr(0, 64)) shown.push_back(c >= 0x20 && c < 0x7f ? c : '?');
    return bad("unknown frame type \"" + shown + "\"", "type");
  }
  if (r.error()) return *r.error();
  return in;
}

}  // namespace rcan::drivers
