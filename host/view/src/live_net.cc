// Live backend: polls palpad's authenticated status channel (palpa/net/client.h, issue 7) from
// one background thread and keeps the latest record. The page reads only that record, so a slow
// browser or many tabs never reach palpad: it sees one STATUS exchange per period, handled on its
// non-RT side from counters the servo loop publishes through its wait-free telemetry ring.
#include <atomic>
#include <mutex>
#include <thread>

#include <nlohmann/json.hpp>

#include "palpa/net/client.h"
#include "palpa/view/live.h"

namespace palpa::view {
namespace {

class NetLiveFeed final : public LiveFeed {
 public:
  NetLiveFeed(std::string endpoint_text, net::Endpoint endpoint, net::Key key, std::chrono::milliseconds period)
      : endpoint_text_(std::move(endpoint_text)),
        endpoint_(std::move(endpoint)),
        key_(key),
        period_(period),
        thread_([this](std::stop_token stop) { Poll(stop); }) {}

  ~NetLiveFeed() override {
    thread_.request_stop();
    thread_.join();
  }

  std::string LatestJson() const override {
    std::lock_guard lock(mutex_);
    nlohmann::json j;
    j["endpoint"] = endpoint_text_;
    j["connected"] = connected_;
    j["polls"] = polls_;
    j["errors"] = errors_;
    j["last_error"] = last_error_;
    if (status_json_.empty()) {
      j["status"] = nullptr;
      j["age_ms"] = nullptr;
    } else {
      j["status"] = nlohmann::json::parse(status_json_, nullptr, false);
      j["age_ms"] =
          std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::steady_clock::now() - status_at_).count();
    }
    return j.dump();
  }

  std::string Endpoint() const override { return endpoint_text_; }

  Counts PollCounts() const override {
    std::lock_guard lock(mutex_);
    return {polls_, errors_, last_error_};
  }

 private:
  void Poll(const std::stop_token& stop) {
    auto next = std::chrono::steady_clock::now();
    while (!stop.stop_requested()) {
      auto status = net::FetchStatus(endpoint_, key_, std::chrono::milliseconds(500));
      {
        std::lock_guard lock(mutex_);
        ++polls_;
        connected_ = status.has_value();
        if (status) {
          status_json_ = net::ToJson(*status);
          status_at_ = std::chrono::steady_clock::now();
        } else {
          ++errors_;
          last_error_ = status.error().message;
        }
      }
      next += period_;
      const auto now = std::chrono::steady_clock::now();
      if (next < now) next = now;  // behind (palpad down, slow network): no burst to catch up
      std::this_thread::sleep_until(next);
    }
  }

  const std::string endpoint_text_;
  const net::Endpoint endpoint_;
  const net::Key key_;
  const std::chrono::milliseconds period_;
  mutable std::mutex mutex_;
  bool connected_ = false;
  std::uint64_t polls_ = 0, errors_ = 0;
  std::string last_error_;
  std::string status_json_;
  std::chrono::steady_clock::time_point status_at_;
  std::jthread thread_;  // last: starts after every member it uses is constructed
};

}  // namespace

bool LiveAvailable() { return true; }

std::string LiveUnavailableReason() { return ""; }

std::expected<std::unique_ptr<LiveFeed>, Error> StartLiveFeed(const std::string& endpoint, const std::string& key_file,
                                                              std::chrono::milliseconds period) {
  auto to = net::ParseEndpoint(endpoint);
  if (!to) return std::unexpected(Error{to.error().message});
  auto key = net::ReadKeyFile(key_file);
  if (!key) return std::unexpected(Error{key.error().message});
  return std::make_unique<NetLiveFeed>(endpoint, std::move(*to), *key, period);
}

}  // namespace palpa::view
