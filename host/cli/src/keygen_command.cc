// palpa keygen (issue 7; docs/upload.md): a new shared key for palpad --listen.
#include <sys/stat.h>

#include <fmt/core.h>

#include "commands.h"
#include "palpa/net/client.h"

namespace palpa::cli {

int RunKeygen(const std::string& output, bool force) {
  // The user's choices are refused with 2 (a device or directory, an existing key without
  // --force); anything failing after that is the file system's (a read-only directory): 1.
  if (const int refused = CheckOutput("keygen", output); refused != kExitOk) return refused;
  struct stat st {};
  if (!force && ::lstat(output.c_str(), &st) == 0) {
    fmt::print(stderr, "palpa keygen: {}: exists; refusing to overwrite a key (--force replaces it)\n", output);
    return kExitBadInput;
  }
  if (auto written = net::WriteNewKeyFile(output, force); !written) {
    fmt::print(stderr, "palpa keygen: {}\n", written.error().message);
    return kExitIo;
  }
  fmt::print(
      "palpa keygen: wrote a 32-byte key to {} (mode 0600); copy it to the controller over a secure "
      "channel (palpad --key-file)\n",
      output);
  return kExitOk;
}

}  // namespace palpa::cli
