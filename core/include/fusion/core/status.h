// The error type of the layers above core: the service and the client tools return a Status
// (or a StatusOr<T>) from everything that can fail on bad input (files, configuration, the
// network), and callers must look at it. Core itself reports broken preconditions by exception
// and the outcome of a map operation by its MapStatus; it does not use this type. Header-only,
// no dependencies (fusion::status), so tools that do not link core can use it.
#pragma once

#include <optional>
#include <string>
#include <utility>

namespace fusion {

class [[nodiscard]] Status {
 public:
  Status() = default;
  static Status Ok() { return Status(); }
  static Status Error(std::string message) { return Status(std::move(message)); }

  [[nodiscard]] bool ok() const { return !failed_; }
  [[nodiscard]] const std::string& message() const { return message_; }

  // Prefixes the message with context ("reading x.pcd: ..."); OK stays OK.
  [[nodiscard]] Status WithContext(const std::string& context) const {
    return ok() ? *this : Error(context + ": " + message_);
  }

 private:
  explicit Status(std::string message) : failed_(true), message_(std::move(message)) {}
  bool failed_ = false;
  std::string message_;
};

// A value, or the Status that says why there is none.
template <class T>
class [[nodiscard]] StatusOr {
 public:
  StatusOr(T value) : value_(std::move(value)) {}  // NOLINT: implicit, as `return value;`
  StatusOr(Status status) : status_(std::move(status)) {  // NOLINT: as `return Status::Error(..)`
    if (status_.ok()) status_ = Status::Error("StatusOr built from an OK status without a value");
  }

  [[nodiscard]] bool ok() const { return value_.has_value(); }
  [[nodiscard]] const Status& status() const { return status_; }
  // Only when ok().
  [[nodiscard]] T& value() { return *value_; }
  [[nodiscard]] const T& value() const { return *value_; }
  T& operator*() { return *value_; }
  const T& operator*() const { return *value_; }
  T* operator->() { return &*value_; }
  const T* operator->() const { return &*value_; }

 private:
  std::optional<T> value_;
  Status status_;
};

}  // namespace fusion
