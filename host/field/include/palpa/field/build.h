// One-call pipeline: packing (paper §3.1) -> indicator -> erosion distance field (§3.2).
#pragma once

#include <expected>
#include <functional>
#include <vector>

#include <Eigen/Core>

#include "palpa/field/erosion_field.h"
#include "palpa/field/error.h"
#include "palpa/field/grid.h"
#include "palpa/field/packing.h"
#include "palpa/field/transform.h"

namespace palpa::field {

struct BuildOptions {
  GridOptions grid;
};

struct BuildResult {
  DenseField field;
  Transform transform;  // identity: the caller passed device (already fitted) positions
  Packing packing;      // metres
  double seconds_packing = 0.0;
  double seconds_indicator = 0.0;
  double seconds_distance = 0.0;
};

// Builds the erosion field of oriented points already in device coordinates (metres; see
// FitTransform). Packing uses r_max = longest bounding-box side of `device_positions`.
// Normals are normalised here. `progress`, if set, is called on the calling thread only with
// non-decreasing values in [0, 1], ending with 1.
// Errors: size mismatch; fewer than 4 points; non-finite position; zero or non-finite normal;
// any MakeGrid error; out of memory.
std::expected<BuildResult, Error> BuildErosionField(const std::vector<Eigen::Vector3d>& device_positions,
                                                    const std::vector<Eigen::Vector3d>& normals,
                                                    const BuildOptions& options,
                                                    std::function<void(double fraction)> progress = {});

}  // namespace palpa::field
