#include <filesystem>
#include <system_error>

#include <fmt/core.h>

#include "commands.h"
#include "palpa/io/file_safety.h"

namespace palpa::cli {

bool SamePath(const std::string& a, const std::string& b) {
  if (a == b) return true;
  // An error leaves an empty path: two failures must not compare equal.
  const auto resolve = [](const std::string& path) {
    std::error_code error;
    std::filesystem::path out = std::filesystem::absolute(path, error);
    if (!error) out = std::filesystem::weakly_canonical(out, error);
    return error ? std::filesystem::path() : out;
  };
  const std::filesystem::path x = resolve(a), y = resolve(b);
  return !x.empty() && x == y;
}

int CheckOutput(const char* command, const std::string& path, const std::vector<std::string>& inputs) {
  auto ok = io::CheckOutputTarget(path, inputs);
  if (ok) return kExitOk;
  fmt::print(stderr, "palpa {}: {}\n", command, ok.error().message);
  return ok.error().fault == io::Fault::kBadInput ? kExitBadInput : kExitIo;
}

}  // namespace palpa::cli
