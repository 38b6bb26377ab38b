// Result<T>: a value or an Error, the way errors travel through librcan.
//
// librcan never throws across module lines. Every fallible operation returns
// Result<T> (or Status for operations without a value). An Error carries a code
// from the protocol's error catalogue (rcan/errors.h), a human-readable message,
// and an optional field name that points at the offending input.
#pragma once

#include <string>
#include <utility>
#include <variant>

#include "rcan/error_code.h"

namespace rcan {

struct Error {
  ErrorCode code = ErrorCode::kInternal;
  std::string message;  // one sentence, for humans
  std::string field;    // offending field or segment, empty when not applicable
  std::string reason;   // machine-readable sub-reason (e.g. "estop_active"), may be empty

  Error() = default;
  Error(ErrorCode c, std::string msg, std::string fld = {}, std::string rsn = {})
      : code(c), message(std::move(msg)), field(std::move(fld)), reason(std::move(rsn)) {}
};

// E is Error everywhere in librcan; the client library uses its own error type
// (rcan::client::Result<T> = Result<T, client::ClientError>, include/rcan/client.h).
template <typename T, typename E = Error>
class [[nodiscard]] Result {
 public:
  Result(T value)
      : v_(std::in_place_index<0>, std::move(value)) {}  // NOLINT(google-explicit-constructor)
  Result(E err)
      : v_(std::in_place_index<1>, std::move(err)) {}  // NOLINT(google-explicit-constructor)

  bool ok() const { return v_.index() == 0; }
  explicit operator bool() const { return ok(); }

  T& value() & { return std::get<0>(v_); }
  const T& value() const& { return std::get<0>(v_); }
  T&& value() && { return std::get<0>(std::move(v_)); }
  T* operator->() { return &std::get<0>(v_); }
  const T* operator->() const { return &std::get<0>(v_); }
  T& operator*() & { return std::get<0>(v_); }
  const T& operator*() const& { return std::get<0>(v_); }

  const E& error() const& { return std::get<1>(v_); }
  E&& error() && { return std::get<1>(std::move(v_)); }

 private:
  std::variant<T, E> v_;
};

// Status: success, or an Error.
class [[nodiscard]] Status {
 public:
  Status() = default;
  Status(Error err) : err_(std::move(err)), ok_(false) {}  // NOLINT(google-explicit-constructor)
  static Status Ok() { return Status(); }

  bool ok() const { return ok_; }
  explicit operator bool() const { return ok_; }
  const Error& error() const { return err_; }

 private:
  Error err_;
  bool ok_ = true;
};

}  // namespace rcan
