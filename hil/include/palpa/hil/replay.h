// What one replay of a case left behind: palpad's per-tick output CSV (shared/record's run record)
// read into ticks, its summary, exit status and device report. The goldens, the invariants and the
// reports all read this. Non-RT host code.
#pragma once

#include <array>
#include <cstdint>
#include <expected>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

namespace palpa::hil {

/// Goldens store forces in units of 2^-24 N (exact for palpad's Q16.16 forces times its ramps).
inline constexpr double kForceScale = 16777216.0;

/// One tick of palpad's output. Device frame, metres and newtons.
struct Tick {
  double t_s = 0;
  std::array<double, 3> hip{}, proxy{}, force{};
  bool contact = false;
  std::array<std::int32_t, 3> force_q24{};  ///< force in 2^-24 N (rounded from the CSV's force_n)
  std::uint16_t row_hash = 0;               ///< RowHash of the CSV row's text
  std::uint8_t flags = 0;  ///< deterministic telemetry flags (record::kDeterministicFlags), from timing.csv
};

/// FNV-1a (32-bit) of a CSV row's text, folded to 16 bits: a golden's per-tick witness of the
/// whole row (HIP, proxy, force, contact) at two bytes a tick.
[[nodiscard]] std::uint16_t RowHash(std::string_view line);

/// palpad's output CSV (record::kCsvHeader, then record::ParseCsvRow rows; blank lines skipped),
/// flags left 0. An empty text or one without a line end is no ticks. Error: "NAME:LINE: why",
/// `name` being the path to report.
[[nodiscard]] std::expected<std::vector<Tick>, std::string> ParseOutput(const std::string& csv,
                                                                        const std::string& name);

/// A replay (or a case's `output` measured as one).
struct Replay {
  int exit_code = -1;  ///< palpad's exit status (128 + signal if killed); a case's expect_exit for `output`
  std::string csv;     ///< out.csv, byte for byte (its SHA-256 is in the golden)
  std::vector<Tick> ticks;
  std::string summary_json;   ///< palpad --summary-json (empty for `output`)
  std::string stderr_text;    ///< palpad's stderr
  std::string device_report;  ///< the Falcon driver's end-of-run lines from stderr (deterministic)
  double wall_s = 0;          ///< wall time of the run, s
  std::filesystem::path dir;  ///< results/MODE/NAME: the run's files (docs/hil.md § Layout)
};

}  // namespace palpa::hil
