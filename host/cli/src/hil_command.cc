// palpa hil run | bless | report: hardware-in-the-loop replay (docs/hil.md). The options are
// parsed in main.cc; the harness is the palpa_hil library (hil/include/palpa/hil/): the case list
// (suite), replays through palpad (run), the invariants, the goldens and the reports. This file
// picks the cases, decides each verdict, writes the files through the host's atomic writer and
// maps outcomes to exit codes. Non-RT host code.
//  - fast (lockstep): the per-tick output must match the committed golden bit for bit;
//  - realtime: paced on the wall clock; checks invariants and reports latency, never goldens.
#include <algorithm>
#include <filesystem>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <fmt/core.h>

#include "commands.h"
#include "palpa/hil/field_probe.h"
#include "palpa/hil/golden.h"
#include "palpa/hil/report.h"
#include "palpa/hil/run.h"
#include "palpa/hil/suite.h"
#include "palpa/io/atomic_file.h"

namespace palpa::cli {
namespace {

namespace fs = std::filesystem;

constexpr int kExitFailed = 1;  // a replay did not match or broke an invariant

std::expected<void, std::string> WriteText(const fs::path& p, std::string_view text) {
  return io::WriteFileAtomically(p.string(), std::as_bytes(std::span(text.data(), text.size())));
}

int RunCases(const hil::Harness& h, const HilArgs& args, const std::string& action) {
  const bool fast = args.mode != "realtime";
  const bool bless = action == "bless";
  hil::Selection selection;
  if (bless) selection.names = args.names;
  selection.filter = args.filter;
  selection.device = args.device;
  selection.realtime = !fast;
  const std::vector<const hil::Case*> selected = hil::SelectCases(h.suite, selection);
  if (bless && args.names.empty() && !args.all) {
    fmt::print(stderr, "palpa hil bless: name the cases to bless, or --all\n");
    return kExitBadInput;
  }
  if (bless)
    for (const auto& n : args.names)
      if (std::none_of(h.suite.cases.begin(), h.suite.cases.end(), [&](const hil::Case& c) { return c.name == n; })) {
        fmt::print(stderr, "palpa hil bless: no case named '{}' in {}\n", n, h.suite.cases_path.string());
        return kExitBadInput;
      }
  if (selected.empty()) {
    fmt::print(stderr, "palpa hil: no case matches '{}'\n", args.filter);
    return kExitBadInput;
  }
  fmt::print("{}", hil::RunHeader(h, action, fast, selected.size()));
  int failed = 0;
  std::vector<std::string> results;
  hil::FieldProbes probes;
  hil::Latency all;
  for (const hil::Case* cp : selected) {
    const hil::Case& c = *cp;
    auto r = hil::ReplayCase(h, c, fast, probes);
    if (!r) {
      fmt::print(stderr, "palpa hil: {}\n", r.error());
      return kExitBadInput;
    }
    all.Append(r->latency);
    std::string verdict = r->metrics.failures.empty() ? "ok" : "FAIL";
    std::string detail;
    if (fast && !bless) {
      auto g = hil::ReadGolden(h.goldens, c.name);
      if (!g) {
        verdict = "NO GOLDEN";
        detail = "    " + g.error() + "\n";
      } else if (!hil::Reproduces(*g, r->replay)) {
        verdict = "MISMATCH";
        detail = hil::Differences(h.goldens, c.name, *g, r->replay);
      }
    }
    if (bless) {
      auto old = hil::ReadGolden(h.goldens, c.name);
      fs::create_directories(h.goldens);
      std::string what = "new golden";
      if (old)
        what = hil::Reproduces(*old, r->replay) ? "unchanged"
                                                : "changed:\n" + hil::Differences(h.goldens, c.name, *old, r->replay);
      const std::string trace_sha = hil::Sha256HexOfFile(h.suite.hil_dir / c.trace);
      const std::string toml = hil::GoldenToml(c, h.suite.fields.at(c.field), h.settings, r->replay, trace_sha);
      auto w = WriteText(hil::GoldenTicksPath(h.goldens, c.name), hil::EncodeTicks(r->replay.ticks));
      if (w) w = WriteText(hil::GoldenTomlPath(h.goldens, c.name), toml);
      if (!w) {
        fmt::print(stderr, "palpa hil bless: {}\n", w.error());
        return kExitIo;
      }
      detail = "    " + what + (what.ends_with("\n") ? "" : "\n");
      verdict = r->metrics.failures.empty() ? "blessed" : "blessed (FAILS invariants)";
    }
    if (verdict != "ok" && verdict != "blessed") ++failed;
    fmt::print("{}{}", hil::CaseText(c, *r, verdict, fast, h.suite.cases_path), detail);
    const auto series = hil::SeriesCsv(r->replay.ticks, c, *r->field, h.settings.k_n_per_m, h.settings.max_force_n);
    if (auto w = WriteText(r->replay.dir / "series.csv", series); !w) fmt::print(stderr, "palpa hil: {}\n", w.error());
    results.push_back(hil::ResultJson(c, *r, h.settings, fast, verdict));
    if (auto w = WriteText(r->replay.dir / "result.json", results.back() + "\n"); !w)
      fmt::print(stderr, "palpa hil: {}\n", w.error());
  }
  const fs::path index_path = h.work / "results" / (fast ? "fast" : "realtime") / "index.json";
  if (auto w = WriteText(index_path, hil::IndexJson(results)); !w) fmt::print(stderr, "palpa hil: {}\n", w.error());
  if (!fast) fmt::print("{}", hil::LatencySummary(all, h.settings.rate_hz));
  fmt::print("{} passed, {} failed\n", selected.size() - static_cast<std::size_t>(failed), failed);
  return failed == 0 ? kExitOk : kExitFailed;
}

}  // namespace

int RunHil(const HilArgs& args, const std::string& action) {
  hil::Harness h;
  h.palpa = hil::SelfExe();
  std::optional<fs::path> cases = args.cases.empty() ? hil::FindCases({fs::current_path(), h.palpa.parent_path()})
                                                     : std::optional<fs::path>(args.cases);
  if (!cases) {
    fmt::print(stderr, "palpa hil: no hil/cases.toml above the current directory (use --cases)\n");
    return kExitBadInput;
  }
  auto suite = hil::LoadSuite(*cases);
  if (!suite) {
    fmt::print(stderr, "palpa hil: {}\n", suite.error());
    return kExitBadInput;
  }
  h.suite = std::move(*suite);
  if (!args.palpad.empty()) {
    h.palpad = fs::absolute(args.palpad);
  } else {
    const fs::path dir = h.palpa.parent_path();
    for (const fs::path& p : {dir / "palpad", dir / ".." / ".." / "firmware" / "palpad"})
      if (fs::exists(p)) {
        h.palpad = fs::canonical(p);
        break;
      }
  }
  if (h.palpad.empty() || !fs::exists(h.palpad)) {
    fmt::print(stderr, "palpa hil: palpad not found next to {} (use --palpad)\n", h.palpa.string());
    return kExitBadInput;
  }
  h.emulator = args.emulator;
  h.work = fs::absolute(args.work.empty() ? h.suite.root / "build" / "hil-work" : fs::path(args.work));
  h.goldens = fs::absolute(args.goldens.empty() ? h.suite.hil_dir / "goldens" : fs::path(args.goldens));
  h.settings.k_n_per_m = args.k.value_or(h.suite.settings.k_n_per_m);
  h.settings.max_force_n = args.max_force.value_or(h.suite.settings.max_force_n);
  h.settings.rate_hz = args.rate.value_or(h.suite.settings.rate_hz);
  h.write_text = WriteText;
  if (action == "bless" &&
      (args.k || args.max_force || args.rate || !args.emulator.empty() || args.mode == "realtime")) {
    fmt::print(stderr, "palpa hil bless: goldens are blessed with the cases' own settings, natively, in fast mode\n");
    return kExitBadInput;
  }
  std::error_code ec;
  fs::create_directories(h.work, ec);
  if (ec) {
    fmt::print(stderr, "palpa hil: cannot create {}: {}\n", h.work.string(), ec.message());
    return kExitIo;
  }
  if (action != "report") return RunCases(h, args, action);
  const int rc = RunCases(h, args, "run");
  if (rc == kExitBadInput || rc == kExitIo) return rc;
  const fs::path results = h.work / "results" / (args.mode == "realtime" ? "realtime" : "fast");
  const hil::ScriptRun py = hil::RunReportScript(h.suite.root, results, args.report_dir, h.work);
  fmt::print("{}", py.out);
  if (py.status != 0) {
    fmt::print(stderr, "palpa hil report: {} failed (exit {}):\n{}", py.script.string(), py.status, py.err);
    return kExitIo;
  }
  return rc;
}

}  // namespace palpa::cli
