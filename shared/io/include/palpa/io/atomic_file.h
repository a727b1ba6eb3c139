// The one atomic-file writer of palpa and palpad (issue 21): every output is written so that a
// failure never leaves a half-written file and never replaces what is not palpa's to replace.
// The target is checked (CheckOutputTarget: no device, FIFO, socket, directory or input), then
// written to a temporary `<path>.tmp.XXXXXX` in the target's directory, fsync'ed, checked again,
// renamed over the target, and the directory fsync'ed. Readers see the old file or the complete
// new one. The temporary is removed by the destructor of an uncommitted file, and by palpad's
// fatal-signal handler (palpa/io/temp_registry.h) while it exists.
//
// Non-RT (allocates, makes syscalls); compiled without exceptions so that the board builds take it.
#pragma once

#include <cstddef>
#include <cstdio>
#include <expected>
#include <span>
#include <string>
#include <utility>
#include <vector>

namespace palpa::io {

struct AtomicFileOptions {
  /// The command's inputs: a target that is the same file as one of them is refused.
  std::vector<std::string> inputs{};
  /// Permission bits of the new file, less the umask, as open(2) creates a file (0600: a key).
  unsigned mode = 0666;
  /// fsync the file before the rename and the directory after it, so that a crash leaves the old
  /// file or the complete new one. false: the rename alone, atomic for readers but not durable
  /// (palpad's status file, a live view rewritten every second).
  bool durable = true;
};

/// One output, written through file() or Append and replacing its target only by Commit.
class AtomicFile {
 public:
  /// CheckOutputTarget(path, options.inputs), then the temporary, open for writing and reading
  /// back. Error: a sentence naming the path and the refusal or the failing step.
  [[nodiscard]] static std::expected<AtomicFile, std::string> Create(const std::string& path,
                                                                     AtomicFileOptions options = {});

  AtomicFile(AtomicFile&& other) noexcept;
  AtomicFile& operator=(AtomicFile&&) = delete;
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;
  /// Uncommitted: closes and removes the temporary; the target is left as it was.
  ~AtomicFile();

  /// The temporary as a stdio stream ("w+": palpad's binary trace reads itself back for its CRC);
  /// nullptr once committed or abandoned. Write errors show at Commit.
  [[nodiscard]] std::FILE* file() const { return file_; }
  /// Writes `bytes` at the end, past what file() buffered, with write(2) (no stdio copy of them).
  /// Error: names the path; the output is then abandoned.
  [[nodiscard]] std::expected<void, std::string> Append(std::span<const std::byte> bytes);
  /// Flushes, fsyncs (durable), closes, checks the target again (rename replaces any node),
  /// renames the temporary onto it and fsyncs the directory (durable). Error: names the path and
  /// the step; the temporary is then removed and the target left as it was.
  [[nodiscard]] std::expected<void, std::string> Commit();

  [[nodiscard]] const std::string& path() const { return path_; }
  /// The temporary's name; empty once renamed or removed.
  [[nodiscard]] const std::string& temp_path() const { return temp_; }

 private:
  AtomicFile(std::string path, AtomicFileOptions options, std::string temp, std::FILE* file, int slot)
      : path_(std::move(path)), options_(std::move(options)), temp_(std::move(temp)), file_(file), slot_(slot) {}
  /// Closes and removes the temporary; the error names the path, the step and errno.
  std::unexpected<std::string> Abandon(const char* step);
  void Discard() noexcept;

  std::string path_;
  AtomicFileOptions options_;
  std::string temp_;
  std::FILE* file_ = nullptr;  // nullptr once committed or abandoned
  int slot_ = -1;              // RegisterTempPath slot of temp_
};

/// AtomicFile::Create, Append(bytes), Commit: `path` replaced by `bytes`, or left as it was.
[[nodiscard]] std::expected<void, std::string> WriteFileAtomically(const std::string& path,
                                                                   std::span<const std::byte> bytes,
                                                                   AtomicFileOptions options = {});

}  // namespace palpa::io
