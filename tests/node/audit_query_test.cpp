// GET /api/audit's query on a real audit log: pages and their cursors, each filter, the time
// window, auto-refresh after a seq, the scan budget, and bad parameters.
#include "node/api/audit_query.h"

#include <gtest/gtest.h>

#include <map>
#include <set>
#include <string>

#include "audit_util.h"
#include "test_support.h"

namespace rcan::node {
namespace {

using audit::testutil::entry;
using audit::testutil::options;

// Records msg-1..msg-3000, over several segments (each begins with a checkpoint record, so a
// record's seq is not its number: the tests name records by message_id).
constexpr int kRecords = 3000;
constexpr int64_t kT0 = 1740000000000;

class AuditQueryTest : public ::testing::Test {
 protected:
  void SetUp() override {
    auto log = audit::AuditLog::open(tmp_.path() + "/log", options(256 << 10));  // many segments
    ASSERT_TRUE(log.ok()) << log.error().message;
    log_ = std::move(log).value();
    for (int i = 1; i <= kRecords; ++i) {
      audit::AuditEntry e = entry(i);
      e.timestamp_ms = kT0 + int64_t{i} * 1000;  // one a second
      e.event = i % 10 == 0 ? "ESTOP" : "COMMAND";
      e.outcome = i % 4 == 0 ? "blocked" : "ok";
      e.sub = i % 100 == 0 ? "Alice.Operator" : "user-" + std::to_string(i % 7);
      if (i == 1234) e.detail.set("note", "Needle in the haystack");
      if (i == 2500 || i == 2501) e.message_id = "shared-id";
      ASSERT_TRUE(log_->append(std::move(e)).ok());
    }
  }
  AuditPage run(AuditQuery q) { return run_audit_query(*log_, q); }
  static std::vector<int64_t> seqs(const AuditPage& p) {
    std::vector<int64_t> out;
    for (const auto& e : p.entries) out.push_back(json::int_field(e, "seq"));
    return out;
  }
  static std::vector<std::string> ids(const AuditPage& p) {
    std::vector<std::string> out;
    for (const auto& e : p.entries) out.push_back(json::string_field(e, "message_id"));
    return out;
  }
  int64_t last() const { return static_cast<int64_t>(log_->stats().last_seq); }
  test::TempDir tmp_;
  std::unique_ptr<audit::AuditLog> log_;
};

TEST_F(AuditQueryTest, PagesWalkTheWholeLogNewestFirstWithoutGapsOrRepeats) {
  AuditQuery q;
  q.limit = 100;
  AuditPage first = run(q);
  ASSERT_EQ(first.entries.size(), 100u);
  EXPECT_EQ(seqs(first).front(), last() - 99);
  EXPECT_EQ(seqs(first).back(), last());  // ascending within a page
  EXPECT_EQ(ids(first).back(), "msg-3000");
  std::set<int64_t> seen;
  uint64_t before = 0;
  int pages = 0;
  do {
    q.before = before;
    AuditPage p = run(q);
    EXPECT_TRUE(p.complete);
    for (int64_t s : seqs(p)) EXPECT_TRUE(seen.insert(s).second) << "seq " << s << " twice";
    before = p.next_before;
    ++pages;
  } while (before != 0 && pages < 100);
  EXPECT_EQ(seen.size(), static_cast<size_t>(last()));  // the checkpoints included
  EXPECT_GT(last(), kRecords + 2);                      // more than one segment
  EXPECT_EQ(*seen.begin(), 1);
  EXPECT_EQ(pages, (last() + 99) / 100);
}

TEST_F(AuditQueryTest, EachFilterAndTheirCombination) {
  AuditQuery q;
  q.limit = 1000;
  q.event = "ESTOP";
  AuditPage p = run(q);
  EXPECT_EQ(p.entries.size(), 300u);
  for (const auto& e : p.entries) EXPECT_EQ(json::string_field(e, "event"), "ESTOP");
  q.outcome = "blocked";  // i % 10 == 0 and i % 4 == 0: every 20th
  EXPECT_EQ(run(q).entries.size(), 150u);
  q = {};
  q.limit = 1000;
  q.event = "ESTOP,COMMAND";
  q.scan_budget = 10'000;
  EXPECT_EQ(run(q).entries.size(), 1000u);
  q = {};
  q.principal = "alice.OPERATOR";  // case-insensitive, in `sub`
  q.limit = 1000;
  EXPECT_EQ(run(q).entries.size(), 30u);
  q = {};
  q.text = "needle IN the";
  AuditPage needle = run(q);
  ASSERT_EQ(needle.entries.size(), 1u);
  EXPECT_EQ(json::string_field(*needle.entries[0].get("detail"), "note"), "Needle in the haystack");
  q = {};
  q.message_id = "shared-id";
  AuditPage shared = run(q);
  ASSERT_EQ(shared.entries.size(), 2u);
  EXPECT_EQ(json::int_field(shared.entries[0], "timestamp_ms"), kT0 + 2500 * 1000);
  EXPECT_EQ(json::int_field(shared.entries[1], "timestamp_ms"), kT0 + 2501 * 1000);
  q.outcome = "blocked";  // 2500 % 4 == 0
  AuditPage blocked = run(q);
  ASSERT_EQ(blocked.entries.size(), 1u);
  EXPECT_EQ(json::int_field(blocked.entries[0], "timestamp_ms"), kT0 + 2500 * 1000);
  q = {};
  q.message_id = "no-such-id";
  EXPECT_TRUE(run(q).entries.empty());
}

TEST_F(AuditQueryTest, TimeWindowIsFoundByBinarySearchAndAppliedExactly) {
  AuditQuery q;
  q.limit = 1000;
  q.from_ms = kT0 + 1000 * 1000;  // records 1000..1099
  q.to_ms = kT0 + 1099 * 1000;
  AuditPage p = run(q);
  ASSERT_EQ(p.entries.size(), 100u);
  EXPECT_EQ(ids(p).front(), "msg-1000");
  EXPECT_EQ(ids(p).back(), "msg-1099");
  EXPECT_LT(p.scanned, 200u) << "the window is located, not scanned from the newest record";
  q.from_ms = kT0 + 5000 * 1000;  // after the last record
  q.to_ms = 0;
  EXPECT_TRUE(run(q).entries.empty());
}

TEST_F(AuditQueryTest, AfterACursorGivesWhatIsNewOldestFirst) {
  AuditQuery q;
  q.after = static_cast<uint64_t>(last() - 5);
  AuditPage p = run(q);
  EXPECT_EQ(ids(p),
            (std::vector<std::string>{"msg-2996", "msg-2997", "msg-2998", "msg-2999", "msg-3000"}));
  audit::AuditEntry e = entry(9999);
  e.event = "RESUME";
  ASSERT_TRUE(log_->append(std::move(e)).ok());
  q.after = static_cast<uint64_t>(last() - 1);
  p = run(q);
  ASSERT_EQ(p.entries.size(), 1u);
  EXPECT_EQ(json::string_field(p.entries[0], "event"), "RESUME");
}

TEST_F(AuditQueryTest, ASearchThatRunsOutOfBudgetSaysWhereToGoOn) {
  AuditQuery q;
  q.text = "needle";
  q.scan_budget = 1000;
  AuditPage p = run(q);
  EXPECT_FALSE(p.complete);
  EXPECT_TRUE(p.entries.empty());
  EXPECT_EQ(p.scanned, 1000u);
  ASSERT_EQ(p.next_before, static_cast<uint64_t>(last() - 999));
  int rounds = 1;
  while (p.entries.empty() && p.next_before != 0 && rounds < 10) {
    q.before = p.next_before;
    p = run(q);
    ++rounds;
  }
  ASSERT_EQ(p.entries.size(), 1u);
  EXPECT_EQ(json::string_field(p.entries[0], "message_id"), "msg-1234");
  EXPECT_EQ(rounds,
            2 + static_cast<int>((last() - 1000 - json::int_field(p.entries[0], "seq")) / 1000));
}

TEST(AuditQueryParams, BadParametersAreNamed) {
  auto parse = [](std::map<std::string, std::string> params) {
    return parse_audit_query(
        [&](std::string_view name) -> std::optional<std::string_view> {
          auto it = params.find(std::string(name));
          if (it == params.end()) return std::nullopt;
          return std::string_view(it->second);
        },
        50);
  };
  EXPECT_TRUE(parse({}).ok());
  EXPECT_EQ(parse({})->limit, 50u);
  auto ok = parse(
      {{"limit", "20"}, {"before", "77"}, {"from", "1740000000"}, {"event", "ESTOP"}, {"q", "x"}});
  ASSERT_TRUE(ok.ok());
  EXPECT_EQ(ok->from_ms, 1740000000000);  // seconds read as seconds
  EXPECT_EQ(ok->to_json().find("before")->as_int(), 77);
  for (auto [k, v] :
       std::vector<std::pair<std::string, std::string>>{{"limit", "0"},
                                                        {"limit", "1001"},
                                                        {"limit", "-1"},
                                                        {"limit", "ten"},
                                                        {"before", "0"},
                                                        {"after", "x"},
                                                        {"from", "yesterday"},
                                                        {"to", "99999999999999999999"},
                                                        {"q", std::string(300, 'a')},
                                                        {"event", "A\nB"},
                                                        {"message_id", std::string(200, 'm')}}) {
    auto r = parse({{k, v}});
    ASSERT_FALSE(r.ok()) << k << "=" << v;
    EXPECT_EQ(r.error().code, ErrorCode::kSchemaValidationFailed);
    EXPECT_EQ(r.error().field, k) << r.error().message;
  }
  EXPECT_FALSE(parse({{"before", "5"}, {"after", "3"}}).ok());
  EXPECT_FALSE(parse({{"from", "1740000100"}, {"to", "1740000000"}}).ok());
}

}  // namespace
}  // namespace rcan::node
