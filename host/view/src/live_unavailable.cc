// Live view stub: this build has no status-channel client (shared/net, issue 7).
#include "palpa/view/live.h"

namespace palpa::view {

bool LiveAvailable() { return false; }

std::string LiveUnavailableReason() {
  return "live view is not available in this build: palpa was built without the authenticated status channel "
         "client (shared/net, issue 7)";
}

std::expected<std::unique_ptr<LiveFeed>, Error> StartLiveFeed(const std::string&, const std::string&,
                                                              std::chrono::milliseconds) {
  return std::unexpected(Error{LiveUnavailableReason()});
}

}  // namespace palpa::view
