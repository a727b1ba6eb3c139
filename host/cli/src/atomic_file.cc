#include "atomic_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
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

std::expected<void, std::string> WriteFileAtomically(const std::string& path, std::span<const std::byte> bytes,
                                                     const std::vector<std::string>& inputs) {
  // Checked again here (not only by CheckOutput before the work): rename replaces any node.
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
  auto fail = [&](const char* step) {
    const std::string why = std::strerror(errno);
    ::close(fd);
    ::unlink(name.data());
    return std::unexpected(path + ": " + step + " failed: " + why);
  };
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0) {
      if (errno == EINTR) continue;
      return fail("write");
    }
    done += static_cast<std::size_t>(n);
  }
  if (::fchmod(fd, 0644) != 0) return fail("chmod");
  if (::fsync(fd) != 0) return fail("fsync");
  if (::close(fd) != 0) {
    const std::string why = std::strerror(errno);
    ::unlink(name.data());
    return std::unexpected(path + ": close failed: " + why);
  }
  if (::rename(name.data(), path.c_str()) != 0) {
    const std::string why = std::strerror(errno);
    ::unlink(name.data());
    return std::unexpected(path + ": rename failed: " + why);
  }
  const int dfd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY);
  if (dfd >= 0) {
    ::fsync(dfd);  // best effort: the rename is already visible
    ::close(dfd);
  }
  return {};
}

}  // namespace palpa::cli
