// FillSamplelessPockets against an analytic solid: a ball with outside pockets cut into it, some
// enclosed and some joined to the outside by one-node tunnels, with samples on the ball and on one
// pocket; what is filled, and every node's sign and value, are worked out from the construction.
// CutSamplelessIslands the same way, on small balls floating beside a sampled one.
#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <vector>

#include <gtest/gtest.h>

#include "palpa/field/pockets.h"
#include "palpa/field/sparse_field.h"

namespace palpa::field {
namespace {

using V3 = Eigen::Vector3d;

constexpr int kBand = 6;

// n points spread evenly over the sphere (c, r) (a Fibonacci lattice), normals pointing away from
// c (`outward`) or towards it.
void SphereSamples(const V3& c, double r, int n, bool outward, std::vector<V3>& out, std::vector<V3>& normals) {
  const double golden = std::numbers::pi * (3.0 - std::sqrt(5.0));
  for (int m = 0; m < n; ++m) {
    const double z = 1.0 - 2.0 * (m + 0.5) / n, s = std::sqrt(1.0 - z * z);
    const V3 u(s * std::cos(golden * m), s * std::sin(golden * m), z);
    out.push_back(c + r * u);
    normals.push_back(outward ? u : V3(-u));
  }
}

struct Solid {
  GridSpec grid;
  V3 centre{30.0, 29.0, 26.0};
  double radius = 22.0;
  // Outside pockets (balls) cut into the solid; [1] and [2] each joined to the outside by a
  // straight one-node tunnel, along k and along j (across brick faces on those axes).
  std::array<V3, 5> pocket_centre;
  std::array<double, 5> pocket_radius = {5.0, 4.0, 4.0, 4.0, 1.5};
  std::vector<float> dense;  // phi in voxels, C order
  Solid() {
    grid.dims = {61, 58, 53};  // not multiples of 8: part bricks at the far faces
    grid.voxel_m = 1.0;
    grid.band_voxels = kBand;
    pocket_centre = {centre + V3(-8, 0, 0),    // [0] enclosed, no sample near: filled
                     centre + V3(0, 0, 10),    // [1] tunnel to +k
                     centre + V3(0, 10, 0),    // [2] tunnel to +j
                     centre + V3(10, 0, 0),    // [3] enclosed, sampled
                     centre + V3(0, 0, -19)};  // [4] enclosed, 1.5 voxels inside the sampled ball
    dense.resize(grid.NodeCount());
    for (int i = 0; i < grid.dims[0]; ++i)
      for (int j = 0; j < grid.dims[1]; ++j)
        for (int k = 0; k < grid.dims[2]; ++k) {
          const V3 p(i, j, k);
          double phi = (p - centre).norm() - radius;
          for (std::size_t q = 0; q < pocket_centre.size(); ++q)
            phi = std::max(phi, pocket_radius[q] - (p - pocket_centre[q]).norm());
          const auto c = centre.cast<int>();
          const bool tunnel_k = i == c.x() && j == c.y() && k > c.z() + 10;
          const bool tunnel_j = i == c.x() && k == c.z() && j > c.y() + 10;
          if (tunnel_k || tunnel_j) phi = std::max(phi, 0.5);
          dense[grid.Index(i, j, k)] = static_cast<float>(std::clamp(phi, -1.0 * kBand, 1.0 * kBand));
        }
  }
  int PocketOf(int i, int j, int k) const {
    for (std::size_t q = 0; q < pocket_centre.size(); ++q)
      if ((V3(i, j, k) - pocket_centre[q]).norm() < pocket_radius[q]) return static_cast<int>(q);
    return -1;
  }
};

// A grid of 1-metre voxels from the origin (so that a node's index is its position).
GridSpec UnitGrid(const std::array<int, 3>& dims, int band) {
  GridSpec grid;
  grid.dims = dims;
  grid.voxel_m = 1.0;
  grid.band_voxels = band;
  return grid;
}

double NearestDistance(const std::vector<V3>& samples, const V3& p) {
  double best = 1e300;
  for (const V3& s : samples) best = std::min(best, (s - p).norm());
  return best;
}

TEST(FillSamplelessPockets, FillsOnlyTheEnclosedPocketNoSampleBounds) {
  const Solid solid;
  std::vector<V3> samples, normals;
  SphereSamples(solid.centre, solid.radius, 2000, true, samples, normals);  // 1.75 voxels apart
  // Pocket 3's wall, its outward normals into the pocket.
  SphereSamples(solid.pocket_centre[3], solid.pocket_radius[3], 200, false, samples, normals);
  // Spacings of 10 voxels: every sample within a spacing of pocket 0 (its surface 9 voxels from
  // the ball's) has it behind.
  const std::vector<double> spacing(samples.size(), 10.0);
  SparseField field = SparseField::FromDense(solid.grid, solid.dense);

  const PocketFill filled = FillSamplelessPockets(field, samples, normals, spacing);

  std::size_t pocket0 = 0;
  for (int i = 0; i < solid.grid.dims[0]; ++i)
    for (int j = 0; j < solid.grid.dims[1]; ++j)
      for (int k = 0; k < solid.grid.dims[2]; ++k) {
        const float before = solid.dense[solid.grid.Index(i, j, k)];
        const float after = field.Value(i, j, k);
        const V3 p(i, j, k);
        if (solid.PocketOf(i, j, k) == 0) {
          ++pocket0;
          const double d = NearestDistance(samples, p);
          ASSERT_GT(d, 3.0);  // the construction: every node of pocket 0 is beyond the reach
          EXPECT_NEAR(after, -std::min(static_cast<double>(kBand), d), 1e-4) << i << " " << j << " " << k;
          continue;
        }
        // Every other node keeps its side.
        ASSERT_EQ(after <= 0.0f, before <= 0.0f) << i << " " << j << " " << k << " pocket " << solid.PocketOf(i, j, k);
        // Inside nodes round pocket 0 that lie beyond the reach take the far pass's depth; the
        // rest keep their values.
        const double from_pocket = (p - solid.pocket_centre[0]).norm() - solid.pocket_radius[0];
        const double d = NearestDistance(samples, p);
        if (before <= 0.0f && before > -kBand && from_pocket < 1.0 && d > 3.0) {
          EXPECT_NEAR(after, std::min(before, static_cast<float>(-std::min(1.0 * kBand, d))), 1e-4);
        } else if (from_pocket > kBand + 1.0) {
          EXPECT_EQ(after, before) << i << " " << j << " " << k;
        }
      }
  EXPECT_EQ(filled.components, 1u);
  EXPECT_EQ(filled.nodes, pocket0);
  EXPECT_GT(pocket0, 400u);  // 4/3 pi 5^3 = 524
}

// Pocket 3 with its wall's samples 4 voxels away (a sphere of radius 8 about it), beyond the 3
// voxels that keep any pocket: kept while they face it and it lies within their spacing; filled
// when they turn their backs on it, or when their spacing is under 4 voxels.
TEST(FillSamplelessPockets, APocketStaysWhereNearbySamplesFaceIt) {
  const Solid solid;
  std::size_t in0 = 0, in3 = 0;
  for (int i = 0; i < solid.grid.dims[0]; ++i)
    for (int j = 0; j < solid.grid.dims[1]; ++j)
      for (int k = 0; k < solid.grid.dims[2]; ++k) {
        in0 += solid.PocketOf(i, j, k) == 0 ? 1u : 0u;
        in3 += solid.PocketOf(i, j, k) == 3 ? 1u : 0u;
      }
  const auto fill = [&](bool facing, double wall_spacing) {
    std::vector<V3> samples, normals;
    SphereSamples(solid.centre, solid.radius, 2000, true, samples, normals);
    std::vector<double> spacing(samples.size(), 2.0);
    SphereSamples(solid.pocket_centre[3], 8.0, 400, !facing, samples, normals);
    spacing.resize(samples.size(), wall_spacing);
    SparseField field = SparseField::FromDense(solid.grid, solid.dense);
    const PocketFill filled = FillSamplelessPockets(field, samples, normals, spacing);
    // Pocket 3's centre: outside while kept, inside once filled.
    const Eigen::Vector3i c = solid.pocket_centre[3].cast<int>();
    EXPECT_EQ(field.Value(c.x(), c.y(), c.z()) <= 0.0f, filled.components == 2u);
    return filled;
  };
  const PocketFill faced = fill(true, 6.0);
  EXPECT_EQ(faced.components, 1u);
  EXPECT_EQ(faced.nodes, in0);
  const PocketFill turned = fill(false, 6.0);
  EXPECT_EQ(turned.components, 2u);
  EXPECT_EQ(turned.nodes, in0 + in3);
  const PocketFill near_spaced = fill(true, 3.5);
  EXPECT_EQ(near_spaced.components, 2u);
  EXPECT_EQ(near_spaced.nodes, in0 + in3);
}

// With no enclosed pocket the field is left as it was.
TEST(FillSamplelessPockets, NothingEnclosedChangesNothing) {
  const GridSpec grid = UnitGrid({40, 37, 35}, 4);
  const V3 c(20, 18, 17);
  std::vector<float> dense(grid.NodeCount());
  for (int i = 0; i < grid.dims[0]; ++i)
    for (int j = 0; j < grid.dims[1]; ++j)
      for (int k = 0; k < grid.dims[2]; ++k)
        dense[grid.Index(i, j, k)] = static_cast<float>(std::clamp((V3(i, j, k) - c).norm() - 12.0, -4.0, 4.0));
  SparseField field = SparseField::FromDense(grid, dense);
  const PocketFill filled = FillSamplelessPockets(field, {}, {}, {});
  EXPECT_EQ(filled.components, 0u);
  EXPECT_EQ(filled.nodes, 0u);
  EXPECT_EQ(field.ToDense(), SparseField::FromDense(grid, dense).ToDense());
}

// A uniform outside brick wholly inside a pocket is a pocket's too: a ball of radius 9 holds an
// 8^3 brick (its nodes 3.5 sqrt 3 = 6.1 voxels from the centre at most), which FromDense keeps
// uniform (no node within the band of 2 voxels).
TEST(FillSamplelessPockets, FillsAPocketThatHoldsAUniformBrick) {
  const GridSpec grid = UnitGrid({56, 56, 56}, 2);
  const V3 c(27.5, 27.5, 27.5);  // the centre of brick (3, 3, 3)
  std::vector<float> dense(grid.NodeCount());
  std::size_t pocket = 0;
  for (int i = 0; i < 56; ++i)
    for (int j = 0; j < 56; ++j)
      for (int k = 0; k < 56; ++k) {
        const double r = (V3(i, j, k) - c).norm();
        const double phi = std::max(r - 20.0, 9.0 - r);
        pocket += r < 9.0 ? 1u : 0u;
        dense[grid.Index(i, j, k)] = static_cast<float>(std::clamp(phi, -2.0, 2.0));
      }
  SparseField field = SparseField::FromDense(grid, dense);
  bool uniform_out = false;
  for (std::size_t b = 0; b < 343; ++b) {
    const auto bc = field.BrickCoords(b);
    const V3 mid = V3(bc[0], bc[1], bc[2]) * 8.0 + V3::Constant(3.5);
    uniform_out = uniform_out || ((mid - c).norm() < 5.0 && field.Slot(b) == SparseField::kUniformOutside);
  }
  ASSERT_TRUE(uniform_out);  // the construction holds what the test is for
  std::vector<V3> samples, normals;
  SphereSamples(c, 20.0, 3000, true, samples, normals);
  const PocketFill filled = FillSamplelessPockets(field, samples, normals, std::vector<double>(samples.size(), 1.0));
  EXPECT_EQ(filled.components, 1u);
  EXPECT_EQ(filled.nodes, pocket);
  for (int i = 0; i < 56; ++i)
    for (int j = 0; j < 56; ++j)
      for (int k = 0; k < 56; ++k) {
        const double r = (V3(i, j, k) - c).norm();
        EXPECT_EQ(field.Value(i, j, k) <= 0.0f, r <= 20.0) << i << " " << j << " " << k;
      }
}

// A ball (radius 10) with three floating balls of radius 2 beside it: [0] 8 voxels from its
// surface, no sample near; [1] with its own samples; [2] 5 voxels above a patch of samples
// (a disc) whose normals point away from it (down) or towards it (up).
TEST(CutSamplelessIslands, CutsOnlyTheIslandNoSampleBounds) {
  const GridSpec grid = UnitGrid({70, 45, 43}, 4);
  const V3 c(20, 22, 21);
  const std::array<V3, 3> isl = {c + V3(20, 0, 0), c + V3(35, 10, 0), V3(50, 22, 33)};
  std::vector<float> dense(grid.NodeCount());
  std::array<std::size_t, 3> count{};
  for (int i = 0; i < grid.dims[0]; ++i)
    for (int j = 0; j < grid.dims[1]; ++j)
      for (int k = 0; k < grid.dims[2]; ++k) {
        const V3 p(i, j, k);
        double phi = (p - c).norm() - 10.0;
        for (std::size_t q = 0; q < isl.size(); ++q) {
          phi = std::min(phi, (p - isl[q]).norm() - 2.0);
          count[q] += (p - isl[q]).norm() <= 2.0 ? 1u : 0u;
        }
        dense[grid.Index(i, j, k)] = static_cast<float>(std::clamp(phi, -4.0, 4.0));
      }
  const auto cut = [&](bool disc_facing_island, double disc_spacing) {
    std::vector<V3> samples, normals;
    SphereSamples(c, 10.0, 1500, true, samples, normals);
    std::vector<double> spacing(samples.size(), 2.0);
    SphereSamples(isl[1], 2.0, 60, true, samples, normals);
    // A disc of samples 5 voxels below island 2, in the plane z = 26.
    for (int u = -4; u <= 4; ++u)
      for (int v = -4; v <= 4; ++v) {
        samples.push_back(V3(isl[2].x() + u, isl[2].y() + v, isl[2].z() - 7.0));
        normals.push_back(V3(0, 0, disc_facing_island ? 1.0 : -1.0));
      }
    spacing.resize(samples.size(), disc_spacing);
    SparseField field = SparseField::FromDense(grid, dense);
    const PocketFill got = CutSamplelessIslands(field, samples, normals, spacing);
    for (std::size_t q = 0; q < isl.size(); ++q) {
      const Eigen::Vector3i n = isl[q].cast<int>();
      EXPECT_EQ(field.Value(n.x(), n.y(), n.z()) > 0.0f,
                q == 0 || (q == 2 && (disc_facing_island || disc_spacing < 5.0)))
          << "island " << q;
    }
    // The big ball is untouched.
    EXPECT_LE(field.Value(20, 22, 21), -4.0f);
    return got;
  };
  // Facing the disc's samples (in front of them): cut; behind them within a spacing: kept.
  const PocketFill facing = cut(true, 6.0);
  EXPECT_EQ(facing.components, 2u);
  EXPECT_EQ(facing.nodes, count[0] + count[2]);
  const PocketFill behind = cut(false, 6.0);
  EXPECT_EQ(behind.components, 1u);
  EXPECT_EQ(behind.nodes, count[0]);
  // Behind them but beyond their spacing (3 voxels; the island is 5 away): cut.
  const PocketFill far_behind = cut(false, 3.0);
  EXPECT_EQ(far_behind.components, 2u);
}

}  // namespace
}  // namespace palpa::field
