// rcan keys — robot identity key directories (see include/rcan/crypto/keys.h).
#include <cstdio>
#include <iostream>

#include "cli.h"
#include "rcan/crypto/ed25519.h"
#include "rcan/crypto/keys.h"
#include "rcan/hash.h"
#include "rcan/json.h"

namespace rcan::cli {
namespace {

constexpr const char* kHelp =
    "usage:\n"
    "  rcan keys generate --dir D\n"
    "      Creates D (mode 0700) with fresh random mldsa65.seed, mldsa65.pub, ed25519.seed,\n"
    "      ed25519.pub. Seeds are written 0600 with O_EXCL; existing files are never replaced.\n"
    "  rcan keys derive --dir D --mldsa-seed HEX --ed25519-seed HEX\n"
    "      Same, from given 32-byte seeds (recovery, tests).\n"
    "  rcan keys show --dir D [--json]\n"
    "      Prints the public keys: kid (first 8 hex of SHA-256 of the ML-DSA-65 pk), the\n"
    "      rcan-py JWK of the ML-DSA-65 key, and the Ed25519 key (hex, PEM, rcan-py kid).\n"
    "  rcan keys issuer --dir D [--name ISSUER]\n"
    "      A JWT issuer's Ed25519 key pair: D/ed25519.seed (0600; `rcan token issue --key`\n"
    "      signs with it) and D/ed25519.pub.pem (what security.jwt.issuers[].key_file names).\n"
    "      Existing files are kept. Prints the config line.\n"
    "  Exit: 0 ok, 1 failure (file exists, bad permissions…), 2 usage.\n";

void print_summary(const keys::PublicKeys& pub, const std::string& dir, bool as_json) {
  auto pem = ed25519::public_key_to_pem(pub.ed25519_pk);
  auto edkid = keys::ed25519_kid(pub.ed25519_pk);
  if (as_json) {
    json::Object ml;
    ml.set("kid", pub.kid());
    ml.set("public_key_sha256",
           sha256_hex(std::string_view(reinterpret_cast<const char*>(pub.mldsa65_pk.data()),
                                       pub.mldsa65_pk.size())));
    ml.set("jwk", keys::mldsa65_jwk(pub.mldsa65_pk));
    json::Object ed;
    ed.set("public_key_hex", to_hex(pub.ed25519_pk));
    ed.set("pem", pem.ok() ? *pem : std::string());
    ed.set("kid", edkid.ok() ? *edkid : std::string());
    json::Object out;
    out.set("dir", dir);
    out.set("kid", pub.kid());
    out.set("mldsa65", json::Value(std::move(ml)));
    out.set("ed25519", json::Value(std::move(ed)));
    std::cout << json::dump(json::Value(std::move(out))) << "\n";
    return;
  }
  std::cout << "kid: " << pub.kid() << "\n"
            << "ml-dsa-65 jwk: " << json::dump(keys::mldsa65_jwk(pub.mldsa65_pk)) << "\n"
            << "ed25519 public key: " << to_hex(pub.ed25519_pk) << "\n"
            << "ed25519 kid (rcan-py, sha256 of PEM): " << (edkid.ok() ? *edkid : "?") << "\n"
            << (pem.ok() ? *pem : std::string());
}

int write_keys(const std::string& verb, const std::string& dir, const keys::RobotKeys& k) {
  Status s = keys::write_dir(dir, k);
  if (!s.ok()) {
    std::fprintf(stderr, "rcan keys %s: %s\n", verb.c_str(), s.error().message.c_str());
    return 1;
  }
  print_summary(k.pub, dir, false);
  return 0;
}

int keys_main(const Args& args) {
  if (args.empty() || args[0] == "--help" || args[0] == "-h") {
    std::fputs(kHelp, args.empty() ? stderr : stdout);
    return args.empty() ? 2 : 0;
  }
  const std::string sub = args[0];
  Args rest(args.begin() + 1, args.end());
  if (sub == "generate") {
    Options o(rest, {}, {"dir"});
    if (!o.ok()) return usage_error("keys generate", o.error());
    if (o.get("dir").empty() || !o.positional().empty())
      return usage_error("keys generate", "--dir D is required");
    auto k = keys::generate();
    if (!k.ok()) return usage_error("keys generate", k.error().message);
    return write_keys(sub, o.get("dir"), *k);
  }
  if (sub == "derive") {
    Options o(rest, {}, {"dir", "mldsa-seed", "ed25519-seed"});
    if (!o.ok()) return usage_error("keys derive", o.error());
    if (o.get("dir").empty() || !o.positional().empty())
      return usage_error("keys derive", "--dir D is required");
    auto ms = from_hex(o.get("mldsa-seed"));
    auto es = from_hex(o.get("ed25519-seed"));
    if (!ms || ms->size() != 32)
      return usage_error("keys derive", "--mldsa-seed must be 64 hex digits");
    if (!es || es->size() != 32)
      return usage_error("keys derive", "--ed25519-seed must be 64 hex digits");
    auto k = keys::derive(*ms, *es);
    secure_wipe(ms->data(), ms->size());
    secure_wipe(es->data(), es->size());
    if (!k.ok()) return usage_error("keys derive", k.error().message);
    return write_keys(sub, o.get("dir"), *k);
  }
  if (sub == "show") {
    Options o(rest, {"json"}, {"dir"});
    if (!o.ok()) return usage_error("keys show", o.error());
    if (o.get("dir").empty() || !o.positional().empty())
      return usage_error("keys show", "--dir D is required");
    auto pub = keys::load_public_dir(o.get("dir"));
    if (!pub.ok()) {
      std::fprintf(stderr, "rcan keys show: %s\n", pub.error().message.c_str());
      return 1;
    }
    print_summary(*pub, o.get("dir"), o.has("json"));
    return 0;
  }
  if (sub == "issuer") {
    Options o(rest, {}, {"dir", "name"});
    if (!o.ok()) return usage_error("keys issuer", o.error());
    if (o.get("dir").empty() || !o.positional().empty())
      return usage_error("keys issuer", "--dir D is required");
    const std::string dir = o.get("dir");
    auto made = keys::ensure_issuer_dir(dir);
    if (!made.ok()) {
      std::fprintf(stderr, "rcan keys issuer: %s\n", made.error().message.c_str());
      return 1;
    }
    const std::string name = o.get("name").empty() ? "my-issuer" : o.get("name");
    std::cout << (*made ? "created " : "kept ") << dir << "/" << keys::kIssuerSeedFile
              << " (0600) and " << dir << "/" << keys::kIssuerPubFile << "\n"
              << "config (security.jwt.issuers):\n  - {issuer: " << name << ", key_file: " << dir
              << "/" << keys::kIssuerPubFile << "}\n"
              << "tokens: rcan token issue --key " << dir << "/" << keys::kIssuerSeedFile
              << " --iss " << name << " --aud RURI --sub NAME --role user\n";
    return 0;
  }
  return usage_error("keys", "unknown subcommand " + sub + " (generate | derive | show | issuer)");
}

const Registration kReg{"keys", "robot identity keys and token issuer keys", &keys_main};

}  // namespace
}  // namespace rcan::cli
