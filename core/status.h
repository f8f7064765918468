// Internal error type. Inside the engine a failure is thrown as lodstream::Failure carrying the status
// the user will see; the public entry points (stream/api.cpp) catch it and return a Result.
#pragma once

#include <stdexcept>
#include <string>

#include "lodstream/lodstream.h"

namespace lodstream {

class Failure : public std::runtime_error {
 public:
  Failure(Status status, const std::string& message) : std::runtime_error(message), status_(status) {}
  Status status() const { return status_; }

 private:
  Status status_;
};

[[noreturn]] inline void fail(Status status, const std::string& message) { throw Failure(status, message); }

}  // namespace lodstream
