// palpad's command line. A small hand-written parser: the controller cross-builds with nothing
// but the C++ standard library. Non-RT.
#pragma once

#include <expected>
#include <span>
#include <string>

namespace palpa::palpad {

/// Exit codes.
inline constexpr int kExitOk = 0;
inline constexpr int kExitRunFailed = 1;  ///< device error during the run, or the output could not be written
inline constexpr int kExitBadInput = 2;   ///< usage error, bad field blob, bad trace, bad parameters, bad output path
inline constexpr int kExitNotBuilt = 3;   ///< the requested device backend is not in this build

/// Parsed options; defaults as documented in Usage().
struct Options {
  std::string device;             ///< "sim" (default) or "falcon"
  std::string field_path;         ///< blob v1
  std::string trace_path;         ///< HIP trace (required for --device sim)
  std::string out_path;           ///< output CSV
  std::string summary_json_path;  ///< empty: no JSON summary
  bool fast = false;
  double rate_hz = 1000;   ///< 1..10000
  double k_n_per_m = 800;  ///< checked by proxy::MakeProxyParams
  double max_force_n = 8;  ///< checked by proxy::MakeProxyParams
  bool help = false;       ///< --help/-h given: print Usage(), ignore the rest
};

/// Parses `args` (argv without the program name). `--opt value` and `--opt=value` forms.
/// Errors (one sentence): unknown option, missing or repeated value, positional argument,
/// a number that is not a finite decimal, --rate outside 1..10000, unknown --device, a missing
/// required option (--field, --out; --trace for sim).
std::expected<Options, std::string> ParseArgs(std::span<const char* const> args);

/// Multi-line usage text.
const char* Usage();

}  // namespace palpa::palpad
