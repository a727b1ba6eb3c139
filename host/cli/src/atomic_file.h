// Writing outputs so that a failure never leaves a half-written file, and never replaces what is
// not palpa's to replace: the target is checked (palpa/io/file_safety.h), then written to a
// temporary file in the target's directory, fsync'ed, renamed over the target, and the directory
// fsync'ed. Non-RT.
#pragma once

#include <cstddef>
#include <expected>
#include <span>
#include <string>
#include <vector>

namespace palpa::cli {

/// Atomically replaces `path` with `bytes`, after io::CheckOutputTarget(path, inputs). Error: a
/// sentence naming the path and the refusal or failing step (create, write, fsync, rename); the
/// target is then untouched and no temporary remains.
[[nodiscard]] std::expected<void, std::string> WriteFileAtomically(const std::string& path,
                                                                   std::span<const std::byte> bytes,
                                                                   const std::vector<std::string>& inputs = {});

/// io::CheckOutputTarget for a command, run before any work: prints "palpa COMMAND: <why>" to
/// stderr and returns the exit code (2: a device, FIFO, socket, directory or an input; 1: the
/// target cannot be checked), or 0 when `path` may be written.
[[nodiscard]] int CheckOutput(const char* command, const std::string& path,
                              const std::vector<std::string>& inputs = {});

}  // namespace palpa::cli
