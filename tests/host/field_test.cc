#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <deque>
#include <limits>
#include <numbers>
#include <random>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include "palpa/field/build.h"
#include "palpa/field/erosion_field.h"
#include "palpa/field/indicator.h"
#include "palpa/field/point_io.h"
#include "palpa/field/transform.h"
#include "test_util.h"

namespace palpa::field {
namespace {

using testing::DataFile;

// --- Indicator -------------------------------------------------------------------------------

// Independent per-node test; nodes within rounding of the sphere (|d^2 - r^2| tiny) may go either
// way and are only counted.
void ExpectIndicatorMatchesBruteForce(const GridSpec& grid, const Packing& packing) {
  const std::vector<std::uint8_t> fast = Indicator(grid, packing);
  ASSERT_EQ(fast.size(), grid.NodeCount());
  std::size_t mismatches = 0;
  std::size_t borderline = 0;
  std::size_t inside = 0;
  for (int i = 0; i < grid.dims[0]; ++i) {
    for (int j = 0; j < grid.dims[1]; ++j) {
      for (int k = 0; k < grid.dims[2]; ++k) {
        const Eigen::Vector3d x = grid.origin_m + grid.voxel_m * Eigen::Vector3d(i, j, k);
        bool truth = false;
        bool near = false;
        for (std::size_t b = 0; b < packing.radii.size(); ++b) {
          const double d2 = (x - packing.centres[b]).squaredNorm();
          const double r2 = packing.radii[b] * packing.radii[b];
          truth = truth || d2 < r2;
          near = near || std::abs(d2 - r2) <= 1e-12 * r2;
        }
        inside += truth ? 1 : 0;
        if ((fast[grid.Index(i, j, k)] != 0) != truth) {
          if (near) {
            ++borderline;
          } else {
            ++mismatches;
          }
        }
      }
    }
  }
  EXPECT_EQ(mismatches, 0u);
  EXPECT_GT(inside, 0u);
  std::printf("[ indicator ] %zu inside nodes, %zu borderline differences\n", inside, borderline);
}

GridSpec SmallGrid() {
  GridSpec grid;
  grid.dims = {41, 37, 33};
  grid.origin_m = Eigen::Vector3d(-0.211, -0.187, -0.163);
  grid.voxel_m = 0.0103;
  grid.band_voxels = 4;
  return grid;
}

TEST(Indicator, SingleBallEqualsBruteForce) {
  Packing one;
  one.centres = {Eigen::Vector3d(0.0123, -0.0071, 0.0049)};
  one.radii = {0.1377};
  ExpectIndicatorMatchesBruteForce(SmallGrid(), one);
}

TEST(Indicator, SeveralBallsEqualBruteForce) {
  // Includes a ball cut by the grid faces, a tiny one between nodes and one centred on a node.
  const GridSpec grid = SmallGrid();
  Packing balls;
  balls.centres = {Eigen::Vector3d(0.19, 0.15, -0.12), Eigen::Vector3d(-0.05, 0.02, 0.03),
                   Eigen::Vector3d(0.001, 0.001, 0.001), grid.Node(10, 12, 14)};
  balls.radii = {0.09, 0.06, 0.003, 5 * grid.voxel_m};
  ExpectIndicatorMatchesBruteForce(grid, balls);
}

// --- Erosion field against a literal multi-source BFS ----------------------------------------

std::vector<float> ReferenceErosion(const GridSpec& grid, std::vector<std::uint8_t> s) {
  const int nx = grid.dims[0], ny = grid.dims[1], nz = grid.dims[2];
  const int band = grid.band_voxels;
  for (int i = 0; i < nx; ++i)
    for (int j = 0; j < ny; ++j)
      for (int k = 0; k < nz; ++k)
        if (i == 0 || j == 0 || k == 0 || i == nx - 1 || j == ny - 1 || k == nz - 1)
          s[grid.Index(i, j, k)] = 0;  // grid faces are outside
  // BFS distance from the nodes with s == source_value through the others.
  const auto bfs = [&](std::uint8_t source_value) {
    std::vector<int> dist(s.size(), -1);
    std::deque<std::array<int, 3>> queue;
    for (int i = 0; i < nx; ++i)
      for (int j = 0; j < ny; ++j)
        for (int k = 0; k < nz; ++k)
          if (s[grid.Index(i, j, k)] == source_value) {
            dist[grid.Index(i, j, k)] = 0;
            queue.push_back({i, j, k});
          }
    constexpr int kSteps[6][3] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
    while (!queue.empty()) {
      const auto [i, j, k] = queue.front();
      queue.pop_front();
      for (const auto& step : kSteps) {
        const int a = i + step[0], b = j + step[1], c = k + step[2];
        if (a < 0 || b < 0 || c < 0 || a >= nx || b >= ny || c >= nz) continue;
        int& d = dist[grid.Index(a, b, c)];
        if (d >= 0) continue;
        d = dist[grid.Index(i, j, k)] + 1;
        queue.push_back({a, b, c});
      }
    }
    return dist;
  };
  const std::vector<int> d_out = bfs(0);
  const std::vector<int> d_in = bfs(1);
  std::vector<float> phi(s.size());
  for (std::size_t x = 0; x < s.size(); ++x) {
    // Unreached nodes (no source at all) are beyond the band.
    const int out = d_out[x] < 0 ? band + 1 : d_out[x];
    const int in = d_in[x] < 0 ? band : d_in[x];
    phi[x] = s[x] ? -static_cast<float>(std::min(band, out - 1)) : static_cast<float>(std::min(band, in));
  }
  return phi;
}

TEST(ErosionField, EqualsReferenceBfs) {
  GridSpec grid;
  grid.dims = {26, 19, 23};
  grid.voxel_m = 1.0;
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int band : {1, 3, 6}) {
    grid.band_voxels = band;
    // Random blobs, a ball through the grid faces, and salt noise (holes and specks).
    Packing blobs;
    for (int b = 0; b < 6; ++b) {
      blobs.centres.emplace_back(26 * u(rng), 19 * u(rng), 23 * u(rng));
      blobs.radii.push_back(2.0 + 7.0 * u(rng));
    }
    std::vector<std::uint8_t> indicator = Indicator(grid, blobs);
    for (auto& v : indicator) {
      if (u(rng) < 0.02) v = static_cast<std::uint8_t>(1 - v);
    }
    const DenseField field = ErosionField(grid, indicator);
    const std::vector<float> reference = ReferenceErosion(grid, indicator);
    ASSERT_EQ(field.phi_voxels.size(), reference.size());
    std::size_t mismatches = 0;
    std::size_t inside = 0;
    for (std::size_t x = 0; x < reference.size(); ++x) {
      mismatches += field.phi_voxels[x] != reference[x] ? 1u : 0u;
      inside += reference[x] <= 0.0f ? 1u : 0u;
    }
    EXPECT_EQ(mismatches, 0u) << "band " << band;
    EXPECT_EQ(field.inside_nodes, inside) << "band " << band;
  }
}

TEST(ErosionField, GridFacesAreOutsideEvenUnderALeakingBall) {
  GridSpec grid;
  grid.dims = {10, 12, 14};
  grid.voxel_m = 1.0;
  grid.band_voxels = 6;
  const std::vector<std::uint8_t> all(grid.NodeCount(), 1);
  const DenseField field = ErosionField(grid, all);
  EXPECT_EQ(field.inside_nodes, 8u * 10u * 12u);
  EXPECT_EQ(field.phi_voxels[grid.Index(0, 5, 5)], 1.0f);
  EXPECT_EQ(field.phi_voxels[grid.Index(1, 5, 5)], 0.0f);
  EXPECT_EQ(field.phi_voxels[grid.Index(4, 5, 6)], -3.0f);
  EXPECT_EQ(field.phi_voxels[grid.Index(9, 11, 13)], 3.0f);  // corner: S is 3 steps away
}

// --- Sphere926 against the analytic sphere ---------------------------------------------------

struct SphereCase {
  BuildResult build;
  Eigen::Vector3d centre;  // device
  double radius = 0.0;     // device
};

SphereCase BuildSphere926(int cells) {
  const auto points = ReadPoints(DataFile("sphere926.pwn"));
  EXPECT_TRUE(points.has_value());
  const Transform fit = FitTransform(*points, 0.06);
  const PointSet device = ApplyTransform(fit, *points);
  BuildOptions options;
  options.grid.cells = cells;
  options.method = FieldMethod::kErosion;
  auto build = BuildField(device.positions, device.normals, options);
  EXPECT_TRUE(build.has_value()) << build.error().message;
  return SphereCase{std::move(*build), fit.Apply(Eigen::Vector3d::Zero()), 10.0 * fit.scale};
}

// Error bound, derived (all lengths in voxels; s = true signed distance |x - c| - R at node x).
// Let the packed-ball union U satisfy B(c, R - Din) in U in B(c, R + Dout); S = nodes strictly
// inside U. Facts: ||v||_2 <= ||v||_1 <= sqrt(3) ||v||_2; any point q has a lattice node within
// ||.||_1 <= 3/2 (||.||_2 <= sqrt(3)/2) of it.
//  x not in S: phi = min(band, d_in).
//    d_in >= |x-y|_2 > s - Dout for every y in S (|y-c| < R + Dout)  ==>  s - phi < Dout.
//    The node y nearest q = c + (R - Din - sqrt3/2) u (u toward x) is in S, and
//    d_in <= ||x-q||_1 + 3/2 <= sqrt3 (s + Din + sqrt3/2) + 3/2  ==>
//    phi - s <= min(band - s, (sqrt3 - 1) s + sqrt3 Din + 3).
//  x in S: phi = -min(band, d_out - 1).
//    Nodes not in S have |z-c| >= R - Din, so d_out >= -s - Din  ==>  phi - s <= Din + 1.
//    The node z nearest q = c + (R + Dout + sqrt3/2) u is not in S  ==>
//    d_out <= sqrt3 (-s + Dout) + 3  ==>  s - phi <= min(band + s, (sqrt3 - 1)(-s) + sqrt3 Dout + 2).
// Dout is exact: max_i |c_i - c| + r_i - R. Din: every ball contains c (checked), so U is
// star-shaped about c and Din = R - min_u rho(u), rho = U's radial extent, estimated on 40,000
// directions. Din, Dout come from the packing geometry (normal noise), not from the field.
struct Bound {
  double upper;  // phi - s <= upper
  double lower;  // s - phi <= lower
};
Bound ErrorBound(double s, double band, double d_in, double d_out) {
  const double r3 = std::numbers::sqrt3;
  return {std::max(d_in + 1.0, std::min(band - s, (r3 - 1.0) * s + r3 * d_in + 3.0)),
          std::max(d_out, std::min(band + s, (r3 - 1.0) * -s + r3 * d_out + 2.0))};
}

// Radial extent of the packed-ball union about the sphere centre, in metres (plain arithmetic:
// this runs in sanitizer builds too).
struct UnionExtent {
  double min_rho;  // min over sampled directions of the union's radial extent
  double max_rho;  // exact: max_i |c_i - c| + r_i
};
UnionExtent MeasureUnion(const Packing& packing, const Eigen::Vector3d& centre) {
  std::vector<std::array<double, 4>> balls;  // centre relative to the sphere centre, r^2
  UnionExtent extent{std::numeric_limits<double>::infinity(), 0.0};
  for (std::size_t i = 0; i < packing.radii.size(); ++i) {
    const Eigen::Vector3d c = packing.centres[i] - centre;
    const double r = packing.radii[i];
    EXPECT_LT(c.norm(), r) << "ball " << i << " does not contain the centre";
    extent.max_rho = std::max(extent.max_rho, c.norm() + r);
    balls.push_back({c.x(), c.y(), c.z(), r * r});
  }
  constexpr int kDirections = 40000;
  for (int d = 0; d < kDirections; ++d) {  // Fibonacci sphere
    const double uz = 1.0 - (2.0 * d + 1.0) / kDirections;
    const double azimuth = d * std::numbers::pi * (3.0 - std::sqrt(5.0));
    const double rxy = std::sqrt(1.0 - uz * uz);
    const double ux = rxy * std::cos(azimuth);
    const double uy = rxy * std::sin(azimuth);
    double rho = 0.0;
    for (const auto& [cx, cy, cz, r2] : balls) {
      const double cu = cx * ux + cy * uy + cz * uz;
      rho = std::max(rho, cu + std::sqrt(r2 - (cx * cx + cy * cy + cz * cz) + cu * cu));
    }
    extent.min_rho = std::min(extent.min_rho, rho);
  }
  return extent;
}

void CheckSphere(int cells) {
  const SphereCase sphere = BuildSphere926(cells);
  const GridSpec& grid = sphere.build.field.grid();
  DenseField field{grid, sphere.build.field.ToDense(), sphere.build.inside_nodes};
  const double h = grid.voxel_m;
  const double band = grid.band_voxels;
  const UnionExtent extent = MeasureUnion(sphere.build.packing, sphere.centre);
  const double d_in = std::max(0.0, sphere.radius - extent.min_rho) / h;
  const double d_out = std::max(0.0, extent.max_rho - sphere.radius) / h;

  double max_bound = 0.0;
  for (double s = -band; s <= band; s += 1e-3) {
    const Bound b = ErrorBound(s, band, d_in, d_out);
    max_bound = std::max({max_bound, b.upper, b.lower});
  }

  double sum_error = 0.0;
  double sum_bound = 0.0;
  double max_error = 0.0;
  std::size_t count = 0;
  std::size_t violations = 0;
  const double cx = (sphere.centre.x() - grid.origin_m.x()) / h;
  const double cy = (sphere.centre.y() - grid.origin_m.y()) / h;
  const double cz = (sphere.centre.z() - grid.origin_m.z()) / h;
  const double radius = sphere.radius / h;
  for (int i = 0; i < grid.dims[0]; ++i) {
    for (int j = 0; j < grid.dims[1]; ++j) {
      for (int k = 0; k < grid.dims[2]; ++k) {
        const double s = std::hypot(i - cx, j - cy, k - cz) - radius;
        if (std::abs(s) > band) continue;
        const double error = field.phi_voxels[grid.Index(i, j, k)] - s;
        const Bound b = ErrorBound(s, band, d_in, d_out);
        if (error > b.upper || -error > b.lower) ++violations;
        sum_error += std::abs(error);
        sum_bound += std::max(b.upper, b.lower);
        max_error = std::max(max_error, std::abs(error));
        ++count;
      }
    }
  }
  const double mean_error = sum_error / static_cast<double>(count);
  std::printf(
      "[ sphere926 %d cells ] grid %dx%dx%d voxel %.3f mm, R %.1f voxels, union radial extent "
      "%+.3f..%+.3f voxels (Din %.3f Dout %.3f); %zu band nodes: |error| mean %.3f max %.3f voxels "
      "(bound: max %.3f, mean %.3f)\n",
      cells, grid.dims[0], grid.dims[1], grid.dims[2], h * 1e3, radius, (extent.min_rho - sphere.radius) / h,
      (extent.max_rho - sphere.radius) / h, d_in, d_out, count, mean_error, max_error, max_bound,
      sum_bound / static_cast<double>(count));
  EXPECT_GT(count, 1000u);
  EXPECT_EQ(violations, 0u);
  EXPECT_LE(max_error, max_bound);
  EXPECT_LE(mean_error, sum_bound / static_cast<double>(count));
}

TEST(Sphere926, FieldWithinErosionBound150Cells) { CheckSphere(150); }
TEST(Sphere926, FieldWithinErosionBound300Cells) { CheckSphere(300); }

// --- Determinism, API, timings ---------------------------------------------------------------

TEST(BuildField, ErosionOneAndTwoThreadsGiveIdenticalFields) {
  const auto points = ReadPoints(DataFile("kitten.xyz"));
  ASSERT_TRUE(points.has_value()) << points.error().message;
  const PointSet device = ApplyTransform(FitTransform(*points, 0.06), *points);
  BuildOptions options;
  options.grid.cells = 120;
  options.method = FieldMethod::kErosion;
  const auto build_with = [&](std::size_t threads) {
    const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    auto result = BuildField(device.positions, device.normals, options);
    EXPECT_TRUE(result.has_value());
    return std::move(*result);
  };
  const BuildResult one = build_with(1);
  const BuildResult two = build_with(2);
  EXPECT_EQ(one.packing.radii, two.packing.radii);
  EXPECT_EQ(one.field.ToDense(), two.field.ToDense());
  EXPECT_EQ(one.inside_nodes, two.inside_nodes);
  EXPECT_GT(one.inside_nodes, 0u);
}

TEST(BuildField, ErrorsAndProgress) {
  const std::vector<Eigen::Vector3d> p = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  const std::vector<Eigen::Vector3d> n = {{-1, -1, -1}, {2, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  EXPECT_FALSE(BuildField(p, {n.begin(), n.end() - 1}, {}).has_value());
  auto bad_normal = n;
  bad_normal[2] = Eigen::Vector3d::Zero();
  EXPECT_FALSE(BuildField(p, bad_normal, {}).has_value());
  BuildOptions bad_grid;
  bad_grid.grid.cells = 10;
  const auto grid_error = BuildField(p, n, bad_grid);
  ASSERT_FALSE(grid_error.has_value());
  EXPECT_NE(grid_error.error().message.find("cells"), std::string::npos);

  std::vector<double> reported;
  const std::thread::id caller = std::this_thread::get_id();
  bool other_thread = false;
  BuildOptions small;
  small.grid.cells = 60;
  const auto ok = BuildField(p, n, small, [&](double f) {
    reported.push_back(f);
    other_thread = other_thread || std::this_thread::get_id() != caller;
  });
  ASSERT_TRUE(ok.has_value()) << ok.error().message;
  EXPECT_FALSE(other_thread);
  ASSERT_FALSE(reported.empty());
  EXPECT_TRUE(std::is_sorted(reported.begin(), reported.end()));
  EXPECT_GE(reported.front(), 0.0);
  EXPECT_EQ(reported.back(), 1.0);
  EXPECT_EQ(ok->transform.scale, 1.0);
  EXPECT_GT(ok->inside_nodes, 0u);
}

TEST(BuildField, ErosionKittenTimings300Cells) {
  const auto points = ReadPoints(DataFile("kitten.xyz"));
  ASSERT_TRUE(points.has_value()) << points.error().message;
  const PointSet device = ApplyTransform(FitTransform(*points, 0.06), *points);
  BuildOptions options;
  options.grid.cells = 300;
  options.method = FieldMethod::kErosion;
  const auto build = BuildField(device.positions, device.normals, options);
  ASSERT_TRUE(build.has_value()) << build.error().message;
  const GridSpec& g = build->field.grid();
  std::printf(
      "[ kitten 300 cells ] %zu points, grid %dx%dx%d, %zu inside nodes; packing %.3f s, "
      "indicator %.3f s, distance %.3f s (threads: %u)\n",
      device.positions.size(), g.dims[0], g.dims[1], g.dims[2], build->inside_nodes, build->seconds_packing,
      build->seconds_indicator, build->seconds_distance, std::thread::hardware_concurrency());
  EXPECT_GT(build->inside_nodes, 0u);
}

}  // namespace
}  // namespace palpa::field
