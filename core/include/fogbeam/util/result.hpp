// fogbeam — a small result type with std::expected's member names.
//
// GCC 12 ships no std::expected; this is the one place that defines the
// project's error-or-value type (house style: written once, in core).
// Error policy: bugs abort (assert / std::terminate), expected failures such as
// a malformed file return Error, routine events (a dropped packet) are counted.
#pragma once

#include <cassert>
#include <string>
#include <utility>
#include <variant>

namespace fogbeam {

/// A failure that a caller can report to a person: what went wrong and where.
/// `message` is complete on its own, e.g. "low.ies:14: expected 37 vertical angles, found 36".
struct Error {
  std::string message;
};

/// Build an Error whose message starts with "file:line: " (line 0 omits the line).
[[nodiscard]] inline Error fileError(const std::string& file, std::size_t line, const std::string& what) {
  if (line == 0) return Error{file + ": " + what};
  return Error{file + ":" + std::to_string(line) + ": " + what};
}

/// Holds either a T or an Error. Member names follow std::expected (C++23).
/// Thread-safety: a value type; const access from several threads is safe.
template <class T>
class [[nodiscard]] Result {
 public:
  Result(T value) : v_(std::move(value)) {}          // NOLINT(google-explicit-constructor)
  Result(Error error) : v_(std::move(error)) {}      // NOLINT(google-explicit-constructor)

  [[nodiscard]] bool has_value() const noexcept { return v_.index() == 0; }
  explicit operator bool() const noexcept { return has_value(); }

  T& value() & { assert(has_value()); return std::get<0>(v_); }
  const T& value() const& { assert(has_value()); return std::get<0>(v_); }
  T&& value() && { assert(has_value()); return std::get<0>(std::move(v_)); }
  T* operator->() { return &value(); }
  const T* operator->() const { return &value(); }
  T& operator*() & { return value(); }
  const T& operator*() const& { return value(); }

  const Error& error() const { assert(!has_value()); return std::get<1>(v_); }

 private:
  std::variant<T, Error> v_;
};

/// Result of an operation that yields nothing on success.
struct Ok {};
using Status = Result<Ok>;

}  // namespace fogbeam
