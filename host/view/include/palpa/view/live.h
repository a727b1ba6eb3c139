// Live view (`palpa view --connect`): follows a running palpad through its authenticated,
// read-only status channel (issue 7) from a background thread, and keeps the latest record for
// the page. The servo loop is never touched: palpad's status comes out of its wait-free telemetry
// ring on its own non-RT side. The backend is chosen by CMake: the status-channel client when
// the tree has it (live_net.cc), else a stub that says live view is not in this build. Non-RT.
#pragma once

#include <chrono>
#include <cstdint>
#include <expected>
#include <memory>
#include <string>

#include "palpa/field/error.h"

namespace palpa::view {

using Error = field::Error;

class LiveFeed {
 public:
  virtual ~LiveFeed() = default;
  /// The latest record as one JSON object: {"connected": bool, "polls": n, "errors": n,
  /// "last_error": "...", "age_ms": ms since it arrived, "status": {...palpad's status...}|null}.
  /// Thread-safe; never blocks on the network.
  [[nodiscard]] virtual std::string LatestJson() const = 0;
  /// Status requests made and how many failed, since start.
  struct Counts {
    std::uint64_t polls = 0;
    std::uint64_t errors = 0;
    std::string last_error;  ///< the latest failure's message ("" if none)
  };
  [[nodiscard]] virtual Counts PollCounts() const = 0;
  /// The endpoint polled, HOST:PORT.
  [[nodiscard]] virtual std::string Endpoint() const = 0;
};

/// True when this build has the status-channel client.
bool LiveAvailable();

/// Why live view is unavailable, when it is ("" otherwise).
std::string LiveUnavailableReason();

/// Starts polling `endpoint` (HOST:PORT) every `period` (≤ 33 ms for ≥ 30 Hz) with the key read
/// from `key_file`. Errors: live view not in this build; unreadable or malformed key file; bad
/// endpoint. A palpad that is not (yet) running is not an error: the feed reports it and retries.
std::expected<std::unique_ptr<LiveFeed>, Error> StartLiveFeed(const std::string& endpoint, const std::string& key_file,
                                                              std::chrono::milliseconds period);

}  // namespace palpa::view
