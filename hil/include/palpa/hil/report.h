// What `palpa hil` reports of its replays: the lines it prints (docs/hil.md shows them), each
// case's result.json and series.csv, the run's index.json, and the HTML pages of
// `palpa hil report` (scripts/hil-report.py over the results). Texts only; writing is the caller's.
#pragma once

#include <cstddef>
#include <filesystem>
#include <string>
#include <vector>

#include "palpa/hil/run.h"
#include "palpa/hil/suite.h"
#include "palpa/hil/timing.h"

namespace palpa::hil {

/// The first line: "palpa hil ACTION (MODE): N case(s), palpad PATH[ under EMULATOR], k .., max
/// force .., rate ..\n".
[[nodiscard]] std::string RunHeader(const Harness& h, const std::string& action, bool fast, std::size_t cases);

/// A case's lines: name, device, ticks, contact, max |f|, φmin, wall time and `verdict`; the
/// sphere's Fig. 9 figures; paced, its latency (µs) and recording note; deepest HIP, worst slope
/// excess, releases and holds; then each failure ("invariant: ..."), known failure and xfail that
/// no longer occurs (naming the case list to remove it from).
[[nodiscard]] std::string CaseText(const Case& c, const CaseResult& r, const std::string& verdict, bool fast,
                                   const std::filesystem::path& cases_path);

/// After a paced run: the latency table over all its ticks at `rate_hz` (µs).
[[nodiscard]] std::string LatencySummary(const Latency& all, double rate_hz);

/// series.csv, one row a tick: t_s, |f|, analytic |f| (sphere; empty otherwise), spring
/// |X_h − X_p|, φ(HIP), φ(proxy) on `field`, analytic HIP depth — seconds, newtons, metres.
[[nodiscard]] std::string SeriesCsv(const std::vector<Tick>& ticks, const Case& c, const PhiField& field, double k,
                                    double max_force);

/// result.json on one line (no line end): the case, mode, settings, the metrics, the analytic
/// figures, latency, e-stop ticks, failures, verdict and palpad's own summary (null if none or
/// not JSON). Keys in this order; text that is not UTF-8 is written with U+FFFD.
[[nodiscard]] std::string ResultJson(const Case& c, const CaseResult& r, const Settings& s, bool fast,
                                     const std::string& verdict);

/// index.json: the results as a JSON array, one a line.
[[nodiscard]] std::string IndexJson(const std::vector<std::string>& results);

/// scripts/hil-report.py (under `root`, run there with /usr/bin/python3) on `results`, writing
/// its pages to `out_dir`; its stdout and stderr are kept in WORK/report.log and report.err.
struct ScriptRun {
  int status = -1;  ///< Spawn's
  std::string out, err;
  std::filesystem::path script;
};
[[nodiscard]] ScriptRun RunReportScript(const std::filesystem::path& root, const std::filesystem::path& results,
                                        const std::filesystem::path& out_dir, const std::filesystem::path& work);

}  // namespace palpa::hil
