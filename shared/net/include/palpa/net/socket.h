// TCP helpers for both sides of the upload protocol: connect and accept with deadlines, and
// reads/writes bounded by an absolute deadline and an idle time. Blocking sockets driven by
// poll(2); writes use MSG_NOSIGNAL (no SIGPIPE). Non-RT.
#pragma once

#include <cstddef>
#include <cstdint>
#include <expected>
#include <span>
#include <string>

namespace palpa::net {

/// One trivially copyable value (a header, a reply) as the bytes that go on the wire.
template <typename T>
std::span<const std::byte> Bytes(const T& v) {
  return std::as_bytes(std::span<const T>(&v, 1));
}
/// The same, to receive into.
template <typename T>
std::span<std::byte> WritableBytes(T& v) {
  return std::as_writable_bytes(std::span<T>(&v, 1));
}

/// CLOCK_MONOTONIC now, ns.
std::int64_t NowNs();

/// An owned file descriptor (closed on destruction).
class Socket {
 public:
  Socket() = default;
  explicit Socket(int fd) : fd_(fd) {}
  Socket(Socket&& o) noexcept : fd_(o.fd_) { o.fd_ = -1; }
  Socket& operator=(Socket&& o) noexcept;
  Socket(const Socket&) = delete;
  Socket& operator=(const Socket&) = delete;
  ~Socket();
  int fd() const { return fd_; }
  bool valid() const { return fd_ >= 0; }

 private:
  int fd_ = -1;
};

enum class IoResult {
  kOk,       ///< every byte moved
  kEof,      ///< the peer closed (reads) before every byte arrived
  kTimeout,  ///< the deadline passed, or no byte moved for `idle_ns`
  kError,    ///< a socket error (errno kept)
};

/// Reads exactly buf.size() bytes unless the peer closes, `deadline_ns` (NowNs clock) passes, or
/// no byte arrives for `idle_ns` (0: no idle limit). `got` receives the count read.
IoResult RecvAll(int fd, std::span<std::byte> buf, std::int64_t deadline_ns, std::int64_t idle_ns, std::size_t& got);
/// Writes every byte of `data` within the deadline.
IoResult SendAll(int fd, std::span<const std::byte> data, std::int64_t deadline_ns);

/// Connects to host:port (getaddrinfo, every address tried) by `deadline_ns`. Errors: a sentence.
std::expected<Socket, std::string> ConnectTcp(const std::string& host, std::uint16_t port, std::int64_t deadline_ns);
/// Binds and listens on host:port (port 0: ephemeral, see LocalPort). SO_REUSEADDR. Errors: a sentence.
std::expected<Socket, std::string> ListenTcp(const std::string& host, std::uint16_t port);
/// The local port a socket is bound to; 0 on error.
std::uint16_t LocalPort(int fd);

}  // namespace palpa::net
