#include "atomic_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <utility>
#include <vector>

#include <fmt/core.h>

#include "commands.h"
#include "palpa/io/file_safety.h"

namespace palpa::cli {

int CheckOutput(const char* command, const std::string& path, const std::vector<std::string>& inputs) {
  auto ok = io::CheckOutputTarget(path, inputs);
  if (ok) return kExitOk;
  fmt::print(stderr, "palpa {}: {}\n", command, ok.error().message);
  return ok.error().fault == io::Fault::kBadInput ? kExitBadInput : kExitIo;
}

std::expected<AtomicOutput, std::string> AtomicOutput::Create(const std::string& path,
                                                              const std::vector<std::string>& inputs) {
  if (auto ok = io::CheckOutputTarget(path, inputs); !ok) return std::unexpected(std::move(ok.error().message));
  const std::filesystem::path target(path);
  const std::filesystem::path dir = target.has_parent_path() ? target.parent_path() : std::filesystem::path(".");
  std::string leaf = ".";  // built by appends: GCC 12 -O3 warns (-Wrestrict) on operator+ chains here
  leaf += target.filename().string();
  leaf += ".tmp.XXXXXX";
  const std::string tmpl = (dir / leaf).string();
  std::vector<char> name(tmpl.begin(), tmpl.end());
  name.push_back('\0');
  const int fd = ::mkstemp(name.data());
  if (fd < 0)
    return std::unexpected(path + ": cannot create a temporary file in " + dir.string() + ": " + std::strerror(errno));
  return AtomicOutput(path, inputs, std::string(name.data()), fd);
}

AtomicOutput::AtomicOutput(AtomicOutput&& other) noexcept
    : path_(std::move(other.path_)),
      inputs_(std::move(other.inputs_)),
      temp_(std::move(other.temp_)),
      fd_(std::exchange(other.fd_, -1)) {}

AtomicOutput::~AtomicOutput() {
  if (fd_ >= 0) {
    ::close(fd_);
    ::unlink(temp_.c_str());
  }
}

std::expected<void, std::string> AtomicOutput::Fail(const char* step) {
  const std::string why = std::strerror(errno);
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
  ::unlink(temp_.c_str());
  return std::unexpected(path_ + ": " + step + " failed: " + why);
}

std::expected<void, std::string> AtomicOutput::Append(std::span<const std::byte> bytes) {
  if (fd_ < 0) return std::unexpected(path_ + ": write after the output was closed");
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(fd_, bytes.data() + done, bytes.size() - done);
    if (n < 0) {
      if (errno == EINTR) continue;
      return Fail("write");
    }
    done += static_cast<std::size_t>(n);
  }
  return {};
}

std::expected<void, std::string> AtomicOutput::Commit() {
  if (fd_ < 0) return std::unexpected(path_ + ": commit after the output was closed");
  if (::fchmod(fd_, 0644) != 0) return Fail("chmod");
  if (::fsync(fd_) != 0) return Fail("fsync");
  const int fd = std::exchange(fd_, -1);
  if (::close(fd) != 0) {
    const std::string why = std::strerror(errno);
    ::unlink(temp_.c_str());
    return std::unexpected(path_ + ": close failed: " + why);
  }
  // Checked again here (not only by CheckOutput before the work): rename replaces any node.
  if (auto ok = io::CheckOutputTarget(path_, inputs_); !ok) {
    ::unlink(temp_.c_str());
    return std::unexpected(std::move(ok.error().message));
  }
  if (::rename(temp_.c_str(), path_.c_str()) != 0) {
    const std::string why = std::strerror(errno);
    ::unlink(temp_.c_str());
    return std::unexpected(path_ + ": rename failed: " + why);
  }
  const std::filesystem::path target(path_);
  const std::filesystem::path dir = target.has_parent_path() ? target.parent_path() : std::filesystem::path(".");
  const int dfd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY);
  if (dfd >= 0) {
    ::fsync(dfd);  // best effort: the rename is already visible
    ::close(dfd);
  }
  return {};
}

std::expected<void, std::string> WriteFileAtomically(const std::string& path, std::span<const std::byte> bytes,
                                                     const std::vector<std::string>& inputs) {
  auto out = AtomicOutput::Create(path, inputs);
  if (!out) return std::unexpected(std::move(out.error()));
  if (auto w = out->Append(bytes); !w) return w;
  return out->Commit();
}

}  // namespace palpa::cli
