// palpa view (issue 11, docs/view.md): serves the browser view of a field — its zero
// iso-surface, a replay of a palpad run (--trace) or a running palpad (--connect).
#include <pthread.h>
#include <signal.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <thread>

#include <fmt/core.h>

#include "commands.h"
#include "palpa/mesh/field_file.h"
#include "palpa/mesh/iso_surface.h"
#include "palpa/view/assets.h"
#include "palpa/view/live.h"
#include "palpa/view/server.h"

namespace palpa::cli {
namespace {

// "HOST:PORT" or "[V6]:PORT" → host, port. False if malformed.
bool SplitHostPort(const std::string& s, std::string& host, int& port) {
  const auto colon = s.rfind(':');
  if (colon == std::string::npos || colon == 0 || colon + 1 == s.size()) return false;
  host = s.substr(0, colon);
  if (host.size() >= 2 && host.front() == '[' && host.back() == ']') host = host.substr(1, host.size() - 2);
  const std::string p = s.substr(colon + 1);
  if (p.size() > 5 || p.find_first_not_of("0123456789") != std::string::npos) return false;
  port = std::stoi(p);
  return !host.empty() && port <= 65535;
}

bool IsLoopback(const std::string& host) { return host == "localhost" || host == "::1" || host.starts_with("127."); }

}  // namespace

int RunView(const ViewArgs& args) {
  // SIGINT/SIGTERM go to one waiting thread, which stops the server; every other thread
  // (the live poller, httplib's pool) starts after this and inherits them blocked.
  sigset_t stop_signals;
  sigemptyset(&stop_signals);
  sigaddset(&stop_signals, SIGINT);
  sigaddset(&stop_signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &stop_signals, nullptr);

  std::string host;
  int port = 0;
  if (!SplitHostPort(args.bind, host, port)) {
    fmt::print(stderr, "palpa view: --bind expects HOST:PORT (e.g. 127.0.0.1:8080), got '{}'\n", args.bind);
    return kExitBadInput;
  }
  view::ViewContent content;
  content.field_path = args.field;
  auto field = mesh::LoadField(args.field);  // v2 read in place
  if (!field) {
    fmt::print(stderr, "palpa view: {}\n", field.error().message);
    return kExitBadInput;
  }
  content.field.emplace(std::move(*field));
  auto surface = mesh::ExtractZeroSurface(content.field->view());
  if (!surface) {
    fmt::print(stderr, "palpa view: {}: {}\n", args.field, surface.error().message);
    return kExitBadInput;
  }
  content.surface = std::move(*surface);
  if (!args.trace.empty()) {
    auto trace = view::ReadTrace(args.trace);
    if (!trace) {
      fmt::print(stderr, "palpa view: {}\n", trace.error().message);
      return kExitBadInput;
    }
    content.trace = std::move(*trace);
  }
  if (!args.connect.empty()) {
    content.live_endpoint = args.connect;
    if (args.key_file.empty()) {
      fmt::print(stderr, "palpa view: --connect needs --key-file (the key palpa keygen wrote)\n");
      return kExitBadInput;
    }
    // 25 ms: 40 Hz, above the 30 fps the page draws at.
    auto live = view::StartLiveFeed(args.connect, args.key_file, std::chrono::milliseconds(25));
    if (!live) {
      fmt::print(stderr, "palpa view: --connect {}: {}\n", args.connect, live.error().message);
      return kExitBadInput;
    }
    content.live = std::move(*live);
  }
  auto dir = view::FindAssetDir(args.assets);
  if (!dir) {
    fmt::print(stderr, "palpa view: {}\n", dir.error().message);
    return kExitIo;
  }
  auto assets = view::LoadAssets(*dir);
  if (!assets) {
    fmt::print(stderr, "palpa view: {}\n", assets.error().message);
    return kExitIo;
  }
  const std::size_t triangles = content.surface.faces.size();

  const view::LiveFeed* live = content.live.get();  // owned by the server's content below
  const auto started = std::chrono::steady_clock::now();
  view::ViewServer server(std::move(content), std::move(*assets));
  const auto bound = server.Bind(host, port);
  if (!bound) {
    fmt::print(stderr, "palpa view: {}\n", bound.error().message);
    return kExitIo;
  }
  if (!IsLoopback(host))
    fmt::print(stderr,
               "palpa view: warning: serving on {} (not loopback): anyone who can reach this address can see the "
               "field and the run\n",
               host);
  const std::string url_host = host.find(':') != std::string::npos ? "[" + host + "]" : host;
  fmt::print("palpa view: {} ({} triangles{}{}) at http://{}:{}/\n", args.field, triangles,
             args.trace.empty() ? "" : ", replay " + args.trace, args.connect.empty() ? "" : ", live " + args.connect,
             url_host == "0.0.0.0" ? "127.0.0.1" : url_host, *bound);
  std::fflush(stdout);

  std::thread waiter([&server, stop_signals] {
    int sig = 0;
    sigwait(&stop_signals, &sig);
    server.Stop();
  });
  const bool ok = server.Run();
  // Run returned without a signal (listener failure): wake the waiter so it can be joined.
  pthread_kill(waiter.native_handle(), SIGTERM);
  waiter.join();
  if (live != nullptr) {
    // One line for `palpa bench latency --with-viewer` (and the curious): how hard palpad was polled.
    const auto counts = live->PollCounts();
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
    fmt::print(stderr, "palpa view: live: {} status polls ({} failed) in {:.2f} s, {:.1f} per second\n", counts.polls,
               counts.errors, s, static_cast<double>(counts.polls) / std::max(s, 1e-9));
    if (!counts.last_error.empty()) fmt::print(stderr, "palpa view: live: last failure: {}\n", counts.last_error);
  }
  return ok ? kExitOk : kExitIo;
}

}  // namespace palpa::cli
