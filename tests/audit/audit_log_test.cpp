// AuditLog: records, chain, reopen, rotation, retention, indexes, tampering detection, CLI.
#include "rcan/audit/audit_log.h"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <thread>

#include "audit/fast_seal.h"
#include "audit_util.h"
#include "rcan/audit/secret.h"
#include "rcan/audit/verify.h"
#include "rcan/hash.h"
#include "test_support.h"
#include "testing/fault_env.h"

namespace rcan::audit {
namespace {

using namespace testutil;
using base::FaultInjectionEnv;
using rcan::test::TempDir;

std::unique_ptr<AuditLog> open_log(const std::string& dir, AuditOptions o = options()) {
  auto r = AuditLog::open(dir, std::move(o));
  EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.error().message);
  return r.ok() ? std::move(r).value() : nullptr;
}

// A chain of n appended records plus the genesis checkpoint, exported.
std::vector<std::string> make_chain(const TempDir& tmp, int n) {
  auto log = open_log(tmp.path() + "/log");
  for (int i = 1; i <= n; ++i) EXPECT_TRUE(log->append(entry(i)).ok());
  return export_lines(*log);
}

TEST(Audit, AppendAssignsSeqAndChainsRecords) {
  TempDir tmp;
  auto log = open_log(tmp.path() + "/log");
  for (int i = 1; i <= 10; ++i) {
    auto r = log->append(entry(i));
    ASSERT_TRUE(r.ok()) << r.error().message;
    EXPECT_EQ(r->seq, static_cast<uint64_t>(i + 1));  // seq 1 is the genesis checkpoint
    EXPECT_EQ(r->hmac.size(), 64u);
  }
  auto lines = export_lines(*log);
  ASSERT_EQ(lines.size(), 11u);
  EXPECT_EQ(kind_of(lines[0]), "checkpoint");
  auto first = parse(lines[0]);
  EXPECT_TRUE(first.get("prev_hash")->is_null());
  EXPECT_EQ(first.get("seq")->as_int(), 1);
  // prev_hash = sha256(canonical without hmac) of the previous record.
  for (size_t i = 1; i < lines.size(); ++i) {
    auto prev = parse(lines[i - 1]);
    auto cur = parse(lines[i]);
    EXPECT_EQ(cur.get("prev_hash")->as_string(),
              sha256_hex(json::canonical_without(prev.as_object(), "hmac")));
    EXPECT_EQ(cur.get("hmac")->as_string(),
              hmac_sha256_hex(kSecret, json::canonical_without(cur.as_object(), "hmac")));
    EXPECT_EQ(lines[i], json::canonical(cur));  // stored lines are canonical JSON
  }
  auto rep = verify_jsonl(join(lines), kSecret);
  EXPECT_TRUE(rep.ok) << rep.why;
  EXPECT_EQ(rep.count, 11u);
}

// Disk footprint: a fresh log holds one preallocated segment; the next one (prealloc.tmp) is
// prepared only once the active segment is half full, and a rotation uses it. With
// background_index off the spare is written inline, so the order of events is exact.
std::vector<std::string> segment_files(const std::string& dir) {
  std::vector<std::string> out;
  for (const auto& e : std::filesystem::directory_iterator(dir))
    if (e.path().extension() == ".log" || e.path().extension() == ".tmp")
      out.push_back(e.path().filename().string());
  std::sort(out.begin(), out.end());
  return out;
}

TEST(Audit, AFreshLogHoldsOneSegmentAndPreparesTheNextOnlyWhenHalfFull) {
  TempDir tmp;
  const std::string dir = tmp.path() + "/log";
  const uint64_t seg = 64 << 10;
  AuditOptions o = options(seg);
  o.background_index = false;
  auto log = open_log(dir, o);
  ASSERT_TRUE(log->append(entry(1)).ok());
  EXPECT_EQ(segment_files(dir), (std::vector<std::string>{"seg-00000001.log"}));
  EXPECT_EQ(std::filesystem::file_size(dir + "/seg-00000001.log"), seg);
  // Below half of the segment there is still no spare.
  int i = 2;
  while (log->stats().total_bytes < seg / 2 - 2048) ASSERT_TRUE(log->append(entry(i++)).ok());
  EXPECT_FALSE(std::filesystem::exists(dir + "/prealloc.tmp"));
  // Past half, the spare appears before the segment fills.
  while (log->stats().total_bytes < seg / 2 + 2048) ASSERT_TRUE(log->append(entry(i++)).ok());
  EXPECT_EQ(log->stats().segments, 1u);
  ASSERT_TRUE(std::filesystem::exists(dir + "/prealloc.tmp"))
      << "the next segment is prepared once the active one is half full";
  EXPECT_EQ(std::filesystem::file_size(dir + "/prealloc.tmp"), seg);
  // The rotation takes the spare: two segments, the second preallocated, no spare left yet.
  // (stats() counts the sealed segment as soon as it is sealed; the record after it is durable
  // only once the rotation is complete.)
  while (log->stats().segments == 1) ASSERT_TRUE(log->append(entry(i++)).ok());
  ASSERT_TRUE(log->append(entry(i++)).ok());
  EXPECT_EQ(segment_files(dir), (std::vector<std::string>{"seg-00000001.log", "seg-00000002.log"}));
  EXPECT_EQ(std::filesystem::file_size(dir + "/seg-00000002.log"), seg);
}

// The node's mode: the spare is written by a background thread once the active segment is half
// full (appends do not wait for it). A rotation that comes before the spare is synced simply
// starts an unpreallocated segment, so only the spare's appearance is checked here.
TEST(Audit, TheSpareIsPreparedInTheBackgroundPastHalf) {
  TempDir tmp;
  const std::string dir = tmp.path() + "/log";
  const uint64_t seg = 64 << 10;
  auto log = open_log(dir, options(seg));
  int i = 1;
  while (log->stats().total_bytes < seg / 2 - 2048) ASSERT_TRUE(log->append(entry(i++)).ok());
  EXPECT_FALSE(std::filesystem::exists(dir + "/prealloc.tmp"));
  while (log->stats().total_bytes < seg / 2 + 2048) ASSERT_TRUE(log->append(entry(i++)).ok());
  bool spare = false;
  for (int t = 0; t < 3000 && !spare; ++t) {
    spare = std::filesystem::exists(dir + "/prealloc.tmp");
    if (!spare) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  EXPECT_TRUE(spare) << "the next segment is prepared once the active one is half full";
  EXPECT_EQ(log->stats().segments, 1u);
}

TEST(Audit, FastSealIsByteIdenticalToCanonicalSeal) {
  internal::Hasher hasher(kSecret);
  for (int i = 0; i < 40; ++i) {
    AuditEntry e = entry(i);
    e.principal = "op\xc3\xa9rateur \"quoted\"\n";
    e.detail.set("zeta", json::Array{1, 2.5, "x"});
    e.detail.set("alpha", json::Object{{"b", 1}, {"a", nullptr}});
    if (i % 4 == 1) {
      e.gate_bypassed = true;
      e.hitl_timeout_bypass = true;
      e.reason = "gate allow";
      e.sender_type = "cloud_function";
      e.cloud_provider = "gcp";
      e.function_name = "f\u00e9";
    }
    std::string prev = i == 0 ? "" : std::string(64, 'a' + (i % 6));
    SealedRecord slow = seal(to_object(e), static_cast<uint64_t>(i + 1), prev, kSecret);
    for (const auto& prep : {internal::prepare(to_object(e)), internal::prepare(e)}) {
      SealedRecord fast = internal::seal_prepared(prep, static_cast<uint64_t>(i + 1), prev, hasher);
      EXPECT_EQ(fast.preimage, slow.preimage);
      EXPECT_EQ(fast.line, slow.line);
      EXPECT_EQ(fast.hmac, slow.hmac);
      EXPECT_EQ(fast.record_hash, slow.record_hash);
    }
  }
  // Keys longer than a SHA-256 block are hashed first, as HMAC requires.
  std::string long_key(100, 'k');
  internal::Hasher lh(long_key);
  EXPECT_EQ(lh.hmac_hex("data"), hmac_sha256_hex(long_key, "data"));
}

TEST(Audit, RecordCarriesProfileFieldsAndOmitsUnknownConfidence) {
  TempDir tmp;
  auto log = open_log(tmp.path() + "/log");
  AuditEntry e = entry(1);
  e.sender_type = "cloud_function";
  e.cloud_provider = "firebase";
  e.function_name = "relayCommand";
  AiBlock ai;
  ai.provider = "openai";
  ai.model = "gpt-4o";
  ai.layer = "planner";
  ai.escalated = true;
  e.ai = ai;  // no confidence
  e.gate_bypassed = true;
  e.hitl_timeout_bypass = true;
  e.watermark_token = "rcan-wm-v1:0123456789abcdef0123456789abcdef";
  e.reason = "allowed by gate";
  e.detail.set("invoke_id", "inv-audit-001");
  ASSERT_TRUE(log->append(e).ok());
  AuditEntry plain = entry(2);  // no ai, no bypasses
  ASSERT_TRUE(log->append(plain).ok());
  auto lines = export_lines(*log);
  auto rec = parse(lines[1]);
  for (const char* f : {"principal",
                        "ruri",
                        "timestamp_ms",
                        "message_id",
                        "event",
                        "outcome",
                        "seq",
                        "sender_type",
                        "sub",
                        "cloud_provider",
                        "function_name",
                        "ai",
                        "gate_bypassed",
                        "hitl_timeout_bypass",
                        "watermark_token",
                        "action",
                        "reason",
                        "prev_hash",
                        "hmac",
                        "detail"})
    EXPECT_NE(rec.get(f), nullptr) << f;
  EXPECT_EQ(rec.get("ai")->get("confidence"), nullptr);
  EXPECT_TRUE(rec.get("ai")->get("escalated")->as_bool());
  EXPECT_EQ(rec.get("sender_type")->as_string(), "cloud_function");
  auto rec2 = parse(lines[2]);
  EXPECT_EQ(rec2.get("ai"), nullptr);
  EXPECT_EQ(rec2.get("gate_bypassed"), nullptr);
  EXPECT_EQ(rec2.get("hitl_timeout_bypass"), nullptr);
  EXPECT_EQ(rec2.get("sender_type")->as_string(), "human");
}

TEST(Audit, RejectsIncompleteEntriesWithoutWriting) {
  TempDir tmp;
  auto log = open_log(tmp.path() + "/log");
  AuditEntry e = entry(1);
  e.sender_type = "cloud_function";
  auto r = log->append(e);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::kSchemaValidationFailed);
  EXPECT_EQ(r.error().field, "cloud_provider");
  AuditEntry ai = entry(2);
  ai.ai = AiBlock{};
  ai.ai->provider = "openai";
  r = log->append(ai);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().field, "ai.model");
  AuditEntry sys = entry(3);
  sys.kind = "checkpoint";
  EXPECT_FALSE(log->append(sys).ok());
  EXPECT_EQ(export_lines(*log).size(), 1u);
}

TEST(Audit, RefusesToOpenWithoutSecret) {
  TempDir tmp;
  AuditOptions o = options();
  o.secret.clear();
  auto r = AuditLog::open(tmp.path() + "/log", o);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::kAuditUnavailable);

  ::unsetenv("RCAN_AUDIT_SECRET_FILE");
  ::unsetenv("RCAN_AUDIT_SECRET");
  auto s = load_chain_secret();
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().message.find("rcan audit new-secret"), std::string::npos);
}

TEST(Audit, SecretFileRules) {
  TempDir tmp;
  std::string f = tmp.file("secret");
  write_file(f, kSecret, 0644);
  auto r = read_secret_file(f);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("chmod 600"), std::string::npos);
  write_file(f, std::string(kSecret) + "\n", 0600);
  EXPECT_FALSE(read_secret_file(f).ok());
  write_file(f, "short", 0600);
  EXPECT_FALSE(read_secret_file(f).ok());
  write_file(f, kSecret, 0600);
  auto ok = read_secret_file(f);
  ASSERT_TRUE(ok.ok());
  EXPECT_EQ(*ok, kSecret);
  ::setenv("RCAN_AUDIT_SECRET_FILE", f.c_str(), 1);
  auto env = load_chain_secret();
  ::unsetenv("RCAN_AUDIT_SECRET_FILE");
  ASSERT_TRUE(env.ok());
  EXPECT_EQ(*env, kSecret);

  std::string made = tmp.file("new.secret");
  ASSERT_TRUE(create_secret_file(made).ok());
  struct stat st {};
  ASSERT_EQ(::stat(made.c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0600u);
  auto m = read_secret_file(made);
  ASSERT_TRUE(m.ok());
  EXPECT_EQ(m->size(), 64u);
  EXPECT_FALSE(create_secret_file(made).ok());  // never overwrites
}

TEST(Audit, ReopenContinuesChainAndCleanShutdownWritesNoRecovery) {
  TempDir tmp;
  std::string dir = tmp.path() + "/log";
  {
    auto log = open_log(dir);
    for (int i = 1; i <= 5; ++i) ASSERT_TRUE(log->append(entry(i)).ok());
  }
  {
    auto log = open_log(dir);
    auto r = log->append(entry(6));
    ASSERT_TRUE(r.ok());
    EXPECT_EQ(r->seq, 7u);
    auto lines = export_lines(*log);
    ASSERT_EQ(lines.size(), 7u);
    for (const auto& l : lines) EXPECT_NE(kind_of(l), "recovery");
    EXPECT_TRUE(verify_jsonl(join(lines), kSecret).ok);
  }
  EXPECT_TRUE(verify_dir(dir, kSecret).ok);
}

TEST(Audit, SecondWriterIsLockedOut) {
  TempDir tmp;
  auto log = open_log(tmp.path() + "/log");
  auto again = AuditLog::open(tmp.path() + "/log", options());
  ASSERT_FALSE(again.ok());
  EXPECT_EQ(again.error().code, ErrorCode::kAuditUnavailable);
}

// A record's length comes from an index on disk; a corrupt one (found by audit_store_fuzz: an
// index entry claiming 0x7270000000000173 bytes) must give a short read, not a huge allocation.
TEST(Audit, EnvReadRangeNeverReadsOrAllocatesPastTheFile) {
  TempDir tmp;
  const std::string f = tmp.file("ten");
  {
    std::FILE* fp = std::fopen(f.c_str(), "wb");
    ASSERT_NE(fp, nullptr);
    std::fputs("0123456789", fp);
    std::fclose(fp);
  }
  rcan::audit::Env* env = rcan::audit::Env::posix();
  auto mid = env->read_range(f, 4, 0x7270000000000173ull);
  ASSERT_TRUE(mid.ok()) << mid.error().message;
  EXPECT_EQ(*mid, "456789");
  auto past = env->read_range(f, 1000, size_t{1} << 40);
  ASSERT_TRUE(past.ok()) << past.error().message;
  EXPECT_EQ(*past, "");
  auto exact = env->read_range(f, 2, 3);
  ASSERT_TRUE(exact.ok());
  EXPECT_EQ(*exact, "234");
}

TEST(Audit, WrongSecretRefusesToOpen) {
  TempDir tmp;
  std::string dir = tmp.path() + "/log";
  {
    auto log = open_log(dir);
    ASSERT_TRUE(log->append(entry(1)).ok());
  }
  AuditOptions o = options();
  o.secret = "another-secret-of-enough-length";
  auto r = AuditLog::open(dir, o);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("hmac mismatch"), std::string::npos) << r.error().message;
  // Nothing was cut.
  EXPECT_TRUE(verify_dir(dir, kSecret).ok);
}

TEST(Audit, WellFormedCorruptionIsNeverAutoRepaired) {
  TempDir tmp;
  std::string dir = tmp.path() + "/log";
  {
    auto log = open_log(dir);
    for (int i = 1; i <= 5; ++i) ASSERT_TRUE(log->append(entry(i)).ok());
  }
  std::string seg = dir + "/seg-00000001.log";
  std::string data = rcan::test::read_file(seg);
  auto pos = data.find("\"outcome\":\"ok\"", data.find("msg-3"));
  ASSERT_NE(pos, std::string::npos);
  data.replace(pos, 14, "\"outcome\":\"no\"");
  write_file(seg, data);
  auto r = AuditLog::open(dir, options());
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("seq 4"), std::string::npos) << r.error().message;
  auto rep = verify_dir(dir, kSecret);
  EXPECT_FALSE(rep.ok);
  EXPECT_EQ(rep.first_bad_seq, 4u);
}

// ---- tampering: each kind detected at the right seq ----

struct Tamper {
  std::vector<std::string> lines;
};

TEST(AuditTamper, FieldMutationFailsAtThatSeq) {
  TempDir tmp;
  auto lines = make_chain(tmp, 10);
  auto v = parse(lines[4]);  // seq 5
  v.as_object().set("outcome", "blocked");
  lines[4] = json::canonical(v);
  auto rep = verify_jsonl(join(lines), kSecret);
  EXPECT_FALSE(rep.ok);
  EXPECT_EQ(rep.first_bad_seq, 5u);
  EXPECT_EQ(rep.why.rfind("hmac mismatch", 0), 0u) << rep.why;
  EXPECT_EQ(rep.count, 4u);
}

TEST(AuditTamper, ConformanceL2Hmac001FirstRecordOutcome) {
  TempDir tmp;
  auto lines = make_chain(tmp, 1);
  auto v = parse(lines[1]);  // first ordinary record
  v.as_object().set("outcome", "FAILURE");
  lines[1] = json::canonical(v);
  auto rep = verify_jsonl(join(lines), kSecret);
  EXPECT_FALSE(rep.ok);
  EXPECT_EQ(rep.first_bad_seq, 2u);
  // The genesis record itself.
  auto lines2 = make_chain(tmp, 0);
  auto g = parse(lines2[0]);
  g.as_object().set("outcome", "FAILURE");
  lines2[0] = json::canonical(g);
  rep = verify_jsonl(join(lines2), kSecret);
  EXPECT_EQ(rep.first_bad_seq, 1u);
}

TEST(AuditTamper, InsertionOfForgedRecordFails) {
  TempDir tmp;
  auto lines = make_chain(tmp, 10);
  // A forger without the secret: correct seq and prev_hash, hmac under another key.
  auto prev = parse(lines[3]);  // seq 4
  json::Object forged = to_object(entry(99));
  SealedRecord s = seal(forged, 5, sha256_hex(json::canonical_without(prev.as_object(), "hmac")),
                        "not-the-secret-but-long-enough");
  lines.insert(lines.begin() + 4, s.line);
  auto rep = verify_jsonl(join(lines), kSecret);
  EXPECT_FALSE(rep.ok);
  EXPECT_EQ(rep.first_bad_seq, 5u);
  EXPECT_EQ(rep.why, "hmac mismatch");
  // Inserting a genuine record again (replay) breaks the seq order.
  auto lines2 = make_chain(tmp, 10);
  lines2.insert(lines2.begin() + 4, lines2[2]);
  rep = verify_jsonl(join(lines2), kSecret);
  EXPECT_EQ(rep.first_bad_seq, 5u);
  EXPECT_EQ(rep.why.rfind("seq gap", 0), 0u) << rep.why;
}

TEST(AuditTamper, ForgedReplacementWithWrongKeyFails) {
  TempDir tmp;
  auto lines = make_chain(tmp, 10);
  auto prev = parse(lines[5]);  // seq 6
  SealedRecord s =
      seal(to_object(entry(7)), 7, sha256_hex(json::canonical_without(prev.as_object(), "hmac")),
           "wrong-key-wrong-key-wrong-key");
  lines[6] = s.line;
  auto rep = verify_jsonl(join(lines), kSecret);
  EXPECT_EQ(rep.first_bad_seq, 7u);
  EXPECT_EQ(rep.why, "hmac mismatch");
}

TEST(AuditTamper, DeletionFailsAtTheMissingSeq) {
  TempDir tmp;
  auto lines = make_chain(tmp, 10);
  lines.erase(lines.begin() + 4);  // seq 5
  auto rep = verify_jsonl(join(lines), kSecret);
  EXPECT_EQ(rep.first_bad_seq, 5u);
  EXPECT_EQ(rep.why.rfind("seq gap", 0), 0u) << rep.why;
  // Deleting the genesis record: the chain no longer starts anywhere.
  auto lines2 = make_chain(tmp, 3);
  lines2.erase(lines2.begin());
  rep = verify_jsonl(join(lines2), kSecret);
  EXPECT_FALSE(rep.ok);
  EXPECT_EQ(rep.first_bad_seq, 2u);
  EXPECT_EQ(rep.why.rfind("bad chain start", 0), 0u) << rep.why;
}

TEST(AuditTamper, ReorderFailsAtTheFirstSwappedSeq) {
  TempDir tmp;
  auto lines = make_chain(tmp, 10);
  std::swap(lines[4], lines[5]);  // seq 5 <-> 6
  auto rep = verify_jsonl(join(lines), kSecret);
  EXPECT_EQ(rep.first_bad_seq, 5u);
  EXPECT_EQ(rep.why.rfind("seq gap", 0), 0u);
}

TEST(AuditTamper, TruncationIsDetected) {
  TempDir tmp;
  auto lines = make_chain(tmp, 10);  // seqs 1..11
  std::string text = join(lines);
  std::string torn = text.substr(0, text.size() - 40);  // inside the last record
  auto rep = verify_jsonl(torn, kSecret);
  EXPECT_EQ(rep.first_bad_seq, 11u);
  EXPECT_EQ(rep.why.rfind("malformed line", 0), 0u) << rep.why;
  // Whole trailing records cut: detectable against the expected head.
  lines.pop_back();
  lines.pop_back();
  VerifyOptions o;
  o.expect_last_seq = 11;
  rep = verify_jsonl(join(lines), kSecret, o);
  EXPECT_FALSE(rep.ok);
  EXPECT_EQ(rep.first_bad_seq, 10u);
  EXPECT_EQ(rep.why.rfind("truncated", 0), 0u);
}

TEST(AuditTamper, PrevHashRewriteIsCaughtByHmac) {
  TempDir tmp;
  auto lines = make_chain(tmp, 6);
  auto v = parse(lines[3]);
  v.as_object().set("prev_hash", std::string(64, '0'));
  lines[3] = json::canonical(v);
  auto rep = verify_jsonl(join(lines), kSecret);
  EXPECT_EQ(rep.first_bad_seq, 4u);
  EXPECT_EQ(rep.why.rfind("prev_hash mismatch", 0), 0u);
}

// ---- rotation, retention, indexes ----

TEST(AuditStorage, RotationCarriesChainAcrossSegmentsViaCheckpoints) {
  TempDir tmp;
  std::string dir = tmp.path() + "/log";
  {
    auto log = open_log(dir, options(4096));
    for (int i = 1; i <= 200; ++i) ASSERT_TRUE(log->append(entry(i)).ok());
    auto st = log->stats();
    EXPECT_GT(st.segments, 5u);
    auto lines = export_lines(*log);
    auto rep = verify_jsonl(join(lines), kSecret);
    EXPECT_TRUE(rep.ok) << rep.why << " at " << rep.first_bad_seq;
    int checkpoints = 0;
    for (const auto& l : lines) checkpoints += kind_of(l) == "checkpoint";
    EXPECT_EQ(static_cast<uint64_t>(checkpoints), st.segments);
    // Indexes across sealed (idx file or memory) and active segments.
    for (int i : {1, 17, 100, 199, 200}) {
      auto found = log->find_by_message_id("msg-" + std::to_string(i));
      ASSERT_TRUE(found.ok());
      ASSERT_EQ(found->size(), 1u) << i;
      EXPECT_EQ(parse((*found)[0]).get("message_id")->as_string(), "msg-" + std::to_string(i));
    }
    auto wm = log->find_by_watermark("rcan-wm-v1:" + std::string(31, '0') + "5");
    ASSERT_TRUE(wm.ok());
    EXPECT_EQ(wm->size(), 20u);  // i = 5, 15, 25, … 195
    auto g = log->get(50);
    ASSERT_TRUE(g.ok());
    EXPECT_EQ(parse(*g).get("seq")->as_int(), 50);
  }
  EXPECT_TRUE(verify_dir(dir, kSecret).ok);
  // After reopen the sealed segments are served from their .idx files.
  auto log = open_log(dir, options(4096));
  auto found = log->find_by_message_id("msg-3");
  ASSERT_TRUE(found.ok());
  ASSERT_EQ(found->size(), 1u);
  EXPECT_EQ(log->find_by_message_id("nope")->size(), 0u);
  // Time index: [t+10, t+19] holds msg-10 … msg-19.
  auto range = log->export_jsonl(1740000000010, 1740000000019);
  ASSERT_TRUE(range.ok());
  std::vector<std::string> got;
  size_t start = 0;
  while (start < range->size()) {
    size_t nl = range->find('\n', start);
    got.push_back(range->substr(start, nl - start));
    start = nl + 1;
  }
  // A contiguous slice: msg-10 … msg-19 plus any checkpoint between them.
  std::vector<std::string> mids;
  for (const auto& l : got)
    if (kind_of(l).empty()) mids.push_back(parse(l).get("message_id")->as_string());
  ASSERT_EQ(mids.size(), 10u);
  EXPECT_EQ(mids.front(), "msg-10");
  EXPECT_EQ(mids.back(), "msg-19");
  EXPECT_EQ(parse(got.front()).get("message_id")->as_string(), "msg-10");
  VerifyOptions partial;
  partial.allow_partial_start = true;
  EXPECT_TRUE(verify_jsonl(*range, kSecret, partial).ok);
}

TEST(AuditStorage, RetentionKeepsWhatRemainsVerifiable) {
  TempDir tmp;
  std::string dir = tmp.path() + "/log";
  AuditOptions o = options(4096);
  o.retention_max_bytes = 16384;
  auto log = open_log(dir, o);
  for (int i = 1; i <= 300; ++i) ASSERT_TRUE(log->append(entry(i)).ok());
  auto st = log->stats();
  EXPECT_GT(st.first_seq, 1u);
  EXPECT_LE(st.total_bytes, 16384u + 8192u);
  auto lines = export_lines(*log);
  EXPECT_EQ(kind_of(lines[0]), "checkpoint");
  auto rep = verify_jsonl(join(lines), kSecret);
  EXPECT_TRUE(rep.ok) << rep.why;
  EXPECT_EQ(rep.first_seq, st.first_seq);
  bool saw_retention = false;
  for (const auto& l : lines) saw_retention |= kind_of(l) == "retention";
  EXPECT_TRUE(saw_retention);
  log.reset();
  EXPECT_TRUE(verify_dir(dir, kSecret).ok);
  // The retained head cannot be mistaken for an arbitrary mid-chain cut: dropping the
  // opening checkpoint is a bad start.
  lines.erase(lines.begin());
  EXPECT_FALSE(verify_jsonl(join(lines), kSecret).ok);
}

TEST(AuditStorage, AgeRetention) {
  TempDir tmp;
  FaultInjectionEnv env(base::Env::posix());
  AuditOptions o = options(2048);
  o.env = env.audit();
  o.retention_max_age_ms = 1000;
  auto log = open_log(tmp.path() + "/log", o);
  for (int i = 1; i <= 100; ++i) {
    AuditEntry e = entry(i);
    e.timestamp_ms = 0;  // stamped by the (advancing) clock
    ASSERT_TRUE(log->append(e).ok());
    env.advance_clock(100);
  }
  auto st = log->stats();
  EXPECT_LE(st.segments, 3u + 1000 / 100);  // ~1 s of records, plus the active segment
  EXPECT_TRUE(verify_jsonl(join(export_lines(*log)), kSecret).ok);
}

TEST(AuditStorage, WrongSegmentLinkIsNamed) {
  TempDir tmp;
  std::string dir = tmp.path() + "/log";
  {
    auto log = open_log(dir, options(2048));
    for (int i = 1; i <= 60; ++i) ASSERT_TRUE(log->append(entry(i)).ok());
  }
  auto segs = list_segments(dir);
  ASSERT_TRUE(segs.ok());
  ASSERT_GE(segs->size(), 4u);
  // Renumber the last segment: it no longer opens with its own checkpoint.
  std::string last = segs->back();
  std::string renamed = dir + "/seg-00000099.log";
  ASSERT_EQ(std::rename(last.c_str(), renamed.c_str()), 0);
  auto rep = verify_dir(dir, kSecret);
  EXPECT_FALSE(rep.ok);
  EXPECT_EQ(rep.why.rfind("wrong segment link", 0), 0u) << rep.why;
}

TEST(AuditStorage, MissingIndexIsRebuiltOnOpen) {
  TempDir tmp;
  std::string dir = tmp.path() + "/log";
  {
    auto log = open_log(dir, options(2048));
    for (int i = 1; i <= 60; ++i) ASSERT_TRUE(log->append(entry(i)).ok());
  }
  std::filesystem::remove(dir + "/seg-00000001.idx");
  std::string idx2 = dir + "/seg-00000002.idx";
  write_file(idx2, "garbage");
  auto log = open_log(dir, options(2048));
  auto f = log->find_by_message_id("msg-2");
  ASSERT_TRUE(f.ok());
  EXPECT_EQ(f->size(), 1u);
  EXPECT_TRUE(std::filesystem::exists(dir + "/seg-00000001.idx"));
}

// An index file is outside the chain: a damaged entry must make get() slower, never wrong.
TEST(AuditStorage, DamagedIndexEntryNeverAnswersWithAnotherRecord) {
  TempDir tmp;
  std::string dir = tmp.path() + "/log";
  {
    auto log = open_log(dir, options(4096));
    for (int i = 1; i <= 60; ++i) ASSERT_TRUE(log->append(entry(i)).ok());
  }
  const std::string idx = dir + "/seg-00000001.idx";
  ASSERT_TRUE(std::filesystem::exists(idx));
  std::string data = rcan::test::read_file(idx);
  constexpr size_t kHeader = 64,
                   kEntry = 32;  // docs/AUDIT.md §6: header, then (seq, offset, length, ts)
  auto get64 = [&](size_t at) {
    uint64_t v = 0;
    std::memcpy(&v, data.data() + at, 8);
    return v;
  };
  auto put64 = [&](size_t at, uint64_t v) { std::memcpy(data.data() + at, &v, 8); };
  const uint64_t count = get64(8), first = get64(16);
  ASSERT_GE(count, 6u);
  ASSERT_EQ(get64(kHeader), first);  // the layout this test edits
  // Entry 1 points at entry 3's record (a well-formed, verifying line: the wrong answer).
  put64(kHeader + 1 * kEntry + 8, get64(kHeader + 3 * kEntry + 8));
  put64(kHeader + 1 * kEntry + 16, get64(kHeader + 3 * kEntry + 16));
  // Entry 2: a length running past the end of the segment.
  put64(kHeader + 2 * kEntry + 16, uint64_t{1} << 20);
  // Entry 4: the wrong seq.
  put64(kHeader + 4 * kEntry, first + 5);
  write_file(idx, data);

  auto log = open_log(dir, options(4096));
  for (uint64_t seq = first; seq < first + count; ++seq) {
    auto line = log->get(seq);
    ASSERT_TRUE(line.ok()) << seq << ": " << line.error().message;
    auto v = json::parse(*line);
    ASSERT_TRUE(v.ok());
    EXPECT_EQ(v->get("seq")->as_int(), static_cast<int64_t>(seq)) << *line;
  }
  // Entries 1 and 2 sent the read to the segment; entry 4's offset still led to the record.
  EXPECT_EQ(log->stats().index_fallbacks, 2u);
  // find_by_message_id reads through the same check (entry 2's length ran past the segment).
  auto second = log->get(first + 2);
  ASSERT_TRUE(second.ok());
  const std::string mid = json::parse(*second)->get("message_id")->as_string();
  auto found = log->find_by_message_id(mid);
  ASSERT_TRUE(found.ok()) << found.error().message;
  ASSERT_EQ(found->size(), 1u);
  EXPECT_EQ(json::parse((*found)[0])->get("seq")->as_int(), static_cast<int64_t>(first + 2));

  // A record whose bytes were changed on disk is refused: through a damaged entry (first + 1),
  // through an intact one (first + 5), and in the active segment (served from memory).
  auto tamper = [](const std::string& path, uint64_t seq) {
    std::string text = rcan::test::read_file(path);
    for (size_t begin = 0; begin < text.size();) {
      size_t end = text.find('\n', begin);
      if (end == std::string::npos) break;
      auto v = json::parse(std::string_view(text).substr(begin, end - begin));
      if (v.ok() && v->get("seq") && v->get("seq")->as_int() == static_cast<int64_t>(seq)) {
        size_t at = text.find("move_forward", begin);
        if (at == std::string::npos || at > end) return false;
        text[at] = 'M';  // same length: offsets stay valid
        write_file(path, text);
        return true;
      }
      begin = end + 1;
    }
    return false;
  };
  const std::string seg = dir + "/seg-00000001.log";
  ASSERT_TRUE(tamper(seg, first + 1));
  ASSERT_TRUE(tamper(seg, first + 5));
  const uint64_t last = log->stats().last_seq;
  const std::string active = dir + "/" + [&] {
    char name[32];
    std::snprintf(name, sizeof name, "seg-%08llu.log",
                  static_cast<unsigned long long>(log->stats().active_segment));
    return std::string(name);
  }();
  ASSERT_TRUE(tamper(active, last));
  for (uint64_t seq : {first + 1, first + 5, last}) {
    auto refused = log->get(seq);
    ASSERT_FALSE(refused.ok()) << seq;
    EXPECT_EQ(refused.error().code, ErrorCode::kAuditUnavailable);
    EXPECT_NE(refused.error().message.find("hmac"), std::string::npos) << refused.error().message;
  }
  auto neighbour = log->get(first + 3);  // its entry was not damaged; its record was not changed
  ASSERT_TRUE(neighbour.ok());
}

// ---- CLI ----

TEST(AuditCli, ExportAndVerify) {
  TempDir tmp;
  std::string dir = tmp.path() + "/data";
  std::filesystem::create_directories(dir);
  {
    auto log = open_log(dir + "/audit", options(4096));
    for (int i = 1; i <= 50; ++i) ASSERT_TRUE(log->append(entry(i)).ok());
  }
  std::string secret_file = tmp.file("secret");
  write_file(secret_file, kSecret);
  auto ex = rcan::test::run_cli({"audit", "export", "--data-dir", dir});
  ASSERT_EQ(ex.exit_code, 0) << ex.err;
  std::string jsonl = tmp.file("audit.jsonl");
  write_file(jsonl, ex.out);
  auto ok = rcan::test::run_cli({"audit", "verify", jsonl, "--secret-file", secret_file});
  EXPECT_EQ(ok.exit_code, 0) << ok.out << ok.err;
  EXPECT_NE(ok.out.find("records"), std::string::npos);
  auto dirv =
      rcan::test::run_cli({"audit", "verify", "--data-dir", dir, "--secret-file", secret_file});
  EXPECT_EQ(dirv.exit_code, 0) << dirv.out << dirv.err;
  // A directory given in FILE's place is verified as a data directory, not read as a file.
  auto dirp = rcan::test::run_cli({"audit", "verify", dir, "--secret-file", secret_file});
  EXPECT_EQ(dirp.exit_code, 0) << dirp.out << dirp.err;
  EXPECT_EQ(dirp.out, dirv.out);

  // Tamper with seq 20.
  auto lines = export_dir_lines(dir + "/audit");
  auto v = parse(lines[19]);
  v.as_object().set("outcome", "blocked");
  lines[19] = json::canonical(v);
  write_file(jsonl, join(lines));
  auto bad = rcan::test::run_cli({"audit", "verify", jsonl, "--secret-file", secret_file});
  EXPECT_EQ(bad.exit_code, 1);
  EXPECT_NE((bad.out + bad.err).find("seq 20"), std::string::npos) << bad.out << bad.err;
  EXPECT_NE((bad.out + bad.err).find("hmac mismatch"), std::string::npos);

  auto usage = rcan::test::run_cli({"audit", "verify", jsonl});
  EXPECT_EQ(usage.exit_code, 2);
}

// A file rewritten in place (Env::open_existing_at, the latch file): a FIFO in its place is
// refused at once instead of blocking the open until a reader comes, and a file removed between
// the open and the sync fails the sync, since what was written is then in no file.
TEST(PosixEnv, AnInPlaceFileThatIsNotRegularOrWasRemovedIsAnError) {
  TempDir dir;
  Env* env = Env::posix();
  const std::string fifo = dir.file("fifo");
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  {
    // With a reader the open itself succeeds: refused as not a regular file.
    const int reader = ::open(fifo.c_str(), O_RDONLY | O_NONBLOCK);
    ASSERT_GE(reader, 0);
    auto opened = env->open_existing_at(fifo, 0);
    ::close(reader);
    ASSERT_FALSE(opened.ok());
    EXPECT_NE(opened.error().message.find("not a regular file"), std::string::npos)
        << opened.error().message;
  }
  auto no_reader = env->open_existing_at(fifo, 0);  // refused at once, not blocked
  ASSERT_FALSE(no_reader.ok());
  EXPECT_NE(no_reader.error().message.find(fifo), std::string::npos) << no_reader.error().message;
  const std::string f = dir.file("state");
  ASSERT_TRUE(env->write_file_synced(f, "cleared").ok());
  {
    auto kept = env->open_existing_at(f, 0);
    ASSERT_TRUE(kept.ok()) << kept.error().message;
    ASSERT_TRUE((*kept)->append("latched").ok());
    EXPECT_TRUE((*kept)->sync().ok());
  }
  auto removed = env->open_existing_at(f, 0);
  ASSERT_TRUE(removed.ok()) << removed.error().message;
  ASSERT_EQ(::unlink(f.c_str()), 0);
  ASSERT_TRUE((*removed)->append("latched").ok());
  Status s = (*removed)->sync();
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().message.find("removed while written"), std::string::npos)
      << s.error().message;
}

}  // namespace
}  // namespace rcan::audit
