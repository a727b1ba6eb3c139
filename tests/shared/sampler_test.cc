#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

#include "analytic_fields.h"
#include "palpa/sampler/trilinear.h"

namespace palpa::sampler {
namespace {

constexpr std::int32_t kOne = 1 << 16;

TEST(Interpolate, CornersReturnCornerValues) {
  Stencil v{};
  for (int n = 0; n < 8; ++n) v[static_cast<std::size_t>(n)] = (n * 37 - 100) * 1000;
  for (int n = 0; n < 8; ++n) {
    const Sample s = Interpolate(v, (n & 4) ? kOne : 0, (n & 2) ? kOne : 0, (n & 1) ? kOne : 0);
    EXPECT_EQ(s.phi, v[static_cast<std::size_t>(n)]) << n;
  }
}

TEST(Interpolate, LinearFieldIsExactWithConstantGradient) {
  // φ = 4x + 2y + z voxels on the unit cell (hand-computed corners 0..7).
  Stencil v{};
  for (int n = 0; n < 8; ++n) v[static_cast<std::size_t>(n)] = n * kOne;
  const Sample mid = Interpolate(v, kOne / 2, kOne / 2, kOne / 2);
  EXPECT_EQ(mid.phi, 7 * kOne / 2);                     // 3.5 voxels
  const Sample s = Interpolate(v, 16384, 49152, 8192);  // (0.25, 0.75, 0.125)
  EXPECT_EQ(s.phi, 4 * 16384 + 2 * 49152 + 8192);
  EXPECT_EQ(s.grad[0], 4 * kOne);
  EXPECT_EQ(s.grad[1], 2 * kOne);
  EXPECT_EQ(s.grad[2], kOne);
}

double TrilinearReference(const Stencil& v, double x, double y, double z) {
  double out = 0;
  for (int n = 0; n < 8; ++n) {
    const double wx = (n & 4) ? x : 1 - x, wy = (n & 2) ? y : 1 - y, wz = (n & 1) ? z : 1 - z;
    out += wx * wy * wz * v[static_cast<std::size_t>(n)] / 65536.0;
  }
  return out;
}

TEST(Interpolate, MatchesFloat64TrilinearWithin1e3Voxel) {
  std::mt19937 rng(7);
  std::uniform_int_distribution<std::int32_t> value(-6 * kOne, 6 * kOne);
  std::uniform_int_distribution<std::int32_t> frac(0, kOne);
  double worst = 0;
  for (int trial = 0; trial < 100000; ++trial) {
    Stencil v{};
    for (auto& x : v) x = value(rng);
    const std::int32_t fx = frac(rng), fy = frac(rng), fz = frac(rng);
    const double ref = TrilinearReference(v, fx / 65536.0, fy / 65536.0, fz / 65536.0);
    worst = std::max(worst, std::abs(Interpolate(v, fx, fy, fz).phi / 65536.0 - ref));
  }
  RecordProperty("max_phi_error_voxels", std::to_string(worst));
  EXPECT_LE(worst, 1e-3);
}

TEST(Sampler, OutsideTheGridIsBackgroundAtEveryFaceEdgeAndCorner) {
  const auto bytes = testing::SphereBlob(6, 0.001, 4, 2.0);
  const auto view = blob::Verify(bytes).value();
  const TrilinearSampler s(view);
  const std::int32_t last = 5 * kOne;
  const std::int32_t coords[] = {-1, 0, 2 * kOne + 123, last, last + 1};
  int outside = 0;
  for (std::int32_t x : coords)
    for (std::int32_t y : coords)
      for (std::int32_t z : coords) {
        const bool in = x >= 0 && x <= last && y >= 0 && y <= last && z >= 0 && z <= last;
        const Sample a = s.At({x, y, z});
        EXPECT_EQ(a.in_grid, in) << x << "," << y << "," << z;
        if (!in) {
          ++outside;
          EXPECT_EQ(a.phi, 4 * kOne);
          EXPECT_EQ(a.grad[0] | a.grad[1] | a.grad[2], 0);
        }
      }
  EXPECT_EQ(outside, 125 - 27);
  // Exactly on the last node: the node's own value.
  EXPECT_EQ(s.At({last, last, last}).phi, view.phi[6 * 6 * 6 - 1]);
  // Far outside, at int32's extremes: still no out-of-bounds read.
  EXPECT_EQ(s.At({INT32_MIN, INT32_MAX, 0}).phi, 4 * kOne);
}

TEST(Sampler, SphereNormalFromTheInCellGradient) {
  // Sphere of radius 20 voxels: the normalised gradient vs the radial direction, random points
  // within 1 voxel of the surface. The in-cell analytic gradient is first-order: its direction
  // error on a sphere grows like h/R (measured 1.98° at R = 20 voxels), so 2.5° is asserted.
  // Issue 6 moves to a continuous gradient with a 0.5° goal. The force direction itself comes
  // from X_p − X_h (eq. 10), which the proxy tests check to 2°.
  const std::uint32_t n = 56;
  const double c = 0.5 * (n - 1);
  const auto bytes = testing::SphereBlob(n, 0.001, 6, 20.0);
  const TrilinearSampler s(blob::Verify(bytes).value());
  std::mt19937 rng(11);
  std::normal_distribution<double> g;
  std::uniform_real_distribution<double> shell(19.0, 21.0);
  double worst_deg = 0;
  for (int trial = 0; trial < 20000; ++trial) {
    double d[3] = {g(rng), g(rng), g(rng)};
    const double len = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    const double r = shell(rng);
    GridPos p{static_cast<std::int32_t>(std::lround((c + r * d[0] / len) * 65536)),
              static_cast<std::int32_t>(std::lround((c + r * d[1] / len) * 65536)),
              static_cast<std::int32_t>(std::lround((c + r * d[2] / len) * 65536))};
    const Sample a = s.At(p);
    const double gx = a.grad[0], gy = a.grad[1], gz = a.grad[2];
    const double gl = std::sqrt(gx * gx + gy * gy + gz * gz);
    const double cosang = (gx * d[0] + gy * d[1] + gz * d[2]) / (gl * len);
    worst_deg = std::max(worst_deg, std::acos(std::min(1.0, cosang)) * 180 / std::numbers::pi);
  }
  RecordProperty("max_normal_error_deg", std::to_string(worst_deg));
  EXPECT_LE(worst_deg, 2.5);
}

}  // namespace
}  // namespace palpa::sampler
