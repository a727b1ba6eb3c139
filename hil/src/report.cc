#include "palpa/hil/report.h"

#include <algorithm>
#include <utility>

#include <fmt/core.h>
#include <fmt/format.h>
#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "text.h"

namespace palpa::hil {

namespace fs = std::filesystem;

// result.json and index.json keep their keys in the order written.
using Json = nlohmann::ordered_json;

std::string RunHeader(const Harness& h, const std::string& action, bool fast, std::size_t cases) {
  return fmt::format("palpa hil {} ({}): {} case(s), palpad {}{}, k {} N/m, max force {} N, rate {} Hz\n", action,
                     fast ? "fast, lockstep" : "realtime, paced", cases, h.palpad.string(),
                     h.emulator.empty() ? "" : " under " + detail::Join(h.emulator), h.settings.k_n_per_m,
                     h.settings.max_force_n, h.settings.rate_hz);
}

std::string CaseText(const Case& c, const CaseResult& r, const std::string& verdict, bool fast,
                     const fs::path& cases_path) {
  const Metrics& m = r.metrics;
  std::string out = fmt::format(
      "  {:<32} {:<14} {:>6} ticks {:>6} contact  max |f| {:7.3f} N  φmin {:+.3f} vx  {:6.2f} s  {}\n", c.name,
      c.device, m.ticks, m.contact_ticks, m.max_force_n, m.min_proxy_phi_voxels, r.replay.wall_s, verdict);
  if (m.analytic)
    out += fmt::format(
        "      sphere (Fig. 9): peak {:.3f} N, force RMS error {:.4f} N = {:.3f} % of peak, direction RMS "
        "{:.3f}° (max {:.3f}°, {} ticks)\n",
        m.peak_analytic_n, m.rms_error_n, m.rms_error_pct, m.rms_angle_deg, m.max_angle_deg, m.angle_ticks);
  if (!fast) {
    const Percentiles pw = Figures(r.latency.wake_ns), pc = Figures(r.latency.compute_ns),
                      pt = Figures(r.latency.total_ns);
    out += fmt::format(
        "      latency (µs, {} ticks): wake-up p50 {:.1f} p99 {:.1f} p99.9 {:.1f} max {:.1f}; compute p50 {:.1f} "
        "p99 {:.1f} max {:.1f}; total p99 {:.1f} max {:.1f}; {}\n",
        pw.count, pw.p50, pw.p99, pw.p999, pw.max, pc.p50, pc.p99, pc.max, pt.p99, pt.max, r.recorded_note);
  }
  out += fmt::format(
      "      deepest HIP {:.2f} mm, worst slope excess {:+.4f} N, releases {} (largest {:.3f} N), holds {} "
      "(longest {} ticks)\n",
      m.deepest_hip_mm, m.ticks > 1 ? m.worst_slope_excess_n : 0.0, m.releases, m.max_release_n, m.holds,
      m.longest_hold_ticks);
  for (const auto& f : m.failures) out += fmt::format("    invariant: {}\n", f);
  for (const auto& f : r.known.known) out += fmt::format("    known failure (xfail in cases.toml): {}\n", f);
  for (const auto& x : r.known.gone)
    out += fmt::format("    xfail '{}' no longer occurs: remove it from {}\n", x, cases_path.string());
  return out;
}

std::string LatencySummary(const Latency& all, double rate_hz) {
  const Percentiles w = Figures(all.wake_ns), c = Figures(all.compute_ns), t = Figures(all.total_ns);
  std::string out = fmt::format("latency over all {} ticks at {} Hz (µs):\n", w.count, rate_hz);
  out += fmt::format("  {:<16} {:>8} {:>8} {:>8} {:>9}\n", "", "p50", "p99", "p99.9", "max");
  for (const auto& [name, p] : {std::pair{"wake-up latency", w}, std::pair{"compute", c}, std::pair{"total", t}})
    out += fmt::format("  {:<16} {:>8.1f} {:>8.1f} {:>8.1f} {:>9.1f}\n", name, p.p50, p.p99, p.p999, p.max);
  return out;
}

std::string SeriesCsv(const std::vector<Tick>& ticks, const Case& c, const PhiField& field, double k,
                      double max_force) {
  std::string out = "t_s,force_n,analytic_n,spring_m,phi_hip_m,phi_proxy_m,analytic_depth_m\n";
  for (const Tick& t : ticks) {
    const Eigen::Vector3d h(t.hip[0], t.hip[1], t.hip[2]), p(t.proxy[0], t.proxy[1], t.proxy[2]);
    const Eigen::Vector3d f(t.force[0], t.force[1], t.force[2]);
    std::string analytic = ",", depth;
    if (c.sphere_centre_m) {
      const Eigen::Vector3d centre((*c.sphere_centre_m)[0], (*c.sphere_centre_m)[1], (*c.sphere_centre_m)[2]);
      const double d = c.sphere_radius_m - (h - centre).norm();
      analytic = fmt::format("{:.9g},", std::min(k * std::max(0.0, d), max_force));
      depth = fmt::format("{:.9g}", std::max(0.0, d));
    }
    out += fmt::format("{:.9g},{:.9g},{}{:.9g},{:.9g},{:.9g},{}\n", t.t_s, f.norm(), analytic, (h - p).norm(),
                       field.Phi(h), field.Phi(p), depth);
  }
  return out;
}

std::string ResultJson(const Case& c, const CaseResult& r, const Settings& s, bool fast, const std::string& verdict) {
  const Metrics& m = r.metrics;
  Json j = {{"case", c.name},
            {"mode", fast ? "fast" : "realtime"},
            {"device", c.device},
            {"field", c.field},
            {"trace", c.trace},
            {"why", c.why},
            {"k_n_per_m", s.k_n_per_m},
            {"max_force_n", s.max_force_n},
            {"rate_hz", s.rate_hz},
            {"exit_code", r.replay.exit_code},
            {"wall_s", r.replay.wall_s},
            {"ticks", m.ticks},
            {"contact_ticks", m.contact_ticks},
            {"max_force_n_seen", m.max_force_n},
            {"max_slope_n", m.max_slope_n},
            {"slope_limit_n", m.slope_limit_n},
            {"releases", m.releases},
            {"max_release_n", m.max_release_n},
            {"worst_slope_excess_n", m.worst_slope_excess_n},
            {"deepest_hip_mm", m.deepest_hip_mm},
            {"holds", m.holds},
            {"longest_hold_ticks", m.longest_hold_ticks},
            {"clear_way_force_ticks", m.clear_way_force_ticks},
            {"drops_inside", m.drops_inside},
            {"off_surface_force_ticks", m.off_surface_force_ticks},
            {"min_proxy_phi_voxels", m.min_proxy_phi_voxels},
            {"energy_j", m.energy_j},
            {"min_passivity_margin_j", m.min_passivity_margin_j}};
  if (m.analytic) {
    j["analytic"] = {{"kind", "sphere"},
                     {"centre_m", *c.sphere_centre_m},
                     {"radius_m", c.sphere_radius_m},
                     {"peak_n", m.peak_analytic_n},
                     {"rms_error_n", m.rms_error_n},
                     {"rms_error_pct", m.rms_error_pct},
                     {"rms_angle_deg", m.rms_angle_deg},
                     {"max_angle_deg", m.max_angle_deg},
                     {"angle_ticks", m.angle_ticks}};
  }
  auto fig = [](const Percentiles& p) {
    return Json{{"count", p.count}, {"p50_us", p.p50}, {"p99_us", p.p99}, {"p999_us", p.p999}, {"max_us", p.max}};
  };
  j["latency"] = {{"wake", fig(Figures(r.latency.wake_ns))},
                  {"compute", fig(Figures(r.latency.compute_ns))},
                  {"total", fig(Figures(r.latency.total_ns))}};
  j["estop_ticks"] = r.estop_ticks;
  j["failures"] = m.failures;
  j["verdict"] = verdict;
  Json summary = Json::parse(r.replay.summary_json, nullptr, /*allow_exceptions=*/false);
  j["summary"] = summary.is_discarded() ? Json(nullptr) : std::move(summary);  // none, or not JSON
  // (A path or message that is not UTF-8 is written with U+FFFD rather than failing the run.)
  return j.dump(-1, ' ', false, Json::error_handler_t::replace);
}

std::string IndexJson(const std::vector<std::string>& results) {
  std::string index = "[";
  for (const auto& json : results) index += (index.size() > 1 ? ",\n" : "\n") + json;  // one case a line
  return index + "\n]\n";
}

ScriptRun RunReportScript(const fs::path& root, const fs::path& results, const fs::path& out_dir,
                          const fs::path& work) {
  ScriptRun s;
  s.script = root / "scripts" / "hil-report.py";
  const std::vector<std::string> argv = {
      "/usr/bin/python3", s.script.string(), "--results", results.string(), "-o", fs::absolute(out_dir).string()};
  s.status = Spawn(argv, work / "report.log", work / "report.err", root);
  s.out = detail::Slurp(work / "report.log");
  s.err = detail::Slurp(work / "report.err");
  return s;
}

}  // namespace palpa::hil
