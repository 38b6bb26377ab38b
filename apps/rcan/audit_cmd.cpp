// rcan audit — export, verify and inspect audit logs offline (docs/AUDIT.md).
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <thread>

#include "cli.h"
#include "net_common.h"
#include "rcan/audit/audit_log.h"
#include "rcan/audit/secret.h"
#include "rcan/audit/verify.h"
#include "rcan/json.h"

namespace rcan::cli {
namespace {

constexpr const char* kHelp =
    "usage:\n"
    "  rcan audit export [--from MS] [--to MS] [--out FILE] [--url URL] [--token-file F]\n"
    "      Without --data-dir: asks the running node (GET /api/v1/audit, OWNER + scope config)\n"
    "      for its chain as JSONL, verifiable offline with `rcan audit verify`.\n"
    "  rcan audit tail [-n N] [--follow] [--url URL] [--token-file F] [--json]\n"
    "      The node's latest N records (GET /api/audit, OWNER, default 20) as a table: seq,\n"
    "      time, principal, event, outcome, reason. --follow keeps printing new records (1 s\n"
    "      poll). The node records every read (AUDIT_READ).\n"
    "  rcan audit export --data-dir D [--from MS] [--to MS] [--format jsonl|rcanpy]\n"
    "                    [--secret-file F | --secret S] [--out FILE]\n"
    "      Prints the log as JSONL, one canonical record per line, in seq order, reading the\n"
    "      segment files directly (no network, safe while the node runs; a torn last line is\n"
    "      skipped). D is the node's data directory (its audit/ subdirectory is used when\n"
    "      present) or the audit directory itself. --from/--to select timestamp_ms (inclusive);\n"
    "      a ranged export verifies with --partial. --format rcanpy re-states the chain as\n"
    "      rcan-py CommitmentRecord v0.3 lines signed with the chain secret (needs the secret).\n"
    "  rcan audit verify [FILE | - | --data-dir D | D] (--secret-file F | --secret S)\n"
    "                    [--format native|rcanpy] [--partial] [--expect-last-seq N]\n"
    "      Verifies an exported chain offline. Exit 0 printing the number of records; exit 1\n"
    "      naming the first bad seq (rcanpy: 0-based index) and why: hmac mismatch, prev_hash\n"
    "      mismatch, seq gap, malformed line, wrong segment link, bad chain start, truncated.\n"
    "      --data-dir D (or the directory D alone) verifies the segment files themselves,\n"
    "      including segment links. With neither FILE nor a directory it fetches the running\n"
    "      node's chain (--url, --token-file).\n"
    "  rcan audit new-secret --out F\n"
    "      Writes a new chain secret (64 hex characters, mode 0600, no newline). Never "
    "overwrites.\n"
    "  Exit: 0 ok, 1 verification failed (or refused by the node), 2 usage or unreadable input,\n"
    "        3 node unreachable.\n";

std::string resolve_dir(const std::string& d) {
  auto sub = audit::list_segments(d + "/audit");
  if (sub.ok() && !sub->empty()) return d + "/audit";
  return d;
}

Result<std::string> secret_from(const Options& o) {
  if (o.has("secret-file") && o.has("secret"))
    return Error(ErrorCode::kSchemaValidationFailed, "give --secret-file or --secret, not both");
  if (o.has("secret-file")) return audit::read_secret_file(o.get("secret-file"));
  if (o.has("secret")) {
    if (o.get("secret").empty())
      return Error(ErrorCode::kSchemaValidationFailed, "--secret is empty");
    return o.get("secret");
  }
  return Error(ErrorCode::kSchemaValidationFailed,
               "--secret-file F or --secret S is required (there is no default secret)");
}

bool parse_i64(const std::string& s, int64_t* out) {
  if (s.empty()) return false;
  char* end = nullptr;
  errno = 0;
  long long v = std::strtoll(s.c_str(), &end, 10);
  if (errno != 0 || *end != '\0') return false;
  *out = v;
  return true;
}

int remote_export(const Options& o) {
  std::string err;
  auto co = client_options(o, true, err);
  if (!err.empty()) return usage_error("audit export", err);
  std::optional<int64_t> from, to;
  int64_t v = 0;
  if (o.has("from")) {
    if (!parse_i64(o.get("from"), &v))
      return usage_error("audit export", "--from must be milliseconds since the epoch");
    from = v;
  }
  if (o.has("to")) {
    if (!parse_i64(o.get("to"), &v))
      return usage_error("audit export", "--to must be milliseconds since the epoch");
    to = v;
  }
  if (o.get("format", "jsonl") != "jsonl")
    return usage_error("audit export", "the node exports jsonl (use --data-dir for rcanpy)");
  client::Client c(co);
  auto text = c.audit_export(from, to);
  if (!text.ok()) return report_error("audit export", text.error(), false);
  if (o.has("out")) {
    std::ofstream f(o.get("out"), std::ios::binary | std::ios::trunc);
    if (!f) return usage_error("audit export", "cannot write " + o.get("out"));
    f << *text;
  } else {
    std::cout << *text;
  }
  size_t n = static_cast<size_t>(std::count(text->begin(), text->end(), '\n'));
  std::fprintf(stderr, "rcan audit export: %zu records from %s\n", n, co.url.c_str());
  return 0;
}

int tail_main(const Args& args) {
  Args norm;
  for (const auto& a : args) norm.push_back(a == "-n" ? "--lines" : a);
  std::vector<std::string> flags{"follow"}, valued{"lines"};
  flags.insert(flags.end(), net_flags().begin(), net_flags().end());
  valued.insert(valued.end(), net_valued().begin(), net_valued().end());
  Options o(norm, flags, valued);
  if (!o.ok()) return usage_error("audit tail", o.error());
  if (!o.positional().empty())
    return usage_error("audit tail", "unexpected argument " + o.positional()[0]);
  int64_t n = 20;
  if (o.has("lines") && (!parse_i64(o.get("lines"), &n) || n < 1 || n > 1000))
    return usage_error("audit tail", "-n must be 1..1000");
  std::string err;
  auto co = client_options(o, true, err);
  if (!err.empty()) return usage_error("audit tail", err);
  client::Client c(co);
  bool json_out = want_json(o);
  int64_t last_seen = 0;
  bool header = false;
  while (true) {
    auto page = c.audit_recent(static_cast<int>(last_seen ? 1000 : n));
    if (!page.ok()) return report_error("audit tail", page.error(), json_out);
    if (!page->unreadable.empty() && page->unreadable.back() > last_seen) {
      std::string seqs;
      for (int64_t s : page->unreadable)
        if (s > last_seen) seqs += (seqs.empty() ? "" : ", ") + std::to_string(s);
      std::cerr << "warning: audit records that failed their check on the node are not shown: seq "
                << seqs << " (rcan audit verify --data-dir on the robot names the fault)\n";
    }
    std::vector<std::vector<std::string>> rows;
    for (const auto& e : page->entries) {
      const json::Value* seq = e.get("seq");
      int64_t s = seq && seq->is_int() ? seq->as_int() : 0;
      if (s <= last_seen) continue;
      last_seen = s;
      if (json_out) {
        std::cout << json::dump(e) << "\n";
        continue;
      }
      auto f = [&](const char* k) {
        const json::Value* v = e.get(k);
        return v ? brief(*v, 48) : std::string("-");
      };
      const json::Value* ts = e.get("timestamp_ms");
      std::string outcome = f("outcome");
      outcome = outcome == "ok"        ? green(outcome)
                : outcome == "blocked" ? red(outcome)
                                       : yellow(outcome);
      std::string reason = f("reason");
      rows.push_back({std::to_string(s), when(ts && ts->is_int() ? ts->as_int() : 0),
                      f("principal"), f("event"), outcome, reason == "null" ? "-" : reason});
    }
    if (!json_out && !rows.empty()) {
      if (!header) {
        print_table({"SEQ", "TIME", "PRINCIPAL", "EVENT", "OUTCOME", "REASON"}, rows);
        header = true;
      } else {
        for (const auto& r : rows) {
          std::string line;
          for (const auto& cell : r) line += cell + "  ";
          std::printf("%s\n", line.c_str());
        }
      }
    }
    std::fflush(stdout);
    if (!o.has("follow")) return 0;
    std::this_thread::sleep_for(std::chrono::seconds(1));
  }
}

int export_main(const Args& args) {
  std::vector<std::string> flags,
      valued{"data-dir", "from", "to", "format", "secret-file", "secret", "out"};
  flags.insert(flags.end(), net_flags().begin(), net_flags().end());
  valued.insert(valued.end(), net_valued().begin(), net_valued().end());
  Options o(args, flags, valued);
  if (!o.ok()) return usage_error("audit export", o.error());
  if (!o.positional().empty())
    return usage_error("audit export", "unexpected argument " + o.positional()[0]);
  if (o.get("data-dir").empty()) return remote_export(o);
  int64_t from = INT64_MIN, to = INT64_MAX;
  if (o.has("from") && !parse_i64(o.get("from"), &from))
    return usage_error("audit export", "--from must be milliseconds since the epoch");
  if (o.has("to") && !parse_i64(o.get("to"), &to))
    return usage_error("audit export", "--to must be milliseconds since the epoch");
  std::string format = o.get("format", "jsonl");
  if (format != "jsonl" && format != "rcanpy")
    return usage_error("audit export", "--format is jsonl or rcanpy");
  std::optional<audit::RcanpyExporter> rcanpy;
  if (format == "rcanpy") {
    auto secret = secret_from(o);
    if (!secret.ok()) return usage_error("audit export", secret.error().message);
    rcanpy.emplace(*secret);
  }
  std::ofstream file;
  if (o.has("out")) {
    file.open(o.get("out"), std::ios::binary | std::ios::trunc);
    if (!file) return usage_error("audit export", "cannot write " + o.get("out"));
  }
  std::ostream& out = o.has("out") ? static_cast<std::ostream&>(file) : std::cout;
  std::string dir = resolve_dir(o.get("data-dir"));
  std::string err;
  uint64_t n = 0;
  Status s = audit::export_dir(dir, from, to, [&](std::string_view line) {
    if (rcanpy) {
      json::ParseOptions po;
      po.max_bytes = 8u << 20;
      auto v = json::parse(line, po);
      if (!v.ok() || !v->is_object()) {
        err = "malformed record in the log: " +
              (v.ok() ? std::string("not an object") : v.error().message);
        return false;
      }
      auto l = rcanpy->add(v->as_object());
      if (!l.ok()) {
        err = l.error().message;
        return false;
      }
      out << *l << '\n';
    } else {
      out << line << '\n';
    }
    ++n;
    return true;
  });
  out.flush();
  if (!s.ok()) {
    std::fprintf(stderr, "rcan audit export: %s\n", s.error().message.c_str());
    return 2;
  }
  if (!err.empty()) {
    std::fprintf(stderr, "rcan audit export: %s\n", err.c_str());
    return 2;
  }
  std::fprintf(stderr, "rcan audit export: %llu records\n", static_cast<unsigned long long>(n));
  return 0;
}

int verify_main(const Args& args) {
  std::vector<std::string> flags{"partial"},
      valued{"secret-file", "secret", "format", "data-dir", "expect-last-seq"};
  flags.insert(flags.end(), net_flags().begin(), net_flags().end());
  valued.insert(valued.end(), net_valued().begin(), net_valued().end());
  Options o(args, flags, valued);
  if (!o.ok()) return usage_error("audit verify", o.error());
  auto secret = secret_from(o);
  if (!secret.ok()) return usage_error("audit verify", secret.error().message);
  std::string format = o.get("format", "native");
  if (format == "jsonl") format = "native";
  if (format != "native" && format != "rcanpy")
    return usage_error("audit verify", "--format is native or rcanpy");

  audit::VerifyReport rep;
  // A directory given as FILE is a data directory (or its audit/ subdirectory), as with
  // --data-dir: reading it as a file would only say "no records".
  std::error_code dir_ec;
  const bool positional_dir = o.positional().size() == 1 && o.positional()[0] != "-" &&
                              std::filesystem::is_directory(o.positional()[0], dir_ec);
  if (o.has("data-dir") || positional_dir) {
    if (o.has("data-dir") && !o.positional().empty())
      return usage_error("audit verify", "give FILE or --data-dir, not both");
    if (format != "native")
      return usage_error("audit verify", "a data directory holds native segments");
    rep = audit::verify_dir(resolve_dir(positional_dir ? o.positional()[0] : o.get("data-dir")),
                            *secret);
  } else {
    if (o.positional().size() > 1)
      return usage_error("audit verify", "expected one FILE (or - for stdin)");
    std::string text;
    if (o.positional().empty()) {
      // The running node's chain, fetched and verified here with the secret.
      std::string err;
      auto co = client_options(o, true, err);
      if (!err.empty()) return usage_error("audit verify", err + " (or give FILE / --data-dir)");
      client::Client c(co);
      auto t = c.audit_export();
      if (!t.ok()) return report_error("audit verify", t.error(), false);
      text = std::move(t).value();
    } else if (o.positional()[0] == "-") {
      text = read_stdin();
    } else {
      auto t = read_file(o.positional()[0]);
      if (!t.ok()) return usage_error("audit verify", t.error().message);
      text = std::move(*t);
    }
    if (format == "rcanpy") {
      rep = audit::verify_rcanpy_jsonl(text, *secret, /*strict_start=*/true);
    } else {
      audit::VerifyOptions vo;
      vo.allow_partial_start = o.has("partial");
      if (o.has("expect-last-seq")) {
        int64_t n = 0;
        if (!parse_i64(o.get("expect-last-seq"), &n) || n < 1)
          return usage_error("audit verify", "--expect-last-seq must be a positive integer");
        vo.expect_last_seq = static_cast<uint64_t>(n);
      }
      rep = audit::verify_jsonl(std::string_view(text), *secret, vo);
    }
  }
  if (rep.ok) {
    if (format == "rcanpy") {
      std::printf("ok: %llu records verified (rcan-py CommitmentRecord v0.3 chain)\n",
                  static_cast<unsigned long long>(rep.count));
    } else {
      std::printf("ok: %llu records verified (seq %llu..%llu)\n",
                  static_cast<unsigned long long>(rep.count),
                  static_cast<unsigned long long>(rep.first_seq),
                  static_cast<unsigned long long>(rep.last_seq));
    }
    return 0;
  }
  if (format == "rcanpy") {
    std::printf("FAILED at index %llu: %s (%llu records verified before it)\n",
                static_cast<unsigned long long>(rep.first_bad_index), rep.why.c_str(),
                static_cast<unsigned long long>(rep.count));
  } else {
    std::printf("FAILED at seq %llu (line %llu): %s (%llu records verified before it)\n",
                static_cast<unsigned long long>(rep.first_bad_seq),
                static_cast<unsigned long long>(rep.first_bad_index + 1), rep.why.c_str(),
                static_cast<unsigned long long>(rep.count));
  }
  return 1;
}

int new_secret_main(const Args& args) {
  Options o(args, {}, {"out"});
  if (!o.ok()) return usage_error("audit new-secret", o.error());
  if (o.get("out").empty()) return usage_error("audit new-secret", "--out FILE is required");
  Status s = audit::create_secret_file(o.get("out"));
  if (!s.ok()) {
    std::fprintf(stderr, "rcan audit new-secret: %s\n", s.error().message.c_str());
    return 1;
  }
  std::printf("wrote a new audit chain secret to %s (mode 0600)\n", o.get("out").c_str());
  return 0;
}

int audit_main(const Args& args) {
  if (args.empty() || args[0] == "--help" || args[0] == "-h" || args[0] == "help") {
    std::fputs(kHelp, args.empty() ? stderr : stdout);
    return args.empty() ? 2 : 0;
  }
  Args rest(args.begin() + 1, args.end());
  for (const auto& a : rest) {
    if (a == "--help" || a == "-h") {
      std::fputs(kHelp, stdout);
      return 0;
    }
  }
  if (args[0] == "export") return export_main(rest);
  if (args[0] == "verify") return verify_main(rest);
  if (args[0] == "new-secret") return new_secret_main(rest);
  if (args[0] == "tail") return tail_main(rest);
  return usage_error("audit",
                     "unknown subcommand " + args[0] + " (export, verify, tail, new-secret)");
}

const Registration kReg{"audit", "export, verify and tail audit logs (node or files)", &audit_main};

}  // namespace
}  // namespace rcan::cli
