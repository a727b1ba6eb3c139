// How much of a built field's zero surface the samples do not cover (issue 20: an open scan's
// note reports the area the field closed over). Host only, non-RT.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "palpa/field/sparse_field.h"

namespace palpa::field {

struct Coverage {
  double uncovered_area_m2 = 0.0;  ///< zero-surface area farther than `min_distance_m` from every sample
  double total_area_m2 = 0.0;      ///< the whole zero surface's area, by the same estimate
  double min_distance_m = 0.0;     ///< the distance used (3 median sample spacings, at least a voxel)
};

/// Area of the field's zero surface, and of its part away from every sample. Every grid edge whose
/// end nodes differ in sign (phi <= 0 inside) is a crossing; its point, by linear interpolation, is
/// uncovered when its nearest sample lies farther than 3 x the median nearest-neighbour spacing
/// of the samples, and at least a voxel (a random sampling leaves 0.2 % of a covered surface that
/// far from its samples). A surface of area A crosses A (|n_x| + |n_y| + |n_z|) / h^2 edges,
/// 1.5 A / h^2 on average over directions, so area = crossings h^2 / 1.5 (within ~10 % for a
/// surface of any one orientation: a plane normal to an axis counts 1.5 x its area, a (1, 1, 1)
/// plane 0.87 x; tests/host/coverage_test.cc). `samples`: the positions the field was built from,
/// in the grid's metres. Parallel, deterministic.
Coverage MeasureCoverage(const SparseField& field, const std::vector<Eigen::Vector3d>& samples);

}  // namespace palpa::field
