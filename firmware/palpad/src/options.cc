#include "palpa/palpad/options.h"

#include <charconv>
#include <cmath>
#include <string_view>

namespace palpa::palpad {
namespace {

// Each option names the Options member it sets: adding an option is one row.
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
};

std::expected<double, std::string> ParseNumber(std::string_view name, std::string_view text) {
  double v = 0;
  const char* end = text.data() + text.size();
  const auto [ptr, ec] = std::from_chars(text.data(), end, v);
  if (text.empty() || ec != std::errc() || ptr != end || !std::isfinite(v))
    return std::unexpected(std::string(name) + ": '" + std::string(text) + "' is not a finite number");
  return v;
}

}  // namespace

const char* Usage() {
  return "usage: palpad --device sim --field F.palpa --trace T.csv --out OUT.csv [options]\n"
         "\n"
         "Runs the haptic servo loop (paper eq. 9 proxy, eq. 10 force) on a verified field blob.\n"
         "\n"
         "  --device sim|falcon   HIP source (default sim): sim replays --trace (falcon: not built yet)\n"
         "  --field PATH          signed distance field, blob v1 (palpa build)\n"
         "  --trace PATH          HIP trace CSV t_s,x_m,y_m,z_m (required for sim)\n"
         "  --out PATH            per-tick CSV, written atomically at the end\n"
         "  --fast                tick back to back (deterministic replay) instead of pacing\n"
         "  --rate HZ             tick rate, 1..10000 (default 1000); sim replays at t = tick/rate\n"
         "  --k N_PER_M           stiffness k (default 800)\n"
         "  --max-force N         force clamp (default 8)\n"
         "  --summary-json PATH   also write the summary as JSON\n"
         "  --help                this text\n"
         "\n"
         "exit: 0 ok, 1 device error or output not written, 2 bad input, 3 backend not built\n";
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

  Options o;
  bool seen[std::size(kSpecs)] = {};
  for (std::size_t i = 0; i < args.size(); ++i) {
    const std::string_view arg(args[i]);
    if (!arg.starts_with("--")) return std::unexpected("unexpected argument '" + std::string(arg) + "'");
    const auto eq = arg.find('=');
    const std::string_view name = arg.substr(0, eq);
    std::size_t spec = 0;
    while (spec < std::size(kSpecs) && kSpecs[spec].name != name) ++spec;
    if (spec == std::size(kSpecs)) return std::unexpected("unknown option '" + std::string(name) + "'");
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

  if (o.device.empty()) o.device = "sim";  // the simulated device is the default
  if (o.device != "sim" && o.device != "falcon")
    return std::unexpected("--device: unknown device '" + o.device + "' (sim or falcon)");
  if (o.field_path.empty()) return std::unexpected("--field is required");
  if (o.out_path.empty()) return std::unexpected("--out is required");
  if (o.device == "sim" && o.trace_path.empty()) return std::unexpected("--trace is required with --device sim");
  if (!(o.rate_hz >= 1 && o.rate_hz <= 10000)) return std::unexpected("--rate must be in 1..10000 Hz");
  return o;
}

}  // namespace palpa::palpad
