// carmba's error convention.
//
// CHECK() is for programmer bugs only. Bad data and failed numerics are reported through a
// Status that carries a one-line reason naming the file, line or key and what was expected
// (Ceres returns bool + message; COLMAP returns std::optional). A batch survives one bad data set
// and records its Status.
#pragma once

#include <optional>
#include <string>
#include <utility>

namespace carmba {

class Status {
 public:
  Status() = default;  // OK
  static Status Ok() { return Status(); }
  static Status Error(std::string message) { return Status(std::move(message)); }

  bool ok() const { return !message_.has_value(); }
  // The one-line reason; empty when ok().
  const std::string& message() const {
    static const std::string kEmpty;
    return message_ ? *message_ : kEmpty;
  }
  // Returns a copy whose message is prefixed with `context: `.
  Status WithContext(const std::string& context) const {
    return ok() ? *this : Status(context + ": " + *message_);
  }

 private:
  explicit Status(std::string m) : message_(std::move(m)) {}
  std::optional<std::string> message_;
};

// A value or an error. Accessing value() of an error is a programmer bug.
template <typename T>
class StatusOr {
 public:
  StatusOr(T value) : value_(std::move(value)) {}  // NOLINT: implicit by design
  StatusOr(Status status) : status_(std::move(status)) {}  // NOLINT
  bool ok() const { return status_.ok(); }
  const Status& status() const { return status_; }
  const T& value() const& { return *value_; }
  T& value() & { return *value_; }
  T&& value() && { return std::move(*value_); }
  const T& operator*() const { return *value_; }
  const T* operator->() const { return &*value_; }
  T* operator->() { return &*value_; }

 private:
  Status status_;
  std::optional<T> value_;
};

}  // namespace carmba

#define CARMBA_RETURN_IF_ERROR(expr)        \
  do {                                      \
    ::carmba::Status _carmba_s = (expr);    \
    if (!_carmba_s.ok()) return _carmba_s;  \
  } while (0)
