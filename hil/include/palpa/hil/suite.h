// The HIL suite: hil/cases.toml as a model (docs/hil.md § Layout). Each case replays a trace from
// hil/traces/ through palpad on a field built at run time from the bundled data (or a committed
// blob), on a device, with the limits the invariants hold it to. Non-RT host code.
#pragma once

#include <array>
#include <cstdint>
#include <expected>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace palpa::hil {

/// How a case's field is made: `palpa build` at run time (the default), or a committed blob.
struct FieldSpec {
  std::vector<std::string> prepare;  ///< palpa commands run first, words split on spaces ({work} substituted)
  std::string build;                 ///< "build POINTS ..." (without -o), or empty with `blob`
  std::string blob;                  ///< a committed blob, relative to the suite's root
};

/// What the invariants allow (cases.toml [defaults]); the comments give each check.
struct Limits {
  double phi_tolerance_voxels = 0.26;  ///< proxy never inside: φ(proxy) ≥ −this (δ = 0.25 voxel + rounding)
  double slope_factor = 2.0;           ///< |Δf| ≤ factor·k·(|ΔX_h| + |ΔX_p|) + slope_floor_n per tick
  double slope_floor_n = 0.01;         ///< N
  double energy_tolerance_j = 1e-6;    ///< passivity: E_n ≥ −B_n − this, J
};

/// The servo settings a replay runs with: the suite's [defaults], or palpa hil's overrides.
struct Settings {
  double rate_hz = 1000;
  double k_n_per_m = 800;
  double max_force_n = 8;
};

/// One [[case]].
struct Case {
  std::string name, trace, field, device, why;  ///< trace: relative to hil/; device: sim | virtual-falcon
  std::vector<std::string> palpad;              ///< extra palpad arguments
  int expect_exit = 0;
  std::optional<std::array<double, 3>> sphere_centre_m;  ///< analytic truth (Fig. 9), when set
  double sphere_radius_m = 0;
  std::optional<double> validate_rms_pct, validate_angle_deg;  ///< Fig. 9 thresholds, when set
  bool realtime = true;                                        ///< also replayed by --realtime
  /// A field swap mid-replay (palpad --swap-at): tick swap_at runs on swap_field. Both or neither.
  std::string swap_field;
  std::int64_t swap_at = -1;
  /// Known failures (substrings of failure sentences), each with its reason in cases.toml: reported
  /// as "known", not counted; one that no longer occurs is reported so that it gets removed.
  std::vector<std::string> xfail;
  /// A palpad output CSV (relative to the case list) measured instead of a replay: checks the
  /// invariants on a run made elsewhere (and lets tests feed violating runs); never a golden.
  std::string output;
};

/// A parsed case list. Paths are absolute: `cases_path` the file, `hil_dir` its folder (traces and
/// outputs are relative to it), `root` the folder above (blobs, field builds and palpad run there).
struct Suite {
  std::filesystem::path root, hil_dir, cases_path;
  Settings settings;
  Limits limits;
  std::map<std::string, FieldSpec> fields;
  std::vector<Case> cases;  ///< in file order, names unique
};

/// Parses a case list. Error: "FILE:LINE: why" (FILE:LINE:COLUMN for TOML syntax); a problem with
/// one key names that key's line, else its [[case]]'s or field's line; "FILE: no [fields] table"
/// and "FILE: no [[case]] entries" name no line.
[[nodiscard]] std::expected<Suite, std::string> LoadSuite(const std::filesystem::path& cases_path);

/// hil/cases.toml in the first of `starts` or a folder above it that has one.
[[nodiscard]] std::optional<std::filesystem::path> FindCases(const std::vector<std::filesystem::path>& starts);

/// Which cases a command replays.
struct Selection {
  std::vector<std::string> names;  ///< exact case names (bless); when given, `filter` is not used
  std::string filter;              ///< names containing any of these comma-separated words; empty: all
  std::string device;              ///< only cases on this device; empty: all
  bool realtime = false;           ///< paced: only cases with realtime = true
};

/// The cases `selection` picks, in file order (pointers into `suite`).
[[nodiscard]] std::vector<const Case*> SelectCases(const Suite& suite, const Selection& selection);

}  // namespace palpa::hil
