// A replayed run for `palpa view --trace`: palpad's output CSV (docs/runtime.md), read into
// columns the page scrubs through. Non-RT.
#pragma once

#include <array>
#include <cstdint>
#include <expected>
#include <string>
#include <vector>

#include "palpa/field/error.h"

namespace palpa::view {

using Error = field::Error;

/// One run, one row per servo tick (or per sample the CSV holds), in file order.
/// Positions in device-frame metres, forces in newtons, time in seconds.
struct TraceSeries {
  std::vector<double> t_s;
  std::vector<std::array<double, 3>> hip_m;    ///< haptic interface point
  std::vector<std::array<double, 3>> proxy_m;  ///< god-object on φ = 0 (paper §3.3)
  std::vector<std::array<double, 3>> force_n;  ///< f = −k (X_h − X_p), clamped (paper eq. 10)
  std::vector<std::uint8_t> contact;           ///< 0 | 1
  std::string source;                          ///< the file read
};

/// Reads `path`: a palpad output CSV (header
/// `t_s,hip_x_m,hip_y_m,hip_z_m,proxy_x_m,proxy_y_m,proxy_z_m,fx_n,fy_n,fz_n,contact`), or a HIL
/// result directory (docs/hil.md: build/hil-work/results/MODE/NAME/), whose `out.csv` is read.
/// Errors name the file and line: a missing or different header, a row without 11 fields, a
/// field that is not a finite number, contact not 0/1, time going backwards, no rows.
std::expected<TraceSeries, Error> ReadTrace(const std::string& path);

/// The series as one JSON object: {"source", "rows", "t_s": [...], "hip_m": [[x,y,z],...],
/// "proxy_m", "force_n", "contact"}; doubles printed to round-trip exactly.
std::string TraceToJson(const TraceSeries& trace);

}  // namespace palpa::view
