#include "palpa/io/file_safety.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <utility>

namespace palpa::io {
namespace {

std::string Quote(std::string_view path) { return Escape(path, 256); }

FileError Bad(std::string message) { return {Fault::kBadInput, std::move(message)}; }
FileError System(std::string message) { return {Fault::kSystem, std::move(message)}; }

// What a non-regular node is, for messages.
const char* TypeName(mode_t mode) {
  if (S_ISDIR(mode)) return "a directory";
  if (S_ISFIFO(mode)) return "a FIFO";
  if (S_ISSOCK(mode)) return "a socket";
  if (S_ISCHR(mode)) return "a character device";
  if (S_ISBLK(mode)) return "a block device";
  return "not a regular file";
}

}  // namespace

std::string FormatBytes(std::uint64_t bytes) {
  static constexpr const char* kUnits[] = {"bytes", "KiB", "MiB", "GiB", "TiB"};
  std::size_t u = 0;
  while (u + 1 < std::size(kUnits) && bytes >= 1024 && bytes % 1024 == 0) bytes /= 1024, ++u;
  return std::to_string(bytes) + " " + kUnits[u];
}

std::expected<void, FileError> CheckOutputTarget(std::string_view path, std::span<const std::string> inputs) {
  const std::string p(path);
  struct stat target {};
  if (::stat(p.c_str(), &target) != 0) {
    if (errno == ENOENT) return {};  // created by the writer (a dangling link: rename replaces the link)
    return std::unexpected(System(Quote(path) + ": cannot check the output target: " + std::strerror(errno)));
  }
  if (!S_ISREG(target.st_mode)) {
    return std::unexpected(Bad(Quote(path) + ": is " + TypeName(target.st_mode) +
                               "; outputs are written only to regular files (refusing to replace it)"));
  }
  for (const std::string& input : inputs) {
    struct stat in {};
    if (::stat(input.c_str(), &in) != 0) continue;
    if (in.st_dev == target.st_dev && in.st_ino == target.st_ino) {
      return std::unexpected(Bad(Quote(path) + ": is the same file as the input " + Quote(input) +
                                 "; refusing to overwrite an input (choose another output)"));
    }
  }
  return {};
}

std::expected<int, FileError> OpenRegular(std::string_view path, std::string_view what, std::uint64_t* size) {
  const std::string p(path);
  // O_NONBLOCK: opening a FIFO with no writer would otherwise wait for ever.
  const int fd = ::open(p.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK | O_NOCTTY);
  if (fd < 0) {
    const int e = errno;
    const std::string why = std::string("cannot read the ") + std::string(what) + ": " + std::strerror(e);
    // A missing or unreadable file is the user's naming (bad input); anything else is the system.
    if (e == ENOENT || e == ENOTDIR || e == EACCES || e == ELOOP || e == ENAMETOOLONG || e == EISDIR)
      return std::unexpected(Bad(Quote(path) + ": " + why));
    return std::unexpected(System(Quote(path) + ": " + why));
  }
  struct stat st {};
  if (::fstat(fd, &st) != 0) {
    const std::string why = std::strerror(errno);
    ::close(fd);
    return std::unexpected(System(Quote(path) + ": cannot stat the " + std::string(what) + ": " + why));
  }
  if (!S_ISREG(st.st_mode)) {
    ::close(fd);
    return std::unexpected(Bad(Quote(path) + ": is " + TypeName(st.st_mode) + ", not a regular file; a " +
                               std::string(what) + " must be a regular file"));
  }
  const int flags = ::fcntl(fd, F_GETFL);
  if (flags >= 0) ::fcntl(fd, F_SETFL, flags & ~O_NONBLOCK);
  if (size != nullptr) *size = static_cast<std::uint64_t>(st.st_size);
  return fd;
}

std::expected<std::vector<std::byte>, FileError> ReadBounded(std::string_view path, std::uint64_t max_bytes,
                                                             std::string_view what) {
  std::uint64_t size = 0;
  auto fd = OpenRegular(path, what, &size);
  if (!fd) return std::unexpected(std::move(fd.error()));
  // `held`: the size, or 0 when only "more than the cap" is known (a file that grew).
  const auto too_large = [&](std::uint64_t held) {
    ::close(*fd);
    const std::string amount = held != 0 ? std::to_string(held) + " bytes" : "more than " + FormatBytes(max_bytes);
    return std::unexpected(Bad(Quote(path) + ": the " + std::string(what) + " holds " + amount + "; at most " +
                               FormatBytes(max_bytes) + " are read"));
  };
  if (size > max_bytes) return too_large(size);
  std::vector<std::byte> data(static_cast<std::size_t>(size));
  std::size_t got = 0;
  // The size at open may be stale (a growing file): past it, read on up to the cap plus one byte.
  // Past it, reads go to a small probe first, so that a file of the size at open (the usual case)
  // is never copied into a vector grown to twice its size.
  std::array<std::byte, 4096> probe{};
  while (true) {
    const bool full = got == data.size();
    if (full && data.size() > max_bytes) return too_large(0);
    const ssize_t n =
        full ? ::read(*fd, probe.data(), probe.size()) : ::read(*fd, data.data() + got, data.size() - got);
    if (n < 0) {
      if (errno == EINTR) continue;
      const std::string why = std::strerror(errno);
      ::close(*fd);
      return std::unexpected(System(Quote(path) + ": cannot read the " + std::string(what) + ": " + why));
    }
    if (n == 0) break;
    if (!full) {
      got += static_cast<std::size_t>(n);
      continue;
    }
    data.resize(static_cast<std::size_t>(std::min<std::uint64_t>(max_bytes + 1, data.size() + 65536)));
    const std::size_t kept = std::min(static_cast<std::size_t>(n), data.size() - got);
    std::memcpy(data.data() + got, probe.data(), kept);
    got += kept;
    if (kept < static_cast<std::size_t>(n)) break;  // past the cap plus one: too large below
  }
  ::close(*fd);
  if (got > max_bytes) return too_large(0);
  data.resize(got);
  return data;
}

std::expected<std::string, FileError> ReadBoundedText(std::string_view path, std::uint64_t max_bytes,
                                                      std::string_view what) {
  auto bytes = ReadBounded(path, max_bytes, what);
  if (!bytes) return std::unexpected(std::move(bytes.error()));
  return std::string(reinterpret_cast<const char*>(bytes->data()), bytes->size());
}

// ---- LineReader ----

LineReader::LineReader(int fd, std::size_t max_line, std::uint64_t size)
    : fd_(fd), max_line_(max_line), size_(size), buffer_(65536) {}

LineReader::LineReader(LineReader&& other) noexcept { *this = std::move(other); }

LineReader& LineReader::operator=(LineReader&& other) noexcept {
  if (this != &other) {
    if (fd_ >= 0) ::close(fd_);
    fd_ = std::exchange(other.fd_, -1);
    max_line_ = other.max_line_;
    size_ = other.size_;
    buffer_ = std::move(other.buffer_);
    begin_ = other.begin_;
    end_ = other.end_;
    line_ = std::move(other.line_);
    eof_ = other.eof_;
    line_number_ = other.line_number_;
    offset_ = other.offset_;
    error_ = other.error_;
  }
  return *this;
}

LineReader::~LineReader() {
  if (fd_ >= 0) ::close(fd_);
}

std::expected<LineReader, FileError> LineReader::Open(std::string_view path, std::size_t max_line,
                                                      std::string_view what) {
  std::uint64_t size = 0;
  auto fd = OpenRegular(path, what, &size);
  if (!fd) return std::unexpected(std::move(fd.error()));
  return LineReader(*fd, max_line, size);
}

bool LineReader::Fill() {
  while (true) {
    const ssize_t n = ::read(fd_, buffer_.data(), buffer_.size());
    if (n < 0) {
      if (errno == EINTR) continue;
      error_ = errno;
      return false;
    }
    begin_ = 0;
    end_ = static_cast<std::size_t>(n);
    if (n == 0) eof_ = true;
    return true;
  }
}

LineReader::Status LineReader::Next(std::string_view& line) {
  line_.clear();
  bool any = false;
  while (true) {
    if (begin_ == end_) {
      if (eof_ || !Fill()) {
        if (error_ != 0) return Status::kError;
        if (!any) return Status::kEnd;
        ++line_number_;
        line = line_;
        return Status::kLine;
      }
      if (eof_) continue;
    }
    any = true;
    const char* start = buffer_.data() + begin_;
    const void* nl = std::memchr(start, '\n', end_ - begin_);
    const std::size_t take = nl ? static_cast<std::size_t>(static_cast<const char*>(nl) - start) : end_ - begin_;
    if (line_.size() + take > max_line_) {
      ++line_number_;
      return Status::kTooLong;
    }
    line_.append(start, take);
    begin_ += take;
    offset_ += take;
    if (nl) {
      ++begin_;
      ++offset_;
      ++line_number_;
      line = line_;
      return Status::kLine;
    }
  }
}

}  // namespace palpa::io
