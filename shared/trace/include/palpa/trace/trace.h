// HIP traces: the CSV a simulated device replays and palpa trace synth writes. Non-RT (parsing
// and files); the servo loop reads the parsed samples from memory allocated at start-up.
//
// Format v1 (docs/trace-format.md): UTF-8 text, one sample a line `t_s,x_m,y_m,z_m` (seconds and
// device-frame metres), optional header line `t_s,x_m,y_m,z_m`, lines starting with `#` and blank
// lines ignored. Time strictly increasing, every value finite.
#pragma once

#include <array>
#include <expected>
#include <string>
#include <vector>

namespace palpa::trace {

struct TraceSample {
  double t_s = 0;
  std::array<double, 3> hip_m{};
};

/// A parse failure: `line` is 1-based (0 for file-level errors), message names the file.
struct TraceError {
  std::size_t line = 0;
  std::string message;
};

/// Reads a v1 trace. Errors: missing file, a line without exactly 4 numbers, non-finite values,
/// time not strictly increasing, fewer than 2 samples — each naming file and line.
[[nodiscard]] std::expected<std::vector<TraceSample>, TraceError> ReadTrace(const std::string& path);

/// Parses trace text (same rules); `name` is used in messages.
[[nodiscard]] std::expected<std::vector<TraceSample>, TraceError> ParseTrace(const std::string& text,
                                                                             const std::string& name);

/// Formats a v1 trace: a format comment, `comment` (if any) as a `#` line, the column line, then
/// samples with 9 significant digits for time and 10 for positions (0.1 µm at 0.1 m).
[[nodiscard]] std::string FormatTrace(const std::vector<TraceSample>& samples, const std::string& comment);

/// HIP at time t by linear interpolation between samples (clamped to the first/last sample).
/// `hint` is a cursor kept by the caller so that monotonic queries cost O(1) amortised. RT-safe.
std::array<double, 3> HipAt(const std::vector<TraceSample>& samples, double t_s, std::size_t& hint);

}  // namespace palpa::trace
