// Error type shared by the palpa_field API (returned through std::expected; nothing throws).
#pragma once

#include <string>

namespace palpa::field {

// A human-readable failure description. Messages about a file start with the file name, and with
// "FILE:LINE:" when a particular line is at fault.
struct Error {
  std::string message;
};

}  // namespace palpa::field
