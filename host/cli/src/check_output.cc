#include <fmt/core.h>

#include "commands.h"
#include "palpa/io/file_safety.h"

namespace palpa::cli {

int CheckOutput(const char* command, const std::string& path, const std::vector<std::string>& inputs) {
  auto ok = io::CheckOutputTarget(path, inputs);
  if (ok) return kExitOk;
  fmt::print(stderr, "palpa {}: {}\n", command, ok.error().message);
  return ok.error().fault == io::Fault::kBadInput ? kExitBadInput : kExitIo;
}

}  // namespace palpa::cli
