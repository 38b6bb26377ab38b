// libFuzzer target: message signatures in every form and hybrid signed bodies. The input is
// parsed as JSON; objects go through parse_sig_block (on their "sig" and on themselves), the
// rcan-py / canonical / rcan-ts pre-image builders (and js_stringify), msgsig::verify against
// fixed trusted keys (sig {alg,kid,value}, hybrid sig {ml_dsa,ed25519,ed25519_pub}, rcan-ts
// signature {alg,kid,sig}), and hybrid::verify_body in strict and SDK mode. Must never crash.
// Invariants: a message that verifies carries a well-formed block of the form that verified
// (and a hybrid one passes strict verify_body); a body accepted in strict mode is also accepted
// in SDK mode (strict only adds checks). (The seed corpus holds validly signed messages, so
// verification itself may succeed.)
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string_view>

#include "rcan/crypto/ed25519.h"
#include "rcan/crypto/hybrid.h"
#include "rcan/crypto/message_sig.h"
#include "rcan/crypto/mldsa65.h"

namespace {

using namespace rcan;

struct Trusted {
  msgsig::TrustedKeys keys;
  Bytes mldsa_pk;
};

const Trusted& trusted() {
  static const Trusted t = [] {
    Trusted out;
    Bytes seed(32, 0);
    for (int i = 0; i < 32; ++i) seed[static_cast<size_t>(i)] = static_cast<uint8_t>(i);
    auto kp = mldsa65::keygen_from_seed(seed);
    if (kp.ok()) out.mldsa_pk = kp->public_key;
    out.keys.mldsa65.push_back(out.mldsa_pk);
    auto ed = ed25519::public_key_from_seed(Bytes(32, 7));
    if (ed.ok()) out.keys.ed25519.push_back(*ed);
    return out;
  }();
  return t;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  json::ParseOptions po;
  po.max_bytes = 64 * 1024;
  auto v = json::parse(std::string_view(reinterpret_cast<const char*>(data), size), po);
  if (!v.ok()) return 0;
  (void)msgsig::parse_sig_block(*v);
  if (!v->is_object()) return 0;
  const json::Object& obj = v->as_object();
  const json::Value* sig = obj.find("sig");
  if (sig) (void)msgsig::parse_sig_block(*sig);
  auto pre = msgsig::preimage(obj);
  auto ts_pre = msgsig::rcants_preimage(obj);
  if (ts_pre.ok() && ts_pre->empty()) std::abort();
  (void)msgsig::js_stringify(*v);
  hybrid::VerifyOptions strict;
  if (msgsig::verify(obj, trusted().keys).ok()) {
    // Whichever form verified must be well-formed on its own terms.
    if (!msgsig::signature_member(obj)) std::abort();
    if (sig && sig->is_object() && sig->get("ml_dsa")) {
      if (!hybrid::verify_body(obj, trusted().mldsa_pk, strict).ok()) std::abort();
    } else if (sig && !sig->is_null()) {
      if (!msgsig::parse_sig_block(*sig).ok() || !pre.ok()) std::abort();
    } else if (!ts_pre.ok()) {
      std::abort();
    }
  }
  hybrid::VerifyOptions sdk;
  sdk.strict = false;
  bool strict_ok = hybrid::verify_body(obj, trusted().mldsa_pk, strict).ok();
  bool sdk_ok = hybrid::verify_body(obj, trusted().mldsa_pk, sdk).ok();
  if (strict_ok && !sdk_ok) std::abort();
  return 0;
}
