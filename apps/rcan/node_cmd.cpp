// rcan status | claim | release | handoff | estop | resume | command | stream | discover —
// operate a running node through rcan::client (include/rcan/client.h). Conventions and exit
// codes: net_common.h.
#include <signal.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <thread>

#include "base/clock.h"
#include "net_common.h"
#include "rcan/errors.h"

namespace rcan::cli {
namespace {

int64_t now_ms() { return unix_ms(); }

std::vector<std::string> with_net(std::vector<std::string> v, bool flags) {
  const auto& extra = flags ? net_flags() : net_valued();
  v.insert(v.end(), extra.begin(), extra.end());
  return v;
}

// Parses options common to simple verbs; returns false (with `rc` set) on usage errors.
bool setup(const char* verb, const Args& args, const std::vector<std::string>& flags,
           const std::vector<std::string>& valued, bool need_token, size_t max_positional,
           Options*& out, client::ClientOptions& co, int& rc) {
  static std::unique_ptr<Options> holder;
  holder = std::make_unique<Options>(args, with_net(flags, true), with_net(valued, false));
  out = holder.get();
  if (!out->ok()) {
    rc = usage_error(verb, out->error());
    return false;
  }
  if (out->positional().size() > max_positional) {
    rc = usage_error(verb, "unexpected argument " + out->positional()[max_positional]);
    return false;
  }
  std::string err;
  co = client_options(*out, need_token, err);
  if (!err.empty()) {
    rc = usage_error(verb, err);
    return false;
  }
  return true;
}

void print_reply(const client::Reply& r, const char* what) {
  std::string type = r.type.empty() ? "OK" : r.type;
  std::printf("%s %s", green(type).c_str(), what);
  if (r.payload.is_object()) {
    for (const char* k :
         {"session_id", "action", "status", "result", "state", "target_user_id", "window_ms"})
      if (const json::Value* f = r.payload.get(k)) std::printf("  %s=%s", k, brief(*f, 60).c_str());
  }
  std::printf("\n");
}

// ------------------------------------------------------------------------------------------
// status

constexpr const char* kStatusHelp =
    "usage: rcan status [--url URL] [--token-file F] [--json]\n"
    "  Shows the node's identity, ESTOP state, mode and control sessions (GET /rcan/v1/status).\n"
    "  With a token the node adds the robot's live state (pose, speeds, arm).\n";

int status_main(const Args& args) {
  if (help_requested(args, (std::string(kStatusHelp) + kNetHelp).c_str())) return 0;
  Options* o;
  client::ClientOptions co;
  int rc = 0;
  if (!setup("status", args, {}, {}, false, 0, o, co, rc)) return rc;
  client::Client c(co);
  auto s = c.status();
  if (!s.ok()) return report_error("status", s.error(), want_json(*o));
  if (want_json(*o)) {
    std::cout << json::dump(s->raw) << "\n";
    return 0;
  }
  std::string extensions;
  for (const auto& e : s->extensions) extensions += (extensions.empty() ? "" : ", ") + e;
  std::string caps;
  for (const auto& e : s->capabilities) caps += (caps.empty() ? "" : ", ") + e;
  std::printf("%-10s %s\n", "ruri", bold(s->ruri).c_str());
  std::printf("%-10s %s\n", "name", s->name.c_str());
  std::printf("%-10s %s\n", "rrn", s->rrn.c_str());
  std::printf("%-10s %s (%s)\n", "version", s->rcan_version.c_str(), extensions.c_str());
  std::printf("%-10s %s\n", "estop",
              s->estop_active ? red("ACTIVE").c_str() : green("clear").c_str());
  std::printf("%-10s %s\n", "mode", s->mode.c_str());
  std::printf("%-10s %s\n", "audit", s->audit_available ? "available" : red("UNAVAILABLE").c_str());
  std::printf("%-10s %s\n", "caps", caps.c_str());
  std::printf("%-10s %lld\n", "sessions", static_cast<long long>(s->active_sessions));
  for (const auto& se : s->sessions)
    std::printf("  %s  %s  %s\n", se.session_id.c_str(), se.role.c_str(), se.principal.c_str());
  if (s->robot.is_object()) {  // the safety core's state: scalars, and the base pose
    std::printf("%s\n", bold("robot").c_str());
    for (const auto& [k, v] : s->robot.as_object())
      // estop and the session count are already shown above
      if (!v.is_object() && !v.is_array() && k != "estop_active" && k != "sessions")
        std::printf("  %-20s %s\n", k.c_str(), brief(v, 80).c_str());
    const json::Value* inner = s->robot.get("robot");
    const json::Value* base = inner ? inner->get("base") : nullptr;
    if (base && base->is_object()) {
      std::string pose;
      for (const char* k : {"x", "y", "theta", "linear", "angular"})
        if (const json::Value* f = base->get(k); f && f->is_number()) {
          char b[48];
          std::snprintf(b, sizeof b, "%s%s=%.3f", pose.empty() ? "" : " ", k, f->to_double());
          pose += b;
        }
      if (!pose.empty()) std::printf("  %-20s %s\n", "base", pose.c_str());
    }
  }
  return 0;
}

// ------------------------------------------------------------------------------------------
// claim / release / handoff

constexpr const char* kClaimHelp =
    "usage: rcan claim [--role ROLE] [--url URL] [--token-file F] [--json]\n"
    "  Claims control (POST /rcan/v1/auth/claim): prints the session id, role and capabilities.\n"
    "  Needs USER or above with scope control. --role asks for a lower role than the token's.\n"
    "  A robot held by someone of the same or higher role answers CONTROL_CONFLICT (exit 1).\n"
    "  While you hold control, send commands or `rcan command heartbeat` within the heartbeat\n"
    "  timeout, or the robot safe-stops.\n";

int claim_main(const Args& args) {
  if (help_requested(args, (std::string(kClaimHelp) + kNetHelp).c_str())) return 0;
  Options* o;
  client::ClientOptions co;
  int rc = 0;
  if (!setup("claim", args, {}, {"role"}, true, 0, o, co, rc)) return rc;
  client::Client c(co);
  auto g = c.claim(o->get("role"));
  if (!g.ok()) return report_error("claim", g.error(), want_json(*o));
  if (want_json(*o)) {
    std::cout << json::dump(g->raw) << "\n";
    return 0;
  }
  std::string caps;
  for (const auto& e : g->capabilities) caps += (caps.empty() ? "" : ",") + e;
  std::printf("%s session %s as %s\n", green("GRANTED").c_str(), bold(g->session_id).c_str(),
              g->role.c_str());
  std::printf("  capabilities: %s\n  heartbeat timeout: %lld ms\n  expires in: %s\n", caps.c_str(),
              static_cast<long long>(g->heartbeat_timeout_ms),
              g->expires_in_s < 0 ? "never" : (std::to_string(g->expires_in_s) + " s").c_str());
  return 0;
}

constexpr const char* kReleaseHelp =
    "usage: rcan release [SESSION_ID] [--url URL] [--token-file F] [--json]\n"
    "  Releases control (DELETE /rcan/v1/auth/release). Without SESSION_ID, the session your\n"
    "  token holds.\n";

int release_main(const Args& args) {
  if (help_requested(args, (std::string(kReleaseHelp) + kNetHelp).c_str())) return 0;
  Options* o;
  client::ClientOptions co;
  int rc = 0;
  if (!setup("release", args, {}, {}, true, 1, o, co, rc)) return rc;
  client::Client c(co);
  auto r = c.release(o->positional().empty() ? "" : o->positional()[0]);
  if (!r.ok()) return report_error("release", r.error(), want_json(*o));
  if (want_json(*o))
    std::cout << json::dump(r->raw) << "\n";
  else
    print_reply(*r, "control released");
  return 0;
}

constexpr const char* kHandoffHelp =
    "usage: rcan handoff SESSION_ID --to USER_ID [--role ROLE] [--reason TEXT] [--url URL]\n"
    "                    [--token-file F] [--json]\n"
    "  Hands control to USER_ID (POST /rcan/v1/handoff): your session ends and the robot is\n"
    "  reserved for USER_ID for the handoff window (30 s); they claim it with their own token.\n"
    "  --role lowers the role they will get.\n";

int handoff_main(const Args& args) {
  if (help_requested(args, (std::string(kHandoffHelp) + kNetHelp).c_str())) return 0;
  Options* o;
  client::ClientOptions co;
  int rc = 0;
  if (!setup("handoff", args, {}, {"to", "role", "reason"}, true, 1, o, co, rc)) return rc;
  if (o->positional().size() != 1) return usage_error("handoff", "SESSION_ID is required");
  if (o->get("to").empty()) return usage_error("handoff", "--to USER_ID is required");
  client::Client c(co);
  auto r = c.handoff(o->positional()[0], o->get("to"), o->get("role"), o->get("reason"));
  if (!r.ok()) return report_error("handoff", r.error(), want_json(*o));
  if (want_json(*o))
    std::cout << json::dump(r->raw) << "\n";
  else
    print_reply(*r, ("control handed to " + o->get("to")).c_str());
  return 0;
}

// ------------------------------------------------------------------------------------------
// estop / resume

constexpr const char* kEstopHelp =
    "usage: rcan estop [--reason TEXT] [--url URL] [--token-file F] [--json]\n"
    "  Latches ESTOP (POST /api/stop): the robot stops at once and refuses motion until a\n"
    "  RESUME. Any authenticated role may stop the robot.\n";
constexpr const char* kResumeHelp =
    "usage: rcan resume [--reason TEXT] [--url URL] [--token-file F] [--json]\n"
    "  Clears a latched ESTOP (a SAFETY RESUME message). Needs LEASEE or above.\n";

int safety_main(const char* verb, const char* help, const Args& args) {
  if (help_requested(args, (std::string(help) + kNetHelp).c_str())) return 0;
  Options* o;
  client::ClientOptions co;
  int rc = 0;
  if (!setup(verb, args, {}, {"reason"}, true, 0, o, co, rc)) return rc;
  client::Client c(co);
  bool stop = std::string(verb) == "estop";
  auto r = stop ? c.estop(o->get("reason")) : c.resume(o->get("reason"));
  if (!r.ok()) return report_error(verb, r.error(), want_json(*o));
  if (want_json(*o))
    std::cout << json::dump(r->raw) << "\n";
  else
    std::printf("%s\n",
                stop ? red("ESTOP latched").c_str() : green("resumed: ESTOP cleared").c_str());
  return 0;
}

int estop_main(const Args& a) { return safety_main("estop", kEstopHelp, a); }
int resume_main(const Args& a) { return safety_main("resume", kResumeHelp, a); }

// ------------------------------------------------------------------------------------------
// command

constexpr const char* kCommandHelp =
    "usage: rcan command ACTION [--PARAM VALUE …] [options]\n"
    "       rcan command '{\"action\":\"move\",\"linear\":0.3}'    (a payload object)\n"
    "       rcan command '{\"type\":\"COMMAND\",…}' | rcan command - < msg.json   (a whole "
    "message)\n"
    "  Sends one COMMAND over HTTP (POST /rcan/v1/command) and prints the answer.\n"
    "  Friendly form: every --name value becomes payload parameter name (dashes become\n"
    "  underscores); values that parse as JSON (numbers, true/false, arrays) are sent as such.\n"
    "    rcan command move --linear 0.3 --angular 0 --duration-ms 1000\n"
    "    rcan command arm_move --joints '[0,0.5,0,0,0,0]'\n"
    "    rcan command chat --text 'where are you?'\n"
    "    rcan command heartbeat          (keeps a claimed session alive)\n"
    "  A whole message gets message_id, timestamp_ms and version filled in when absent.\n"
    "  Options: --ttl-ms N  --priority LOW|NORMAL|HIGH|SAFETY  --confidence X (§16 ai.confidence)\n"
    "           --scope S\n";

// `rcan command`'s words: its own options (`own`, for Options), the payload's --name value pairs
// (dashes to underscores) and the rest. "" or the usage error.
struct CommandWords {
  Args own;
  std::vector<std::pair<std::string, std::string>> params;
  std::vector<std::string> positional;
};
const std::vector<std::string> kCommandValued{"url",        "token-file", "timeout",
                                              "ca-file",    "ttl-ms",     "priority",
                                              "confidence", "scope",      "registry"};
const std::vector<std::string> kCommandFlags{"json", "insecure"};

std::string split_command_words(const Args& args, CommandWords& w) {
  for (size_t i = 0; i < args.size(); ++i) {
    const std::string& a = args[i];
    if (a.size() <= 2 || a.rfind("--", 0) != 0) {
      w.positional.push_back(a);
      continue;
    }
    std::string name = a.substr(2), value;
    bool inline_value = false;
    if (auto eq = name.find('='); eq != std::string::npos) {
      value = name.substr(eq + 1);
      name = name.substr(0, eq);
      inline_value = true;
    }
    if (std::find(kCommandFlags.begin(), kCommandFlags.end(), name) != kCommandFlags.end()) {
      w.own.push_back(a);
      continue;
    }
    if (!inline_value) {
      if (i + 1 >= args.size()) return "--" + name + " needs a value";
      value = args[++i];
    }
    if (std::find(kCommandValued.begin(), kCommandValued.end(), name) != kCommandValued.end()) {
      w.own.push_back("--" + name);
      w.own.push_back(value);
    } else {
      for (auto& ch : name)
        if (ch == '-') ch = '_';
      w.params.emplace_back(name, value);
    }
  }
  return "";
}

// A whole message's missing message_id, timestamp_ms and version (not for rcan-py's `cmd` shape).
void fill_envelope(json::Object& m) {
  if (!m.contains("message_id")) m.set("message_id", new_uuid_v4());
  if (!m.contains("timestamp_ms")) m.set("timestamp_ms", now_ms());
  if (!m.contains("version")) m.set("version", "1.0.0");
}

// The message of a JSON argument (or stdin): a whole message, its missing envelope fields filled
// in (not for rcan-py's `cmd` shape), or a payload object with an "action".
std::string message_from_json(const std::string& text, json::Value& message) {
  auto v = json::parse(text, {.max_depth = 64, .max_bytes = 1u << 20});
  if (!v.ok()) return "not JSON: " + v.error().message;
  if (!v->is_object()) return "the JSON must be an object";
  const bool whole = v->get("type") || v->get("message_type") || v->get("cmd");
  if (!whole) {
    const json::Value* act = v->get("action");
    if (!act || !act->is_string()) return "a payload object needs an \"action\"";
    client::Command c;
    c.action = act->as_string();
    for (const auto& [k, val] : v->as_object())
      if (k != "action") c.params.set(k, val);
    message = client::command_message(c, now_ms());
    return "";
  }
  json::Object m = v->as_object();
  if (v->get("cmd") == nullptr) fill_envelope(m);
  message = json::Value(std::move(m));
  return "";
}

// The message of an ACTION and its parameters (each parsed as JSON when it is, else a string);
// `heartbeat` is a HEARTBEAT message.
json::Value message_from_action(const std::string& action,
                                const std::vector<std::pair<std::string, std::string>>& params) {
  if (action == "heartbeat") {
    return json::Value(json::Object{{"version", "1.0.0"},
                                    {"message_id", new_uuid_v4()},
                                    {"type", "HEARTBEAT"},
                                    {"timestamp_ms", now_ms()},
                                    {"payload", json::Object{}}});
  }
  client::Command c;
  c.action = action;
  for (const auto& [k, val] : params) {
    auto v = json::parse(val, {.max_depth = 16, .max_bytes = 65536});
    if (v.ok())
      c.params.set(k, *v);
    else
      c.params.set(k, val);
  }
  return client::command_message(c, now_ms());
}

// --ttl-ms, --priority, --scope and --confidence onto the message; "" or the usage error.
std::string apply_envelope_options(const Options& o, json::Object& m) {
  if (o.has("ttl-ms")) {
    char* end = nullptr;
    const std::string value_text = o.get("ttl-ms");  // outlives `end`
    long long v = std::strtoll(value_text.c_str(), &end, 10);
    if (!end || *end || v < 0) return "--ttl-ms must be a non-negative integer";
    m.set("ttl_ms", static_cast<int64_t>(v));
  }
  if (o.has("priority")) m.set("priority", o.get("priority"));
  if (o.has("scope")) m.set("scope", o.get("scope"));
  if (o.has("confidence")) {
    char* end = nullptr;
    const std::string value_text = o.get("confidence");  // outlives `end`
    double c = std::strtod(value_text.c_str(), &end);
    if (!end || *end || !(c >= 0 && c <= 1)) return "--confidence must be within 0..1";
    m.set("ai", json::Object{{"confidence", c}});
  }
  return "";
}

void print_command_answer(const json::Value& message, const client::Reply& r) {
  if (r.pending()) {
    std::string id = r.payload.is_object() && r.payload.get("message_id")
                         ? brief(*r.payload.get("message_id"))
                         : r.reply_to;
    std::printf(
        "%s the command waits for a human authorization (message %s)\n"
        "  approve: rcan authorize %s --approve   deny: rcan authorize %s --deny\n",
        yellow("PENDING_AUTH").c_str(), id.c_str(), id.c_str(), id.c_str());
    return;
  }
  std::printf("%s", green(r.type.empty() ? "OK" : r.type).c_str());
  if (const json::Value* mid = message.get("message_id"); mid && mid->is_string())
    std::printf(" %s", dim(mid->as_string()).c_str());
  std::printf("\n");
  if (r.payload.is_object())
    for (const auto& [k, v] : r.payload.as_object())
      std::printf("  %-14s %s\n", k.c_str(), brief(v, 100).c_str());
}

int command_main(const Args& args) {
  if (args.empty()) {
    std::fputs(kCommandHelp, stderr);
    return kExitUsage;
  }
  if (help_requested(args, (std::string(kCommandHelp) + kNetHelp).c_str())) return 0;
  CommandWords w;
  if (std::string e = split_command_words(args, w); !e.empty()) return usage_error("command", e);
  Options o(w.own, kCommandFlags, kCommandValued);
  if (!o.ok()) return usage_error("command", o.error());
  if (w.positional.size() != 1)
    return usage_error("command", "give one ACTION, a JSON object, or - (see --help)");
  std::string err;
  client::ClientOptions co = client_options(o, true, err);
  if (!err.empty()) return usage_error("command", err);

  json::Value message;
  const std::string& first = w.positional[0];
  if (first == "-" || (!first.empty() && first[0] == '{')) {
    if (!w.params.empty())
      return usage_error("command", "parameters go inside the JSON when JSON is given");
    err = message_from_json(first == "-" ? read_stdin() : first, message);
    if (!err.empty()) return usage_error("command", err);
  } else {
    message = message_from_action(first, w.params);
  }
  err = apply_envelope_options(o, message.as_object());
  if (!err.empty()) return usage_error("command", err);
  client::Client c(co);
  auto r = c.send(message);
  if (!r.ok()) return report_error("command", r.error(), want_json(o));
  if (want_json(o))
    std::cout << json::dump(r->raw) << "\n";
  else
    print_command_answer(message, *r);
  return r->pending() ? kExitPending : kExitOk;
}

// ------------------------------------------------------------------------------------------
// stream

constexpr const char* kStreamHelp =
    "usage: rcan stream [--hz N | --no-telemetry] [--count N] [--seconds S] [--send-stdin]\n"
    "                   [--max-attempts N] [--url URL] [--token-file F] [--json]\n"
    "  Opens the node's WebSocket stream (/rcan/v1/stream, CONNECT with your token) and prints\n"
    "  live telemetry (default 2 Hz) and events (ESTOP, RESUME, AVAILABLE, PENDING_AUTH, …) until\n"
    "  Ctrl-C. On a lost connection it reconnects with backoff 1, 2, 4, 8, 16, 30 s (±0.5 s).\n"
    "  --send-stdin sends each stdin line (a JSON message or payload object with \"action\")\n"
    "  over the stream; answers are printed like events. --count/--seconds stop after that many\n"
    "  frames / seconds. --json prints every frame as one JSON line. Connection states go to "
    "stderr.\n";

std::atomic<bool> g_interrupted{false};
void on_sigint(int) { g_interrupted.store(true); }

std::string render_frame(const json::Value& v) {
  std::string type = v.get("type") && v.get("type")->is_string() ? v.get("type")->as_string() : "?";
  std::string ts = when(v.get("timestamp_ms") && v.get("timestamp_ms")->is_int()
                            ? v.get("timestamp_ms")->as_int()
                            : now_ms());
  ts = ts.size() > 11 ? ts.substr(11) : ts;
  if (type == "STREAM") {
    const json::Value* p = v.get("payload");
    std::string line = dim(ts) + " telemetry";
    if (v.get("estop_active") && v.get("estop_active")->is_bool() &&
        v.get("estop_active")->as_bool())
      line += " " + red("ESTOP");
    if (p && p->is_object()) {
      if (const json::Value* b = p->get("base"); b && b->is_object()) {
        for (const char* k : {"x", "y", "theta", "linear", "angular"})
          if (const json::Value* f = b->get(k); f && f->is_number()) {
            char buf[48];
            std::snprintf(buf, sizeof buf, " %s=%.3f", k, f->to_double());
            line += buf;
          }
      }
      for (const char* k : {"loop_count", "paused", "battery_v"})
        if (const json::Value* f = p->get(k)) line += std::string(" ") + k + "=" + brief(*f, 20);
    }
    return line;
  }
  if (type == "ERROR") {
    const json::Value* p = v.get("payload");
    std::string code = p && p->get("error_code")
                           ? brief(*p->get("error_code"))
                           : brief(v.get("name") ? *v.get("name") : json::Value());
    std::string msg = p && p->get("error") ? brief(*p->get("error"), 120) : "";
    return dim(ts) + " " + red("ERROR " + code) + " " + msg;
  }
  std::string line =
      dim(ts) + " " +
      (type == "EVENT" || type == "AVAILABLE" || type == "PENDING_AUTH" ? yellow(type)
                                                                        : bold(type));
  for (const char* k : {"event", "session_id", "reply_to", "reserved_for"})
    if (const json::Value* f = v.get(k); f && f->is_string() && !f->as_string().empty())
      line += std::string(" ") + k + "=" + f->as_string();
  if (const json::Value* p = v.get("payload"); p && p->is_object() && !p->as_object().empty())
    line += " " + brief(*p, 120);
  return line;
}

// `rcan stream`'s numbers: --hz (0: no telemetry), --count, --seconds, --max-attempts (-1: not
// given); "" or the usage error.
struct StreamLimits {
  double hz = 2;
  long count = -1, seconds = -1, attempts = -1;
};

std::string stream_limits(const Options& o, StreamLimits& l) {
  if (o.has("hz")) {
    char* end = nullptr;
    const std::string value_text = o.get("hz");  // outlives `end`
    l.hz = std::strtod(value_text.c_str(), &end);
    if (!end || *end || !(l.hz >= 0.2 && l.hz <= 50)) return "--hz must be within 0.2..50";
  }
  if (o.has("no-telemetry")) l.hz = 0;
  for (auto [name, dst] : {std::pair<const char*, long*>{"count", &l.count},
                           {"seconds", &l.seconds},
                           {"max-attempts", &l.attempts}}) {
    if (!o.has(name)) continue;
    char* end = nullptr;
    const std::string value_text = o.get(name);  // outlives `end`
    *dst = std::strtol(value_text.c_str(), &end, 10);
    if (!end || *end || *dst < 1) return std::string("--") + name + " must be a positive integer";
  }
  return "";
}

// --send-stdin: each stdin line, a whole message (envelope filled in) or a payload with an
// "action", sent on the stream until `done` or the end of stdin; other lines are skipped, said.
void relay_stdin(client::Stream& stream, const std::atomic<bool>& done) {
  std::string line;
  while (!done.load() && std::getline(std::cin, line)) {
    if (line.empty()) continue;
    auto v = json::parse(line, {.max_depth = 64, .max_bytes = 1u << 20});
    if (!v.ok() || !v->is_object()) {
      std::fprintf(stderr, "rcan stream: skipped a line that is not a JSON object\n");
      continue;
    }
    if (!v->get("type") && !v->get("cmd")) {
      const json::Value* act = v->get("action");
      if (!act || !act->is_string()) {
        std::fprintf(stderr, "rcan stream: skipped a payload without \"action\"\n");
        continue;
      }
      client::Command c;
      c.action = act->as_string();
      for (const auto& [k, val] : v->as_object())
        if (k != "action") c.params.set(k, val);
      stream.send_command(c);
    } else {
      json::Object m = v->as_object();
      if (!v->get("cmd")) fill_envelope(m);
      stream.send(json::Value(std::move(m)));
    }
  }
}

int stream_main(const Args& args) {
  if (help_requested(args, (std::string(kStreamHelp) + kNetHelp).c_str())) return 0;
  Options* o;
  client::ClientOptions co;
  int rc = 0;
  if (!setup("stream", args, {"no-telemetry", "send-stdin"},
             {"hz", "count", "seconds", "max-attempts"}, true, 0, o, co, rc))
    return rc;
  StreamLimits lim;
  if (std::string e = stream_limits(*o, lim); !e.empty()) return usage_error("stream", e);
  bool json_out = want_json(*o);
  std::atomic<long> frames{0};
  client::StreamOptions so;
  so.client = co;
  so.telemetry_hz = lim.hz;
  so.max_attempts = static_cast<int>(lim.attempts);
  client::Stream* sp = nullptr;
  so.on_message = [&](const json::Value& v) {
    if (json_out)
      std::cout << json::dump(v) << "\n" << std::flush;
    else
      std::cout << render_frame(v) << "\n" << std::flush;
    if (lim.count > 0 && ++frames >= lim.count && sp) sp->stop();
  };
  so.on_state = [&](const std::string& s) { std::fprintf(stderr, "rcan stream: %s\n", s.c_str()); };
  client::Stream stream(so);
  sp = &stream;
  struct sigaction sa {};
  sa.sa_handler = on_sigint;
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  auto started = steady_now();
  std::atomic<bool> done{false};
  std::thread watchdog([&] {
    while (!done.load()) {
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
      if (g_interrupted.load() ||
          (lim.seconds > 0 && steady_now() - started >= std::chrono::seconds(lim.seconds))) {
        stream.stop();
        return;
      }
    }
  });
  std::thread reader;
  if (o->has("send-stdin")) reader = std::thread([&] { relay_stdin(stream, done); });
  client::ClientError end = stream.run();
  done.store(true);
  watchdog.join();
  int code = end.code == "STOPPED" ? kExitOk : report_error("stream", end, false);
  if (reader.joinable()) {
    // The stdin reader may be blocked in a read that cannot be interrupted: end the process
    // here, before the stream it uses goes out of scope.
    std::cout.flush();
    std::fflush(nullptr);
    std::_Exit(code);
  }
  return code;
}

// ------------------------------------------------------------------------------------------
// discover

constexpr const char* kDiscoverHelp =
    "usage: rcan discover [--hosts a,b:8081,https://c] [--timeout MS] [--no-mdns] [--json]\n"
    "                     [--ca-file F] [--insecure]\n"
    "  Finds RCAN nodes: browses _rcan._tcp over mDNS (through the Avahi daemon) for --timeout\n"
    "  (default 2000 ms) and probes each given host with GET /rcan/v1/status (default port\n"
    "  8080). Each mDNS answer is confirmed the same way. Without --hosts, $RCAN_URL (else\n"
    "  http://127.0.0.1:8080) is probed too, so the robot on this machine is found even\n"
    "  without mDNS. Prints NAME, URL, RURI, STATUS (available, claimed, estop) and SOURCE.\n"
    "  Exit: 0 at least one robot found, 1 none, 2 usage.\n";

int discover_main(const Args& args) {
  if (help_requested(args, kDiscoverHelp)) return 0;
  Options o(args, {"json", "insecure", "no-mdns"},
            {"hosts", "timeout", "ca-file", "url", "token-file"});
  if (!o.ok()) return usage_error("discover", o.error());
  if (!o.positional().empty())
    return usage_error("discover", "unexpected argument " + o.positional()[0]);
  client::DiscoverOptions d;
  if (o.has("timeout")) {
    char* end = nullptr;
    const std::string value_text = o.get("timeout");  // outlives `end`
    long v = std::strtol(value_text.c_str(), &end, 10);
    if (!end || *end || v < 100 || v > 600000)
      return usage_error("discover", "--timeout must be 100..600000 ms");
    d.timeout_ms = static_cast<int>(v);
  }
  d.mdns = !o.has("no-mdns");
  d.ca_file = o.get("ca-file");
  d.insecure = o.has("insecure");
  d.hosts = split_list(o.get("hosts"));
  if (!o.has("hosts")) {
    std::string url = o.get("url");
    if (url.empty())
      if (const char* env = std::getenv("RCAN_URL"); env && *env) url = env;
    d.hosts.push_back(url.empty() ? "http://127.0.0.1:8080" : url);
  }
  auto rep = client::discover(d);
  if (!rep.mdns_error.empty() && d.mdns)
    std::fprintf(stderr, "rcan discover: mDNS: %s\n", rep.mdns_error.c_str());
  if (want_json(o)) {
    json::Array list;
    for (const auto& r : rep.robots) {
      json::Object txt;
      for (const auto& [k, v] : r.txt) txt.set(k, v);
      json::Object e{{"name", r.name},           {"url", r.url},
                     {"ruri", r.ruri},           {"model", r.model},
                     {"version", r.version},     {"status", r.status_word},
                     {"source", r.source},       {"reachable", r.reachable},
                     {"interface", r.interface}, {"txt", txt}};
      list.push_back(json::Value(std::move(e)));
    }
    json::Object out{{"robots", list}};
    if (!rep.mdns_error.empty()) out.set("mdns_error", rep.mdns_error);
    std::cout << json::dump(json::Value(std::move(out))) << "\n";
  } else if (rep.robots.empty()) {
    std::printf("no RCAN robot found\n");
  } else {
    std::vector<std::vector<std::string>> rows;
    for (const auto& r : rep.robots) {
      std::string st = r.status_word.empty() ? "-" : r.status_word;
      st = st == "estop"       ? red(st)
           : st == "available" ? green(st)
           : st == "claimed"   ? yellow(st)
                               : st;
      rows.push_back({r.name, r.url + (r.reachable ? "" : " (unreachable)"), r.ruri, st, r.source});
    }
    print_table({"NAME", "URL", "RURI", "STATUS", "SOURCE"}, rows);
  }
  return rep.robots.empty() ? kExitRefused : kExitOk;
}

const Registration kStatus{"status", "show a node's status, ESTOP state and sessions",
                           &status_main};
const Registration kClaim{"claim", "claim control of a robot", &claim_main};
const Registration kRelease{"release", "release control", &release_main};
const Registration kHandoff{"handoff", "hand control to another user", &handoff_main};
const Registration kEstop{"estop", "latch ESTOP (any authenticated role)", &estop_main};
const Registration kResume{"resume", "clear a latched ESTOP (LEASEE or above)", &resume_main};
const Registration kCommand{"command", "send a command (friendly form or raw JSON)", &command_main};
const Registration kStream{"stream", "live telemetry and events over the WebSocket stream",
                           &stream_main};
const Registration kDiscover{"discover", "find robots via mDNS and host probing", &discover_main};

}  // namespace
}  // namespace rcan::cli
