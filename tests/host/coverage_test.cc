// The zero surface's area and its part away from every sample (issue 20: the area an open scan's
// note reports), against an analytic sphere's field: its area 4 pi r^2, and the cap farther than
// the cover distance from the samples of its upper half.
#include "palpa/field/coverage.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <vector>

#include <gtest/gtest.h>

#include "test_util.h"

namespace palpa::field {
namespace {

using V3 = Eigen::Vector3d;

constexpr double kVoxel = 1e-3, kRadius = 0.02;  // metres

SparseField SphereField() {
  GridSpec grid;
  grid.dims = {64, 64, 64};
  grid.origin_m = V3::Constant(-0.032);
  grid.voxel_m = kVoxel;
  grid.band_voxels = 4;
  std::vector<float> phi(grid.NodeCount());
  for (int i = 0; i < 64; ++i)
    for (int j = 0; j < 64; ++j)
      for (int k = 0; k < 64; ++k) {
        const V3 p = grid.origin_m + kVoxel * V3(i, j, k);
        phi[(static_cast<std::size_t>(i) * 64 + static_cast<std::size_t>(j)) * 64 + static_cast<std::size_t>(k)] =
            static_cast<float>(std::clamp((p.norm() - kRadius) / kVoxel, -4.0, 4.0));
      }
  return SparseField::FromDense(grid, phi);
}

TEST(MeasureCoverage, ASampledSphereIsCoveredAndItsAreaIsFourPiRSquared) {
  std::vector<V3> samples;
  for (std::size_t i = 0; i < 3000; ++i) samples.push_back(kRadius * testing::FibonacciPoint(i, 3000));
  const Coverage c = MeasureCoverage(SphereField(), samples);
  const double area = 4 * std::numbers::pi * kRadius * kRadius;
  EXPECT_NEAR(c.total_area_m2, area, 0.03 * area);
  EXPECT_LT(c.uncovered_area_m2, 0.01 * area);
  EXPECT_GE(c.min_distance_m, kVoxel);
}

TEST(MeasureCoverage, TheLowerHalfOfASphereSampledAboveIsUncoveredBeyondTheCoverDistance) {
  std::vector<V3> samples;
  for (std::size_t i = 0; i < 3000; ++i) {
    const V3 u = testing::FibonacciPoint(i, 3000);
    if (u.z() >= 0) samples.push_back(kRadius * u);
  }
  const Coverage c = MeasureCoverage(SphereField(), samples);
  // Below the equator, a point at angle a from it lies 2 r sin(a / 2) from the nearest sample (on
  // the equator): uncovered beyond a0 = 2 asin(d / 2r), a cap of area 2 pi r^2 (1 - sin a0).
  const double a0 = 2 * std::asin(c.min_distance_m / (2 * kRadius));
  const double expected = 2 * std::numbers::pi * kRadius * kRadius * (1 - std::sin(a0));
  EXPECT_NEAR(c.uncovered_area_m2, expected, 0.06 * expected) << c.min_distance_m;
  EXPECT_NEAR(c.total_area_m2, 4 * std::numbers::pi * kRadius * kRadius, 0.03 * c.total_area_m2);
}

}  // namespace
}  // namespace palpa::field
