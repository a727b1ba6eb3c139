// What a replay must hold, in both modes (docs/hil.md § Invariants): proxy never inside, force ≤
// clamp, force slope (releases counted apart), no force with the way clear, no drop while inside,
// proxy at the surface when felt, passivity; e-stop ticks without force, a field swap on its tick,
// a paced run's recording; and for a sphere, the paper's Fig. 9 validation against the analytic
// force. Each broken check is one sentence in Metrics::failures; the figures are reported too.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "palpa/hil/field_probe.h"
#include "palpa/hil/replay.h"
#include "palpa/hil/suite.h"
#include "palpa/hil/timing.h"

namespace palpa::hil {

/// A replay's figures (metres, newtons, joules, voxels of the field in force at the tick).
struct Metrics {
  std::size_t ticks = 0, contact_ticks = 0;
  double max_force_n = 0, max_slope_n = 0, slope_limit_n = 0, min_proxy_phi_voxels = 1e9;
  std::size_t releases = 0;  ///< contact ends with a force above the slope limit (god-object release)
  double max_release_n = 0;
  /// Issue 19: worst |Δf| − limit over the ticks held to the slope limit (≤ 0 passes), the deepest
  /// HIP (its distance from the proxy while inside, mm), holds (runs of ticks with a force and the
  /// HIP outside: the proxy held on a blocked way) and the longest, ticks with a force while the way
  /// is clear, drops to zero with the HIP inside, forces with the proxy off the surface.
  double worst_slope_excess_n = -1e9, deepest_hip_mm = 0;
  std::size_t holds = 0, longest_hold_ticks = 0, clear_way_force_ticks = 0, drops_inside = 0,
              off_surface_force_ticks = 0;
  double energy_j = 0, min_passivity_margin_j = 0;
  double max_hip_step_m = 0;
  /// Sphere (analytic) validation, when the case has one.
  bool analytic = false;
  double peak_analytic_n = 0, rms_error_n = 0, rms_error_pct = 0, rms_angle_deg = 0, max_angle_deg = 0;
  std::size_t angle_ticks = 0;
  std::vector<std::string> failures;  ///< invariant and validation failures, one sentence each
};

/// Measures `ticks` (flags filled in from the timing record) against the invariants and, for a
/// sphere case, Fig. 9. `first_field` is the field the replay starts on; `swap_field` the one from
/// tick c.swap_at on (a swap case), else nullptr. `k` N/m and `max_force` N as the replay ran.
[[nodiscard]] Metrics Measure(const std::vector<Tick>& ticks, const Case& c, const PhiField& first_field,
                              const PhiField* swap_field, double k, double max_force, const Limits& lim);

/// The checks on palpad's run beyond its ticks, appended to m.failures in this order: the exit
/// code is the case's expect_exit (the message quotes 400 bytes of stderr); every tick flagged
/// e-stop has zero force; a case wiring --estop sees it asserted; a swap case's swap lands on its
/// tick. Returns the number of e-stop ticks.
std::size_t CheckRun(const Replay& r, const std::vector<TimingRow>& timing, const Case& c, Metrics& m);

/// --record (paced runs): `recorded` (the recording read back, or its read error) must hold the
/// HIP the loop read, tick by tick (dropped samples skipped, 1e-9 m). Appends failures to m;
/// returns the note "recorded N of M HIP samples (D dropped)" (empty on a read error).
std::string CheckRecording(const Replay& r, const std::filesystem::path& recorded, Metrics& m);

/// The case's known failures (xfail) taken out of m.failures: `known` the failures an xfail
/// matched (one each), `gone` the xfails that matched none (to be removed from cases.toml).
struct KnownFailures {
  std::vector<std::string> known, gone;
};
KnownFailures SetAsideKnown(const Case& c, Metrics& m);

}  // namespace palpa::hil
