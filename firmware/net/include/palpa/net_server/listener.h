// palpad's upload listener (issue 7; docs/upload.md): an accept thread (SCHED_OTHER, normal
// priority) that hands each TCP connection to a worker thread of its own (at most
// kMaxConnections at once; issue 18: one slow client must not lock the others out), so that each
// connection runs on its own deadlines; each worker authenticates its request, and
//   - STATUS: answers with the field in use, the loop's counters and its latest telemetry;
//   - UPLOAD: receives the blob into the spare buffer allocated at start-up, verifies it
//     (blob::Verify), builds its ServoField, offers it to the loop (ServoLoop::OfferField: one
//     atomic exchange on each side) and waits for the loop's acknowledgement (field_epoch) before
//     answering; only then does the old buffer become the spare. A refused or failed upload never
//     touches the field in use.
// Every refusal is logged as one line and sent to the client with the same sentence. Uploads are
// one at a time (there is one spare buffer): a second one waits up to read_timeout_ms, then is
// refused "busy". When all
// kMaxConnections slots are taken, the oldest connection that has not yet authenticated its
// request is closed to make room (its worker ends at once); if every slot is authenticated, the
// new connection is closed unanswered.
//
// Memory: two blob buffers of max_blob bytes each, allocated and touched in Create (the field in
// use and the spare); nothing the loop reads is ever written while it may read it.
// Thread rules: Create/LoadInitial/Attach/Start/Stop on the start-up thread; the listener thread
// is the only other user. Non-RT.
#pragma once

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <expected>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>

#include "palpa/blob/blob.h"
#include "palpa/net/client.h"
#include "palpa/net/protocol.h"
#include "palpa/net/socket.h"
#include "palpa/proxy/proxy.h"
#include "palpa/rt/thread.h"
#include "palpa/servo/servo_loop.h"

namespace palpa::net_server {

struct ListenerConfig {
  std::string host = "127.0.0.1";
  std::uint16_t port = 0;                         ///< 0: an ephemeral port (see UploadListener::port)
  net::Key key;                                   ///< the shared key (net::ReadKeyFile)
  std::uint64_t max_blob = net::kDefaultMaxBlob;  ///< upload body cap and buffer size, bytes
  std::int64_t read_timeout_ms = 2000;            ///< header deadline and body idle limit
  std::int64_t ack_timeout_ms = 1000;             ///< wait for the loop to take a field
  int max_connections = 256;                      ///< connections served at once (1..kMaxConnections)
  proxy::ProxyConfig proxy;                       ///< parameters for new fields (k, clamp, ...)
  /// One log line per upload outcome and per refused request (no newline). Listener thread.
  std::function<void(const std::string&)> log;
  /// Fills the loop's counters and latest sample into a status (palpad: from the telemetry
  /// drain's live status). Listener thread.
  std::function<void(net::ControllerStatus&)> fill_status;
  int avoid_cpu = -1;  ///< keep off the servo thread's CPU
};

/// Upper bound of ListenerConfig::max_connections: one worker thread (128 KiB stack) each.
inline constexpr int kMaxConnections = 1024;
/// listen(2) backlog: connections the kernel queues while the accept thread hands others out.
inline constexpr int kListenBacklog = 1024;

class UploadListener {
 public:
  /// Allocates and touches the two buffers, binds and listens. Errors: a sentence (bad cap, the
  /// address in use, ...).
  static std::expected<std::unique_ptr<UploadListener>, std::string> Create(ListenerConfig config);
  UploadListener(const UploadListener&) = delete;
  UploadListener& operator=(const UploadListener&) = delete;
  ~UploadListener();

  /// Reads the start-up field from `path` into the first buffer and verifies it. The view reads
  /// that buffer. Errors name the file (and the verifier's field and byte).
  std::expected<blob::FieldView, std::string> LoadInitial(const std::string& path);
  /// The loop to hand fields to (its initial field must be LoadInitial's view). Before Start.
  void Attach(servo::ServoLoop& loop) { loop_ = &loop; }
  /// Starts the listener thread; 0 or an errno.
  int Start();
  /// Stops accepting and joins the thread (a connection in progress ends within its deadline).
  void Stop();

  std::uint16_t port() const { return port_; }
  /// Both buffers, for the RT set-up's pre-fault list.
  std::array<std::span<const std::byte>, 2> buffers() const;
  std::uint64_t accepted() const { return accepted_.load(std::memory_order_acquire); }
  std::uint64_t refused() const { return refused_.load(std::memory_order_acquire); }
  /// Connections closed to make room for a newer one (oldest unauthenticated first).
  std::uint64_t evicted() const { return evicted_.load(std::memory_order_acquire); }

 private:
  // One connection and its worker thread. The accept thread owns the slot while `busy` is false;
  // the worker sets `done` when it has finished (the accept thread then joins it).
  struct Slot {
    UploadListener* owner = nullptr;
    rt::HelperThread thread;
    net::Socket conn;
    std::string peer;
    std::int64_t accepted_ns = 0;
    bool busy = false;                       // accept thread only
    std::atomic<bool> done{false};           // worker → accept thread
    std::atomic<bool> authenticated{false};  // the request header verified: never evicted
  };

  explicit UploadListener(ListenerConfig config);
  static void Body(void* self);
  static void Work(void* slot);
  void Reap(bool all);
  Slot* FreeSlot();
  void Serve(net::Socket& conn, const std::string& peer, std::atomic<bool>& authenticated);

  struct Buffer {
    std::byte* data = nullptr;
    std::optional<servo::ServoField> field;  // built over `data` once verified
    std::uint32_t crc32c = 0;
    std::array<std::uint32_t, 3> dims{};
    double voxel_m = 0;
    std::uint64_t bytes = 0;
  };

  ListenerConfig config_;
  net::Socket listen_;
  std::uint16_t port_ = 0;
  std::size_t buffer_bytes_ = 0;  // max_blob
  std::array<Buffer, 2> buffers_;
  std::atomic<std::size_t> in_use_{0};  // the buffer the loop reads; the other is the spare
  std::mutex meta_mutex_;               // the Buffer fields other than data/field, read by STATUS workers
  std::timed_mutex upload_mutex_;       // one upload at a time (one spare buffer)
  std::unique_ptr<Slot[]> slots_;
  std::atomic<std::uint64_t> evicted_{0};
  servo::ServoLoop* loop_ = nullptr;
  rt::HelperThread thread_;
  std::atomic<bool> quit_{false};
  std::atomic<std::uint64_t> accepted_{0};
  std::atomic<std::uint64_t> refused_{0};
};

}  // namespace palpa::net_server
