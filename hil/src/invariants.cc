#include "palpa/hil/invariants.h"

#include <algorithm>
#include <cmath>
#include <cstdint>

#include <fmt/core.h>
#include <Eigen/Core>

#include "palpa/record/run_record.h"
#include "palpa/trace/trace.h"
#include "text.h"

namespace palpa::hil {

Metrics Measure(const std::vector<Tick>& ticks, const Case& c, const PhiField& first_field, const PhiField* swap_field,
                double k, double max_force, const Limits& lim) {
  Metrics m;
  m.ticks = ticks.size();
  for (std::size_t i = 1; i < ticks.size(); ++i) {
    const Eigen::Vector3d d(ticks[i].hip[0] - ticks[i - 1].hip[0], ticks[i].hip[1] - ticks[i - 1].hip[1],
                            ticks[i].hip[2] - ticks[i - 1].hip[2]);
    m.max_hip_step_m = std::max(m.max_hip_step_m, d.norm());
  }
  m.slope_limit_n = lim.slope_factor * k * m.max_hip_step_m + lim.slope_floor_n;
  double energy = 0, bound = 0;
  std::size_t worst_phi_tick = 0, worst_slope_tick = 0, clear_tick = 0, drop_tick = 0, off_tick = 0;
  std::size_t hold_run = 0, clear_run = 0;
  double worst_off_phi = 0;
  // The proxy is not run during an e-stop, and restarts at the HIP after it, following the HIP
  // with zero force until the HIP has been outside once (proxy::ProxyTick): "never inside"
  // holds from then on. Unseated ticks are not checked (a trace starts outside: seated at once).
  bool seated = false;
  for (std::size_t i = 0; i < ticks.size(); ++i) {
    const Tick& t = ticks[i];
    const Eigen::Vector3d f(t.force[0], t.force[1], t.force[2]);
    const Eigen::Vector3d proxy(t.proxy[0], t.proxy[1], t.proxy[2]);
    m.contact_ticks += t.contact ? 1 : 0;
    m.max_force_n = std::max(m.max_force_n, f.norm());
    const bool swapped = swap_field != nullptr && c.swap_at >= 0 && i >= static_cast<std::size_t>(c.swap_at);
    const PhiField& field_at = swapped ? *swap_field : first_field;
    if ((t.flags & record::kFlagEstop) != 0) seated = false;
    // A swap whose HIP is beyond the new field's band restarts the proxy at the HIP (docs/upload.md).
    if ((t.flags & record::kFlagSwap) != 0 && t.proxy == t.hip) seated = false;
    if (!seated)
      seated = (t.flags & record::kFlagEstop) == 0 && field_at.Phi(Eigen::Vector3d(t.hip[0], t.hip[1], t.hip[2])) >= 0;
    const double phi_voxels = seated ? field_at.Phi(proxy) / field_at.voxel_m() : m.min_proxy_phi_voxels;
    if (phi_voxels < m.min_proxy_phi_voxels) {
      m.min_proxy_phi_voxels = phi_voxels;
      worst_phi_tick = i;
    }
    // Issue 19's invariants, in voxels of the field in force at this tick.
    const double vox = field_at.voxel_m();
    const Eigen::Vector3d hip(t.hip[0], t.hip[1], t.hip[2]);
    const double phi_h = field_at.Phi(hip) / vox;
    const double fn = f.norm();
    const bool exempt = (t.flags & (record::kFlagEstop | record::kFlagRamp)) != 0;
    if (fn > 0 && phi_h < 0) m.deepest_hip_mm = std::max(m.deepest_hip_mm, 1e3 * (hip - proxy).norm());
    // Held: a force with the HIP outside. Allowed only while the straight way from the proxy runs
    // into the object: deeper than where the proxy rests (or the surface) by more than δ/4 (δ =
    // the proxy's depth tolerance, here phi_tolerance); a clear way may keep the force for its
    // release tick, not two.
    const bool outside = phi_h >= 0.01;
    if (fn > 0 && outside && seated && !exempt) {
      if (++hold_run == 1) ++m.holds;
      m.longest_hold_ticks = std::max(m.longest_hold_ticks, hold_run);
      const double floor = std::min(phi_voxels, 0.0) - 0.25 * lim.phi_tolerance_voxels;
      bool clear = true;
      const Eigen::Vector3d d = hip - proxy;
      const int steps = 1 + static_cast<int>(16.0 * d.norm() / vox);  // every 1/16 voxel
      for (int s = 0; s <= steps && clear; ++s) clear = field_at.Phi(proxy + d * (double(s) / steps)) / vox >= floor;
      clear_run = clear ? clear_run + 1 : 0;
      if (clear_run >= 2) {
        if (m.clear_way_force_ticks++ == 0) clear_tick = i;
      }
    } else {
      hold_run = 0;
      clear_run = 0;
    }
    // The proxy at the surface whenever the force is felt: |φ(proxy)| ≤ ½ voxel (+ rounding).
    if (fn > 0.05 && seated && !exempt && std::abs(phi_voxels) > 0.51) {
      if (m.off_surface_force_ticks++ == 0) off_tick = i, worst_off_phi = phi_voxels;
    }
    if (i > 0) {
      const Tick& p = ticks[i - 1];
      const double slope =
          Eigen::Vector3d(t.force[0] - p.force[0], t.force[1] - p.force[1], t.force[2] - p.force[2]).norm();
      const double pn = Eigen::Vector3d(p.force[0], p.force[1], p.force[2]).norm();
      // No drop to zero while the HIP is inside.
      if (pn > 0 && fn == 0 && phi_h < -0.01 && !exempt && seated) {
        if (m.drops_inside++ == 0) drop_tick = i;
      }
      // A spring changes only as fast as its ends move: |Δf| ≤ factor·k·(|ΔX_h| + |ΔX_p|) + floor.
      // A force that ends with the HIP outside is a release (the god-object proxy leaves the surface
      // at a silhouette, or round a part the HIP went through, once the way is clear: Zilles &
      // Salisbury 1995): counted and reported, not held to the limit. Every rise, every change in
      // contact and every end with the HIP inside is.
      const double dh = Eigen::Vector3d(t.hip[0] - p.hip[0], t.hip[1] - p.hip[1], t.hip[2] - p.hip[2]).norm();
      const double dp =
          Eigen::Vector3d(t.proxy[0] - p.proxy[0], t.proxy[1] - p.proxy[1], t.proxy[2] - p.proxy[2]).norm();
      const double limit = lim.slope_factor * k * (dh + dp) + lim.slope_floor_n;
      if (fn == 0 && pn > 0 && phi_h >= -0.01 && slope > limit) {
        ++m.releases;
        m.max_release_n = std::max(m.max_release_n, slope);
      } else if (!exempt && slope - limit > m.worst_slope_excess_n) {
        m.worst_slope_excess_n = slope - limit;
        m.max_slope_n = slope;
        worst_slope_tick = i;
      }
      // Passivity observer (Hannaford & Ryu 2002), zero-order hold: E_n = −Σ f_m·(x_{m+1} − x_m);
      // a sampled spring may return at most B_n = k/2 Σ|Δx_h|² over the intervals that start or
      // end in contact (docs/realtime-core.md § Passivity observer; as proxy::PassivityObserver).
      double work = 0, dh2 = 0;
      for (std::size_t a = 0; a < 3; ++a) {
        work += p.force[a] * (t.hip[a] - p.hip[a]);
        dh2 += (t.hip[a] - p.hip[a]) * (t.hip[a] - p.hip[a]);
      }
      energy -= work;
      if (p.contact || t.contact) bound += 0.5 * k * dh2;
      m.min_passivity_margin_j = std::min(m.min_passivity_margin_j, energy + bound);
    }
  }
  m.energy_j = energy;
  if (m.max_force_n > max_force + 1e-4)
    m.failures.push_back(fmt::format("force {:.6f} N exceeds the clamp {} N", m.max_force_n, max_force));
  if (m.min_proxy_phi_voxels < -lim.phi_tolerance_voxels)
    m.failures.push_back(fmt::format("proxy inside the object at tick {}: φ = {:.4f} voxel < −{} voxel", worst_phi_tick,
                                     m.min_proxy_phi_voxels, lim.phi_tolerance_voxels));
  if (m.worst_slope_excess_n > 0)
    m.failures.push_back(fmt::format("force step {:.4f} N at tick {} exceeds the slope limit by {:.4f} N",
                                     m.max_slope_n, worst_slope_tick, m.worst_slope_excess_n));
  if (m.clear_way_force_ticks > 0)
    m.failures.push_back(
        fmt::format("force with the way clear (HIP outside, the straight way from the proxy never "
                    "below −{:.3f} voxel) on {} ticks beyond the release tick, first at tick {}",
                    0.5 * lim.phi_tolerance_voxels, m.clear_way_force_ticks, clear_tick));
  if (m.drops_inside > 0)
    m.failures.push_back(
        fmt::format("force dropped to zero with the HIP inside {} times, first at tick {}", m.drops_inside, drop_tick));
  if (m.off_surface_force_ticks > 0)
    m.failures.push_back(
        fmt::format("force above 0.05 N with the proxy off the surface (|φ| > ½ voxel) on {} ticks, "
                    "first at tick {} (φ = {:.3f} voxel)",
                    m.off_surface_force_ticks, off_tick, worst_off_phi));
  if (m.min_passivity_margin_j < -lim.energy_tolerance_j)
    m.failures.push_back(fmt::format("passivity observer: energy fell {:.3g} J below the sampled-spring bound",
                                     -m.min_passivity_margin_j));

  if (c.sphere_centre_m) {
    m.analytic = true;
    const Eigen::Vector3d centre((*c.sphere_centre_m)[0], (*c.sphere_centre_m)[1], (*c.sphere_centre_m)[2]);
    std::vector<double> fa(ticks.size());
    for (std::size_t i = 0; i < ticks.size(); ++i) {
      const Eigen::Vector3d h(ticks[i].hip[0], ticks[i].hip[1], ticks[i].hip[2]);
      fa[i] = std::min(k * std::max(0.0, c.sphere_radius_m - (h - centre).norm()), max_force);
      m.peak_analytic_n = std::max(m.peak_analytic_n, fa[i]);
    }
    double se = 0, sa = 0;
    for (std::size_t i = 0; i < ticks.size(); ++i) {
      const Eigen::Vector3d f(ticks[i].force[0], ticks[i].force[1], ticks[i].force[2]);
      se += (f.norm() - fa[i]) * (f.norm() - fa[i]);
      if (fa[i] >= 0.1 * m.peak_analytic_n && f.norm() > 0) {
        const Eigen::Vector3d h(ticks[i].hip[0], ticks[i].hip[1], ticks[i].hip[2]);
        const Eigen::Vector3d n = (h - centre).normalized();
        const double angle = std::acos(std::clamp(f.normalized().dot(n), -1.0, 1.0)) * 180.0 / M_PI;
        sa += angle * angle;
        m.max_angle_deg = std::max(m.max_angle_deg, angle);
        ++m.angle_ticks;
      }
    }
    m.rms_error_n = ticks.empty() ? 0 : std::sqrt(se / static_cast<double>(ticks.size()));
    m.rms_error_pct = m.peak_analytic_n > 0 ? 100 * m.rms_error_n / m.peak_analytic_n : 0;
    m.rms_angle_deg = m.angle_ticks > 0 ? std::sqrt(sa / static_cast<double>(m.angle_ticks)) : 0;
    if (c.validate_rms_pct && !(m.rms_error_pct <= *c.validate_rms_pct))
      m.failures.push_back(fmt::format("Fig. 9 validation: force RMS error {:.3f} % of peak > {} %", m.rms_error_pct,
                                       *c.validate_rms_pct));
    if (c.validate_angle_deg && !(m.rms_angle_deg <= *c.validate_angle_deg))
      m.failures.push_back(
          fmt::format("Fig. 9 validation: direction RMS error {:.3f}° > {}°", m.rms_angle_deg, *c.validate_angle_deg));
  }
  return m;
}

std::size_t CheckRun(const Replay& r, const std::vector<TimingRow>& timing, const Case& c, Metrics& m) {
  if (r.exit_code != c.expect_exit)
    m.failures.push_back(fmt::format("palpad exited {} (expected {}): {}", r.exit_code, c.expect_exit,
                                     detail::Replace(r.stderr_text.substr(0, 400), "\n", " | ")));
  std::size_t estop_ticks = 0, estop_force_ticks = 0;
  for (std::size_t i = 0; i < timing.size(); ++i) {
    if ((timing[i].flags & record::kFlagEstop) != 0 && i < r.ticks.size()) {
      ++estop_ticks;
      const auto& f = r.ticks[i].force;
      if (f[0] != 0 || f[1] != 0 || f[2] != 0) ++estop_force_ticks;
    }
  }
  if (estop_force_ticks > 0)
    m.failures.push_back(
        fmt::format("e-stop asserted on {} ticks, {} of them with non-zero force", estop_ticks, estop_force_ticks));
  if (estop_ticks == 0 && std::ranges::find(c.palpad, "--estop") != c.palpad.end())
    m.failures.push_back("the case wires an e-stop but no tick saw it asserted");
  if (!c.swap_field.empty()) {
    const auto swapped = std::ranges::find_if(timing, [](const auto& t) { return (t.flags & record::kFlagSwap) != 0; });
    if (swapped == timing.end())
      m.failures.push_back(
          fmt::format("the case swaps to field {} at tick {}, but no tick took it", c.swap_field, c.swap_at));
    else if (swapped - timing.begin() != c.swap_at)
      m.failures.push_back(
          fmt::format("the field swap landed on tick {}, not tick {}", swapped - timing.begin(), c.swap_at));
  }
  return estop_ticks;
}

std::string CheckRecording(const Replay& r, const std::filesystem::path& recorded, Metrics& m) {
  auto rec = trace::ReadTraceFile(recorded.string());
  if (!rec) {
    m.failures.push_back("--record: " + rec.error().message);
    return {};
  }
  const auto dropped = static_cast<std::size_t>(std::max<std::int64_t>(
      0, static_cast<std::int64_t>(r.ticks.size()) - static_cast<std::int64_t>(rec->samples.size())));
  std::size_t off = 0;
  for (std::size_t i = 0, j = 0; i < rec->samples.size() && j < r.ticks.size(); ++j) {
    if (std::abs(rec->samples[i].t_s - r.ticks[j].t_s) > 1e-9) continue;  // a dropped sample
    for (std::size_t a = 0; a < 3; ++a)
      if (std::abs(rec->samples[i].hip_m[a] - r.ticks[j].hip[a]) > 1e-9) ++off;
    ++i;
  }
  if (off > 0) m.failures.push_back(fmt::format("--record: {} coordinates differ from the HIP the loop read", off));
  return fmt::format("recorded {} of {} HIP samples ({} dropped)", rec->samples.size(), r.ticks.size(), dropped);
}

KnownFailures SetAsideKnown(const Case& c, Metrics& m) {
  KnownFailures k;
  for (const auto& x : c.xfail) {
    const auto it = std::find_if(m.failures.begin(), m.failures.end(),
                                 [&](const std::string& f) { return f.find(x) != std::string::npos; });
    if (it == m.failures.end()) {
      k.gone.push_back(x);
    } else {
      k.known.push_back(*it);
      m.failures.erase(it);
    }
  }
  return k;
}

}  // namespace palpa::hil
