#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <numbers>
#include <optional>
#include <random>
#include <vector>

#include "analytic_fields.h"
#include "palpa/sampler/trilinear.h"

namespace palpa::sampler {
namespace {

constexpr std::int32_t kOne = 1 << 16;

double AngleDeg(const std::array<std::int32_t, 3>& g, const double d[3]) {
  const double gx = g[0], gy = g[1], gz = g[2];
  const double gl = std::sqrt(gx * gx + gy * gy + gz * gz);
  const double dl = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
  const double c = (gx * d[0] + gy * d[1] + gz * d[2]) / (gl * dl);
  return std::acos(std::clamp(c, -1.0, 1.0)) * 180 / std::numbers::pi;
}

TEST(Interpolate, CornersReturnCornerValues) {
  Stencil v{};
  for (int n = 0; n < 8; ++n) v[static_cast<std::size_t>(n)] = (n * 37 - 100) * 1000;
  for (int n = 0; n < 8; ++n) {
    const std::int32_t fx = (n & 4) ? kOne : 0, fy = (n & 2) ? kOne : 0, fz = (n & 1) ? kOne : 0;
    EXPECT_EQ(InterpolatePhi(v, fx, fy, fz), v[static_cast<std::size_t>(n)]) << n;
    EXPECT_EQ(InterpolateCellGradient(v, fx, fy, fz).phi, v[static_cast<std::size_t>(n)]) << n;
  }
}

TEST(Interpolate, LinearFieldIsExactWithConstantGradient) {
  // φ = 4x + 2y + z voxels on the unit cell (hand-computed corners 0..7).
  Stencil v{};
  for (int n = 0; n < 8; ++n) v[static_cast<std::size_t>(n)] = n * kOne;
  EXPECT_EQ(InterpolatePhi(v, kOne / 2, kOne / 2, kOne / 2), 7 * kOne / 2);  // 3.5 voxels
  const Sample s = InterpolateCellGradient(v, 16384, 49152, 8192);           // (0.25, 0.75, 0.125)
  EXPECT_EQ(s.phi, 4 * 16384 + 2 * 49152 + 8192);
  EXPECT_EQ(s.grad, (std::array<std::int32_t, 3>{4 * kOne, 2 * kOne, kOne}));
  // The same linear field on the 4×4×4 neighbourhood: central differences are exact too.
  WideStencil w;
  for (std::size_t n = 0; n < 8; ++n) {
    const int dx = (n >> 2) & 1, dy = (n >> 1) & 1, dz = n & 1;
    const auto at = [](int x, int y, int z) { return (4 * x + 2 * y + z) * kOne; };
    w.corner[n] = at(dx, dy, dz);
    w.x_out[n] = at(dx ? 2 : -1, dy, dz);
    w.y_out[n] = at(dx, dy ? 2 : -1, dz);
    w.z_out[n] = at(dx, dy, dz ? 2 : -1);
  }
  const Sample smooth = InterpolateSmooth(w, 16384, 49152, 8192);
  EXPECT_EQ(smooth.phi, s.phi);
  EXPECT_EQ(smooth.grad, s.grad);
}

TEST(Interpolate, SmoothGradientIsExactForAQuadratic) {
  // φ = (x² + 2y² − z²)/8 voxels: central differences at the nodes are the exact derivatives
  // (x/4, y/2, −z/4), which are linear, so their trilinear interpolation is exact everywhere:
  // hand-checkable, and impossible for the analytic in-cell gradient (constant-ish in x per cell).
  const auto at = [](int x, int y, int z) { return (x * x + 2 * y * y - z * z) * kOne / 8; };
  const int i = 2, j = -1, k = 1;  // the cell's lower corner
  WideStencil w;
  Stencil c{};
  for (std::size_t n = 0; n < 8; ++n) {
    const int dx = (n >> 2) & 1, dy = (n >> 1) & 1, dz = n & 1;
    const int x = i + dx, y = j + dy, z = k + dz;
    c[n] = w.corner[n] = at(x, y, z);
    w.x_out[n] = at(dx ? i + 2 : i - 1, y, z);
    w.y_out[n] = at(x, dy ? j + 2 : j - 1, z);
    w.z_out[n] = at(x, y, dz ? k + 2 : k - 1);
  }
  for (const std::array<std::int32_t, 3> f : {std::array<std::int32_t, 3>{0, 0, 0},
                                              {kOne / 2, kOne / 4, 3 * kOne / 4},
                                              {kOne, kOne / 8, kOne / 2},
                                              {12345, 54321, 33333}}) {
    const Sample s = InterpolateSmooth(w, f[0], f[1], f[2]);
    const double x = i + f[0] / 65536.0, y = j + f[1] / 65536.0, z = k + f[2] / 65536.0;
    EXPECT_NEAR(s.grad[0] / 65536.0, x / 4, 2.0 / 65536) << f[0];
    EXPECT_NEAR(s.grad[1] / 65536.0, y / 2, 2.0 / 65536) << f[1];
    EXPECT_NEAR(s.grad[2] / 65536.0, -z / 4, 2.0 / 65536) << f[2];
    EXPECT_EQ(s.phi, InterpolatePhi(c, f[0], f[1], f[2]));
  }
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
    worst = std::max(worst, std::abs(InterpolatePhi(v, fx, fy, fz) / 65536.0 - ref));
  }
  RecordProperty("max_phi_error_voxels", std::to_string(worst));
  std::printf("[ measured ] max |φ − φ_float64| = %.3g voxel over 100,000 random points\n", worst);
  EXPECT_LE(worst, 1e-3);
  EXPECT_LE(worst, 2.0 / 65536);  // the rounding analysis in docs/realtime-core.md: ≤ 1.5 LSB
}

TEST(Sampler, OutsideTheGridIsTheBoundaryExtendedOutwardAtEveryFaceEdgeAndCorner) {
  // Outside the grid φ is the value at the nearest grid point (issue 19: a face where φ < 0 must
  // not read as free space), and the gradient loses its components along the clamped axes.
  const auto bytes = testing::SphereBlob(6, 0.001, 4, 2.0);
  const auto view = blob::Verify(bytes).value();
  const TrilinearSampler s(view);
  const std::int32_t last = 5 * kOne;
  const std::int32_t coords[] = {INT32_MIN, -1, 0, 2 * kOne + 123, last, last + 1, INT32_MAX};
  const auto clamp = [&](std::int32_t v) { return std::clamp(v, 0, last); };
  int outside = 0, not_background = 0;
  for (std::int32_t x : coords)
    for (std::int32_t y : coords)
      for (std::int32_t z : coords) {
        const bool in = x >= 0 && x <= last && y >= 0 && y <= last && z >= 0 && z <= last;
        const GridPos p{x, y, z};
        const Sample a = s.At(p);
        EXPECT_EQ(a.in_grid, in) << x << "," << y << "," << z;
        EXPECT_EQ(s.Phi(p), a.phi);
        if (!in) {
          ++outside;
          const GridPos q{clamp(x), clamp(y), clamp(z)};
          const Sample b = s.At(q);
          EXPECT_EQ(a.phi, b.phi) << x << "," << y << "," << z;
          EXPECT_EQ(a.grad[0], q.x == x ? b.grad[0] : 0);
          EXPECT_EQ(a.grad[1], q.y == y ? b.grad[1] : 0);
          EXPECT_EQ(a.grad[2], q.z == z ? b.grad[2] : 0);
          not_background += a.phi != 4 * kOne ? 1 : 0;
        }
      }
  EXPECT_EQ(outside, 7 * 7 * 7 - 3 * 3 * 3);
  EXPECT_GT(not_background, 0);  // the sphere's faces are within the band: not the background
  // Exactly on the last node: the node's own value.
  EXPECT_EQ(s.At({last, last, last}).phi, view.dense()->data()[6 * 6 * 6 - 1]);
  EXPECT_EQ(s.Phi({0, 0, 0}), view.dense()->data()[0]);
}

TEST(Sampler, WideStencilOnTheGridFacesRepeatsTheFaceNode) {
  // φ(i,j,k) = i + 10j + 100k (distinct values, |φ| ≤ band): on a 3×3×3 grid every cell touches
  // a face, so every outer neighbour is either inside or the repeated face node.
  std::vector<std::int32_t> phi;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) phi.push_back((i + 2 * j + 4 * k) * kOne);
  blob::BlobMeta meta;
  meta.dims = {3, 3, 3};
  meta.voxel_m = 0.001;
  meta.band_voxels = 64;
  const auto bytes = blob::Encode(meta, phi);
  const TrilinearSampler s(blob::Verify(bytes).value());
  const auto node = [](int i, int j, int k) {
    i = std::clamp(i, 0, 2), j = std::clamp(j, 0, 2), k = std::clamp(k, 0, 2);
    return (i + 2 * j + 4 * k) * kOne;
  };
  for (int i = 0; i < 2; ++i)
    for (int j = 0; j < 2; ++j)
      for (int k = 0; k < 2; ++k) {
        const WideStencil w = s.CopyWide(i, j, k);
        for (std::size_t n = 0; n < 8; ++n) {
          const int dx = (n >> 2) & 1, dy = (n >> 1) & 1, dz = n & 1;
          EXPECT_EQ(w.corner[n], node(i + dx, j + dy, k + dz));
          EXPECT_EQ(w.x_out[n], node(dx ? i + 2 : i - 1, j + dy, k + dz));
          EXPECT_EQ(w.y_out[n], node(i + dx, dy ? j + 2 : j - 1, k + dz));
          EXPECT_EQ(w.z_out[n], node(i + dx, j + dy, dz ? k + 2 : k - 1));
        }
      }
  // Linear field: the gradient is exact in the interior and one-sided-halved on the faces.
  EXPECT_EQ(s.At({kOne, kOne, kOne}).grad, (std::array<std::int32_t, 3>{kOne, 2 * kOne, 4 * kOne}));
  EXPECT_EQ(s.At({0, kOne, kOne}).grad[0], kOne / 2);
}

// Random points within `shell` voxels of a sphere of radius r: worst angle between the sampled
// gradient and the radial direction.
template <typename SampleFn>
double WorstSphereNormalErrorDeg(const SampleFn& sample, double c, double r, double shell, int trials) {
  std::mt19937 rng(11);
  std::normal_distribution<double> g;
  std::uniform_real_distribution<double> radius(r - shell, r + shell);
  double worst = 0;
  for (int trial = 0; trial < trials; ++trial) {
    double d[3] = {g(rng), g(rng), g(rng)};
    const double len = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    const double rr = radius(rng);
    const GridPos p{static_cast<std::int32_t>(std::lround((c + rr * d[0] / len) * 65536)),
                    static_cast<std::int32_t>(std::lround((c + rr * d[1] / len) * 65536)),
                    static_cast<std::int32_t>(std::lround((c + rr * d[2] / len) * 65536))};
    worst = std::max(worst, AngleDeg(sample(p).grad, d));
  }
  return worst;
}

TEST(Sampler, SphereNormalFromTheContinuousGradientWithinHalfADegree) {
  // Sphere of radius 20 voxels, random points within 1 voxel of the surface. Central differences
  // interpolated trilinearly are second-order: the error goes like (h/R)², against h/R for the
  // analytic in-cell gradient, which is measured here too for the docs' comparison.
  const std::uint32_t n = 56;
  const double c = 0.5 * (n - 1);
  const auto bytes = testing::SphereBlob(n, 0.001, 6, 20.0);
  const TrilinearSampler s(blob::Verify(bytes).value());
  const double smooth = WorstSphereNormalErrorDeg([&](GridPos p) { return s.At(p); }, c, 20.0, 1.0, 20000);
  const double cell = WorstSphereNormalErrorDeg([&](GridPos p) { return s.AtCellGradient(p); }, c, 20.0, 1.0, 20000);
  RecordProperty("max_normal_error_deg_continuous", std::to_string(smooth));
  RecordProperty("max_normal_error_deg_cell", std::to_string(cell));
  std::printf("[ measured ] sphere R = 20 voxels: normal error continuous %.4f deg, in-cell analytic %.4f deg\n",
              smooth, cell);
  EXPECT_LE(smooth, 0.5);
  EXPECT_GT(cell, 1.0);  // the reason for the change: the analytic in-cell gradient is much worse
}

TEST(Sampler, TiltedPlaneNormalIsExact) {
  // φ = n·x − c is linear: central differences are exact, so the direction error is rounding only.
  const double nrm[3] = {0.36, -0.48, 0.8};  // unit
  const auto bytes = testing::AnalyticBlob(
      {24, 24, 24}, 0.001, 6, [&](double i, double j, double k) { return nrm[0] * i + nrm[1] * j + nrm[2] * k - 4.0; });
  const TrilinearSampler s(blob::Verify(bytes).value());
  std::mt19937 rng(2);
  std::uniform_real_distribution<double> u(3.0, 20.0);
  double worst = 0;
  int samples = 0;
  for (int t = 0; t < 20000; ++t) {
    const double x = u(rng), y = u(rng), z = u(rng);
    const double phi = nrm[0] * x + nrm[1] * y + nrm[2] * z - 4.0;
    if (std::abs(phi) > 4.0) continue;  // stay where no corner is clamped to the band
    const GridPos p{static_cast<std::int32_t>(x * 65536), static_cast<std::int32_t>(y * 65536),
                    static_cast<std::int32_t>(z * 65536)};
    worst = std::max(worst, AngleDeg(s.At(p).grad, nrm));
    ++samples;
  }
  std::printf("[ measured ] tilted plane: normal error %.5f deg over %d points\n", worst, samples);
  EXPECT_GT(samples, 1000);
  EXPECT_LE(worst, 0.01);
}

TEST(Sampler, ContinuousGradientHasNoJumpAcrossCellFaces) {
  // Random smooth-ish field; the gradient 1 LSB either side of a face differs by rounding only,
  // while the analytic in-cell gradient jumps by the change of edge difference.
  const auto bytes = testing::AnalyticBlob({12, 12, 12}, 0.001, 6, [](double i, double j, double k) {
    return 3.0 * std::sin(0.7 * i) * std::cos(0.5 * j) + 0.4 * k - 2.0;
  });
  const TrilinearSampler s(blob::Verify(bytes).value());
  std::mt19937 rng(4);
  std::uniform_int_distribution<std::int32_t> cell(2, 8);
  std::uniform_int_distribution<std::int32_t> frac(0, kOne - 1);
  std::int32_t worst_smooth = 0, worst_cell = 0;
  for (int t = 0; t < 2000; ++t) {
    const std::int32_t face = cell(rng) * kOne;
    const GridPos below{face - 1, cell(rng) * kOne + frac(rng), cell(rng) * kOne + frac(rng)};
    const GridPos above{face, below.y, below.z};
    for (std::size_t a = 0; a < 3; ++a) {
      worst_smooth = std::max(worst_smooth, std::abs(s.At(above).grad[a] - s.At(below).grad[a]));
      worst_cell = std::max(worst_cell, std::abs(s.AtCellGradient(above).grad[a] - s.AtCellGradient(below).grad[a]));
    }
  }
  std::printf("[ measured ] gradient jump across a face: continuous %d LSB, in-cell %d LSB\n", worst_smooth,
              worst_cell);
  EXPECT_LE(worst_smooth, 8);
  EXPECT_GT(worst_cell, 1000);
}

TEST(Sampler, LipschitzBoundHoldsAndIsTight) {
  // City-block distance |x| + |y| + |z| (what the erosion field computes): |∇φ| = √3 on the
  // diagonals. A Euclidean sphere: |∇φ| ≈ 1 on {φ > −1} (its centre's cone is left out). Random
  // pairs never change φ faster than the bound.
  struct Case {
    const char* name;
    std::function<double(double, double, double)> sdf;
    double norm_lo, norm_hi;
  };
  const double c = 9.5;
  const Case cases[] = {
      {"city-block",
       [=](double i, double j, double k) { return std::abs(i - c) + std::abs(j - c) + std::abs(k - c) - 6; },
       std::sqrt(3.0) - 1e-4, std::sqrt(3.0) + 1e-4},
      // Radius 6 voxels: the curvature lets |∇φ| of the trilinear interpolant exceed 1 a little.
      {"sphere", [=](double i, double j, double k) { return std::hypot(i - c, j - c, k - c) - 6; }, 0.99, 1.15},
  };
  for (const Case& cs : cases) {
    const auto bytes = testing::AnalyticBlob({20, 20, 20}, 0.001, 6, cs.sdf);
    const TrilinearSampler s(blob::Verify(bytes).value());
    const LipschitzBound& lb = s.lipschitz();
    const double norm = lb.norm / 65536.0;
    std::printf("[ measured ] %s: Lipschitz norm %.5f, axis (%.4f, %.4f, %.4f)\n", cs.name, norm, lb.axis[0] / 65536.0,
                lb.axis[1] / 65536.0, lb.axis[2] / 65536.0);
    EXPECT_GE(norm, cs.norm_lo) << cs.name;
    EXPECT_LE(norm, cs.norm_hi) << cs.name;
    std::mt19937 rng(8);
    std::uniform_int_distribution<std::int32_t> pos(0, 19 * kOne);
    std::uniform_int_distribution<std::int32_t> near(-kOne / 2, kOne / 2);
    for (int t = 0; t < 20000; ++t) {
      const GridPos a{pos(rng), pos(rng), pos(rng)};
      GridPos b{a.x + near(rng), a.y + near(rng), a.z + near(rng)};
      b = {std::clamp(b.x, 0, 19 * kOne), std::clamp(b.y, 0, 19 * kOne), std::clamp(b.z, 0, 19 * kOne)};
      // The bound covers the region {φ > −1}; pairs in the outer layer stay in it.
      if (std::min(s.Phi(a), s.Phi(b)) < -kOne / 4) continue;
      const double dx = (b.x - a.x) / 65536.0, dy = (b.y - a.y) / 65536.0, dz = (b.z - a.z) / 65536.0;
      const double change = std::abs(s.Phi(b) - s.Phi(a)) / 65536.0;
      const double slack = 3.0 / 65536;  // fixed-point rounding of the two samples
      ASSERT_LE(change, norm * std::sqrt(dx * dx + dy * dy + dz * dz) + slack) << cs.name;
      ASSERT_LE(change,
                (std::abs(dx) * lb.axis[0] + std::abs(dy) * lb.axis[1] + std::abs(dz) * lb.axis[2]) / 65536.0 + slack)
          << cs.name;
    }
  }
}

TEST(Sampler, BandLipschitzBoundCertifiesSegmentsWhoseEndsAreInTheBand) {
  // A plate tilted from z, stored as palpa build stores it (v2, free-space bounds): the whole
  // field's bound is floored at 1 per axis (free space), the band's is the plate's own |n_i|
  // (what the same blob without free-space bounds reports). The band's bound still certifies:
  // random segments up to 3 voxels per axis whose ends are both ≤ background() and satisfy
  // φ(a) + φ(b) + 2δ ≥ Λ|b − a| (axis form, δ = 1/4 voxel, ends ≥ −δ/2 as the proxy's are) never
  // dip below −δ, sampled every 1/64 voxel along them.
  const double n[3] = {0.3, 0.2, std::sqrt(1 - 0.09 - 0.04)};
  const auto sdf = [&](double i, double j, double k) { return std::abs(n[0] * i + n[1] * j + n[2] * k - 24) - 1.0; };
  const std::array<std::uint32_t, 3> dims = {48, 48, 48};
  const auto bytes = testing::AnalyticBlobV2(dims, 0.0002, 6, sdf);
  const TrilinearSampler s(blob::Verify(bytes).value());
  blob::BlobMetaV2 plain;
  plain.meta = testing::AnalyticMeta(dims, 0.0002, 6);
  plain.band_inside = 6;
  plain.free_space_bounds = false;
  const auto plain_bytes = blob::EncodeV2(plain, testing::AnalyticPhi(dims, 6, sdf));
  const TrilinearSampler without(blob::Verify(plain_bytes).value());
  const LipschitzBound& band = s.lipschitz_band();
  for (std::size_t a = 0; a < 3; ++a) {
    EXPECT_EQ(s.lipschitz().axis[a], std::max(band.axis[a], kOne)) << a;
    EXPECT_EQ(band.axis[a], without.lipschitz().axis[a]) << a;
    EXPECT_LT(band.axis[a], kOne) << a;  // a tilted plane: each axis below 1
  }
  EXPECT_EQ(band.norm, without.lipschitz().norm);

  std::mt19937 rng(12);
  std::uniform_int_distribution<std::int32_t> pos(3 * kOne, 44 * kOne), step(-3 * kOne, 3 * kOne);
  const std::int64_t delta = kOne / 4;
  int certified = 0, rejected = 0;
  for (int t = 0; t < 2000000 && certified < 3000; ++t) {
    const GridPos a{pos(rng), pos(rng), pos(rng)};
    const GridPos b{a.x + step(rng), a.y + step(rng), a.z + step(rng)};
    const std::int64_t pa = s.Phi(a), pb = s.Phi(b);
    if (pa > s.background() || pb > s.background() || pa < -delta / 2 || pb < -delta / 2) continue;
    const std::int64_t variation = std::llabs(std::int64_t{b.x} - a.x) * band.axis[0] +
                                   std::llabs(std::int64_t{b.y} - a.y) * band.axis[1] +
                                   std::llabs(std::int64_t{b.z} - a.z) * band.axis[2];
    if (variation > (pa + pb + 2 * delta) << 16) {
      ++rejected;
      continue;
    }
    ++certified;
    const double length = std::hypot(b.x - a.x, b.y - a.y, b.z - a.z) / kOne;
    const int steps = static_cast<int>(length * 64) + 1;
    for (int m = 0; m <= steps; ++m) {
      const auto at = [&](std::int32_t u, std::int32_t v) {
        return static_cast<std::int32_t>(u + (std::int64_t{v} - u) * m / steps);
      };
      ASSERT_GE(s.Phi({at(a.x, b.x), at(a.y, b.y), at(a.z, b.z)}), -delta - 2)
          << "segment " << certified;  // 2 LSB: the samples' rounding
    }
  }
  std::printf("[ measured ] tilted plate, v2: band axis (%.4f, %.4f, %.4f); %d segments certified, %d not\n",
              band.axis[0] / 65536.0, band.axis[1] / 65536.0, band.axis[2] / 65536.0, certified, rejected);
  EXPECT_EQ(certified, 3000);
}

// A v2 field with every kind of cell: the union of a sphere (radius r voxels) and a tilted plane
// crossing a 27×30×22 grid (not multiples of 8: the last bricks are partial), stored with octants
// inside, outside and on the surface, uniform octants and bricks, free-space bounds, and band
// values on every face of the grid.
std::vector<std::byte> CacheTestBlob(double r) {
  return testing::AnalyticBlobV2({27, 30, 22}, 0.0002, 6, [r](double i, double j, double k) {
    const double sphere = std::sqrt((i - 12.3) * (i - 12.3) + (j - 15.1) * (j - 15.1) + (k - 10.7) * (k - 10.7)) - r;
    const double plane = (30 - 0.5 * i - 0.6 * j - 0.62 * k) / std::sqrt(0.25 + 0.36 + 0.3844);
    return std::min(sphere, plane);
  });
}

void ExpectSameSample(const Sample& a, const Sample& b, const char* what, int n) {
  ASSERT_EQ(a.phi, b.phi) << what << " sample " << n;
  ASSERT_EQ(a.grad, b.grad) << what << " sample " << n;
  ASSERT_EQ(a.in_grid, b.in_grid) << what << " sample " << n;
}

TEST(SampleCache, CachedSamplesEqualUncachedBitForBit) {
  // Walks of 0.02 to 0.6 voxel steps (most samples land in the previous cell: a hit), from anywhere
  // in and around the grid, through octant and brick borders, uniform octants, the grid's faces
  // (whose At cells are never cached) and out of it, with every 5th walk snapped now and then onto
  // a last node (Locate's fraction-1 case, the one a hit must not take). Every cached Phi and At
  // equals the uncached one; the cells of consecutive samples show how many could hit.
  const auto bytes = CacheTestBlob(9);
  const TrilinearSampler s(blob::Verify(bytes).value());
  std::mt19937 rng(21);
  std::uniform_int_distribution<std::int32_t> start_x(-2 * kOne, 28 * kOne), start_y(-2 * kOne, 31 * kOne),
      start_z(-2 * kOne, 23 * kOne);
  std::uniform_real_distribution<double> length(0.02, 0.6), unit(-1, 1);
  PhiCache phi_cache;
  GradientCache gradient_cache;
  int n = 0, same_cell = 0, last_nodes = 0;
  GridPos previous{-1, -1, -1};
  for (int walk = 0; walk < 400; ++walk) {
    GridPos p{start_x(rng), start_y(rng), start_z(rng)};
    for (int step = 0; step < 150; ++step, ++n) {
      if (walk % 5 == 0 && step % 9 == 4) {  // onto the last node along one axis
        const int a = step % 3;
        (a == 0 ? p.x : a == 1 ? p.y : p.z) = (a == 0 ? 26 : a == 1 ? 29 : 21) * kOne;
        ++last_nodes;
      }
      same_cell +=
          (p.x >> 16) == (previous.x >> 16) && (p.y >> 16) == (previous.y >> 16) && (p.z >> 16) == (previous.z >> 16);
      previous = p;
      ASSERT_EQ(s.Phi(p, phi_cache), s.Phi(p)) << "Phi sample " << n;
      ExpectSameSample(s.At(p, gradient_cache), s.At(p), "At", n);
      const double d[3] = {unit(rng), unit(rng), unit(rng)};
      const double l = length(rng) / std::max(1e-9, std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]));
      p = {p.x + static_cast<std::int32_t>(d[0] * l * kOne), p.y + static_cast<std::int32_t>(d[1] * l * kOne),
           p.z + static_cast<std::int32_t>(d[2] * l * kOne)};
    }
  }
  std::printf("[ measured ] %d samples, %d in the previous sample's cell, %d on a last node\n", n, same_cell,
              last_nodes);
  EXPECT_GT(same_cell, n / 2);
  EXPECT_GT(last_nodes, 1000);
}

TEST(SampleCache, LastNodeAfterItsCellAndBack) {
  // Locate puts the last node of an axis at fraction 1 of the cell below it, whose corners a cache
  // may hold: the node must read its own value, then the cell below must hit and stay exact. Every
  // face node whose value differs from the node below it, on the three last faces.
  const auto bytes = CacheTestBlob(9);
  const TrilinearSampler s(blob::Verify(bytes).value());
  const std::array<std::int32_t, 3> last = {26, 29, 21};
  int checked = 0;
  for (std::size_t a = 0; a < 3; ++a) {
    for (std::int32_t u = 0; u < 30; ++u) {
      for (std::int32_t w = 0; w < 30; ++w) {
        std::array<std::int32_t, 3> c{};
        c[a] = last[a];
        c[(a + 1) % 3] = u;
        c[(a + 2) % 3] = w;
        if (c[(a + 1) % 3] > last[(a + 1) % 3] || c[(a + 2) % 3] > last[(a + 2) % 3]) continue;
        const GridPos node{c[0] * kOne, c[1] * kOne, c[2] * kOne};
        GridPos below = node;
        (a == 0 ? below.x : a == 1 ? below.y : below.z) -= kOne / 3;
        GridPos cell_node = node;
        (a == 0 ? cell_node.x : a == 1 ? cell_node.y : cell_node.z) -= kOne;
        if (s.Phi(node) == s.Phi(cell_node)) continue;
        ++checked;
        PhiCache pc;
        for (const GridPos p : {below, node, node, below, node})
          ASSERT_EQ(s.Phi(p, pc), s.Phi(p)) << a << " " << u << " " << w;
      }
    }
  }
  std::printf("[ measured ] %d last-face nodes whose value differs from the node below\n", checked);
  EXPECT_GT(checked, 100);
}

TEST(SampleCache, AHitReadsTheCacheNotTheIndex) {
  // After a sample, point the sample's octant (its brick's table entry) at another stored octant in
  // the blob (which the sampler reads in place): an uncached sample reads the new octant, a sample
  // in the same cell through the cache still the old one (a hit: the index was not read), and after
  // a sample in another cell the new one (a miss). Shows that hits happen and that a cache holds what a
  // field gave it, which is why a field must not change under its sampler (palpad swaps samplers).
  auto bytes = CacheTestBlob(9);
  const blob::FieldView v = blob::Verify(bytes).value();
  const TrilinearSampler s(v);
  const GridPos p{20 * kOne + 9000, 15 * kOne + 30000, 10 * kOne + 100}, q{p.x + 2000, p.y - 3000, p.z + 4000};
  const GridPos elsewhere{5 * kOne, 5 * kOne, 5 * kOne};
  const std::int32_t i = p.x >> 16, j = p.y >> 16, k = p.z >> 16;  // cell (20, 15, 10): local (0, 3, 2)
  const blob::BrickAccessor& b = *v.bricks();
  const std::uint32_t slot =
      b.index()[static_cast<std::size_t>(((i >> 3) * b.brick_dims()[1] + (j >> 3)) * b.brick_dims()[2] + (k >> 3))];
  ASSERT_EQ(slot & blob::kSlotEmpty, 0U);
  auto* entry = const_cast<std::uint32_t*>(b.tables() + 8 * std::size_t{slot} +
                                           (((i >> 2) & 1) << 2 | ((j >> 2) & 1) << 1 | ((k >> 2) & 1)));
  ASSERT_EQ(*entry & blob::kSlotEmpty, 0U);
  PhiCache pc;
  GradientCache gc;
  const std::int32_t phi_p = s.Phi(p, pc), phi_q = s.Phi(q);
  const Sample at_p = s.At(p, gc);
  const std::uint32_t stored = *entry;
  *entry = stored == 0 ? 1 : 0;
  ASSERT_NE(s.Phi(p), phi_p);  // the index now gives other values
  ASSERT_NE(s.Phi(q), phi_q);
  ASSERT_NE(s.At(p).phi, at_p.phi);
  EXPECT_EQ(s.Phi(p, pc), phi_p);  // hits
  EXPECT_EQ(s.Phi(q, pc), phi_q);
  ExpectSameSample(s.At(p, gc), at_p, "At hit", 0);
  s.Phi(elsewhere, pc);  // misses, then misses again in the cell of p
  s.At(elsewhere, gc);
  EXPECT_EQ(s.Phi(p, pc), s.Phi(p));
  ExpectSameSample(s.At(p, gc), s.At(p), "At after a miss", 0);
  *entry = stored;
}

TEST(SampleCache, NeverAnswersForAnotherSampler) {
  // Two fields, their samplers built one after the other in the same storage (the same address):
  // a cache filled by the first answers the second with the second's values.
  const auto a = CacheTestBlob(9), b = CacheTestBlob(7);
  std::optional<TrilinearSampler> s;
  const GridPos p{17 * kOne + 1234, 15 * kOne + 999, 10 * kOne + 31000};
  s.emplace(blob::Verify(a).value());
  PhiCache pc;
  GradientCache gc;
  const std::int32_t phi_a = s->Phi(p, pc);
  const std::int32_t at_phi_a = s->At(p, gc).phi;
  const TrilinearSampler* first = &*s;
  s.emplace(blob::Verify(b).value());
  ASSERT_EQ(&*s, first);
  const TrilinearSampler& other = *s;
  EXPECT_NE(other.Phi(p), phi_a);
  EXPECT_EQ(other.Phi(p, pc), other.Phi(p));
  EXPECT_NE(other.At(p).phi, at_phi_a);
  ExpectSameSample(other.At(p, gc), other.At(p), "At, other sampler", 0);
}

TEST(SampleCache, ACopiedGradientCacheStartsEmpty) {
  // A uniform octant's address points into the cache's own `expanded`, so a copy must not reuse
  // the addresses: after the original moves on, the copy still samples exactly.
  const auto bytes = CacheTestBlob(9);
  const TrilinearSampler s(blob::Verify(bytes).value());
  GradientCache original;
  const GridPos p{12 * kOne + 500, 15 * kOne + 100, 2 * kOne + 40000};  // near the sphere's bottom
  s.At(p, original);
  ASSERT_NE(original.sampler, 0U);
  GradientCache copy = original, assigned;
  assigned = original;
  EXPECT_EQ(copy.sampler, 0U);
  EXPECT_EQ(assigned.sampler, 0U);
  s.At({20 * kOne, 25 * kOne, 17 * kOne}, original);
  ExpectSameSample(s.At(p, copy), s.At(p), "At through a copy", 0);
}

TEST(SampleCache, ADenseGridLeavesItUntouched) {
  const auto bytes = testing::SphereBlob(20, 0.0002, 4, 6);
  const TrilinearSampler s(blob::Verify(bytes).value());
  PhiCache pc;
  GradientCache gc;
  const GridPos p{9 * kOne + 5, 3 * kOne + 700, 10 * kOne};
  EXPECT_EQ(s.Phi(p, pc), s.Phi(p));
  ExpectSameSample(s.At(p, gc), s.At(p), "At dense", 0);
  EXPECT_EQ(pc.sampler, 0U);
  EXPECT_EQ(gc.sampler, 0U);
}

}  // namespace
}  // namespace palpa::sampler
