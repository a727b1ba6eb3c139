#include "palpa/palpad/options.h"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <string_view>
#include <vector>

#include "palpa/device_falcon/falcon_device.h"
#include "palpa/device_sim/sim_device.h"
#include "palpa/io/escape.h"
#include "palpa/palpad/config.h"

namespace palpa::palpad {
namespace {

// Each option names the Options member it sets: adding an option is one row, and it is then
// accepted on the command line and in the config file alike.
struct OptionSpec {
  std::string_view name;
  std::string Options::*text = nullptr;  // string option
  double Options::*number = nullptr;     // number option
  bool Options::*flag = nullptr;         // flag (no value)
};

const OptionSpec kSpecs[] = {
    {"--device", &Options::device},
    {"--field", &Options::field_path},
    {"--trace", &Options::trace_path},
    {"--out", &Options::out_path},
    {"--summary-json", &Options::summary_json_path},
    {"--fast", nullptr, nullptr, &Options::fast},
    {"--rate", nullptr, &Options::rate_hz},
    {"--k", nullptr, &Options::k_n_per_m},
    {"--max-force", nullptr, &Options::max_force_n},
    {"--allow-unsafe-stiffness", nullptr, nullptr, &Options::allow_unsafe_stiffness},
    {"--firmware", &Options::firmware_path},
    {"--usb-index", nullptr, &Options::usb_index},
    {"--fault", &Options::faults},
    {"--home-timeout", nullptr, &Options::home_timeout_s},
    {"--config", &Options::config_path},
    {"--status", &Options::status_path},
    {"--latency-histogram", &Options::latency_histogram_path},
    {"--record", &Options::record_path},
    {"--record-timing", &Options::record_timing_path},
    {"--cpu", nullptr, &Options::cpu},
    {"--priority", nullptr, &Options::priority},
    {"--overrun-limit", nullptr, &Options::overrun_limit},
    {"--watchdog-ms", nullptr, &Options::watchdog_ms},
    {"--estop", &Options::estop},
    {"--estop-active", &Options::estop_active},
    {"--estop-debounce", nullptr, &Options::estop_debounce},
    {"--ramp-ms", nullptr, &Options::ramp_ms},
    {"--tick-gpio", &Options::tick_gpio},
    {"--check-config", nullptr, nullptr, &Options::check_config},
    {"--listen", &Options::listen},
    {"--key-file", &Options::key_file},
    {"--max-blob", nullptr, &Options::max_blob},
    {"--swap-ramp-ms", nullptr, &Options::swap_ramp_ms},
    {"--swap-at", &Options::swap_at},
    {"--net-timeout-ms", nullptr, &Options::net_timeout_ms},
};
constexpr std::size_t kSpecCount = std::size(kSpecs);

std::expected<double, std::string> ParseNumber(std::string_view name, std::string_view text) {
  double v = 0;
  const char* end = text.data() + text.size();
  const auto [ptr, ec] = std::from_chars(text.data(), end, v);
  if (text.empty() || ec != std::errc() || ptr != end || !std::isfinite(v))
    return std::unexpected(std::string(name) + ": '" + io::Escape(text) + "' is not a finite number");
  return v;
}

std::size_t FindSpec(std::string_view name) {
  std::size_t spec = 0;
  while (spec < kSpecCount && kSpecs[spec].name != name) ++spec;
  return spec;
}

bool WholeIn(double v, double lo, double hi) { return v >= lo && v <= hi && v == std::floor(v); }

// Applies the config file's entries to `o`, marking them in `from_config`. Errors name the file,
// the line and the key.
std::expected<void, std::string> ApplyConfig(const std::string& path, Options& o, bool (&from_config)[kSpecCount],
                                             int (&config_line)[kSpecCount]) {
  auto entries = ReadConfigFile(path);
  if (!entries) return std::unexpected(std::move(entries.error()));
  for (const ConfigEntry& e : *entries) {
    const std::string where = path + ":" + std::to_string(e.line) + ": key '" + e.key + "'";
    const std::size_t spec = FindSpec("--" + e.key);
    if (spec == kSpecCount || e.key == "config")
      return std::unexpected(path + ":" + std::to_string(e.line) + ": unknown key '" + io::Escape(e.key) +
                             "' (keys are palpad's options without the leading --)");
    const OptionSpec& opt = kSpecs[spec];
    from_config[spec] = true;
    config_line[spec] = e.line;
    if (opt.flag != nullptr) {
      if (e.kind != ConfigEntry::Kind::kBoolean) return std::unexpected(where + ": must be true or false");
      o.*opt.flag = e.boolean;
    } else if (opt.text != nullptr) {
      if (e.kind != ConfigEntry::Kind::kString) return std::unexpected(where + ": must be a string (in quotes)");
      if (e.text.empty()) return std::unexpected(where + ": must not be empty");
      o.*opt.text = e.text;
    } else {
      if (e.kind != ConfigEntry::Kind::kNumber) return std::unexpected(where + ": must be a number");
      if (!std::isfinite(e.number)) return std::unexpected(where + ": must be a finite number");
      o.*opt.number = e.number;
    }
  }
  return {};
}

std::string Figure(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

// k and the force clamp against what the device renders (issue 18, finding 3). The proxy's own
// bounds (MakeProxyParams) still apply after this; this check runs here so that --check-config
// refuses what the run would refuse.
std::expected<void, std::string> CheckDeviceLimits(const Options& o) {
  if (!(o.k_n_per_m > 0)) return std::unexpected("--k must be a stiffness > 0 N/m, got " + Figure(o.k_n_per_m));
  if (!(o.max_force_n > 0)) return std::unexpected("--max-force must be a force > 0 N, got " + Figure(o.max_force_n));
  // --allow-unsafe-stiffness lifts the device's limits up to the proxy's own bounds, never beyond.
  const device::DeviceLimits& device = o.device == "sim" ? device_sim::kSimLimits : device_falcon::kFalconLimits;
  const device::DeviceLimits& lim = o.allow_unsafe_stiffness ? device_sim::kSimLimits : device;
  const std::string hint =
      &lim == &device_sim::kSimLimits ? std::string() : " (--allow-unsafe-stiffness overrides it for experiments)";
  if (o.k_n_per_m > lim.max_stiffness_n_per_m)
    return std::unexpected("--k " + Figure(o.k_n_per_m) + " N/m is above the " + Figure(lim.max_stiffness_n_per_m) +
                           " N/m that " + lim.name + " renders stably (" + lim.source + ")" + hint);
  if (o.max_force_n > lim.max_force_n)
    return std::unexpected("--max-force " + Figure(o.max_force_n) + " N is above the " + Figure(lim.max_force_n) +
                           " N force rating of " + lim.name + " (" + lim.source + ")" + hint);
  return {};
}

// Range checks of the runtime options; the messages name the option.
std::expected<void, std::string> CheckRuntime(Options& o, const bool (&given)[kSpecCount]) {
  const auto was_given = [&](std::string_view option) { return given[FindSpec(option)]; };
  if (!WholeIn(o.cpu, -1, 1023)) return std::unexpected("--cpu must be a whole number in 0..1023 (or -1: not pinned)");
  if (!WholeIn(o.priority, 1, 99)) return std::unexpected("--priority must be a whole number in 1..99");
  if (!WholeIn(o.overrun_limit, 0, 1e6))
    return std::unexpected("--overrun-limit must be a whole number in 0..1000000 (0: never)");
  if (!(o.watchdog_ms >= 0 && o.watchdog_ms <= 10000))
    return std::unexpected("--watchdog-ms must be in 0..10000 (0: off)");
  if (!WholeIn(o.estop_debounce, 1, 100000))
    return std::unexpected("--estop-debounce must be a whole number of ticks in 1..100000");
  if (!(o.ramp_ms >= 0 && o.ramp_ms <= 10000)) return std::unexpected("--ramp-ms must be in 0..10000");
  auto active = gpio::ParseActiveLevel("--estop-active", o.estop_active);
  if (!active) return std::unexpected(std::move(active.error()));
  o.estop_active_high = *active;
  if (o.estop.starts_with("button:")) {
    // A grip button as the e-stop (a dead-man input): no GPIO chip needed; it works on every
    // device that reports buttons (the Falcon, the virtual Falcon, a replay's buttons column).
    const std::string_view bit = std::string_view(o.estop).substr(7);
    if (bit.size() != 1 || bit[0] < '0' || bit[0] > '7')
      return std::unexpected("--estop button:N needs a button bit N in 0..7 (Falcon grip: 0-3), got '" + o.estop + "'");
    o.estop_button = bit[0] - '0';
  } else if (!o.estop.empty()) {
    auto line = gpio::ParseLineSpec("--estop", o.estop);
    if (!line) return std::unexpected(std::move(line.error()));
    o.estop_line = std::move(*line);
  } else {
    for (const char* option : {"--estop-active", "--estop-debounce", "--ramp-ms"})
      if (was_given(option)) return std::unexpected(std::string(option) + " needs --estop");
  }
  if (!o.tick_gpio.empty()) {
    auto line = gpio::ParseLineSpec("--tick-gpio", o.tick_gpio);
    if (!line) return std::unexpected(std::move(line.error()));
    o.tick_line = std::move(*line);
  }
  if (o.estop_line && o.tick_line && o.estop_line->chip == o.tick_line->chip && o.estop_line->line == o.tick_line->line)
    return std::unexpected("--estop and --tick-gpio name the same line");
  if (!(o.swap_ramp_ms >= 0 && o.swap_ramp_ms <= 10000)) return std::unexpected("--swap-ramp-ms must be in 0..10000");
  if (!o.swap_at.empty()) {
    const auto colon = o.swap_at.find(':');
    auto tick = ParseNumber(
        "--swap-at", colon == std::string::npos ? std::string_view{} : std::string_view(o.swap_at).substr(0, colon));
    if (colon == std::string::npos || colon + 1 == o.swap_at.size() || !tick || !WholeIn(*tick, 0, 1e12))
      return std::unexpected("--swap-at '" + o.swap_at + "': expected TICK:FIELD.palpa, TICK a whole number ≥ 0");
    o.swap_at_tick = static_cast<std::uint64_t>(*tick);
    o.swap_at_field = o.swap_at.substr(colon + 1);
  }
  if (!o.listen.empty()) {
    const auto colon = o.listen.rfind(':');
    std::string host = colon == std::string::npos ? "" : o.listen.substr(0, colon);
    if (host.size() >= 2 && host.front() == '[' && host.back() == ']') host = host.substr(1, host.size() - 2);
    double port = -1;
    if (colon != std::string::npos) {
      auto n = ParseNumber("--listen", o.listen.substr(colon + 1));
      if (n) port = *n;
    }
    if (host.empty() || !WholeIn(port, 0, 65535))
      return std::unexpected("--listen '" + o.listen + "': expected HOST:PORT, port 0..65535 (0: any free port)");
    o.listen_host = host;
    o.listen_port = static_cast<int>(port);
    if (o.key_file.empty()) return std::unexpected("--listen needs --key-file (palpa keygen -o KEY)");
    if (!WholeIn(o.max_blob, 144, 1073741824.0))
      return std::unexpected("--max-blob must be a whole number of bytes in 144..1073741824");
    if (!(o.net_timeout_ms >= 10 && o.net_timeout_ms <= 600000))
      return std::unexpected("--net-timeout-ms must be in 10..600000");
  } else {
    for (const char* option : {"--key-file", "--max-blob", "--net-timeout-ms"})
      if (was_given(option)) return std::unexpected(std::string(option) + " needs --listen");
  }
  return {};
}

}  // namespace

const char* Usage() {
  return "usage: palpad --device sim --field F.palpa --trace T.csv --out OUT.csv [options]\n"
         "       palpad --device falcon [--firmware FW.bin] [--usb-index N] --field F.palpa --out OUT.csv\n"
         "       palpad --device virtual-falcon --trace T.csv [--firmware FW.bin] [--fault LIST] --field F.palpa "
         "--out OUT.csv\n"
         "       palpad --config /etc/palpa/palpad.toml [options]\n"
         "\n"
         "Runs the haptic servo loop (paper eq. 9 proxy, eq. 10 force) on a verified field blob.\n"
         "\n"
         "  --config PATH         TOML file of options (keys without the --); the command line wins\n"
         "  --check-config        check the options, print them as TOML and exit\n"
         "  --device DEV          HIP source (default sim): sim replays --trace; falcon drives a Novint\n"
         "                        Falcon over USB (homing first, then forces until SIGINT/SIGTERM);\n"
         "                        virtual-falcon simulates one, its hand following --trace\n"
         "  --firmware PATH       Novint firmware file, uploaded if none runs (palpa does not ship it)\n"
         "  --usb-index N         falcon: the N-th attached Falcon (default 0)\n"
         "  --fault LIST          virtual-falcon: inject faults, e.g. split@0,unplug@500 (docs/falcon.md)\n"
         "  --home-timeout S      falcon devices: homing time limit in s (default 60)\n"
         "  --field PATH          signed distance field, a blob v1 or v2 (palpa build)\n"
         "  --trace PATH          HIP trace CSV t_s,x_m,y_m,z_m (required for sim)\n"
         "  --out PATH            per-tick CSV, written as the run goes, renamed into place at the end\n"
         "                        (/dev/null: none)\n"
         "  --fast                tick back to back (deterministic replay) instead of pacing\n"
         "  --rate HZ             tick rate, 1..10000 (default 1000); sim replays at t = tick/rate\n"
         "  --k N_PER_M           stiffness k (default 800)\n"
         "  --max-force N         force clamp (default 8)\n"
         "                        k and the clamp must not exceed what the device renders: Falcon\n"
         "                        3000 N/m and 8 N (CHAI3D's specification); sim 1e5 N/m and 100 N\n"
         "  --allow-unsafe-stiffness  experiments only: accept k or a clamp above the device's limits\n"
         "  --summary-json PATH   also write the summary as JSON\n"
         "  --status PATH         live status JSON, rewritten once a second (e.g. /run/palpa/status.json)\n"
         "  --latency-histogram PATH  after the run: the wake-up latency histogram, 1 us bins, in\n"
         "                        cyclictest's -h layout (compare with cyclictest --histfile)\n"
         "  --record PATH         record the HIP as read each tick as a trace (docs/trace-format.md):\n"
         "                        binary v2 if PATH ends in .ptb, else text v2; written by the\n"
         "                        telemetry thread, never by the loop; dropped samples are reported\n"
         "  --record-timing PATH  per-tick CSV tick,t_s,wake_ns,compute_ns,total_ns,flags (same way)\n"
         "\n"
         "Real time (paced runs; docs/runtime.md):\n"
         "  --cpu N               pin the servo thread to CPU N (default: not pinned)\n"
         "  --priority P          SCHED_FIFO priority 1..99 (default 80)\n"
         "  --overrun-limit N     N consecutive overruns: zero force, fault, exit 1 (default 10; 0 never)\n"
         "  --watchdog-ms MS      a tick running longer latches a fault (default 50; 0 off)\n"
         "  --estop CHIP:LINE     e-stop input (libgpiod), e.g. gpiochip0:17: zero force while asserted\n"
         "  --estop button:N      or the device's grip button N (0..7) as the e-stop (read a tick late)\n"
         "  --estop-active LEVEL  high (default) or low: the level that asserts the e-stop\n"
         "  --estop-debounce N    released reads (ticks) before a release counts (default 5)\n"
         "  --ramp-ms MS          after a release the force ramps in over MS (default 500)\n"
         "  --tick-gpio CHIP:LINE output toggled every tick (measure period and jitter with a scope)\n"
         "\n"
         "Upload (docs/upload.md):\n"
         "  --listen HOST:PORT    accept field uploads and status requests while the loop runs\n"
         "                        (port 0: any free port, printed on stderr)\n"
         "  --key-file PATH       shared key (palpa keygen), mode 0600; required with --listen\n"
         "  --max-blob BYTES      largest field accepted; two buffers this size are allocated at\n"
         "                        start-up (default 67108864 = 64 MiB)\n"
         "  --swap-ramp-ms MS     after a field swap the force ramps in over MS (default 50)\n"
         "  --swap-at N:FIELD     replays: swap to FIELD on tick N (as an upload would, on a known tick)\n"
         "  --net-timeout-ms MS   header deadline and body idle limit per request (default 2000)\n"
         "  --help                this text\n"
         "\n"
         "exit: 0 ok, 1 device error, fault or output not written, 2 bad input, 3 device not available\n";
}

std::expected<Options, std::string> ParseArgs(std::span<const char* const> args) {
  for (const char* a : args) {
    const std::string_view arg(a);
    if (arg == "--help" || arg == "-h") {
      Options o;
      o.help = true;
      return o;
    }
  }

  // Pass 1: the config file, if any, sets the starting values.
  Options o;
  bool from_config[kSpecCount] = {};
  int config_line[kSpecCount] = {};
  std::string config_path;
  for (std::size_t i = 0; i < args.size(); ++i) {
    const std::string_view arg(args[i]);
    std::string_view path;
    if (arg.starts_with("--config=")) {
      path = arg.substr(9);
    } else if (arg == "--config" && i + 1 < args.size()) {
      path = args[i + 1];
    } else {
      continue;
    }
    if (path.empty()) return std::unexpected("--config needs a non-empty value");
    config_path = std::string(path);
    if (auto applied = ApplyConfig(config_path, o, from_config, config_line); !applied)
      return std::unexpected(std::move(applied.error()));
    break;  // a second --config is reported as "given twice" below
  }

  // Pass 2: the command line overrides.
  bool seen[kSpecCount] = {};
  for (std::size_t i = 0; i < args.size(); ++i) {
    const std::string_view arg(args[i]);
    if (!arg.starts_with("--")) return std::unexpected("unexpected argument '" + std::string(arg) + "'");
    const auto eq = arg.find('=');
    const std::string_view name = arg.substr(0, eq);
    const std::size_t spec = FindSpec(name);
    if (spec == kSpecCount) return std::unexpected("unknown option '" + std::string(name) + "'");
    if (seen[spec]) return std::unexpected(std::string(name) + " given twice");
    seen[spec] = true;

    const OptionSpec& opt = kSpecs[spec];
    if (opt.flag != nullptr) {
      if (eq != std::string_view::npos) return std::unexpected(std::string(name) + " takes no value");
      o.*opt.flag = true;
      continue;
    }
    std::string_view value;
    if (eq != std::string_view::npos) {
      value = arg.substr(eq + 1);
    } else if (i + 1 < args.size()) {
      value = args[++i];
    } else {
      return std::unexpected(std::string(name) + " needs a value");
    }
    if (value.empty()) return std::unexpected(std::string(name) + " needs a non-empty value");
    if (opt.text != nullptr) {
      o.*opt.text = std::string(value);
      continue;
    }
    auto number = ParseNumber(name, value);
    if (!number) return std::unexpected(std::move(number.error()));
    o.*opt.number = *number;
  }
  bool given[kSpecCount] = {};
  for (std::size_t i = 0; i < kSpecCount; ++i) given[i] = seen[i] || from_config[i];
  const auto was_given = [&](std::string_view option) { return given[FindSpec(option)]; };

  // Every range check below names its option first ("--rate must be …"); when that value came
  // from the config file, the message also names the file and the line (issue 18, finding 11).
  const auto checks = [&]() -> std::expected<void, std::string> {
    if (o.device.empty()) o.device = "sim";  // the simulated device is the default
    if (o.device != "sim" && o.device != "falcon" && o.device != "virtual-falcon")
      return std::unexpected("--device: unknown device '" + o.device + "' (sim, falcon or virtual-falcon)");
    if (o.device == "virtual-falcon" && o.trace_path.empty())
      return std::unexpected("--trace is required with --device virtual-falcon");
    if (o.device == "falcon" && !o.trace_path.empty())
      return std::unexpected("--trace: the real Falcon is moved by hand (use --device virtual-falcon to replay)");
    if (o.device == "sim" && !o.firmware_path.empty()) return std::unexpected("--firmware needs a Falcon device");
    if (o.device != "falcon" && was_given("--usb-index")) return std::unexpected("--usb-index needs --device falcon");
    if (o.device != "virtual-falcon" && !o.faults.empty())
      return std::unexpected("--fault needs --device virtual-falcon");
    if (!(o.usb_index >= 0 && o.usb_index <= 127 && o.usb_index == std::floor(o.usb_index)))
      return std::unexpected("--usb-index must be a whole number in 0..127");
    if (!(o.home_timeout_s >= 1 && o.home_timeout_s <= 3600))
      return std::unexpected("--home-timeout must be in 1..3600 s");
    if (o.field_path.empty()) return std::unexpected("--field is required");
    if (o.out_path.empty()) return std::unexpected("--out is required");
    if (o.device == "sim" && o.trace_path.empty()) return std::unexpected("--trace is required with --device sim");
    if (!(o.rate_hz >= 1 && o.rate_hz <= 10000)) return std::unexpected("--rate must be in 1..10000 Hz");
    if (auto limits = CheckDeviceLimits(o); !limits) return std::unexpected(std::move(limits.error()));
    if (auto runtime = CheckRuntime(o, given); !runtime) return std::unexpected(std::move(runtime.error()));
    return {};
  };
  if (auto checked = checks(); !checked) {
    const std::string& message = checked.error();
    const std::size_t end = message.find_first_of(" =':");
    const std::size_t spec = FindSpec(std::string_view(message).substr(0, end));
    if (spec < kSpecCount && from_config[spec] && !seen[spec])
      return std::unexpected(config_path + ":" + std::to_string(config_line[spec]) + ": key '" +
                             std::string(kSpecs[spec].name.substr(2)) + "': " + message);
    return std::unexpected(message);
  }
  return o;
}

std::string OptionsToml(const Options& o) {
  // Only what differs from the defaults (and the device): the output is itself a valid config.
  const Options defaults;
  std::string out = "# palpad options (palpad --check-config)\n";
  for (const OptionSpec& opt : kSpecs) {
    const std::string key(opt.name.substr(2));
    if (key == "config" || key == "check-config") continue;
    if (opt.flag != nullptr) {
      if (o.*opt.flag) out += key + " = true\n";
    } else if (opt.text != nullptr) {
      const std::string& v = o.*opt.text;
      if (v.empty() || (v == defaults.*opt.text && key != "device")) continue;
      std::string quoted = "\"";
      for (const char ch : v) {
        if (ch == '"' || ch == '\\') quoted += '\\';
        quoted += ch;
      }
      out += key + " = " + quoted + "\"\n";
    } else {
      if (o.*opt.number == defaults.*opt.number) continue;
      char buf[64];
      std::snprintf(buf, sizeof buf, "%.17g", o.*opt.number);
      out += key + " = " + buf + "\n";
    }
  }
  return out;
}

}  // namespace palpa::palpad
