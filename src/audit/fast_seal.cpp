#include "audit/fast_seal.h"

#include <algorithm>
#include <cstring>

#include "rcan/encoding.h"
#include "rcan/hash.h"

namespace rcan::audit::internal {

Hasher::Hasher(std::string_view key) {
  md_ = EVP_MD_fetch(nullptr, "SHA256", nullptr);
  work_ = EVP_MD_CTX_new();
  inner_ = EVP_MD_CTX_new();
  outer_ = EVP_MD_CTX_new();
  uint8_t k[64] = {};
  if (key.size() > 64) {
    Digest256 d = rcan::sha256(key);
    std::memcpy(k, d.data(), d.size());
  } else {
    std::memcpy(k, key.data(), key.size());
  }
  uint8_t ipad[64], opad[64];
  for (int i = 0; i < 64; ++i) {
    ipad[i] = static_cast<uint8_t>(k[i] ^ 0x36);
    opad[i] = static_cast<uint8_t>(k[i] ^ 0x5c);
  }
  EVP_DigestInit_ex(inner_, md_, nullptr);
  EVP_DigestUpdate(inner_, ipad, sizeof ipad);
  EVP_DigestInit_ex(outer_, md_, nullptr);
  EVP_DigestUpdate(outer_, opad, sizeof opad);
  secure_wipe(k, sizeof k);
  secure_wipe(ipad, sizeof ipad);
  secure_wipe(opad, sizeof opad);
}

Hasher::~Hasher() {
  EVP_MD_CTX_free(work_);
  EVP_MD_CTX_free(inner_);
  EVP_MD_CTX_free(outer_);
  EVP_MD_free(md_);
}

void Hasher::digest(EVP_MD_CTX* from, std::string_view data, uint8_t out[32]) {
  if (from) {
    EVP_MD_CTX_copy_ex(work_, from);
  } else {
    EVP_DigestInit_ex(work_, md_, nullptr);
  }
  EVP_DigestUpdate(work_, data.data(), data.size());
  unsigned int n = 0;
  EVP_DigestFinal_ex(work_, out, &n);
}

std::string Hasher::sha256_hex(std::string_view data) {
  uint8_t out[32];
  digest(nullptr, data, out);
  return to_hex(out, sizeof out);
}

std::string Hasher::hmac_hex(std::string_view data) {
  uint8_t ih[32], out[32];
  digest(inner_, data, ih);
  digest(outer_, std::string_view(reinterpret_cast<const char*>(ih), sizeof ih), out);
  return to_hex(out, sizeof out);
}

PreparedRecord prepare(const json::Object& obj) {
  PreparedRecord p;
  p.members.reserve(obj.size());
  for (const auto& [k, v] : obj) {
    std::string frag = json::canonical(json::Value(k));
    frag.push_back(':');
    frag += json::canonical(v);
    p.members.emplace_back(k, std::move(frag));
  }
  std::sort(p.members.begin(), p.members.end(),
            [](const auto& a, const auto& b) { return a.first < b.first; });
  return p;
}

namespace {

std::string str_frag(std::string_view key, std::string_view value) {
  std::string f;
  f.reserve(key.size() + value.size() + 6);
  f.push_back('"');
  f.append(key);
  f.append("\":");
  json::append_string(f, value);
  return f;
}

std::string raw_frag(std::string_view key, std::string_view raw) {
  std::string f;
  f.reserve(key.size() + raw.size() + 3);
  f.push_back('"');
  f.append(key);
  f.append("\":");
  f.append(raw);
  return f;
}

}  // namespace

PreparedRecord prepare(const AuditEntry& e) {
  PreparedRecord p;
  auto& m = p.members;
  m.reserve(20);
  auto str = [&](const char* k, std::string_view v) { m.emplace_back(k, str_frag(k, v)); };
  auto raw = [&](const char* k, std::string_view v) { m.emplace_back(k, raw_frag(k, v)); };
  str("principal", e.principal);
  str("ruri", e.ruri);
  raw("timestamp_ms", std::to_string(e.timestamp_ms));
  str("message_id", e.message_id);
  str("event", e.event);
  str("outcome", e.outcome);
  str("sender_type", e.sender_type);
  if (e.sub) str("sub", *e.sub);
  if (e.cloud_provider) str("cloud_provider", *e.cloud_provider);
  if (e.function_name) str("function_name", *e.function_name);
  if (e.ai) {
    raw("ai", json::canonical(json::Value(to_object(*e.ai))));
  }
  if (e.gate_bypassed) raw("gate_bypassed", "true");
  if (e.hitl_timeout_bypass) raw("hitl_timeout_bypass", "true");
  if (e.watermark_token) str("watermark_token", *e.watermark_token);
  if (e.action) str("action", *e.action);
  if (e.reason) str("reason", *e.reason);
  if (!e.detail.empty()) raw("detail", json::canonical(e.detail));
  if (!e.kind.empty()) str("kind", e.kind);
  if (e.segment) raw("segment", std::to_string(*e.segment));
  std::sort(m.begin(), m.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  return p;
}

namespace {

// Appends the members with extra (key, fragment) pairs merged in sorted position.
void assemble(std::string& out, const PreparedRecord& p,
              const std::pair<std::string_view, std::string_view>* extra, size_t n_extra) {
  out.push_back('{');
  bool first = true;
  size_t e = 0;
  auto put = [&](std::string_view frag) {
    if (!first) out.push_back(',');
    first = false;
    out.append(frag);
  };
  for (const auto& [k, frag] : p.members) {
    while (e < n_extra && extra[e].first < k) put(extra[e++].second);
    put(frag);
  }
  while (e < n_extra) put(extra[e++].second);
  out.push_back('}');
}

}  // namespace

SealedRecord seal_prepared(const PreparedRecord& p, uint64_t seq, std::string_view prev_hash,
                           Hasher& hasher) {
  SealedRecord r;
  r.seq = seq;
  std::string seq_frag = "\"seq\":" + std::to_string(seq);
  std::string prev_frag = prev_hash.empty() ? std::string("\"prev_hash\":null")
                                            : "\"prev_hash\":\"" + std::string(prev_hash) + "\"";
  size_t total = 64 + seq_frag.size() + prev_frag.size();
  for (const auto& m : p.members) total += m.second.size() + 1;
  // Sorted: "hmac" < "prev_hash" < "seq".
  const std::pair<std::string_view, std::string_view> two[] = {{"prev_hash", prev_frag},
                                                               {"seq", seq_frag}};
  r.preimage.reserve(total);
  assemble(r.preimage, p, two, 2);
  r.record_hash = hasher.sha256_hex(r.preimage);
  r.hmac = hasher.hmac_hex(r.preimage);
  std::string hmac_frag = "\"hmac\":\"" + r.hmac + "\"";
  const std::pair<std::string_view, std::string_view> three[] = {
      {"hmac", hmac_frag}, {"prev_hash", prev_frag}, {"seq", seq_frag}};
  r.line.reserve(total + hmac_frag.size());
  assemble(r.line, p, three, 3);
  return r;
}

}  // namespace rcan::audit::internal
