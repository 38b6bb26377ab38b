// Shared plumbing for the verbs that talk to a node through rcan::client: connection
// options, output (tables, colour on a terminal, --json), errors and exit codes.
//
// Connection options (every networked verb):
//   --url URL          node URL (default $RCAN_URL, else http://127.0.0.1:8080); an RRN or a
//                      RURI instead is resolved through the registry (--registry URL, else
//                      $RCAN_REGISTRY; a RURI's own registry host over https otherwise) to
//                      the first endpoint the robot published
//   --token-file F     bearer token file (default $RCAN_TOKEN_FILE)
//   --timeout MS       per request (default 10000)
//   --ca-file F        PEM trust anchors for https/wss;  --insecure skips verification
//   --json             machine output (the node's JSON, one document or JSON lines)
//
// Exit codes: 0 done; 1 the node refused or answered negatively (its error is printed);
// 2 usage error; 3 the node could not be reached (connection, TLS, timeout); 4 accepted but
// waiting for a human authorization (HTTP 202 PENDING_AUTH).
#pragma once

#include <string>
#include <vector>

#include "cli.h"
#include "rcan/client.h"

namespace rcan::cli {

inline constexpr int kExitOk = 0;
inline constexpr int kExitRefused = 1;
inline constexpr int kExitUsage = 2;
inline constexpr int kExitUnreachable = 3;
inline constexpr int kExitPending = 4;

// Option names every networked verb accepts (flags and valued).
const std::vector<std::string>& net_flags();
const std::vector<std::string>& net_valued();
// The help text block describing them.
extern const char* const kNetHelp;

// Where the registry says the robot named by `rrn_or_ruri` answers (its first endpoint).
// `registry` empty: $RCAN_REGISTRY, else https://<the RURI's registry> (an RRN then needs
// $RCAN_REGISTRY or --registry). Defined in registry_cmd.cpp.
Result<std::string> robot_url_from_registry(const std::string& rrn_or_ruri,
                                            const std::string& registry);

// Builds client options from parsed options and the environment. `need_token`: a missing
// token is a usage error (returned in `err`).
client::ClientOptions client_options(const Options& o, bool need_token, std::string& err);

bool want_json(const Options& o);
bool use_colour();
// ANSI styles, empty when colour is off.
std::string bold(const std::string& s);
std::string red(const std::string& s);
std::string green(const std::string& s);
std::string yellow(const std::string& s);
std::string dim(const std::string& s);

// Prints an error (JSON body with --json, else one readable line on stderr) and returns
// the exit code for it (1 refused, 3 unreachable).
int report_error(const std::string& verb, const client::ClientError& e, bool json);

// A simple left-aligned table; column widths from the content (ANSI-aware).
void print_table(const std::vector<std::string>& header,
                 const std::vector<std::vector<std::string>>& rows);

// "1.5s ago", "3m ago", "2026-11-22 02:33:01Z" for a wall-clock ms.
std::string when(int64_t ms);
// A compact one-line rendering of a JSON value (strings unquoted).
std::string brief(const json::Value& v, size_t max = 80);
// Returns true and prints `help` when args contain --help/-h.
bool help_requested(const Args& args, const char* help);

}  // namespace rcan::cli
