// Writing outputs so that a failure never leaves a half-written file, and never replaces what is
// not palpa's to replace: the target is checked (palpa/io/file_safety.h), then written to a
// temporary file in the target's directory, fsync'ed, renamed over the target, and the directory
// fsync'ed. Non-RT.
#pragma once

#include <cstddef>
#include <expected>
#include <span>
#include <string>
#include <utility>
#include <vector>

namespace palpa::cli {

/// Atomically replaces `path` with `bytes`, after io::CheckOutputTarget(path, inputs). Error: a
/// sentence naming the path and the refusal or failing step (create, write, fsync, rename); the
/// target is then untouched and no temporary remains.
[[nodiscard]] std::expected<void, std::string> WriteFileAtomically(const std::string& path,
                                                                   std::span<const std::byte> bytes,
                                                                   const std::vector<std::string>& inputs = {});

/// An output written in pieces, for outputs larger than memory should hold (palpa export): the
/// same checks and steps as WriteFileAtomically, with Append between create and Commit.
/// Destroying it uncommitted removes the temporary; the target is replaced only by Commit.
class AtomicOutput {
 public:
  /// io::CheckOutputTarget(path, inputs), then a temporary file in the target's directory.
  /// Error: a sentence naming the path and the refusal or failing step.
  [[nodiscard]] static std::expected<AtomicOutput, std::string> Create(const std::string& path,
                                                                       const std::vector<std::string>& inputs = {});
  AtomicOutput(AtomicOutput&& other) noexcept;
  AtomicOutput& operator=(AtomicOutput&&) = delete;
  AtomicOutput(const AtomicOutput&) = delete;
  AtomicOutput& operator=(const AtomicOutput&) = delete;
  ~AtomicOutput();

  /// Writes `bytes` at the end. Error: names the path; the output is then abandoned.
  [[nodiscard]] std::expected<void, std::string> Append(std::span<const std::byte> bytes);
  /// chmod 0644, fsync, close, the target checked again and replaced by rename, the directory
  /// fsync'ed. Error: names the path and step; the target is then untouched.
  [[nodiscard]] std::expected<void, std::string> Commit();

 private:
  AtomicOutput(std::string path, std::vector<std::string> inputs, std::string temp, int fd)
      : path_(std::move(path)), inputs_(std::move(inputs)), temp_(std::move(temp)), fd_(fd) {}
  std::expected<void, std::string> Fail(const char* step);

  std::string path_;
  std::vector<std::string> inputs_;
  std::string temp_;
  int fd_ = -1;  // -1 once committed or abandoned
};

/// io::CheckOutputTarget for a command, run before any work: prints "palpa COMMAND: <why>" to
/// stderr and returns the exit code (2: a device, FIFO, socket, directory or an input; 1: the
/// target cannot be checked), or 0 when `path` may be written.
[[nodiscard]] int CheckOutput(const char* command, const std::string& path,
                              const std::vector<std::string>& inputs = {});

}  // namespace palpa::cli
