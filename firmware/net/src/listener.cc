#include "palpa/net_server/listener.h"

#include "palpa/rt/clock.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cinttypes>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <new>
#include <vector>

namespace palpa::net_server {
namespace {

constexpr std::align_val_t kAlign{64};
constexpr std::size_t kChunk = 1 << 20;                // body read and MAC granularity
constexpr std::int64_t kMinRateBytesPerS = 256 << 10;  // slower bodies miss the overall deadline
constexpr std::int64_t kMs = 1'000'000;

using net::Bytes;
using net::WritableBytes;

std::string Hex32(std::uint32_t v) {
  char b[16];
  std::snprintf(b, sizeof b, "0x%08" PRIx32, v);
  return b;
}

std::string PeerName(const sockaddr_storage& ss) {
  char host[INET6_ADDRSTRLEN] = "?";
  unsigned port = 0;
  if (ss.ss_family == AF_INET) {
    const auto* a = reinterpret_cast<const sockaddr_in*>(&ss);
    inet_ntop(AF_INET, &a->sin_addr, host, sizeof host);
    port = ntohs(a->sin_port);
  } else if (ss.ss_family == AF_INET6) {
    const auto* a = reinterpret_cast<const sockaddr_in6*>(&ss);
    inet_ntop(AF_INET6, &a->sin6_addr, host, sizeof host);
    port = ntohs(a->sin6_port);
  }
  return std::string(host) + ":" + std::to_string(port);
}

}  // namespace

UploadListener::UploadListener(ListenerConfig config) : config_(std::move(config)) {}

UploadListener::~UploadListener() {
  Stop();
  for (Buffer& b : buffers_) {
    b.field.reset();
    if (b.data != nullptr) ::operator delete(b.data, kAlign);
  }
}

std::expected<std::unique_ptr<UploadListener>, std::string> UploadListener::Create(ListenerConfig config) {
  if (config.max_blob < blob::kHeaderSize || config.max_blob > net::kMaxBlobCap)
    return std::unexpected("--max-blob must be in " + std::to_string(blob::kHeaderSize) + ".." +
                           std::to_string(net::kMaxBlobCap) + " bytes");
  if (config.max_connections < 1 || config.max_connections > kMaxConnections)
    return std::unexpected("max connections must be in 1.." + std::to_string(kMaxConnections));
  if (!net::InitCrypto()) return std::unexpected(std::string("libsodium could not initialise"));
  std::unique_ptr<UploadListener> l(new UploadListener(std::move(config)));
  l->slots_ = std::make_unique<Slot[]>(static_cast<std::size_t>(l->config_.max_connections));
  for (int i = 0; i < l->config_.max_connections; ++i) l->slots_[static_cast<std::size_t>(i)].owner = l.get();
  l->buffer_bytes_ = static_cast<std::size_t>(l->config_.max_blob);  // ≤ 1 GiB: fits 32-bit size_t
  for (Buffer& b : l->buffers_) {
    b.data = static_cast<std::byte*>(::operator new(l->buffer_bytes_, kAlign, std::nothrow));
    if (b.data == nullptr)
      return std::unexpected("cannot allocate two blob buffers of --max-blob " + std::to_string(l->config_.max_blob) +
                             " bytes");
    std::memset(b.data, 0, l->buffer_bytes_);  // every page touched now, never during a swap
  }
  auto sock = net::ListenTcp(l->config_.host, l->config_.port);
  if (!sock) return std::unexpected("--listen: " + sock.error());
  l->listen_ = std::move(*sock);
  // A deeper queue than ListenTcp's: a burst of connections waits in the kernel, not refused.
  (void)listen(l->listen_.fd(), kListenBacklog);
  l->port_ = net::LocalPort(l->listen_.fd());
  return l;
}

std::expected<blob::FieldView, std::string> UploadListener::LoadInitial(const std::string& path) {
  auto file = blob::ReadFile(path.c_str());  // used in place
  if (!file) return std::unexpected(path + ": " + file.error().what());
  if (file->size() > config_.max_blob)
    return std::unexpected(path + ": the field is " + std::to_string(file->size()) + " bytes, more than --max-blob " +
                           std::to_string(config_.max_blob));
  Buffer& b = buffers_[0];
  std::memcpy(b.data, file->data(), file->size());
  const auto view = blob::Verify(std::span<const std::byte>(b.data, file->size()));
  if (!view) return std::unexpected(path + ": " + view.error().what());
  in_use_.store(0, std::memory_order_release);
  b.crc32c = view->crc32c;
  for (std::size_t a = 0; a < 3; ++a) b.dims[a] = static_cast<std::uint32_t>(view->dims[a]);
  b.voxel_m = view->voxel_m;
  b.bytes = file->size();
  return *view;
}

std::array<std::span<const std::byte>, 2> UploadListener::buffers() const {
  return {std::span<const std::byte>(buffers_[0].data, buffer_bytes_),
          std::span<const std::byte>(buffers_[1].data, buffer_bytes_)};
}

int UploadListener::Start() {
  if (loop_ == nullptr) return EINVAL;
  return thread_.Start("palpad-listen", &UploadListener::Body, this, config_.avoid_cpu);
}

void UploadListener::Stop() {
  quit_.store(true, std::memory_order_release);
  thread_.Join();
  if (!slots_) return;
  // Wake every worker blocked in a read or write; each then ends within its linger (≤ 200 ms).
  for (int i = 0; i < config_.max_connections; ++i) {
    Slot& s = slots_[static_cast<std::size_t>(i)];
    if (s.busy) shutdown(s.conn.fd(), SHUT_RDWR);
  }
  Reap(true);
}

void UploadListener::Work(void* slot) {
  auto& s = *static_cast<Slot*>(slot);
  s.owner->Serve(s.conn, s.peer, s.authenticated);
  s.done.store(true, std::memory_order_release);
}

// Accept thread: joins finished workers (all: waits for every busy one) and frees their slots.
void UploadListener::Reap(bool all) {
  for (int i = 0; i < config_.max_connections; ++i) {
    Slot& s = slots_[static_cast<std::size_t>(i)];
    if (!s.busy || (!all && !s.done.load(std::memory_order_acquire))) continue;
    s.thread.Join();
    s.conn = net::Socket();
    s.busy = false;
  }
}

// Accept thread: a free slot, evicting the oldest unauthenticated connection if none is free;
// nullptr if every connection has authenticated (or the evicted worker did not end in 1 s).
UploadListener::Slot* UploadListener::FreeSlot() {
  for (int attempt = 0; attempt < 2; ++attempt) {
    Reap(false);
    for (int i = 0; i < config_.max_connections; ++i)
      if (!slots_[static_cast<std::size_t>(i)].busy) return &slots_[static_cast<std::size_t>(i)];
    if (attempt == 1) break;
    Slot* oldest = nullptr;
    for (int i = 0; i < config_.max_connections; ++i) {
      Slot& s = slots_[static_cast<std::size_t>(i)];
      if (s.authenticated.load(std::memory_order_acquire) || s.done.load(std::memory_order_acquire)) continue;
      if (oldest == nullptr || s.accepted_ns < oldest->accepted_ns) oldest = &s;
    }
    if (oldest == nullptr) return nullptr;
    shutdown(oldest->conn.fd(), SHUT_RDWR);  // its blocked read returns; the worker ends
    evicted_.fetch_add(1, std::memory_order_acq_rel);
    if (config_.log)
      config_.log("connection from " + oldest->peer + " closed: " + std::to_string(config_.max_connections) +
                  " connections open, it was the oldest one not yet authenticated");
    for (int wait = 0; wait < 1000 && !oldest->done.load(std::memory_order_acquire); ++wait) rt::SleepForNs(1'000'000);
  }
  return nullptr;
}

void UploadListener::Body(void* self) {
  auto& l = *static_cast<UploadListener*>(self);
  while (!l.quit_.load(std::memory_order_acquire)) {
    pollfd p{l.listen_.fd(), POLLIN, 0};
    if (poll(&p, 1, 50) <= 0) {  // wake every 50 ms to see quit_ and reap finished workers
      l.Reap(false);
      continue;
    }
    sockaddr_storage ss{};
    socklen_t len = sizeof ss;
    net::Socket conn(accept4(l.listen_.fd(), reinterpret_cast<sockaddr*>(&ss), &len, SOCK_CLOEXEC));
    if (!conn.valid()) continue;
    Slot* slot = l.FreeSlot();
    if (slot == nullptr) {
      if (l.config_.log)
        l.config_.log("connection from " + PeerName(ss) + " closed unanswered: " +
                      std::to_string(l.config_.max_connections) + " authenticated connections are open");
      continue;  // `conn` closes
    }
    slot->conn = std::move(conn);
    slot->peer = PeerName(ss);
    slot->accepted_ns = net::NowNs();
    slot->done.store(false, std::memory_order_release);
    slot->authenticated.store(false, std::memory_order_release);
    slot->busy = true;
    if (slot->thread.Start("palpad-conn", &UploadListener::Work, slot, l.config_.avoid_cpu, 128 * 1024) != 0) {
      slot->busy = false;  // no thread: serve nobody rather than block the accept thread
      slot->conn = net::Socket();
    }
  }
}

void UploadListener::Serve(net::Socket& conn, const std::string& peer, std::atomic<bool>& authenticated) {
  const int fd = conn.fd();
  const std::int64_t timeout_ns = config_.read_timeout_ms * kMs;
  net::Header hello;
  hello.magic = net::kMagic;
  hello.version = net::kVersion;
  hello.type = static_cast<std::uint16_t>(net::MessageType::kHello);
  hello.body_size = sizeof(net::HelloBody);
  hello.server_nonce = net::NewNonce();
  net::HelloBody hb;
  hb.max_body = config_.max_blob;
  hb.read_timeout_ms = static_cast<std::uint32_t>(config_.read_timeout_ms);
  {
    std::array<std::byte, net::kHeaderSize + sizeof hb + net::kTagBytes> m{};
    std::memcpy(m.data(), &hello, net::kHeaderSize);
    std::memcpy(m.data() + net::kHeaderSize, &hb, sizeof hb);
    if (net::SendAll(fd, m, net::NowNs() + timeout_ns) != net::IoResult::kOk) return;
  }

  net::Header req;
  bool is_upload = false;
  // Sends a sealed reply (both nonces echoed; the client nonce as far as the header arrived).
  const auto reply = [&](net::MessageType type, std::span<const std::byte> body) {
    net::Header h;
    h.magic = net::kMagic;
    h.version = net::kVersion;
    h.type = static_cast<std::uint16_t>(type);
    h.body_size = body.size();
    h.server_nonce = hello.server_nonce;
    h.client_nonce = req.client_nonce;
    const auto tag = net::Seal(config_.key.bytes, h, body);
    std::vector<std::byte> m(net::kHeaderSize + body.size() + net::kTagBytes);
    std::memcpy(m.data(), &h, net::kHeaderSize);
    if (!body.empty()) std::memcpy(m.data() + net::kHeaderSize, body.data(), body.size());
    std::memcpy(m.data() + net::kHeaderSize + body.size(), tag.data(), net::kTagBytes);
    (void)net::SendAll(fd, m, net::NowNs() + timeout_ns);
  };
  const auto refuse = [&](net::Refusal why, const std::string& text) {
    refused_.fetch_add(1, std::memory_order_acq_rel);
    std::uint32_t crc = 0;
    {
      const std::lock_guard<std::mutex> lock(meta_mutex_);
      crc = buffers_[in_use_.load(std::memory_order_acquire)].crc32c;
    }
    if (config_.log)
      config_.log(std::string(is_upload ? "upload" : "request") + " from " + peer + " refused: " + text +
                  " (field in use unchanged: crc32c " + Hex32(crc) + ")");
    net::RefusedBody b;
    b.refusal = static_cast<std::uint32_t>(why);
    std::snprintf(b.text.data(), b.text.size(), "%s", text.c_str());
    reply(net::MessageType::kRefused, Bytes(b));
    // Let the refusal reach the client before the close: stop writing, then read what it still
    // sends for a moment (closing with unread data would reset the connection and lose the reply).
    shutdown(fd, SHUT_WR);
    std::array<std::byte, 4096> sink{};
    const std::int64_t until = net::NowNs() + 200 * kMs;
    std::size_t got = 0;
    while (net::RecvAll(fd, sink, until, 0, got) == net::IoResult::kOk) {
    }
  };

  std::size_t got = 0;
  const net::IoResult hr = net::RecvAll(fd, WritableBytes(req), net::NowNs() + timeout_ns, timeout_ns, got);
  if (got >= 4 && req.magic != net::kMagic)
    return refuse(net::Refusal::kGarbage, "garbage: the first bytes are not a palpa upload header (magic 'PLPU')");
  if (hr == net::IoResult::kTimeout)
    return refuse(net::Refusal::kTimeout, "timeout: " + std::to_string(got) + " of 96 header bytes within " +
                                              std::to_string(config_.read_timeout_ms) + " ms");
  if (hr != net::IoResult::kOk) {
    if (got == 0) return;  // connected and left (a port probe): nothing to report
    return refuse(net::Refusal::kHalfSent,
                  "half-sent: the connection closed after " + std::to_string(got) + " of 96 header bytes");
  }
  if (net::CheckMagicAndVersion(req) == net::Refusal::kBadVersion)
    return refuse(net::Refusal::kBadVersion,
                  "unsupported protocol version " + std::to_string(req.version) + " (this palpad speaks 1)");
  const auto type = static_cast<net::MessageType>(req.type);
  is_upload = type == net::MessageType::kUpload;
  if (!is_upload && type != net::MessageType::kStatusRequest)
    return refuse(net::Refusal::kType,
                  "message type " + std::to_string(req.type) + " is not a request (UPLOAD 2, STATUS 3)");
  if (!is_upload && req.body_size != 0)
    return refuse(net::Refusal::kType,
                  "a STATUS request has an empty body, this one announces " + std::to_string(req.body_size) + " bytes");
  if (is_upload && req.body_size > config_.max_blob)
    return refuse(net::Refusal::kOversize, "oversize: body of " + std::to_string(req.body_size) +
                                               " bytes exceeds the cap of " + std::to_string(config_.max_blob) +
                                               " bytes (--max-blob); not read");
  if (req.server_nonce != hello.server_nonce)
    return refuse(net::Refusal::kReplayed,
                  "replayed: the message answers a nonce this connection did not issue (recorded earlier?)");
  if (!net::TagsEqual(net::HeaderTag(config_.key.bytes, req), req.header_tag))
    return refuse(net::Refusal::kWrongKey, "wrong key: the header's MAC does not verify with palpad's key");
  authenticated.store(true, std::memory_order_release);  // a key holder: not evicted for a newcomer

  net::BodyMac mac(config_.key.bytes, req);
  std::array<unsigned char, net::kTagBytes> tag{};
  if (!is_upload) {
    const net::IoResult r = net::RecvAll(fd, WritableBytes(tag), net::NowNs() + timeout_ns, timeout_ns, got);
    if (r != net::IoResult::kOk)
      return refuse(r == net::IoResult::kTimeout ? net::Refusal::kTimeout : net::Refusal::kHalfSent,
                    "the status request's tag did not arrive");
    if (!net::TagsEqual(mac.Final(), tag))
      return refuse(net::Refusal::kBodyTag, "body altered: the message's MAC does not verify");
    net::ControllerStatus st;
    if (config_.fill_status) config_.fill_status(st);
    net::StatusBody b;
    {
      const std::lock_guard<std::mutex> lock(meta_mutex_);
      const Buffer& use = buffers_[in_use_.load(std::memory_order_acquire)];
      b.field_crc32c = use.crc32c;
      b.dims = use.dims;
      b.voxel_m = use.voxel_m;
      b.field_bytes = use.bytes;
    }
    b.swaps = loop_->field_epoch();
    b.ticks = st.ticks;
    b.overruns = st.overruns;
    b.max_tick_ns = st.max_tick_ns;
    b.force_clamps = st.force_clamps;
    b.estops = st.estops;
    b.contact_ticks = st.contact_ticks;
    b.dropped = st.dropped;
    b.uploads_accepted = accepted();
    b.uploads_refused = refused();
    b.last_tick = st.last_tick;
    b.t_s = st.t_s;
    b.hip_m = st.hip_m;
    b.proxy_m = st.proxy_m;
    b.force_n = st.force_n;
    b.rate_hz = st.rate_hz;
    b.flags = (st.contact ? net::kStatusContact : 0u) | (st.running ? net::kStatusRunning : 0u) |
              (st.swap_ramp ? net::kStatusSwapRamp : 0u);
    reply(net::MessageType::kStatusReply, Bytes(b));
    return;
  }

  // UPLOAD: the header passed; one upload at a time owns the spare buffer.
  // A finishing upload (its reply, a refusal's linger) releases it within ms; a running one may
  // take long: wait up to the header deadline, then refuse.
  std::unique_lock<std::timed_mutex> upload_lock(upload_mutex_, std::defer_lock);
  if (!upload_lock.try_lock_for(std::chrono::milliseconds(config_.read_timeout_ms)))
    return refuse(net::Refusal::kBusy, "busy: another upload is in progress; try again when it has finished");
  // Ask for the body, then read it into the spare buffer.
  const std::size_t spare = 1 - in_use_.load(std::memory_order_acquire);
  Buffer& dst = buffers_[spare];
  dst.field.reset();  // the loop no longer reads the spare (acknowledged at the last swap)
  reply(net::MessageType::kContinue, {});
  const auto size = static_cast<std::size_t>(req.body_size);  // ≤ max_blob ≤ 1 GiB
  const std::int64_t deadline =
      net::NowNs() + timeout_ns + static_cast<std::int64_t>(size) / kMinRateBytesPerS * 1'000'000'000;
  std::size_t have = 0;
  while (have < size) {
    const std::size_t n = std::min(kChunk, size - have);
    const net::IoResult r = net::RecvAll(fd, std::span<std::byte>(dst.data + have, n), deadline, timeout_ns, got);
    have += got;
    if (r == net::IoResult::kTimeout)
      return refuse(net::Refusal::kTimeout, "timeout: " + std::to_string(have) + " of " + std::to_string(size) +
                                                " body bytes arrived, then none for " +
                                                std::to_string(config_.read_timeout_ms) +
                                                " ms (or the deadline passed)");
    if (r != net::IoResult::kOk)
      return refuse(net::Refusal::kHalfSent, "half-sent: the connection closed after " + std::to_string(have) + " of " +
                                                 std::to_string(size) + " body bytes");
    mac.Update(std::span<const std::byte>(dst.data + have - n, n));
  }
  const net::IoResult tr = net::RecvAll(fd, WritableBytes(tag), deadline, timeout_ns, got);
  if (tr == net::IoResult::kTimeout) return refuse(net::Refusal::kTimeout, "timeout: the body's tag did not arrive");
  if (tr != net::IoResult::kOk)
    return refuse(net::Refusal::kHalfSent, "half-sent: the connection closed before the body's tag");
  if (!net::TagsEqual(mac.Final(), tag))
    return refuse(net::Refusal::kBodyTag, "body altered: the blob's MAC does not verify (changed in transit)");

  const auto view = blob::Verify(std::span<const std::byte>(dst.data, size));
  if (!view) return refuse(net::Refusal::kBlobInvalid, std::string("invalid blob: ") + view.error().what());
  const auto params = proxy::MakeProxyParams(config_.proxy, view->voxel_m);
  if (!params) return refuse(net::Refusal::kSetup, std::string("field not renderable: ") + params.error());
  dst.field.emplace(*view, *params, size);
  {
    const std::lock_guard<std::mutex> lock(meta_mutex_);
    dst.crc32c = view->crc32c;
    for (std::size_t a = 0; a < 3; ++a) dst.dims[a] = static_cast<std::uint32_t>(view->dims[a]);
    dst.voxel_m = view->voxel_m;
    dst.bytes = size;
  }

  // The hand-over: one exchange here, one in the loop; then wait for its acknowledgement.
  const std::uint64_t epoch = loop_->field_epoch();
  (void)loop_->OfferField(&*dst.field);
  const std::int64_t ack_deadline = net::NowNs() + config_.ack_timeout_ms * kMs;
  while (loop_->field_epoch() == epoch && net::NowNs() < ack_deadline) rt::SleepForNs(100'000);
  if (loop_->field_epoch() == epoch) {
    if (loop_->OfferField(nullptr) == &*dst.field) {
      dst.field.reset();
      return refuse(net::Refusal::kBusy, "busy: the servo loop did not take the field within " +
                                             std::to_string(config_.ack_timeout_ms) + " ms (is it running?)");
    }
    while (loop_->field_epoch() == epoch) rt::SleepForNs(10'000);  // taken just now: the ack follows at once
  }
  {
    const std::lock_guard<std::mutex> lock(meta_mutex_);
    in_use_.store(spare, std::memory_order_release);  // acknowledged: the old buffer is the spare from now on
  }
  accepted_.fetch_add(1, std::memory_order_acq_rel);
  const std::uint64_t swaps = loop_->field_epoch();
  if (config_.log)
    config_.log("upload from " + peer + " accepted: field crc32c " + Hex32(dst.crc32c) + ", dims " +
                std::to_string(dst.dims[0]) + "x" + std::to_string(dst.dims[1]) + "x" + std::to_string(dst.dims[2]) +
                ", " + std::to_string(size) + " bytes, swap " + std::to_string(swaps));
  net::AcceptedBody b;
  b.crc32c = dst.crc32c;
  b.dims = dst.dims;
  b.voxel_m = dst.voxel_m;
  b.swaps = swaps;
  b.field_bytes = size;
  upload_lock.unlock();  // swapped and copied: the next upload may start while this reply goes out
  reply(net::MessageType::kUploadAccepted, Bytes(b));
}

}  // namespace palpa::net_server
