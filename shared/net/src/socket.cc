#include "palpa/net/socket.h"

#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <ctime>

namespace palpa::net {
namespace {

int PollMs(std::int64_t deadline_ns, std::int64_t idle_until_ns) {
  const std::int64_t until = idle_until_ns < deadline_ns ? idle_until_ns : deadline_ns;
  const std::int64_t left = until - NowNs();
  if (left <= 0) return 0;
  return static_cast<int>((left + 999'999) / 1'000'000);
}

// Waits for `events` on fd; false on timeout or error.
bool WaitFor(int fd, short events, std::int64_t deadline_ns, std::int64_t idle_until_ns) {
  for (;;) {
    const int ms = PollMs(deadline_ns, idle_until_ns);
    if (ms <= 0) return false;
    pollfd p{fd, events, 0};
    const int r = poll(&p, 1, ms);
    if (r > 0) return true;
    if (r == 0) continue;  // re-check the clock: poll may return a little early
    if (errno != EINTR) return false;
  }
}

}  // namespace

std::int64_t NowNs() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

Socket& Socket::operator=(Socket&& o) noexcept {
  if (this != &o) {
    if (fd_ >= 0) close(fd_);
    fd_ = o.fd_;
    o.fd_ = -1;
  }
  return *this;
}

Socket::~Socket() {
  if (fd_ >= 0) close(fd_);
}

IoResult RecvAll(int fd, std::span<std::byte> buf, std::int64_t deadline_ns, std::int64_t idle_ns, std::size_t& got) {
  got = 0;
  constexpr std::int64_t kNoIdle = INT64_MAX;
  while (got < buf.size()) {
    const std::int64_t idle_until = idle_ns > 0 ? NowNs() + idle_ns : kNoIdle;
    if (!WaitFor(fd, POLLIN, deadline_ns, idle_until)) return IoResult::kTimeout;
    const ssize_t n = recv(fd, buf.data() + got, buf.size() - got, 0);
    if (n > 0) {
      got += static_cast<std::size_t>(n);
    } else if (n == 0) {
      return IoResult::kEof;
    } else if (errno != EINTR && errno != EAGAIN) {
      return errno == ECONNRESET ? IoResult::kEof : IoResult::kError;
    }
  }
  return IoResult::kOk;
}

IoResult SendAll(int fd, std::span<const std::byte> data, std::int64_t deadline_ns) {
  std::size_t sent = 0;
  while (sent < data.size()) {
    if (!WaitFor(fd, POLLOUT, deadline_ns, INT64_MAX)) return IoResult::kTimeout;
    const ssize_t n = send(fd, data.data() + sent, data.size() - sent, MSG_NOSIGNAL);
    if (n > 0) {
      sent += static_cast<std::size_t>(n);
    } else if (n < 0 && errno != EINTR && errno != EAGAIN) {
      return (errno == EPIPE || errno == ECONNRESET) ? IoResult::kEof : IoResult::kError;
    }
  }
  return IoResult::kOk;
}

std::expected<Socket, std::string> ConnectTcp(const std::string& host, std::uint16_t port, std::int64_t deadline_ns) {
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  addrinfo* list = nullptr;
  const std::string service = std::to_string(port);
  if (const int rc = getaddrinfo(host.c_str(), service.c_str(), &hints, &list); rc != 0)
    return std::unexpected("cannot resolve '" + host + "': " + gai_strerror(rc));
  std::string last = "no address";
  Socket result;
  for (addrinfo* a = list; a != nullptr && !result.valid(); a = a->ai_next) {
    Socket s(socket(a->ai_family, a->ai_socktype | SOCK_CLOEXEC | SOCK_NONBLOCK, a->ai_protocol));
    if (!s.valid()) {
      last = std::strerror(errno);
      continue;
    }
    int rc = connect(s.fd(), a->ai_addr, a->ai_addrlen);
    if (rc != 0 && errno == EINPROGRESS) {
      if (!WaitFor(s.fd(), POLLOUT, deadline_ns, INT64_MAX)) {
        last = "timed out";
        continue;
      }
      int err = 0;
      socklen_t len = sizeof err;
      getsockopt(s.fd(), SOL_SOCKET, SO_ERROR, &err, &len);
      rc = err == 0 ? 0 : -1;
      errno = err;
    }
    if (rc != 0) {
      last = std::strerror(errno);
      continue;
    }
    // Back to blocking: every later wait goes through poll with a deadline anyway.
    const int flags = fcntl(s.fd(), F_GETFL);
    fcntl(s.fd(), F_SETFL, flags & ~O_NONBLOCK);
    int one = 1;
    setsockopt(s.fd(), IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
    result = std::move(s);
  }
  freeaddrinfo(list);
  if (!result.valid()) return std::unexpected("cannot connect to " + host + ":" + service + ": " + last);
  return result;
}

std::expected<Socket, std::string> ListenTcp(const std::string& host, std::uint16_t port) {
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  hints.ai_flags = AI_PASSIVE;
  addrinfo* list = nullptr;
  const std::string service = std::to_string(port);
  if (const int rc = getaddrinfo(host.empty() ? nullptr : host.c_str(), service.c_str(), &hints, &list); rc != 0)
    return std::unexpected("cannot resolve '" + host + "': " + gai_strerror(rc));
  std::string last = "no address";
  Socket result;
  for (addrinfo* a = list; a != nullptr && !result.valid(); a = a->ai_next) {
    Socket s(socket(a->ai_family, a->ai_socktype | SOCK_CLOEXEC, a->ai_protocol));
    if (!s.valid()) {
      last = std::strerror(errno);
      continue;
    }
    int one = 1;
    setsockopt(s.fd(), SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    if (bind(s.fd(), a->ai_addr, a->ai_addrlen) != 0 || listen(s.fd(), 8) != 0) {
      last = std::strerror(errno);
      continue;
    }
    result = std::move(s);
  }
  freeaddrinfo(list);
  if (!result.valid()) return std::unexpected("cannot listen on " + host + ":" + service + ": " + last);
  return result;
}

std::uint16_t LocalPort(int fd) {
  sockaddr_storage ss{};
  socklen_t len = sizeof ss;
  if (getsockname(fd, reinterpret_cast<sockaddr*>(&ss), &len) != 0) return 0;
  if (ss.ss_family == AF_INET) return ntohs(reinterpret_cast<sockaddr_in*>(&ss)->sin_port);
  if (ss.ss_family == AF_INET6) return ntohs(reinterpret_cast<sockaddr_in6*>(&ss)->sin6_port);
  return 0;
}

}  // namespace palpa::net
