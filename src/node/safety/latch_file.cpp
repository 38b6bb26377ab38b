// The ESTOP latch's file (latch_file.h).
#include "node/safety/latch_file.h"

#include <algorithm>
#include <filesystem>
#include <memory>

#include "rcan/hash.h"
#include "rcan/json.h"

namespace rcan::node {

LatchFile::LatchFile(const std::string& state_dir, base::Env* env)
    : env_(env ? env : base::Env::posix()), path_(state_dir + "/" + kName) {}

Result<LatchRead> LatchFile::read() {
  LatchRead out;
  auto text = env_->read_file(path_);
  if (!text.ok()) {
    if (text.error().code == base::IoCode::kNotFound) {
      out.missing = true;
      return out;
    }
    return Error(ErrorCode::kInternal, "state file unreadable: " + text.error().message, "",
                 kUnreadable);
  }
  auto parsed = json::parse(*text);
  if (!parsed.ok() || !parsed->is_object()) {
    out.corrupt = true;
    out.why = parsed.ok() ? "state file is not an object"
                          : "state file corrupt: " + parsed.error().message;
    return out;
  }
  const auto* fmt = parsed->get("format");
  const auto* active = parsed->get("estop_active");
  const auto* check = parsed->get("check");  // absent in files written before it
  std::string check_of;
  if (check && check->is_string()) {
    json::Object rest = parsed->as_object();
    rest.erase("check");
    check_of = sha256_hex(json::dump(json::Value(std::move(rest))));
  }
  if (!fmt || !fmt->is_string() || fmt->as_string() != kFormat || !active || !active->is_bool()) {
    out.corrupt = true;
    out.why = "state file has an unknown format";
    return out;
  }
  if (check && (!check->is_string() || check->as_string() != check_of)) {
    out.corrupt = true;
    out.why = "state file fails its check (a write torn by a crash?)";
    return out;
  }
  fixed_ = check != nullptr && text->size() == kBytes;
  latched_ = active->as_bool();
  LatchState& st = out.state;
  st.active = active->as_bool();
  if (const auto* s = parsed->get("source"); s && s->is_string()) st.source = s->as_string();
  if (const auto* r = parsed->get("reason"); r && r->is_string()) st.reason = r->as_string();
  if (const auto* t = parsed->get("since_ms"); t && t->is_int()) st.since_wall_ms = t->as_int();
  // Absent in files written before latches kept it: LEASEE's rule, as then.
  if (const auto* b = parsed->get("by_level"); b && b->is_int())
    st.by_level = static_cast<int>(std::clamp<int64_t>(b->as_int(), 0, 5));
  return out;
}

void LatchFile::set_aside() {
  std::error_code ec;
  std::filesystem::rename(path_, path_ + ".corrupt", ec);
}

Status LatchFile::write(const LatchState& st, int64_t written_ms) {
  json::Object o{
      {"format", kFormat},       {"estop_active", st.active},    {"source", st.source},
      {"reason", st.reason},     {"since_ms", st.since_wall_ms}, {"by_level", st.by_level},
      {"written_ms", written_ms}};
  json::Object file{{"check", sha256_hex(json::dump(json::Value(o)))}};
  for (auto& [k, v] : o) file.set(k, std::move(v));
  std::string body = json::dump(json::Value(std::move(file)));
  if (body.size() < kBytes) body.resize(kBytes - 1, ' ');
  body += '\n';
  const bool fixed = body.size() == kBytes;
  base::IoStatus s;
  // In place only from cleared to latched, over the file that is still there (opened without
  // creating it): no new inode, rename or directory sync. A crash in the middle leaves the
  // cleared state (not yet acknowledged) or a torn file, which comes up latched. A re-latch (a
  // higher role) is replaced whole: torn, it would come up latched by the node, which a lower
  // role may clear.
  const bool in_place = st.active && fixed && fixed_ && !latched_;
  std::unique_ptr<base::WritableFile> f;
  if (in_place) {  // gone, or not a regular file (a link, a FIFO): written whole below
    auto opened = env_->open_existing_at(path_, 0);
    if (opened.ok()) f = std::move(opened).value();
  }
  if (f) {
    s = f->append(body);
    if (s.ok()) s = f->sync();
    if (base::IoStatus c = f->close(); s.ok()) s = c;
  }
  // Replaced whole: a clear (one not made durable leaves the latched file as it was), a file of
  // another shape, a failed in-place latch (a failed sync, the file removed or replaced meanwhile).
  std::string in_place_error;
  if (!f || !s.ok()) {
    if (!s.ok()) in_place_error = s.error().message + "; written whole: ";
    s = env_->write_file_atomic(path_, body);
  }
  fixed_ = s.ok() && fixed;
  latched_ = s.ok() ? st.active : true;  // unknown after a failure: never in place
  if (!s.ok())
    return Error(ErrorCode::kInternal, in_place_error + s.error().message, "", kUnwritable);
  return Status::Ok();
}

}  // namespace rcan::node
