#include "palpa/io/atomic_file.h"

#include <fcntl.h>
#include <sys/random.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdint>
#include <cstring>
#include <ctime>

#include "palpa/io/escape.h"
#include "palpa/io/file_safety.h"
#include "palpa/io/temp_registry.h"

namespace palpa::io {
namespace {

std::string Quote(std::string_view path) { return Escape(path, 256); }

std::string DirectoryOf(const std::string& path) {
  const auto slash = path.rfind('/');
  if (slash == std::string::npos) return ".";
  if (slash == 0) return "/";
  return path.substr(0, slash);
}

// Six characters of [0-9A-Za-z], as mkstemp's XXXXXX.
std::string RandomSuffix() {
  static std::atomic<std::uint64_t> counter{0};
  std::uint64_t v = 0;
  if (::getrandom(&v, sizeof v, GRND_NONBLOCK) != static_cast<ssize_t>(sizeof v)) {
    timespec ts{};
    ::clock_gettime(CLOCK_REALTIME, &ts);
    v = static_cast<std::uint64_t>(ts.tv_nsec) ^ (static_cast<std::uint64_t>(ts.tv_sec) << 30) ^
        (static_cast<std::uint64_t>(::getpid()) << 40);
  }
  v ^= counter.fetch_add(1, std::memory_order_relaxed) * 0x9e3779b97f4a7c15ull;
  static constexpr char kChars[] = "0123456789ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz";
  std::string s(6, '0');
  for (char& c : s) {
    c = kChars[v % 62];
    v /= 62;
  }
  return s;
}

}  // namespace

std::expected<AtomicFile, std::string> AtomicFile::Create(const std::string& path, AtomicFileOptions options) {
  // rename() replaces any node: a device, FIFO or directory is never a target (issue 18).
  if (auto ok = CheckOutputTarget(path, options.inputs); !ok) return std::unexpected(std::move(ok.error().message));
  // A name of our own with O_EXCL rather than mkstemp: mkstemp makes the file 0600, and giving it
  // the mode a plain create would means reading the umask with umask(2), process-wide and racy.
  std::string temp;
  int fd = -1;
  for (int attempt = 0; attempt < 100 && fd < 0; ++attempt) {
    temp = path + ".tmp." + RandomSuffix();
    fd = ::open(temp.c_str(), O_RDWR | O_CREAT | O_EXCL | O_CLOEXEC, static_cast<mode_t>(options.mode));
    if (fd < 0 && errno != EEXIST) break;
  }
  if (fd < 0) {
    return std::unexpected(Quote(path) + ": cannot create a temporary file in " + Quote(DirectoryOf(path)) + ": " +
                           std::strerror(errno));
  }
  const int slot = RegisterTempPath(temp.c_str());
  std::FILE* file = ::fdopen(fd, "w+");
  if (file == nullptr) {
    const std::string why = std::strerror(errno);
    ::close(fd);
    ::unlink(temp.c_str());
    UnregisterTempPath(slot);
    return std::unexpected(Quote(path) + ": cannot open the temporary file " + Quote(temp) + ": " + why);
  }
  return AtomicFile(path, std::move(options), std::move(temp), file, slot);
}

AtomicFile::AtomicFile(AtomicFile&& other) noexcept
    : path_(std::move(other.path_)),
      options_(std::move(other.options_)),
      temp_(std::exchange(other.temp_, {})),
      file_(std::exchange(other.file_, nullptr)),
      slot_(std::exchange(other.slot_, -1)) {}

AtomicFile::~AtomicFile() { Discard(); }

void AtomicFile::Discard() noexcept {
  if (file_ != nullptr) std::fclose(std::exchange(file_, nullptr));
  if (!temp_.empty()) ::unlink(std::exchange(temp_, {}).c_str());
  UnregisterTempPath(std::exchange(slot_, -1));  // after the unlink: a crash in between still finds it
}

std::unexpected<std::string> AtomicFile::Abandon(const char* step) {
  const std::string why = std::strerror(errno);
  Discard();
  return std::unexpected(Quote(path_) + ": " + step + " failed: " + why);
}

std::expected<void, std::string> AtomicFile::Append(std::span<const std::byte> bytes) {
  if (file_ == nullptr) return std::unexpected(Quote(path_) + ": the output was already committed or abandoned");
  if (!bytes.empty() && std::fwrite(bytes.data(), 1, bytes.size(), file_) != bytes.size()) return Abandon("write");
  return {};
}

std::expected<void, std::string> AtomicFile::Commit() {
  if (file_ == nullptr) return std::unexpected(Quote(path_) + ": the output was already committed or abandoned");
  if (std::fflush(file_) != 0 || std::ferror(file_) != 0) return Abandon("write");
  if (options_.durable && ::fsync(::fileno(file_)) != 0) return Abandon("fsync");
  if (std::fclose(std::exchange(file_, nullptr)) != 0) return Abandon("close");
  // Checked again here, not only at Create: a device or FIFO may have been put there meanwhile.
  if (auto ok = CheckOutputTarget(path_, options_.inputs); !ok) {
    Discard();
    return std::unexpected(std::move(ok.error().message));
  }
  if (::rename(temp_.c_str(), path_.c_str()) != 0) return Abandon("rename");
  temp_.clear();  // renamed: nothing left to remove
  UnregisterTempPath(std::exchange(slot_, -1));
  if (options_.durable) {
    // Makes the rename itself durable; failing here leaves a complete file, so it is no error.
    const int dir = ::open(DirectoryOf(path_).c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (dir >= 0) {
      (void)::fsync(dir);
      ::close(dir);
    }
  }
  return {};
}

std::expected<void, std::string> WriteFileAtomically(const std::string& path, std::span<const std::byte> bytes,
                                                     AtomicFileOptions options) {
  auto file = AtomicFile::Create(path, std::move(options));
  if (!file) return std::unexpected(std::move(file.error()));
  if (auto appended = file->Append(bytes); !appended) return appended;
  return file->Commit();
}

}  // namespace palpa::io
