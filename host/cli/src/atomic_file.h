// Writing outputs so that a failure never leaves a half-written file: a temporary file in the
// target's directory, fsync, rename over the target, fsync the directory. Non-RT.
#pragma once

#include <cstddef>
#include <expected>
#include <span>
#include <string>

namespace palpa::cli {

/// Atomically replaces `path` with `bytes`. Error: a sentence naming the path and the failing
/// step (create, write, fsync, rename); the target is then untouched and no temporary remains.
[[nodiscard]] std::expected<void, std::string> WriteFileAtomically(const std::string& path,
                                                                   std::span<const std::byte> bytes);

}  // namespace palpa::cli
