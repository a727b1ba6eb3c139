// palpa keygen (issue 7; docs/upload.md): a new shared key for palpad --listen.
#include <fmt/core.h>

#include "commands.h"
#include "palpa/net/client.h"

namespace palpa::cli {

int RunKeygen(const std::string& output, bool force) {
  if (auto written = net::WriteNewKeyFile(output, force); !written) {
    fmt::print(stderr, "palpa keygen: {}\n", written.error().message);
    return kExitBadInput;
  }
  fmt::print(
      "palpa keygen: wrote a 32-byte key to {} (mode 0600); copy it to the controller over a secure "
      "channel (palpad --key-file)\n",
      output);
  return kExitOk;
}

}  // namespace palpa::cli
