// rcan-py CommitmentRecord v0.3: byte-for-byte against the vector chain, the tampered
// variants, and the re-statement of a native chain.
#include <gtest/gtest.h>

#include <filesystem>

#include "audit_util.h"
#include "rcan/audit/verify.h"
#include "rcan/hash.h"
#include "test_support.h"

namespace rcan::audit {
namespace {

using namespace testutil;
using rcan::test::TempDir;

std::string vector_secret(const json::Value& v) { return v.get("secret")->as_string(); }

TEST(AuditRcanpy, VectorRecordsByteForByte) {
  auto v = rcan::test::load_vector("audit-rcanpy-v0.3.json");
  const std::string secret = vector_secret(v);
  const auto& records = v.get("records")->as_array();
  ASSERT_EQ(records.size(), 5u);
  for (const auto& r : records) {
    const std::string line = r.get("jsonl_line")->as_string();
    auto parsed = rcanpy_parse_line(line);
    ASSERT_TRUE(parsed.ok()) << parsed.error().message;
    EXPECT_EQ(rcanpy_preimage(parsed->fields), r.get("canonical_preimage")->as_string());
    EXPECT_EQ(rcanpy_hmac(secret, parsed->fields), r.get("hmac")->as_string());
    EXPECT_EQ(parsed->hmac, r.get("hmac")->as_string());
    EXPECT_EQ(rcanpy_content_hash(parsed->fields), r.get("content_hash")->as_string());
    // Our serializer writes the exact to_dict() line.
    EXPECT_EQ(rcanpy_line(parsed->fields, parsed->hmac), line);
  }
}

TEST(AuditRcanpy, VectorChainVerifies) {
  auto v = rcan::test::load_vector("audit-rcanpy-v0.3.json");
  std::string text =
      rcan::test::read_file(std::string(RCAN_VECTORS_DIR) + "/audit-rcanpy-v0.3.jsonl");
  auto rep = verify_rcanpy_jsonl(text, vector_secret(v));
  EXPECT_TRUE(rep.ok) << rep.why;
  EXPECT_EQ(rep.count, 5u);
}

TEST(AuditRcanpy, TamperedVariantsFailAtTheExpectedIndex) {
  auto v = rcan::test::load_vector("audit-rcanpy-v0.3.json");
  const auto& variants = v.get("tampered_variants")->as_array();
  ASSERT_EQ(variants.size(), 6u);
  for (const auto& t : variants) {
    std::string name = t.get("name")->as_string();
    std::string text;
    for (const auto& l : t.get("jsonl_lines")->as_array()) text += l.as_string() + "\n";
    std::string secret = name == "wrong_secret" ? "wrong-secret" : vector_secret(v);
    const json::Value* expected = t.get("strict_expected_first_failing_index");
    if (!expected) expected = t.get("expected_first_failing_index");
    auto rep = verify_rcanpy_jsonl(text, secret, /*strict_start=*/true);
    if (expected->is_null()) {
      EXPECT_TRUE(rep.ok) << name << ": " << rep.why;  // e.g. a cut tail: not detectable
    } else {
      EXPECT_FALSE(rep.ok) << name;
      EXPECT_EQ(rep.first_bad_index, static_cast<uint64_t>(expected->as_int()))
          << name << ": " << rep.why;
    }
  }
  // rcan-py's own (lenient) start rule accepts a chain missing its first record.
  for (const auto& t : variants) {
    if (t.get("name")->as_string() != "deleted_first_record") continue;
    std::string text;
    for (const auto& l : t.get("jsonl_lines")->as_array()) text += l.as_string() + "\n";
    EXPECT_TRUE(verify_rcanpy_jsonl(text, vector_secret(v), /*strict_start=*/false).ok);
  }
}

TEST(AuditRcanpy, NativeChainRestatedAsCommitmentRecords) {
  TempDir tmp;
  std::vector<std::string> native;
  {
    auto log = AuditLog::open(tmp.path() + "/log", options(4096));
    ASSERT_TRUE(log.ok());
    for (int i = 1; i <= 40; ++i) {
      AuditEntry e = entry(i);
      e.principal = "op\xc3\xa9rateur";  // non-ASCII travels as \u escapes
      ASSERT_TRUE((*log)->append(e).ok());
    }
    native = export_lines(**log);
  }
  RcanpyExporter ex(kSecret);
  std::string text;
  std::vector<std::string> lines;
  for (const auto& n : native) {
    auto l = ex.add(parse(n).as_object());
    ASSERT_TRUE(l.ok()) << l.error().message;
    lines.push_back(*l);
    text += *l + "\n";
  }
  auto rep = verify_rcanpy_jsonl(text, kSecret);
  EXPECT_TRUE(rep.ok) << rep.why;
  EXPECT_EQ(rep.count, native.size());
  // Every line is what rcan-py's to_dict()/json.dumps would write for its fields, and the
  // full native record rides inside params (covered by the CommitmentRecord HMAC).
  std::string natives;
  for (size_t i = 0; i < lines.size(); ++i) {
    auto p = rcanpy_parse_line(lines[i]);
    ASSERT_TRUE(p.ok());
    EXPECT_EQ(rcanpy_line(p->fields, p->hmac), lines[i]);
    EXPECT_EQ(lines[i].find_first_of("\x80\xc3"), std::string::npos);  // ASCII only
    const json::Value* inner = p->fields.find("params")->get("rcan_audit");
    ASSERT_NE(inner, nullptr);
    natives += json::canonical(*inner) + "\n";
  }
  EXPECT_TRUE(verify_jsonl(natives, kSecret).ok);
  // Tampering inside params (the native record) breaks the rcan-py hmac.
  auto p = parse(lines[7]);
  p.as_object().find("params")->get("rcan_audit")->as_object().set("outcome", "blocked");
  lines[7] = json::python_dumps(p, false, false);
  std::string bad;
  for (const auto& l : lines) bad += l + "\n";
  rep = verify_rcanpy_jsonl(bad, kSecret);
  EXPECT_FALSE(rep.ok);
  EXPECT_EQ(rep.first_bad_index, 7u);
}

TEST(AuditRcanpy, CliExportAndVerify) {
  TempDir tmp;
  std::string dir = tmp.path() + "/data/audit";
  std::filesystem::create_directories(dir);
  {
    auto log = AuditLog::open(dir, options());
    ASSERT_TRUE(log.ok());
    for (int i = 1; i <= 10; ++i) ASSERT_TRUE((*log)->append(entry(i)).ok());
  }
  std::string secret_file = tmp.file("secret");
  write_file(secret_file, kSecret);
  auto ex = rcan::test::run_cli({"audit", "export", "--data-dir", tmp.path() + "/data", "--format",
                                 "rcanpy", "--secret-file", secret_file});
  ASSERT_EQ(ex.exit_code, 0) << ex.err;
  std::string f = tmp.file("chain.jsonl");
  write_file(f, ex.out);
  auto ok = rcan::test::run_cli({"audit", "verify", "--format", "rcanpy", f, "--secret", kSecret});
  EXPECT_EQ(ok.exit_code, 0) << ok.out;
  EXPECT_NE(ok.out.find("11 records"), std::string::npos) << ok.out;

  auto v = rcan::test::load_vector("audit-rcanpy-v0.3.json");
  std::string vf = std::string(RCAN_VECTORS_DIR) + "/audit-rcanpy-v0.3.jsonl";
  auto vec = rcan::test::run_cli(
      {"audit", "verify", "--format", "rcanpy", vf, "--secret", vector_secret(v)});
  EXPECT_EQ(vec.exit_code, 0) << vec.out;
  for (const auto& t : v.get("tampered_variants")->as_array()) {
    if (t.get("name")->as_string() != "deleted_first_record") continue;
    std::string text;
    for (const auto& l : t.get("jsonl_lines")->as_array()) text += l.as_string() + "\n";
    auto r = rcan::test::run_cli(
        {"audit", "verify", "--format", "rcanpy", "-", "--secret", vector_secret(v)}, text);
    EXPECT_EQ(r.exit_code, 1);
    EXPECT_NE(r.out.find("index 0"), std::string::npos) << r.out;
  }
}

}  // namespace
}  // namespace rcan::audit
