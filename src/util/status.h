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

// The failures a caller reacts to without reading the message; every other error is kOther.
// The bundle-adjustment engine sets them (as Ceres's TerminationType and COLMAP's
// BundleAdjustmentSummary type theirs), and the front ends add their advice by kind.
enum class ErrorKind {
  kOther,
  // Parameters the observations and priors do not determine: a rank-deficient covariance, a free
  // direction (gauge).
  kNotDetermined,
  // The initial state gives a non-finite residual (a point behind the source, a wrong start).
  kNonFiniteInitialState,
};

class Status {
 public:
  Status() = default;  // OK
  static Status Ok() { return Status(); }
  static Status Error(std::string message, ErrorKind kind = ErrorKind::kOther) {
    return Status(std::move(message), kind);
  }

  bool ok() const { return !message_.has_value(); }
  // kOther for ok() and for errors without a kind.
  ErrorKind kind() const { return kind_; }
  // The one-line reason; empty when ok().
  const std::string& message() const {
    static const std::string kEmpty;
    return message_ ? *message_ : kEmpty;
  }
  // Returns a copy whose message is prefixed with `context: `.
  Status WithContext(const std::string& context) const {
    return ok() ? *this : Status(context + ": " + *message_, kind_);
  }

 private:
  Status(std::string m, ErrorKind kind) : message_(std::move(m)), kind_(kind) {}
  std::optional<std::string> message_;
  ErrorKind kind_ = ErrorKind::kOther;
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
