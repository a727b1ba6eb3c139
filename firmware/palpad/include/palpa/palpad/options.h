// palpad's command line and config file. A small hand-written parser over one option table: the
// config file (--config, TOML; config.h) sets the same options, and the command line wins.
// Non-RT.
#pragma once

#include <cstdint>
#include <expected>
#include <optional>
#include <span>
#include <string>

#include "palpa/gpio/gpio.h"

namespace palpa::palpad {

/// Exit codes.
inline constexpr int kExitOk = 0;
inline constexpr int kExitRunFailed = 1;  ///< device error during the run, or the output could not be written
inline constexpr int kExitBadInput = 2;   ///< usage error, bad field blob, bad trace, bad parameters, bad output path
inline constexpr int kExitNotBuilt = 3;   ///< the requested device backend is not in this build
inline constexpr int kExitNoDevice = 3;   ///< the device is not available (no Falcon, no access, no firmware)

/// Parsed options; defaults as documented in Usage().
struct Options {
  std::string device;             ///< "sim" (default), "falcon" or "virtual-falcon"
  std::string field_path;         ///< blob v1 or v2
  std::string trace_path;         ///< HIP trace (required for --device sim)
  std::string out_path;           ///< output CSV
  std::string summary_json_path;  ///< empty: no JSON summary
  std::string firmware_path;      ///< falcon/virtual-falcon: Novint firmware to upload if none runs
  std::string faults;             ///< virtual-falcon: fault injection list (device_virtual_falcon::ParseFaults)
  double usb_index = 0;           ///< falcon: which 0403:cb48 device (0-based, whole number)
  double home_timeout_s = 60;     ///< falcon/virtual-falcon: homing time limit, 1..3600 s
  bool fast = false;
  double rate_hz = 1000;   ///< 1..10000
  double k_n_per_m = 800;  ///< > 0 and ≤ the device's limit (device/limits.h), unless allow_unsafe_stiffness
  double max_force_n = 8;  ///< > 0 and ≤ the device's force rating, unless allow_unsafe_stiffness
  /// --allow-unsafe-stiffness: experiments only: k and max force above the device's limits (still
  /// within the proxy's bounds, 1e5 N/m and 100 N).
  bool allow_unsafe_stiffness = false;
  bool help = false;  ///< --help/-h given: print Usage(), ignore the rest

  // Runtime (issue 9, docs/runtime.md).
  std::string config_path;             ///< --config: TOML file read before the command line
  std::string status_path;             ///< --status: live status JSON, rewritten once a second
  std::string latency_histogram_path;  ///< --latency-histogram: wake-up histogram after the run (cyclictest layout)
  std::string record_path;             ///< --record: the HIP as read, a trace (.ptb binary, else text v2)
  std::string record_timing_path;      ///< --record-timing: per-tick wake-up latency and compute time, CSV
  double cpu = -1;                     ///< --cpu: pin the servo thread to this CPU; −1: not pinned
  double priority = 80;                ///< --priority: SCHED_FIFO priority of the servo thread, 1..99
  double overrun_limit = 10;           ///< --overrun-limit: consecutive overruns → fault; 0: never
  double watchdog_ms = 50;             ///< --watchdog-ms: a tick running longer trips the watchdog; 0: off
  std::string estop;  ///< --estop CHIP:LINE or button:N (raw text; parsed into estop_line / estop_button)
  std::string estop_active = "high";  ///< --estop-active high|low
  double estop_debounce = 5;          ///< --estop-debounce: released reads (ticks) before a release counts
  double ramp_ms = 500;               ///< --ramp-ms: force ramp after an e-stop release, ms
  std::string tick_gpio;              ///< --tick-gpio CHIP:LINE (raw text; parsed into tick_line)
  bool check_config = false;          ///< --check-config: validate the options, print them, exit

  // Upload (issue 7, docs/upload.md).
  std::string listen;                    ///< --listen HOST:PORT (port 0: ephemeral, printed); empty: no listener
  std::string key_file;                  ///< --key-file: the shared key (palpa keygen), mode 0600
  double max_blob = 64.0 * 1024 * 1024;  ///< --max-blob: upload cap and buffer size, bytes
  double swap_ramp_ms = 50;              ///< --swap-ramp-ms: force ramp after a field swap, ms
  std::string swap_at;                   ///< --swap-at N:FIELD (raw; parsed into swap_at_tick, swap_at_field)
  std::uint64_t swap_at_tick = 0;        ///< offer swap_at_field during tick N (replays; scripted_swap.h)
  std::string swap_at_field;             ///< empty: no scripted swap
  double net_timeout_ms = 2000;          ///< --net-timeout-ms: header deadline, body idle limit

  // Parsed from the above by ParseArgs.
  std::optional<gpio::LineSpec> estop_line;
  int estop_button = -1;  ///< --estop button:N: the device's grip button N (0..7) is the e-stop; -1 none
  bool estop_active_high = true;
  std::optional<gpio::LineSpec> tick_line;
  std::string listen_host;  ///< from --listen
  int listen_port = 0;      ///< from --listen
};

/// Parses `args` (argv without the program name). `--opt value` and `--opt=value` forms. With
/// --config PATH, the file's keys are applied first and the command line overrides them.
/// Errors (one sentence): unknown option, missing or repeated value, positional argument,
/// a number that is not a finite decimal, --rate outside 1..10000, unknown --device, a missing
/// required option (--field, --out; --trace for sim), a bad CHIP:LINE, a runtime option out of
/// range. Config file errors name the file, line and key: "palpad.toml:4: key 'rate': …".
std::expected<Options, std::string> ParseArgs(std::span<const char* const> args);

/// The effective options as TOML (what --check-config prints; a valid config file).
std::string OptionsToml(const Options& o);

/// Multi-line usage text.
const char* Usage();

}  // namespace palpa::palpad
