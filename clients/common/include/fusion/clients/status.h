// Result of an operation on bad-input-prone data (files, the network): callers must look at it.
#pragma once

#include <string>
#include <utility>

namespace fusion::clients {

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

}  // namespace fusion::clients
