// A fixed-size registry of temporary file paths that a fatal-signal handler can unlink
// (issue 18, docs/runtime.md "Fault-injection table"; in shared/io since issue 21, beside the
// writer that fills it). Every io::AtomicFile registers its `<path>.tmp.XXXXXX` name when it
// creates it and unregisters it once it is renamed or removed; palpad's crash handler calls
// UnlinkRegisteredTempPaths, which only reads fixed arrays and calls unlink(2), both
// async-signal-safe.
//
// Thread rules: Register/Unregister from any non-RT thread (lock-free, no allocation);
// UnlinkRegisteredTempPaths from a signal handler or any thread.
#pragma once

namespace palpa::io {

/// Slots in the registry: palpad has at most 6 temporaries at once (--out, --summary-json,
/// --latency-histogram, --status, --record, --record-timing).
inline constexpr int kTempRegistrySlots = 32;
/// Longest path kept, bytes including the NUL (PATH_MAX).
inline constexpr int kTempRegistryPathBytes = 4096;

/// Records `path` (copied). Returns the slot to pass to UnregisterTempPath, or −1 when the path
/// is too long or every slot is taken (the file is then only removed by its owner).
int RegisterTempPath(const char* path) noexcept;
/// Forgets `slot` (−1: no-op). Call before or right after the file is renamed or removed.
void UnregisterTempPath(int slot) noexcept;
/// unlink(2) of every registered path; returns how many were unlinked. Async-signal-safe.
int UnlinkRegisteredTempPaths() noexcept;

}  // namespace palpa::io
