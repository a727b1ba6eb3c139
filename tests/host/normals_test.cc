// Normals estimated and oriented (issue 20, `palpa build --normals`), against analytic shapes:
// the sphere's radial normals, the cube's face normals, a dome (an open one-sided scan), two
// separate bodies, and a thin plate whose two sides face away from each other.
#include "palpa/field/normals.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <map>
#include <numbers>
#include <random>
#include <utility>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include "palpa/field/point_io.h"
#include "palpa/field/samples.h"
#include "palpa/field/winding.h"
#include "test_util.h"

namespace palpa::field {
namespace {

using V3 = Eigen::Vector3d;

struct Oriented {
  std::vector<V3> positions;
  std::vector<V3> normals;  // exact outward normals
};

// n points on a sphere (Fibonacci lattice), radius r about c; only those with z >= z_min / r.
Oriented Sphere(std::size_t n, double r, const V3& c = V3::Zero(), double z_min = -2.0) {
  Oriented out;
  for (std::size_t i = 0; i < n; ++i) {
    const V3 u = testing::FibonacciPoint(i, n);
    if (u.z() < z_min) continue;
    out.positions.push_back(c + r * u);
    out.normals.push_back(u);
  }
  return out;
}

// The six faces of the cube [-1, 1]^3, each an m x m grid of cell centres (no sample on an edge).
Oriented Cube(int m) {
  Oriented out;
  for (int axis = 0; axis < 3; ++axis) {
    for (const double side : {-1.0, 1.0}) {
      for (int a = 0; a < m; ++a) {
        for (int b = 0; b < m; ++b) {
          V3 p;
          p[axis] = side;
          p[(axis + 1) % 3] = -1.0 + 2.0 * (a + 0.5) / m;
          p[(axis + 2) % 3] = -1.0 + 2.0 * (b + 0.5) / m;
          V3 n = V3::Zero();
          n[axis] = side;
          out.positions.push_back(p);
          out.normals.push_back(n);
        }
      }
    }
  }
  return out;
}

// The angle in degrees between a line and a unit normal, whatever the line's sign.
double LineAngleDeg(const V3& line, const V3& normal) {
  return std::acos(std::min(1.0, std::abs(line.dot(normal)))) * 180.0 / std::numbers::pi;
}

double MedianOf(std::vector<double> v) {
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

double WorstAngleDeg(const std::vector<V3>& got, const std::vector<V3>& want) {
  double worst = 0;
  for (std::size_t i = 0; i < got.size(); ++i)
    worst = std::max(worst, std::acos(std::clamp(got[i].dot(want[i]), -1.0, 1.0)) * 180.0 / std::numbers::pi);
  return worst;
}

std::size_t CountAgainst(const std::vector<V3>& got, const std::vector<V3>& want) {
  std::size_t against = 0;
  for (std::size_t i = 0; i < got.size(); ++i) against += got[i].dot(want[i]) < 0 ? 1u : 0u;
  return against;
}

TEST(Normals, JetLinesOnASphereAreRadial) {
  const Oriented s = Sphere(4000, 0.03);
  std::vector<V3> lines;
  EstimateNormalLines(s.positions, lines);
  ASSERT_EQ(lines.size(), s.positions.size());
  for (std::size_t i = 0; i < lines.size(); ++i) {
    EXPECT_NEAR(lines[i].norm(), 1.0, 1e-12);
    EXPECT_GT(std::abs(lines[i].dot(s.normals[i])), std::cos(1.0 * std::numbers::pi / 180)) << i;
  }
}

// A closed box 2 x 2 x `thickness`, each face sampled uniformly at random, one sample per h^2.
Oriented Plate(double h, double thickness, std::uint32_t seed) {
  Oriented out;
  std::mt19937 random(seed);
  std::uniform_real_distribution<double> unit(-0.5, 0.5);
  const V3 size(2.0, 2.0, thickness);
  for (int axis = 0; axis < 3; ++axis) {
    const int a = (axis + 1) % 3, b = (axis + 2) % 3;
    const auto count = static_cast<int>(std::lround(size[a] * size[b] / (h * h)));
    for (const double side : {-1.0, 1.0}) {
      for (int i = 0; i < count; ++i) {
        V3 p;
        p[axis] = side * size[axis] / 2;
        p[a] = size[a] * unit(random);
        p[b] = size[b] * unit(random);
        V3 n = V3::Zero();
        n[axis] = side;
        out.positions.push_back(p);
        out.normals.push_back(n);
      }
    }
  }
  return out;
}

TEST(Normals, CleanSamplesOfAThinPlateKeepEachSidesLine) {
  // Two sides 2.2 spacings apart: the 18 nearest of a sample on one side reach ~2.4 spacings and
  // often take in the other side's, and their jet fit is tilted by the surface it bends to join
  // them; the 10 nearest (~1.8 spacings) rarely do. Measured on the 10,948 face samples at least
  // 3 spacings from the rim, more than 5 degrees off: 346 with 10 neighbours, 5,285 with 18.
  const double h = 1.0 / 40;
  const Oriented plate = Plate(h, 2.2 * h, 3);
  std::vector<V3> lines;
  EXPECT_EQ(EstimateNormalLines(plate.positions, lines), kCleanNormalNeighbours);
  std::size_t considered = 0, off = 0;
  for (std::size_t i = 0; i < lines.size(); ++i) {
    const V3& p = plate.positions[i];
    if (std::abs(plate.normals[i].z()) < 1 || std::max(std::abs(p.x()), std::abs(p.y())) > 1 - 3 * h) continue;
    ++considered;
    off += std::abs(lines[i].dot(plate.normals[i])) < std::cos(5.0 * std::numbers::pi / 180) ? 1u : 0u;
  }
  EXPECT_GT(considered, 10000u);
  EXPECT_LE(off, considered / 20) << off << " of " << considered;
}

TEST(Normals, ACleanWallThinnerThanTheSpacingIsNotTakenForNoise) {
  // Sides 0.6 spacings apart (CGAL's rotor's blades): a sample's 10 nearest hold both, and one
  // quadric through them leaves a residual of noise at 0.5 voxel; two parallel sheets leave ~0.
  // The same plate with that noise (0.2 of the 8th neighbour's distance) is still noisy.
  // Sides 0.8-1.6 spacings apart put one or two of the other side among a sample's 10 nearest, or
  // spread them as far across the wall as along it: the two sheets' fit takes a sheet of one
  // sample, along any axis of the scatter (a plate 1.2 voxels thick, 2,200-8,000 bare samples at
  // 40-80 cells, was read as very noisy: 43-47 % of the band wrong). Noisy, the wider plates are
  // also rough enough for more than 18 neighbours.
  const double h = 1.0 / 40;
  for (const double thickness : {0.6, 0.8, 1.0, 1.3, 1.6}) {
    const Oriented plate = Plate(h, thickness * h, 5);
    std::vector<V3> lines;
    EXPECT_EQ(EstimateNormalLines(plate.positions, lines), kCleanNormalNeighbours) << thickness;
    std::mt19937 random(9);
    std::normal_distribution<double> noise(0.0, 0.2 * std::sqrt(8.0 / std::numbers::pi) * h / std::sqrt(2.0));
    Oriented noisy = plate;
    for (V3& p : noisy.positions) p += V3(noise(random), noise(random), noise(random));
    EXPECT_GE(EstimateNormalLines(noisy.positions, lines), kNormalNeighbours) << thickness;
  }
}

TEST(Normals, NoisySamplesAreFittedOverEighteenNeighbours) {
  // Position noise of 0.2 of the 8th neighbour's distance (what 0.5 voxel is at 150 cells on
  // 5,000 samples): the wider fit averages it. The clean sphere is fitted over 10.
  const Oriented clean = Sphere(4000, 1.0);
  std::vector<V3> lines;
  EXPECT_EQ(EstimateNormalLines(clean.positions, lines), kCleanNormalNeighbours);
  const double spacing = std::sqrt(4 * std::numbers::pi / 4000);
  std::mt19937 random(7);
  std::normal_distribution<double> noise(0.0, 0.2 * std::sqrt(8.0 / std::numbers::pi) * spacing);
  Oriented noisy = clean;
  for (V3& p : noisy.positions) p += V3(noise(random), noise(random), noise(random));
  EXPECT_EQ(EstimateNormalLines(noisy.positions, lines), kNormalNeighbours);
}

TEST(Normals, VeryNoisySamplesWidenTheFit) {
  // Noise of 1.5 sample spacings per axis (CGAL's sphere_20k has 1.6): 18 neighbours span about
  // 2.4 spacings and their fit follows the noise; the widened fit is within a few degrees.
  // Measured on such a sphere: median angle to the radial line 27.3 degrees with 18 neighbours,
  // 11.4 with 40, 4.6 with the 90 chosen.
  const std::size_t n = 8000;
  const Oriented clean = Sphere(n, 1.0);
  const double spacing = std::sqrt(4 * std::numbers::pi / static_cast<double>(n));
  std::mt19937 random(11);
  std::normal_distribution<double> noise(0.0, 1.5 * spacing);
  Oriented noisy = clean;
  for (V3& p : noisy.positions) p += V3(noise(random), noise(random), noise(random));
  std::vector<V3> lines;
  const int neighbours = EstimateNormalLines(noisy.positions, lines);
  EXPECT_GT(neighbours, kNormalNeighbours);
  EXPECT_LE(neighbours, kMostNormalNeighbours);
  std::vector<double> angle;
  for (std::size_t i = 0; i < lines.size(); ++i)
    angle.push_back(LineAngleDeg(lines[i], noisy.positions[i].normalized()));
  EXPECT_LT(MedianOf(angle), 8.0) << neighbours << " neighbours";
}

TEST(Normals, RimSamplesOfAnOpenScanKeepTheirJetFit) {
  // A unit dome (z > 0.3), random samples: at its rim every plane through a sample extrapolates
  // from one side and tilts; the jet fit's quadric does not. Measured on the rim's samples (z <
  // 0.33), median angle to the radial line: 1.7 degrees refined there, 0.0 kept.
  std::mt19937 random(2);
  std::normal_distribution<double> gauss(0.0, 1.0);
  std::vector<V3> positions;
  while (positions.size() < 4200) {
    const V3 u = V3(gauss(random), gauss(random), gauss(random)).normalized();
    if (u.z() > 0.3) positions.push_back(u);
  }
  std::vector<V3> normals;
  const int neighbours = EstimateNormalLines(positions, normals);
  NormalsReport report;
  OrientNormals(positions, normals, false, report, true);
  RefineNormalLines(positions, normals, neighbours);
  std::vector<double> rim;
  for (std::size_t i = 0; i < positions.size(); ++i) {
    EXPECT_GT(normals[i].dot(positions[i]), 0.0) << i;
    if (positions[i].z() < 0.33)
      rim.push_back(std::acos(std::min(1.0, normals[i].dot(positions[i]))) * 180.0 / std::numbers::pi);
  }
  ASSERT_GT(rim.size(), 100u);
  EXPECT_LT(MedianOf(rim), 0.5);
}

TEST(Normals, EstimatedAndOrientedSphereIsOutward) {
  const Oriented s = Sphere(3000, 2.5, V3(10, -4, 7));  // off the origin: the sign may not assume it
  std::vector<V3> normals;
  EstimateNormalLines(s.positions, normals);
  NormalsReport report;
  OrientNormals(s.positions, normals, false, report, true);
  EXPECT_EQ(CountAgainst(normals, s.normals), 0u);
  EXPECT_LT(WorstAngleDeg(normals, s.normals), 1.0);
  EXPECT_EQ(report.components, 1u);
  EXPECT_EQ(report.open_components, 0u);
}

TEST(Normals, OrientRepairsRandomAndWholeFlipsOnACubeWithSharpEdges) {
  const Oriented cube = Cube(24);
  for (const double fraction : {0.05, 0.5, 1.0}) {
    std::vector<V3> normals = cube.normals;
    std::mt19937_64 rng(7);
    std::size_t flipped = 0;
    for (V3& n : normals) {
      if (static_cast<double>(rng() >> 11) * 0x1p-53 < fraction) {
        n = -n;
        ++flipped;
      }
    }
    NormalsReport report;
    OrientNormals(cube.positions, normals, true, report);
    // Lines kept exactly, signs all outward again; the count says how many changed.
    EXPECT_EQ(WorstAngleDeg(normals, cube.normals), 0.0) << fraction;
    EXPECT_EQ(report.flipped, flipped) << fraction;
    EXPECT_EQ(report.components, 1u);
  }
}

TEST(Normals, OrientKeepsConsistentNormalsOfAThinPlate) {
  // Two 40 x 40 sheets 0.3 spacings apart, normals away from each other: the nearest neighbours
  // across the wall are closer than those along it, and their normals are antiparallel.
  Oriented plate;
  for (int a = 0; a < 40; ++a) {
    for (int b = 0; b < 40; ++b) {
      for (const double side : {-1.0, 1.0}) {
        plate.positions.emplace_back(a * 1.0, b * 1.0, side * 0.15);
        plate.normals.emplace_back(0, 0, side);
      }
    }
  }
  std::vector<V3> normals = plate.normals;
  NormalsReport report;
  OrientNormals(plate.positions, normals, true, report);
  EXPECT_EQ(CountAgainst(normals, plate.normals), 0u) << report.Describe();
  EXPECT_EQ(report.flipped, 0u);
}

TEST(Normals, AOneSidedScanOfADomeIsOrientedOutward) {
  const Oriented dome = Sphere(6000, 1.0, V3(0.5, 0.2, -3.0), 0.2);  // the cap above z = 0.2 r
  std::vector<V3> normals;
  EstimateNormalLines(dome.positions, normals);
  NormalsReport report;
  OrientNormals(dome.positions, normals, false, report, true);
  EXPECT_EQ(CountAgainst(normals, dome.normals), 0u);
  EXPECT_EQ(report.components, 1u);
  EXPECT_EQ(report.open_components, 1u);
}

TEST(Normals, AnOpenScanFacingTheRestIsOrientedByItsWindingLevel) {
  // A closed sphere and, 3 radii away, a cap of a smaller sphere scanned from the side facing it
  // (one-sided, open). The cap's outward normals point towards the centre of all samples, so the
  // divergence sum about it calls them inward; the winding number's level (w just inside + just
  // outside) / 2 is positive only for the outward cap, whatever its shape or place.
  Oriented both = Sphere(3000, 1.0);
  const Oriented cap = Sphere(4000, 0.5, V3(3, 0, 0), -2.0);
  std::size_t cap_samples = 0;
  for (std::size_t i = 0; i < cap.positions.size(); ++i) {
    if (cap.normals[i].x() > -0.3) continue;  // the side facing the sphere
    both.positions.push_back(cap.positions[i]);
    both.normals.push_back(cap.normals[i]);
    ++cap_samples;
  }
  ASSERT_GT(cap_samples, 1000u);
  std::vector<V3> normals;
  EstimateNormalLines(both.positions, normals);
  NormalsReport report;
  OrientNormals(both.positions, normals, false, report, true);
  EXPECT_EQ(report.components, 2u);
  EXPECT_EQ(report.open_components, 1u);
  EXPECT_EQ(report.open_level_flipped, 1u);
  EXPECT_EQ(CountAgainst(normals, both.normals), 0u);
}

TEST(Normals, SeparateBodiesAreOrientedEachOnItsOwn) {
  Oriented both = Sphere(1500, 1.0, V3(-3, 0, 0));
  const Oriented second = Sphere(1500, 0.7, V3(3, 1, 0));
  both.positions.insert(both.positions.end(), second.positions.begin(), second.positions.end());
  both.normals.insert(both.normals.end(), second.normals.begin(), second.normals.end());
  std::vector<V3> normals;
  EstimateNormalLines(both.positions, normals);
  NormalsReport report;
  OrientNormals(both.positions, normals, false, report, true);
  EXPECT_EQ(CountAgainst(normals, both.normals), 0u);
  EXPECT_EQ(report.components, 2u);
}

TEST(FlipInvertedParts, APartOrientedInwardAsAWholeIsTurnedOutward) {
  // The union of a unit sphere and a sphere of radius 0.45 about (0, 0, 1.25) (a head on a
  // body): each sphere's samples outside the other. The head's samples inward, as an MST that
  // reached it through a thin neck would leave them; the winding number sees a closed sheet of
  // its own there (level near -1/2), the body's stays near +1/2.
  const Oriented body = Sphere(3000, 1.0);
  const Oriented head = Sphere(600, 0.45, V3(0, 0, 1.25));
  Oriented both;
  std::vector<std::uint8_t> on_head;
  for (std::size_t i = 0; i < body.positions.size(); ++i) {
    if ((body.positions[i] - V3(0, 0, 1.25)).norm() <= 0.45) continue;
    both.positions.push_back(body.positions[i]);
    both.normals.push_back(body.normals[i]);
    on_head.push_back(0);
  }
  for (std::size_t i = 0; i < head.positions.size(); ++i) {
    if (head.positions[i].norm() <= 1.0) continue;
    both.positions.push_back(head.positions[i]);
    both.normals.push_back(head.normals[i]);
    on_head.push_back(1);
  }
  const std::size_t n = both.positions.size();
  std::size_t head_samples = 0;
  for (const std::uint8_t h : on_head) head_samples += h;
  ASSERT_GT(head_samples, 400u);
  const std::vector<std::uint8_t> all(n, 1);
  std::size_t parts = 9;

  std::vector<V3> normals = both.normals;
  for (std::size_t i = 0; i < n; ++i)
    if (on_head[i] != 0) normals[i] = -normals[i];
  EXPECT_EQ(FlipInvertedParts(both.positions, normals, all, parts), head_samples);
  EXPECT_EQ(parts, 1u);
  EXPECT_EQ(CountAgainst(normals, both.normals), 0u);

  // Outward already: nothing flips.
  normals = both.normals;
  EXPECT_EQ(FlipInvertedParts(both.positions, normals, all, parts), 0u);
  EXPECT_EQ(parts, 0u);

  // Not eligible (an open piece's samples): left as they are.
  for (std::size_t i = 0; i < n; ++i)
    if (on_head[i] != 0) normals[i] = -normals[i];
  EXPECT_EQ(FlipInvertedParts(both.positions, normals, std::vector<std::uint8_t>(n, 0), parts), 0u);
  EXPECT_EQ(CountAgainst(normals, both.normals), head_samples);

  // Fewer than 16 flipped samples are one neighbourhood's noise, for the tree to settle: kept.
  normals = both.normals;
  for (std::size_t i = 0; i < 10; ++i) normals[i] = -normals[i];
  EXPECT_EQ(FlipInvertedParts(both.positions, normals, all, parts), 0u);
}

TEST(FlipInvertedParts, AFlipThatDoesNotLiftTheLevelDoesNotStand) {
  // A flat disc (20 x 20 lattice within radius 0.3) at the centre of a sphere whose normals point
  // inward and may not flip: w is -1 all round the disc, so its samples' level is about -1 and
  // they form a group; flipping a flat sheet leaves its own share of the level at 0, so the
  // re-measured level stays about -1 and the flip is undone.
  Oriented set = Sphere(3000, 1.0);
  for (V3& nrm : set.normals) nrm = -nrm;
  std::vector<std::uint8_t> eligible(set.positions.size(), 0);
  for (int a = 0; a < 20; ++a)
    for (int b = 0; b < 20; ++b) {
      const V3 p(-0.3 + 0.03 * (a + 0.5), -0.3 + 0.03 * (b + 0.5), 0.0);
      if (p.norm() > 0.3) continue;
      set.positions.push_back(p);
      set.normals.emplace_back(0, 0, 1);
      eligible.push_back(1);
    }
  ASSERT_GT(set.positions.size(), 3200u);
  std::vector<V3> normals = set.normals;
  std::size_t parts = 9;
  EXPECT_EQ(FlipInvertedParts(set.positions, normals, eligible, parts), 0u);
  EXPECT_EQ(parts, 0u);
  EXPECT_EQ(CountAgainst(normals, set.normals), 0u);
}

TEST(FlipInvertedParts, AThinClosedPlateKeepsBothSides) {
  // A closed box 4 x 4 x 0.1, samples 0.08 apart on every face: its two large faces lie 1.25
  // spacings apart, so each sample's probes reach the other side (the bull's horns and ears).
  Oriented box;
  const auto add = [&](const V3& p, const V3& nrm) {
    box.positions.push_back(p);
    box.normals.push_back(nrm);
  };
  for (int a = 0; a < 50; ++a)
    for (int b = 0; b < 50; ++b)
      for (const double side : {-1.0, 1.0})
        add(V3(-2 + 0.08 * (a + 0.5), -2 + 0.08 * (b + 0.5), 0.05 * side), V3(0, 0, side));
  for (int a = 0; a < 50; ++a)
    for (const double side : {-1.0, 1.0}) {
      add(V3(-2 + 0.08 * (a + 0.5), 2.0 * side, 0.0), V3(0, side, 0));
      add(V3(2.0 * side, -2 + 0.08 * (a + 0.5), 0.0), V3(side, 0, 0));
    }
  std::vector<V3> normals = box.normals;
  std::size_t parts = 9;
  EXPECT_EQ(FlipInvertedParts(box.positions, normals, std::vector<std::uint8_t>(normals.size(), 1), parts), 0u);
  EXPECT_EQ(parts, 0u);
}

// A cube 2 x 2 x 2 (samples 0.05 apart) with a fin 1 x 1 x 0.04 out of its +x face: the fin's
// two faces lie 0.8 spacings apart, each other's nearest samples (the bull's ears and horns).
Oriented CubeWithFin() {
  Oriented shape = Cube(40);
  for (int a = 0; a < 20; ++a)
    for (int b = 0; b < 20; ++b)
      for (const double side : {-1.0, 1.0}) {
        shape.positions.emplace_back(1.0 + 0.05 * (a + 0.5), -0.5 + 0.05 * (b + 0.5), 0.02 * side);
        shape.normals.emplace_back(0, 0, side);
      }
  return shape;
}

TEST(SheetDipoles, TheTreeSumMatchesEverySampleSummedAtProbesNearAndFar) {
  // A cap of about 1,600 samples (z > 0.2 on a unit sphere of 4,000) as the sheet, probed from every
  // sample of the sphere at half a spacing along its normal: on the cap, beside it and across the
  // sphere. The reference sums the smoothed dipoles one by one (the formula in normals.h).
  const Oriented sphere = Sphere(4000, 1.0);
  const std::size_t n = sphere.positions.size();
  const double spacing = std::sqrt(4.0 * std::numbers::pi / static_cast<double>(n));
  const std::vector<double> areas(n, 4.0 * std::numbers::pi / static_cast<double>(n));
  std::vector<std::uint32_t> sheet;
  for (std::size_t i = 0; i < n; ++i)
    if (sphere.positions[i].z() > 0.2) sheet.push_back(static_cast<std::uint32_t>(i));
  ASSERT_GT(sheet.size(), 1500u);
  const SheetDipoles tree(sheet, sphere.positions, sphere.normals, areas);
  const double offset = 0.5 * spacing;
  double worst = 0.0;
  std::size_t exact = 0, far = 0;
  for (std::size_t k = 0; k < n; ++k) {
    const V3 q_in = sphere.positions[k] - offset * sphere.normals[k];
    const V3 q_out = sphere.positions[k] + offset * sphere.normals[k];
    double in = 0.0, out = 0.0;
    bool own = false;
    for (const std::uint32_t j : sheet) {
      const double a = areas[j];
      if (j == k) {
        own = true;
        in += SampleProbes::OwnDisc(a, offset);
        out -= SampleProbes::OwnDisc(a, offset);
        continue;
      }
      for (const bool inside : {true, false}) {
        const V3 d = sphere.positions[j] - (inside ? q_in : q_out);
        const double r2 = d.squaredNorm() + a / std::numbers::pi;
        (inside ? in : out) += a * sphere.normals[j].dot(d) / (4.0 * std::numbers::pi * r2 * std::sqrt(r2));
      }
    }
    const SheetDipoles::Terms t = tree.At(k, offset);
    EXPECT_EQ(t.own, own) << k;
    worst = std::max({worst, std::abs(t.in - in), std::abs(t.out - out)});
    exact += t.exact;
    far += t.far;
  }
  // Measured: 0.0092 at most (the cap's top, where ~50 clusters at 3-4 radii each read a few
  // hundredths low), against w of 0.7 inside and -0.1 outside there; 4.4 % of the pairs summed
  // one by one, ~29 clusters a probe. A cluster summed wrongly, or not at all, misses by more.
  EXPECT_LT(worst, 0.012);
  EXPECT_GT(far, 20 * n);
  EXPECT_LT(static_cast<double>(exact), 0.06 * static_cast<double>(n) * static_cast<double>(sheet.size()));
}

TEST(FlipSheetsByWinding, TheSideOfAThinFinThatTookTheOtherSidesSignIsTurned) {
  const Oriented shape = CubeWithFin();
  std::vector<V3> normals = shape.normals;
  const std::vector<std::uint8_t> all(normals.size(), 1);
  std::size_t sheets = 9;
  // Consistent signs: nothing to turn.
  EXPECT_EQ(FlipSheetsByWinding(shape.positions, normals, all, sheets), 0u);
  EXPECT_EQ(sheets, 0u);
  EXPECT_EQ(CountAgainst(normals, shape.normals), 0u);
  // The fin's underside given its top's sign (what an orientation across the wall does).
  for (std::size_t i = 0; i < normals.size(); ++i)
    if (shape.positions[i].x() > 1.0 && shape.normals[i].z() < 0) normals[i] = -normals[i];
  ASSERT_EQ(CountAgainst(normals, shape.normals), 400u);
  EXPECT_EQ(FlipSheetsByWinding(shape.positions, normals, std::vector<std::uint8_t>(normals.size(), 0), sheets), 0u);
  EXPECT_EQ(FlipSheetsByWinding(shape.positions, normals, all, sheets), 400u);
  EXPECT_EQ(sheets, 1u);
  EXPECT_EQ(CountAgainst(normals, shape.normals), 0u);
  // Or the top given the underside's sign: the top is turned instead.
  normals = shape.normals;
  for (std::size_t i = 0; i < normals.size(); ++i)
    if (shape.positions[i].x() > 1.0 && shape.normals[i].z() > 0) normals[i] = -normals[i];
  EXPECT_EQ(FlipSheetsByWinding(shape.positions, normals, all, sheets), 400u);
  EXPECT_EQ(CountAgainst(normals, shape.normals), 0u);
}

TEST(FlipSheetsByWinding, EverySheetThatLowersTheEnergyIsTurnedHoweverManyRoundsItTakes) {
  // 5,000 samples on a sphere; every sample more than 1.5 spacings from those taken before it (in
  // the lattice's order) given the inward sign: 1,263 wrong normals in some 200 sheets of one to a
  // few samples. A round turns only sheets whose probes lie apart: a cap of 32 rounds left 63
  // inward (the elk's antlers stopped half-way the same way).
  constexpr std::size_t kSamples = 5000;
  const Oriented sphere = Sphere(kSamples, 1.0);
  const double spacing = std::sqrt(4.0 * std::numbers::pi / static_cast<double>(kSamples));
  std::vector<V3> normals = sphere.normals;
  std::vector<std::size_t> taken;
  for (std::size_t i = 0; i < kSamples; ++i) {
    bool apart = true;
    for (const std::size_t t : taken)
      apart = apart && (sphere.positions[t] - sphere.positions[i]).norm() > 1.5 * spacing;
    if (apart) {
      taken.push_back(i);
      normals[i] = -normals[i];
    }
  }
  ASSERT_EQ(CountAgainst(normals, sphere.normals), 1263u);
  std::size_t sheets = 0;
  EXPECT_EQ(FlipSheetsByWinding(sphere.positions, normals, std::vector<std::uint8_t>(normals.size(), 1), sheets),
            1263u);
  EXPECT_GT(sheets, 150u);
  EXPECT_EQ(CountAgainst(normals, sphere.normals), 0u);
}

TEST(FlipSheetsByWinding, TheFineCutAloneTurnsASheetOfAnEighthOfTheSamples) {
  // 5,000 samples on a sphere with a cap of about n / 20 inward, and a coarse pass that may turn
  // only single samples (coarse_fraction n): the fine cut must take the cap. Its old limit of
  // n / 100 left such a sheet unscored (CGAL's 3torus without normals kept a face of 118 of 5,000
  // samples inward; kSheetCuts). With n / 100 this fails: no sheet turned (checked).
  constexpr std::size_t kSamples = 5000;
  const Oriented sphere = Sphere(kSamples, 1.0);
  std::vector<V3> normals = sphere.normals;
  std::size_t cap = 0;
  for (std::size_t i = 0; i < kSamples; ++i)
    if (sphere.positions[i].z() > 0.9) {
      normals[i] = -normals[i];
      ++cap;
    }
  ASSERT_GT(cap, kSamples / 30);
  ASSERT_LT(cap, kSamples / 8);
  std::size_t sheets = 0;
  const std::vector<std::uint8_t> all(kSamples, 1);
  EXPECT_EQ(FlipSheetsByWinding(sphere.positions, normals, all, sheets, kSamples), cap);
  EXPECT_EQ(sheets, 1u);
  EXPECT_EQ(CountAgainst(normals, sphere.normals), 0u);
}

TEST(FlipSheetsOnSharpenedLines, RunsOnlyWhereTheFirstPassRanOnClosedPieces) {
  // A sphere's sampled normals with a cap of 12 inward: the pass turns it on a clean set whose
  // pieces all closed, and leaves it alone on a noisy set's lines or with a piece open.
  constexpr std::size_t kSamples = 2000;
  const Oriented sphere = Sphere(kSamples, 1.0);
  std::vector<V3> wrong = sphere.normals;
  std::size_t cap = 0;
  for (std::size_t i = 0; i < kSamples; ++i) {
    if ((sphere.positions[i] - V3(0, 0, 1)).norm() < 0.15) {
      wrong[i] = -wrong[i];
      ++cap;
    }
  }
  ASSERT_GT(cap, 5u);
  NormalsReport clean;
  clean.neighbours = kCleanNormalNeighbours;
  std::vector<V3> normals = wrong;
  EXPECT_EQ(FlipSheetsOnSharpenedLines(sphere.positions, normals, clean), cap);
  EXPECT_EQ(clean.refined_sheet_samples, cap);
  EXPECT_GE(clean.refined_sheets, 1u);
  EXPECT_EQ(CountAgainst(normals, sphere.normals), 0u);
  EXPECT_NE(clean.Describe().find("turned again on the sharpened normals"), std::string::npos) << clean.Describe();

  NormalsReport noisy;
  noisy.neighbours = kNormalNeighbours;
  NormalsReport open = clean;
  open.refined_sheets = open.refined_sheet_samples = 0;
  open.open_components = 1;
  for (NormalsReport* r : {&noisy, &open}) {
    normals = wrong;
    EXPECT_EQ(FlipSheetsOnSharpenedLines(sphere.positions, normals, *r), 0u);
    EXPECT_EQ(CountAgainst(normals, sphere.normals), cap);
    EXPECT_EQ(r->Describe().find("sharpened"), std::string::npos);
  }
}

TEST(FlipSheetsByWinding, WrongPatchesOnThinPlatesAreTurnedBack) {
  // Closed plates 1 to 2.5 spacings thick, normals exact or tilted by N(0, 0.15) per axis (about
  // 9 degrees, as estimated lines), 30 patches within 1.2 spacings of a random sample turned
  // inward (130-170 wrong normals). A probe 0.6 spacings from the other side read its point
  // dipoles' 1/r^2: with them 5-27 wrong normals stayed on 7 of the 12 exact plates (checked);
  // with the dipoles smoothed over their discs none stay.
  const double h = 1.0 / 20;
  for (const double tilt : {0.0, 0.15})
    for (const double thickness : {1.0, 1.5, 2.0, 2.5})
      for (std::uint32_t seed = 1; seed <= 3; ++seed) {
        Oriented plate = Plate(h, thickness * h, seed);
        std::mt19937 random(seed + 100);
        std::normal_distribution<double> tilted(0.0, tilt);
        for (V3& n : plate.normals) n = (n + V3(tilted(random), tilted(random), tilted(random))).normalized();
        std::vector<V3> normals = plate.normals;
        std::uniform_int_distribution<std::size_t> pick(0, normals.size() - 1);
        for (int patch = 0; patch < 30; ++patch) {
          const std::size_t c = pick(random);
          for (std::size_t i = 0; i < normals.size(); ++i)
            if ((plate.positions[i] - plate.positions[c]).norm() < 1.2 * h &&
                plate.normals[i].dot(plate.normals[c]) > 0.5 && normals[i].dot(plate.normals[i]) > 0)
              normals[i] = -normals[i];
        }
        ASSERT_GT(CountAgainst(normals, plate.normals), 120u);
        std::size_t sheets = 0;
        FlipSheetsByWinding(plate.positions, normals, std::vector<std::uint8_t>(normals.size(), 1), sheets);
        EXPECT_EQ(CountAgainst(normals, plate.normals), 0u)
            << "tilt " << tilt << ", " << thickness << " spacings, seed " << seed;
      }
}

TEST(FlipSheetsByWinding, APatchOfAWallThinnerThanTheSpacingThatTookTheOtherSidesSignIsTurnedBack) {
  // Plates 0.5 and 0.7 spacings thick (CGAL's rotor: blades 0.6), random samples, normals exact or
  // tilted as estimated lines; on the top face, the samples within 5 spacings of one turned to the
  // underside's sign (what an orientation across the wall leaves). Both sides are
  // each other's nearest samples, so the patch and the underside beneath it had been joined as one
  // sheet, and their probes, beyond the wall's middle, scored either side's flip the same.
  const double h = 1.0 / 20;
  for (const double tilt : {0.0, 0.15})
    for (const double thickness : {0.5, 0.7})
      for (std::uint32_t seed = 1; seed <= 3; ++seed) {
        const Oriented plate = Plate(h, thickness * h, seed);
        std::mt19937 random(seed + 200);
        std::normal_distribution<double> tilted(0.0, tilt);
        std::vector<V3> normals = plate.normals;
        for (V3& n : normals) n = (n + V3(tilted(random), tilted(random), tilted(random))).normalized();
        std::size_t centre = 0;
        while (!(plate.normals[centre].z() > 0.5 && plate.positions[centre].head<2>().norm() < 0.5)) ++centre;
        for (std::size_t i = 0; i < normals.size(); ++i)
          if (plate.normals[i].z() > 0.5 && (plate.positions[i] - plate.positions[centre]).norm() < 5 * h)
            normals[i] = -normals[i];
        ASSERT_GT(CountAgainst(normals, plate.normals), 50u);
        std::size_t sheets = 0;
        FlipSheetsByWinding(plate.positions, normals, std::vector<std::uint8_t>(normals.size(), 1), sheets);
        // Tilted, single samples on the patch's rim may stay (1-2; 17-39 were left before).
        EXPECT_LE(CountAgainst(normals, plate.normals), tilt > 0 ? 2u : 0u)
            << "tilt " << tilt << ", " << thickness << " spacings, seed " << seed;
      }
}

TEST(Normals, RefinedLinesTakeTheFaceNormalNearACubeEdge) {
  const Oriented cube = Cube(20);  // spacing 0.1
  std::vector<V3> normals;
  const int neighbours = EstimateNormalLines(cube.positions, normals);
  NormalsReport report;
  OrientNormals(cube.positions, normals, false, report, true);
  ASSERT_EQ(CountAgainst(normals, cube.normals), 0u);
  // Samples beyond the first row off each edge, and how many of them are off by more than 0.5 deg.
  const auto inner_off = [&](const std::vector<V3>& got) {
    std::size_t count = 0;
    for (std::size_t i = 0; i < got.size(); ++i) {
      const V3& p = cube.positions[i];
      const double from_edge =
          1.0 - std::max({std::abs(p.x()) < 1 ? std::abs(p.x()) : 0.0, std::abs(p.y()) < 1 ? std::abs(p.y()) : 0.0,
                          std::abs(p.z()) < 1 ? std::abs(p.z()) : 0.0});
      if (from_edge > 0.1) count += got[i].dot(cube.normals[i]) < std::cos(0.5 * std::numbers::pi / 180) ? 1u : 0u;
    }
    return count;
  };
  const std::size_t jet_off = inner_off(normals);
  RefineNormalLines(cube.positions, normals, neighbours);
  EXPECT_EQ(CountAgainst(normals, cube.normals), 0u);  // signs kept
  // The jet fit blends the faces next to each edge, over the first row and into the second
  // (408 samples beyond the first rows off by more than 0.5 degree); the refined lines are the exact face normals from
  // the second row on. (The first rows of two faces lie on one 45-degree plane through the edge, as well supported as
  // either face.)
  EXPECT_GT(jet_off, 300u);
  EXPECT_EQ(inner_off(normals), 0u);
}

// Issue 20: bare noisy samples of a disc thinner than the spacing. The spanning tree can cross
// the disc round its rim, where the noisy lines blend, and turn one face inward as a whole (CGAL's
// turbine, seeds 22 and 24 at 0.25 voxel: 43 % of the normals inward). The piece is then open by
// its flux, and a second tree that prefers the pairs facing each other across the disc closes it.
// The disc: radius 0.5, 0.03 thick, 5,000 samples, noise 0.25 of a voxel at 150 cells (1 / 133).
TEST(Normals, ANoisyDiscThinnerThanTheSpacingIsNotTurnedInwardOnOneFace) {
  constexpr double kRadius = 0.5, kHalf = 0.015, kSigma = 0.25 / 133.0;
  std::size_t closed_by_tree = 0, worst = 0;
  for (unsigned seed = 1; seed <= 8; ++seed) {
    std::mt19937 random(seed);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    std::normal_distribution<double> noise(0.0, kSigma);
    const double caps = 2.0 * std::numbers::pi * kRadius * kRadius;
    const double side = 2.0 * std::numbers::pi * kRadius * 2.0 * kHalf;
    Oriented disc;
    for (std::size_t k = 0; k < 5000; ++k) {
      const double a = 2.0 * std::numbers::pi * unit(random);
      V3 p, n;
      if (unit(random) < caps / (caps + side)) {
        const double r = kRadius * std::sqrt(unit(random));
        const double z = unit(random) < 0.5 ? kHalf : -kHalf;
        p = V3(r * std::cos(a), r * std::sin(a), z);
        n = V3(0, 0, z > 0 ? 1.0 : -1.0);
      } else {
        p = V3(kRadius * std::cos(a), kRadius * std::sin(a), kHalf * (2.0 * unit(random) - 1.0));
        n = V3(std::cos(a), std::sin(a), 0);
      }
      const double dx = noise(random), dy = noise(random), dz = noise(random);  // in this order
      disc.positions.push_back(p + V3(dx, dy, dz));
      disc.normals.push_back(n);
    }
    std::vector<V3> normals;
    EstimateNormalLines(disc.positions, normals);
    NormalsReport report;
    OrientNormals(disc.positions, normals, false, report, true);
    closed_by_tree += report.closed_by_tree;
    std::size_t inward = 0;
    for (std::size_t i = 0; i < normals.size(); ++i) inward += normals[i].dot(disc.normals[i]) < 0 ? 1u : 0u;
    worst = std::max(worst, inward);
    EXPECT_LT(inward, 250u) << "seed " << seed << ": " << report.Describe();
  }
  // Measured: the second tree stood on 4 of the 8 draws (without it those had 2,376-2,524 normals
  // inward); the most inward on any draw: 144.
  EXPECT_GE(closed_by_tree, 1u);
  std::printf("[ disc ] second tree on %zu of 8 draws; at most %zu of 5000 normals inward\n", closed_by_tree, worst);
}

// Issue 20: bare samples with position noise of a box: near a crease the jet fit and the noisy
// set's refinement blend the two faces; a neighbour's fit that stays on one face does not
// (TakeCleanestPlanes). The noise is fandisk's at 0.5 voxel, 5,000 samples and 150 cells: 0.12 of
// the 8th neighbour's distance. On a slab whose rim faces are narrower than a neighbourhood, every rim
// neighbourhood holds a crease: a rim sample must not take a big face's plane.
TEST(Normals, NoisySamplesNextToACreaseTakeTheirFacesPlane) {
  const double spacing = 0.08;
  // Samples of the box [-1, 1]^2 x [-h, h] with their exact normals, each face's distance to its
  // nearest edge and its normal's axis; 1 / spacing^2 uniform random samples per unit area.
  struct Box {
    Oriented set;
    std::vector<double> from_edge;
    std::vector<int> axis_of;
  };
  const auto sample_box = [&](double h, unsigned seed) {
    const V3 half(1.0, 1.0, h);
    Box box;
    std::mt19937 random(seed);
    std::uniform_real_distribution<double> unit(-1.0, 1.0);
    std::normal_distribution<double> noise(0.0, 0.12 * std::sqrt(8.0 / std::numbers::pi) * spacing);
    for (int axis = 0; axis < 3; ++axis) {
      const int a = (axis + 1) % 3, b = (axis + 2) % 3;
      const auto count = static_cast<std::size_t>(4.0 * half[a] * half[b] / (spacing * spacing));
      for (const double side : {-1.0, 1.0}) {
        for (std::size_t k = 0; k < count; ++k) {
          V3 p, n = V3::Zero();
          p[axis] = side * half[axis];
          p[a] = unit(random) * half[a];
          p[b] = unit(random) * half[b];
          n[axis] = side;
          const double dx = noise(random), dy = noise(random), dz = noise(random);  // in this order
          box.set.positions.push_back(p + V3(dx, dy, dz));
          box.set.normals.push_back(n);
          box.from_edge.push_back(std::min(half[a] - std::abs(p[a]), half[b] - std::abs(p[b])));
          box.axis_of.push_back(axis);
        }
      }
    }
    return box;
  };
  const auto refined = [](const Oriented& set) {
    std::vector<V3> normals;
    const int neighbours = EstimateNormalLines(set.positions, normals);
    EXPECT_EQ(neighbours, kNormalNeighbours);  // called noisy
    NormalsReport report;
    OrientNormals(set.positions, normals, false, report, true);
    RefineNormalLines(set.positions, normals, neighbours);
    return normals;
  };
  {
    const Box cube = sample_box(1.0, 11);
    const std::vector<V3> normals = refined(cube.set);
    std::size_t crease = 0, crease_off = 0;
    double crease_mean = 0;
    for (std::size_t i = 0; i < normals.size(); ++i) {
      // Within half a spacing of an edge a sample lies within the noise of both faces.
      if (cube.from_edge[i] <= 0.5 * spacing || cube.from_edge[i] >= 2.0 * spacing) continue;
      const double angle = LineAngleDeg(normals[i], cube.set.normals[i]);
      ++crease;
      crease_off += angle > 20.0 ? 1u : 0u;
      crease_mean += angle;
    }
    crease_mean /= static_cast<double>(crease);
    // Measured: 84 of 819 samples 0.5-2 spacings off an edge are off by more than 20 degrees,
    // 9.0 degrees on the mean; without TakeCleanestPlanes 302 and 17.5.
    EXPECT_LT(static_cast<double>(crease_off), 0.15 * static_cast<double>(crease)) << crease_off << " of " << crease;
    EXPECT_LT(crease_mean, 12.0);
  }
  // A slab 0.2 thick: its rim faces, 2.5 spacings wide, are narrower than a neighbourhood.
  std::size_t rim = 0, rim_turned = 0;
  for (unsigned seed = 1; seed <= 8; ++seed) {
    const Box slab = sample_box(0.1, seed);
    const std::vector<V3> normals = refined(slab.set);
    for (std::size_t i = 0; i < normals.size(); ++i) {
      if (slab.axis_of[i] == 2 || slab.from_edge[i] <= 0.5 * spacing) continue;
      ++rim;
      rim_turned += LineAngleDeg(normals[i], slab.set.normals[i]) > 60.0 ? 1u : 0u;
    }
  }
  // Measured: 22 of 1,134 rim samples over the 8 draws; without the 50-degree limit on the turn
  // 63, without TakeCleanestPlanes 3.
  EXPECT_LT(static_cast<double>(rim_turned), 0.03 * static_cast<double>(rim)) << rim_turned << " of " << rim;
}

TEST(Normals, RefinedLinesTakeTheFaceNormalNearEdgesOfRandomSamples) {
  struct Face {
    V3 origin, u, v, normal;  // the face is origin + s u + t v, s, t in [0, 1]
  };
  const double wedge = 60.0 * std::numbers::pi / 180;  // the angle between the wedge's two slopes
  const V3 slope_a(std::sin(wedge / 2), 0, std::cos(wedge / 2));
  const V3 slope_b(-std::sin(wedge / 2), 0, std::cos(wedge / 2));
  const std::vector<std::vector<Face>> shapes = {
      {{{-1, -1, -1}, {2, 0, 0}, {0, 2, 0}, {0, 0, -1}},
       {{-1, -1, 1}, {2, 0, 0}, {0, 2, 0}, {0, 0, 1}},
       {{-1, -1, -1}, {0, 2, 0}, {0, 0, 2}, {-1, 0, 0}},
       {{1, -1, -1}, {0, 2, 0}, {0, 0, 2}, {1, 0, 0}},
       {{-1, -1, -1}, {2, 0, 0}, {0, 0, 2}, {0, -1, 0}},
       {{-1, 1, -1}, {2, 0, 0}, {0, 0, 2}, {0, 1, 0}}},
      // Two slopes falling from a ridge along y, their normals 60 degrees apart (an open sheet).
      {{{0, -1, 0}, V3(2 * slope_a.z(), 0, -2 * slope_a.x()), {0, 2, 0}, slope_a},
       {{0, -1, 0}, V3(-2 * slope_b.z(), 0, 2 * slope_b.x()), {0, 2, 0}, slope_b}},
  };
  std::mt19937 random(7);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (std::size_t shape = 0; shape < shapes.size(); ++shape) {
    Oriented set;
    std::vector<double> from_edge;  // distance to the face's nearest edge with another face
    std::vector<double> from_rim;   // the ridge's: distance to the sheet's open boundary
    for (const Face& f : shapes[shape]) {
      for (int i = 0; i < 500; ++i) {
        const double s = unit(random);
        const double t = unit(random);
        set.positions.push_back(f.origin + s * f.u + t * f.v);
        set.normals.push_back(f.normal);
        from_edge.push_back(shape == 0 ? 2.0 * std::min({s, 1 - s, t, 1 - t}) : 2.0 * s);
        from_rim.push_back(shape == 0 ? 2.0 : 2.0 * std::min({1 - s, t, 1 - t}));
      }
    }
    const double spacing =
        std::sqrt(4.0 * static_cast<double>(shapes[shape].size()) / static_cast<double>(set.positions.size()));
    std::vector<V3> normals;
    const int neighbours = EstimateNormalLines(set.positions, normals);
    NormalsReport report;
    OrientNormals(set.positions, normals, false, report, true);
    RefineNormalLines(set.positions, normals, neighbours);
    std::size_t considered = 0;
    std::size_t off = 0;
    for (std::size_t i = 0; i < normals.size(); ++i) {
      // Rim samples keep their jet fit (RefineNormalLines): where the ridge meets the sheet's
      // open boundary it blends the slopes (1 sample of the ridge's 990 before this was excluded).
      if (from_edge[i] < 0.25 * spacing || from_rim[i] < spacing) continue;
      ++considered;
      off += normals[i].dot(set.normals[i]) < std::cos(20.0 * std::numbers::pi / 180) ? 1u : 0u;
    }
    EXPECT_EQ(CountAgainst(normals, set.normals), 0u) << shape;
    // Measured: 4 of 2,867 (cube; 3 with the 18-neighbour jet fit) and 1 of 865 (ridge); with the plane chosen by the
    // wide support (kSelectWidth 1, kSelectNoise 0, triples of the 8 nearest), 37 and 4.
    EXPECT_LE(off, considered / 500) << shape << ": " << off << " of " << considered;
  }
}

// A planar face: origin + s u + t v, s, t in [0, 1], with its outward normal.
struct Face {
  V3 origin, u, v, normal;
};

// Random samples on faces, their number shared by area; each one's distances to its face's
// boundaries across u and across v (model units).
struct FaceSamples {
  Oriented set;
  std::vector<double> along_u, along_v;
  double spacing = 0;  // sqrt(area / samples)
};

FaceSamples SampleFaces(const std::vector<Face>& faces, std::size_t samples, std::mt19937& random) {
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  FaceSamples out;
  double area = 0;
  for (const Face& f : faces) area += f.u.cross(f.v).norm();
  for (const Face& f : faces) {
    const auto count = static_cast<int>(std::lround(static_cast<double>(samples) * f.u.cross(f.v).norm() / area));
    for (int i = 0; i < count; ++i) {
      const double s = unit(random), t = unit(random);
      out.set.positions.push_back(f.origin + s * f.u + t * f.v);
      out.set.normals.push_back(f.normal);
      out.along_u.push_back(std::min(s, 1 - s) * f.u.norm());
      out.along_v.push_back(std::min(t, 1 - t) * f.v.norm());
    }
  }
  out.spacing = std::sqrt(area / static_cast<double>(out.set.positions.size()));
  return out;
}

// Lines estimated, oriented and refined from positions alone, as `palpa build` does for a clean set.
std::vector<V3> CleanRefinedLines(const std::vector<V3>& positions) {
  std::vector<V3> normals;
  const int neighbours = EstimateNormalLines(positions, normals);
  EXPECT_EQ(neighbours, kCleanNormalNeighbours);
  NormalsReport report;
  OrientNormals(positions, normals, false, report, true);
  RefineNormalLines(positions, normals, neighbours);
  return normals;
}

TEST(Normals, FirstRowsNextToSharpEdgesOfNarrowFacesTakeTheirFacesPlane) {
  // Random samples on a box with wide faces (2 x 2 x 1), a hexagonal prism's sides (120-degree
  // edges) and a bar whose faces are 4.3 spacings wide (a gear tooth's, as on CGAL's pinion).
  // There a sample's 16 nearest span three faces, and the plane most of them lie on was as often
  // a blend or the next face: of the bar's samples 0.25-1 spacing from an edge (and a spacing
  // from its open ends), 100 of 531 ended more than 20 degrees off (TakeFacePlanes: 10). Nearer an
  // edge either face's plane is about as right, so those are not counted.
  std::vector<std::vector<Face>> shapes = {{{{-1, -1, -0.5}, {2, 0, 0}, {0, 2, 0}, {0, 0, -1}},
                                            {{-1, -1, 0.5}, {2, 0, 0}, {0, 2, 0}, {0, 0, 1}},
                                            {{-1, -1, -0.5}, {0, 2, 0}, {0, 0, 1}, {-1, 0, 0}},
                                            {{1, -1, -0.5}, {0, 2, 0}, {0, 0, 1}, {1, 0, 0}},
                                            {{-1, -1, -0.5}, {2, 0, 0}, {0, 0, 1}, {0, -1, 0}},
                                            {{-1, 1, -0.5}, {2, 0, 0}, {0, 0, 1}, {0, 1, 0}}}};
  std::vector<Face> prism;  // an open tube: the six sides only
  for (int k = 0; k < 6; ++k) {
    const double a = k * std::numbers::pi / 3, b = (k + 1) * std::numbers::pi / 3;
    const V3 p(std::cos(a), std::sin(a), -1), q(std::cos(b), std::sin(b), -1);
    const V3 mid = 0.5 * (p + q);
    prism.push_back({p, q - p, {0, 0, 2}, V3(mid.x(), mid.y(), 0).normalized()});
  }
  shapes.push_back(prism);
  const double w = 0.2;  // an open bar: its four long sides
  shapes.push_back({{{-2, -w / 2, -w / 2}, {4, 0, 0}, {0, w, 0}, {0, 0, -1}},
                    {{-2, -w / 2, w / 2}, {4, 0, 0}, {0, w, 0}, {0, 0, 1}},
                    {{-2, -w / 2, -w / 2}, {4, 0, 0}, {0, 0, w}, {0, -1, 0}},
                    {{-2, w / 2, -w / 2}, {4, 0, 0}, {0, 0, w}, {0, 1, 0}}});
  const std::array<std::size_t, 3> samples{3000, 3000, 1500};
  std::mt19937 random(11);
  for (std::size_t shape = 0; shape < shapes.size(); ++shape) {
    const FaceSamples faces = SampleFaces(shapes[shape], samples[shape], random);
    const std::vector<V3> normals = CleanRefinedLines(faces.set.positions);
    std::size_t near = 0, off = 0;
    for (std::size_t i = 0; i < normals.size(); ++i) {
      const double u = faces.along_u[i], v = faces.along_v[i];
      const double from_edge = shape == 0 ? std::min(u, v) : shape == 1 ? u : v;  // to an edge between two faces
      const double from_end = shape == 0 ? 1.0 : shape == 1 ? v : u;  // to an open end (the prism's and the bar's)
      if (from_edge < 0.25 * faces.spacing || from_edge >= faces.spacing || from_end < faces.spacing) continue;
      ++near;
      off += std::abs(normals[i].dot(faces.set.normals[i])) < std::cos(20.0 * std::numbers::pi / 180) ? 1u : 0u;
    }
    // Measured: box 2 of 365, prism 3 of 264, bar 10 of 531 (100 before TakeFacePlanes).
    EXPECT_LE(off, near * 3 / 100) << shape << ": " << off << " of " << near;
  }
}

TEST(Normals, SamplesOfAFlatFaceTakeItsExactPlaneUpToTheEdgeAndRingsOfSamplesDoNot) {
  // Random samples on the bar of the test above (faces 4.3 spacings wide) and on a box turned off
  // the axes: a face's samples are coplanar to rounding, the next face's miss that plane by their
  // distance from the edge, so the plane through a sample and two neighbours that five or more of
  // its 16 nearest lie on to 1e-4 of the 16th one's distance is its own face's (TakeExactFacets),
  // however few of them it has. Counted: samples 0.05-1 spacing from an edge, a spacing from the
  // bar's open ends; "exact" is within 0.01 degree.
  const Eigen::Matrix3d turn =
      (Eigen::AngleAxisd(0.4, V3(1, 2, 3).normalized()) * Eigen::AngleAxisd(0.3, V3(0, 0, 1))).toRotationMatrix();
  const auto turned = [&](const std::vector<Face>& faces) {
    std::vector<Face> out;
    for (const Face& f : faces) out.push_back({turn * f.origin, turn * f.u, turn * f.v, turn * f.normal});
    return out;
  };
  const double w = 0.2;
  const std::vector<std::vector<Face>> shapes = {turned({{{-2, -w / 2, -w / 2}, {4, 0, 0}, {0, w, 0}, {0, 0, -1}},
                                                         {{-2, -w / 2, w / 2}, {4, 0, 0}, {0, w, 0}, {0, 0, 1}},
                                                         {{-2, -w / 2, -w / 2}, {4, 0, 0}, {0, 0, w}, {0, -1, 0}},
                                                         {{-2, w / 2, -w / 2}, {4, 0, 0}, {0, 0, w}, {0, 1, 0}}}),
                                                 turned({{{-1, -1, -0.5}, {2, 0, 0}, {0, 2, 0}, {0, 0, -1}},
                                                         {{-1, -1, 0.5}, {2, 0, 0}, {0, 2, 0}, {0, 0, 1}},
                                                         {{-1, -1, -0.5}, {0, 2, 0}, {0, 0, 1}, {-1, 0, 0}},
                                                         {{1, -1, -0.5}, {0, 2, 0}, {0, 0, 1}, {1, 0, 0}},
                                                         {{-1, -1, -0.5}, {2, 0, 0}, {0, 0, 1}, {0, -1, 0}},
                                                         {{-1, 1, -0.5}, {2, 0, 0}, {0, 0, 1}, {0, 1, 0}}})};
  const std::array<std::size_t, 2> samples{1500, 3000};
  std::mt19937 random(13);
  for (std::size_t shape = 0; shape < shapes.size(); ++shape) {
    const FaceSamples faces = SampleFaces(shapes[shape], samples[shape], random);
    const std::vector<V3> normals = CleanRefinedLines(faces.set.positions);
    std::size_t near = 0, exact = 0, off = 0;
    for (std::size_t i = 0; i < normals.size(); ++i) {
      const double u = faces.along_u[i], v = faces.along_v[i];
      const double from_edge = shape == 0 ? v : std::min(u, v), from_end = shape == 0 ? u : 1.0;
      if (from_edge < 0.05 * faces.spacing || from_edge >= faces.spacing || from_end < faces.spacing) continue;
      ++near;
      const double along = std::abs(normals[i].dot(faces.set.normals[i]));
      exact += along > std::cos(0.01 * std::numbers::pi / 180) ? 1u : 0u;
      off += along < std::cos(20.0 * std::numbers::pi / 180) ? 1u : 0u;
    }
    std::printf("[ facets ] shape %zu: %zu of %zu first-row lines exact, %zu over 20 degrees off\n", shape, exact, near,
                off);
    // Measured: bar 626 of 627 exact, box 490 of 494, none off (without TakeExactFacets 123 and 26
    // exact, 27 and 9 over 20 degrees off).
    EXPECT_GE(exact, near * 95 / 100) << shape;
    EXPECT_LE(off, near / 100) << shape;
  }
  // A UV sphere's vertices: each ring's samples are coplanar, and their plane cuts the surface
  // (kFacetOneSide, kFacetAgreeDeg). Measured: none of the 912 away from the poles takes it;
  // without the guard 96, up to 22.5 degrees off radial.
  Oriented rings;
  for (int ring = 1; ring < 24; ++ring) {
    const double polar = ring * std::numbers::pi / 24;
    for (int k = 0; k < 48; ++k) {
      const double a = 2 * std::numbers::pi * (k + 0.5 * (ring % 2)) / 48;
      const V3 p(std::sin(polar) * std::cos(a), std::sin(polar) * std::sin(a), std::cos(polar));
      rings.positions.push_back(turn * p);
      rings.normals.push_back(turn * p);
    }
  }
  const std::vector<V3> normals = CleanRefinedLines(rings.positions);
  // A sample that took its ring's plane has the axis for its line.
  const V3 axis = turn * V3(0, 0, 1);
  std::size_t took = 0;
  // Two rings from each pole are not counted: 48 samples on a circle a sixth of the ring spacing
  // across are the rim of a hole, a face's edge to any local test (they take their plane).
  for (std::size_t i = 2 * 48; i + 2 * 48 < normals.size(); ++i)
    took += std::abs(normals[i].dot(axis)) > std::cos(0.01 * std::numbers::pi / 180) ? 1u : 0u;
  std::printf("[ facets ] UV sphere: %zu of %zu samples took their ring's plane\n", took, normals.size() - 4 * 48);
  EXPECT_EQ(took, 0u);
}

TEST(Normals, RefinedLinesOfACurvedSurfaceAreItsNormalsAtTheSamples) {
  std::mt19937 random(3);
  std::normal_distribution<double> gauss(0.0, 1.0);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  // A unit sphere, 3,000 samples at random: the plane fitted to a sample's supporters is the
  // tangent plane at their centroid, tilted from P_i's by the curvature times the centroid's
  // offset; the supporters' quadric (kSupportQuadric) is not. Measured: median 0.005 degrees, 11
  // lines over 1 degree; with the plane (and the selection widened by the fits' residual), 0.93
  // degrees and 1,374.
  Oriented sphere;
  while (sphere.positions.size() < 3000) {
    const V3 g(gauss(random), gauss(random), gauss(random));
    if (g.norm() < 1e-6) continue;
    sphere.positions.push_back(g.normalized());
    sphere.normals.push_back(g.normalized());
  }
  std::vector<V3> normals = CleanRefinedLines(sphere.positions);
  std::vector<double> angle(normals.size());
  for (std::size_t i = 0; i < normals.size(); ++i) angle[i] = LineAngleDeg(normals[i], sphere.normals[i]);
  std::size_t over = 0;
  for (const double a : angle) over += a > 1.0 ? 1u : 0u;
  std::printf("[ curved ] sphere: median %.4f degrees, %zu of %zu lines over 1 degree\n", MedianOf(angle), over,
              angle.size());
  EXPECT_LT(MedianOf(angle), 0.05);
  EXPECT_LE(over, angle.size() / 100);

  // A closed cylinder, radius 1, height 2, 4,000 samples at random by area: its wall's first rows
  // next to a cap have their supporters on one side, where the plane tilts most. Measured, wall
  // samples 0-1 / 1-2 / over 2 spacings from a rim: median 0.29 / 0.004 / 0.003 degrees, 24 of 185
  // over 5 / 30 of 175 over 1 / 83 of 2,286 over 1; with the plane 1.81 / 1.27 / 0.81 degrees, 22 /
  // 108 / 845; with one quadric fit, not two, the first row's median 1.33 and 40 over 5.
  Oriented cylinder;
  std::vector<double> from_rim;  // wall samples' distance to the nearer cap; caps: -1
  const double wall = 4.0 * std::numbers::pi, cap = std::numbers::pi;
  for (int i = 0; i < 4000; ++i) {
    const double pick = unit(random) * (wall + 2 * cap);
    const double a = 2 * std::numbers::pi * unit(random);
    if (pick < wall) {
      const double z = 2 * unit(random) - 1;
      cylinder.positions.emplace_back(std::cos(a), std::sin(a), z);
      cylinder.normals.emplace_back(std::cos(a), std::sin(a), 0);
      from_rim.push_back(1 - std::abs(z));
    } else {
      const double r = std::sqrt(unit(random)), side = pick < wall + cap ? -1.0 : 1.0;
      cylinder.positions.emplace_back(r * std::cos(a), r * std::sin(a), side);
      cylinder.normals.emplace_back(0, 0, side);
      from_rim.push_back(-1);
    }
  }
  const double spacing = std::sqrt((wall + 2 * cap) / 4000.0);
  normals = CleanRefinedLines(cylinder.positions);
  std::array<std::vector<double>, 3> rows;  // wall samples 0-1, 1-2 and over 2 spacings from a rim
  for (std::size_t i = 0; i < normals.size(); ++i) {
    if (from_rim[i] < 0) continue;
    rows[std::min<std::size_t>(2, static_cast<std::size_t>(from_rim[i] / spacing))].push_back(
        LineAngleDeg(normals[i], cylinder.normals[i]));
  }
  std::array<std::size_t, 3> over_1{}, over_5{};
  for (std::size_t r = 0; r < 3; ++r) {
    for (const double a : rows[r]) {
      over_1[r] += a > 1.0 ? 1u : 0u;
      over_5[r] += a > 5.0 ? 1u : 0u;
    }
    static constexpr std::array<const char*, 3> kRows{"0-1", "1-2", "over 2"};
    std::printf("[ curved ] cylinder wall, %s spacings from a rim: median %.3f degrees, %zu / %zu of %zu over 1 / 5\n",
                kRows[r], MedianOf(rows[r]), over_1[r], over_5[r], rows[r].size());
  }
  EXPECT_LT(MedianOf(rows[2]), 0.05);
  EXPECT_LE(over_1[2], rows[2].size() / 10);
  EXPECT_LE(over_1[1], rows[1].size() / 2);
  EXPECT_LT(MedianOf(rows[0]), 1.0);
  EXPECT_LE(over_5[0], rows[0].size() / 5);
}

TEST(ReadPoints, BarePositionsAreReadOnlyWhenAllowed) {
  const testing::TempFile file("bare.xyz", "0 0 0\n1 0 0\n# comment\n0 1 0\n0 0 1\n");
  auto refused = ReadPoints(file.path());
  ASSERT_FALSE(refused.has_value());
  EXPECT_NE(refused.error().message.find("bare.xyz:1: expected 6 numbers, found 3"), std::string::npos)
      << refused.error().message;
  auto read = ReadPoints(file.path(), ReadOptions{.allow_missing_normals = true});
  ASSERT_TRUE(read.has_value()) << read.error().message;
  EXPECT_FALSE(read->has_normals);
  ASSERT_EQ(read->positions.size(), 4u);
  EXPECT_EQ(read->positions[1], V3(1, 0, 0));
  EXPECT_EQ(read->normals[2], V3::Zero());
  EXPECT_EQ(read->lines[2], 4u);  // the comment line counts
}

TEST(ReadPoints, AFileMixingBareAndOrientedPointsNamesTheLine) {
  const testing::TempFile file("mixed.xyz", "0 0 0\n1 0 0\n0 1 0 0 0 1\n0 0 1\n");
  auto read = ReadPoints(file.path(), ReadOptions{.allow_missing_normals = true});
  ASSERT_FALSE(read.has_value());
  EXPECT_NE(
      read.error().message.find("mixed.xyz:3: expected 3 numbers, found 6 (the file's first point has no normal)"),
      std::string::npos)
      << read.error().message;
  // Oriented first, bare later: the oriented file's rule.
  const testing::TempFile other("mixed2.xyz", "0 0 0 0 0 1\n1 0 0\n");
  auto read2 = ReadPoints(other.path(), ReadOptions{.allow_missing_normals = true});
  ASSERT_FALSE(read2.has_value());
  EXPECT_NE(read2.error().message.find("mixed2.xyz:2: expected 6 numbers, found 3"), std::string::npos);
}

TEST(ReadPly, VerticesWithoutNormalsAreReadOnlyWhenAllowed) {
  const testing::TempFile file(
      "bare.ply",
      "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
      "property float z\nproperty uchar red\nend_header\n0 0 0 1\n1 0 0 2\n0 1 0 3\n0 0 1 4\n");
  auto refused = ReadPoints(file.path());
  ASSERT_FALSE(refused.has_value());
  EXPECT_NE(refused.error().message.find("has no scalar nx, ny, nz"), std::string::npos) << refused.error().message;
  auto read = ReadPoints(file.path(), ReadOptions{.allow_missing_normals = true});
  ASSERT_TRUE(read.has_value()) << read.error().message;
  EXPECT_FALSE(read->has_normals);
  ASSERT_EQ(read->positions.size(), 4u);
  EXPECT_EQ(read->positions[3], V3(0, 0, 1));
  // One normal component of three is a broken file, not bare positions.
  const testing::TempFile partial(
      "partial.ply",
      "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
      "property float z\nproperty float nx\nend_header\n0 0 0 1\n1 0 0 1\n0 1 0 1\n0 0 1 1\n");
  auto broken = ReadPoints(partial.path(), ReadOptions{.allow_missing_normals = true});
  ASSERT_FALSE(broken.has_value());
  EXPECT_NE(broken.error().message.find("has no scalar ny, nz"), std::string::npos) << broken.error().message;
}

// The whole path on the cube with a fin: the jet lines' orientation gives the fin's two sides one
// sign, and the sheets turn the wrong side back. With 3/4 of the -x face unscanned the flux of the
// normals is ~0.15 of the area: closed for the orientation (under 0.2), too open for the sheets,
// whose energy assumes w = 1 inside and 0 outside (an open side's w is near 1/2).
TEST(Normals, AThinFinsWrongSideIsTurnedOnlyOnAClosedPiece) {
  for (const bool closed : {true, false}) {
    const Oriented shape = CubeWithFin();
    Oriented scan;
    for (std::size_t i = 0; i < shape.positions.size(); ++i) {
      if (!closed && shape.normals[i].x() < -0.5 && shape.positions[i].y() > -0.5) continue;
      scan.positions.push_back(shape.positions[i]);
      scan.normals.push_back(shape.normals[i]);
    }
    std::vector<V3> normals;
    NormalsReport report;
    report.neighbours = EstimateNormalLines(scan.positions, normals);
    ASSERT_EQ(report.neighbours, kCleanNormalNeighbours);
    OrientNormals(scan.positions, normals, false, report, true);
    EXPECT_EQ(report.open_components, 0u) << closed;
    if (closed) {
      EXPECT_GT(report.sheets, 0u);
      // Signs are counted where the line is the surface's: the jet lines of the fin's root row
      // (40 samples, 0.025 from the cube's face) lie along the fin, 80 degrees off, and their sign
      // says nothing of the fin's inside.
      std::size_t off_line = 0, against = 0;
      for (std::size_t i = 0; i < normals.size(); ++i) {
        if (std::abs(normals[i].dot(scan.normals[i])) < 0.5) {
          ++off_line;
          continue;
        }
        against += normals[i].dot(scan.normals[i]) < 0 ? 1u : 0u;
      }
      EXPECT_LE(off_line, 40u);
      EXPECT_EQ(against, 0u);
    } else {
      EXPECT_EQ(report.sheets, 0u);
      EXPECT_EQ(report.sheet_samples, 0u);
    }
  }
}

}  // namespace
}  // namespace palpa::field

namespace palpa::field {
namespace {

// Issue 20, dense scans: one sample per cell and normal side, only where the set is denser than
// the cells; the two sides of a thin wall stay apart; a far outlier stays its own sample.
TEST(SimplifyDenseSamples, ASetNoDenserThanTheCellsIsLeftAsItWas) {
  PointSet sparse;
  for (int i = 0; i < 50; ++i) {
    for (int j = 0; j < 50; ++j) {
      sparse.positions.emplace_back(i * 1.0 + 0.01 * j, j * 1.0, 0.0);
      sparse.normals.emplace_back(0, 0, 1);
    }
  }
  const PointSet before = sparse;
  const Simplification s = SimplifyDenseSamples(sparse, 0.9);
  EXPECT_FALSE(s.Applied());
  EXPECT_EQ(sparse.positions, before.positions);
  EXPECT_EQ(sparse.normals, before.normals);
}

TEST(SimplifyDenseSamples, ADenseSphereKeepsOneSamplePerCellOnTheSurface) {
  PointSet dense;
  const double r = 10.0;
  const double golden = std::numbers::pi * (3.0 - std::sqrt(5.0));
  const std::size_t n = 200000;
  for (std::size_t i = 0; i < n; ++i) {
    const double z = 1.0 - 2.0 * (static_cast<double>(i) + 0.5) / static_cast<double>(n);
    const double rho = std::sqrt(1.0 - z * z);
    const Eigen::Vector3d u(rho * std::cos(golden * static_cast<double>(i)),
                            rho * std::sin(golden * static_cast<double>(i)), z);
    dense.positions.push_back(r * u);
    dense.normals.push_back(u);
  }
  const double cell = 0.5;  // area 4 pi r^2 = 1,257: ~5,000-10,000 cells hold samples
  const Simplification s = SimplifyDenseSamples(dense, cell);
  ASSERT_TRUE(s.Applied());
  EXPECT_EQ(s.before, n);
  EXPECT_EQ(s.after, dense.positions.size());
  EXPECT_GT(s.after, 4000u);
  EXPECT_LT(s.after, 20000u);
  for (std::size_t i = 0; i < dense.positions.size(); ++i) {
    // The mean of samples in a cell lies within the sagitta of a cell's chord, (sqrt(3) cell)^2 /
    // (8 r) = 0.0094, inside the sphere; the normal within the angle the cell subtends.
    const double d = dense.positions[i].norm() - r;
    EXPECT_LE(d, 1e-9) << i;
    EXPECT_GT(d, -0.0094) << i;
    EXPECT_NEAR(dense.normals[i].norm(), 1.0, 1e-12);
    EXPECT_GT(dense.normals[i].dot(dense.positions[i].normalized()), std::cos(std::sqrt(3.0) * cell / r)) << i;
  }
}

// A bare scan is thinned by position before its normals are estimated: half-voxel cells where
// they halve the count, else cells of kDenseCellVoxels (a noisy shell thicker than the cells).
TEST(SimplifyBarePositions, HalfVoxelCellsOrWiderOnesThroughAThickShell) {
  PointSet flat;  // 50 x 50 samples 0.1 apart on z = 0: 25 in each half-voxel cell of 0.5
  for (int a = 0; a < 50; ++a)
    for (int b = 0; b < 50; ++b) flat.positions.emplace_back(0.1 * a + 0.05, 0.1 * b + 0.05, 0.0);
  const Simplification thin = SimplifyBarePositions(flat, 1.0);
  EXPECT_TRUE(thin.Applied());
  EXPECT_EQ(thin.cell, 0.5);
  EXPECT_EQ(thin.after, 100u);
  ASSERT_EQ(flat.normals.size(), flat.positions.size());
  for (const V3& n : flat.normals) EXPECT_EQ(n, V3::UnitZ());

  // 3,000 random samples in a 10 x 10 x 3 slab: 2,400 half-voxel cells do not halve them, the
  // cells of 1.5 voxels (7 x 7 x 2 = 98, each holding some) do.
  PointSet slab;
  std::mt19937_64 rng(5);
  const auto uniform = [&] { return static_cast<double>(rng() >> 11) * 0x1p-53; };
  for (int i = 0; i < 3000; ++i) slab.positions.emplace_back(10.0 * uniform(), 10.0 * uniform(), 3.0 * uniform());
  const Simplification thick = SimplifyBarePositions(slab, 1.0);
  EXPECT_TRUE(thick.Applied());
  EXPECT_EQ(thick.cell, kDenseCellVoxels);
  EXPECT_LE(thick.after, 98u);
  EXPECT_GE(thick.after, 90u);
  EXPECT_EQ(slab.positions.size(), thick.after);
  ASSERT_EQ(slab.normals.size(), slab.positions.size());
  for (const V3& n : slab.normals) EXPECT_EQ(n, V3::UnitZ());
}

// A wide cell holding both sides of a wall thinner than the cell keeps every sample (CGAL's rotor,
// 200,000 bare samples at 150 cells: its fins averaged mid-wall, 44.5 % of the band wrong), and no
// cell of a noisy shell does, whose averages are what the wide cells are for.
TEST(SimplifyBarePositions, TheTwoSidesOfAWallThinnerThanTheWideCellsStayApart) {
  // Two clean planes 0.6 voxels apart, 1,600 random samples each on 20 x 20: ~1 a half-voxel
  // cell, which does not halve them; the cells of 1.5 voxels mostly hold both planes.
  PointSet wall;
  std::mt19937_64 rng(11);
  const auto uniform = [&] { return static_cast<double>(rng() >> 11) * 0x1p-53; };
  for (const double z : {0.0, 0.6})
    for (int i = 0; i < 1600; ++i) wall.positions.emplace_back(20.0 * uniform(), 20.0 * uniform(), z);
  // Samples per wide cell (one cell deep in z) and plane, counted here from the cells' definition.
  V3 lo = wall.positions[0];
  for (const V3& p : wall.positions) lo = lo.cwiseMin(p);
  std::map<std::pair<std::int64_t, std::int64_t>, std::array<std::size_t, 2>> cells;
  for (const V3& p : wall.positions)
    ++cells[{static_cast<std::int64_t>(std::floor((p.x() - lo.x()) / kDenseCellVoxels)),
             static_cast<std::int64_t>(std::floor((p.y() - lo.y()) / kDenseCellVoxels))}][p.z() < 0.3 ? 0 : 1];
  // A cell with both planes keeps its samples; a cell with one becomes one sample on it.
  std::size_t both = 0, expect_low = 0, expect_high = 0;
  for (const auto& [key, count] : cells) {
    const bool two = count[0] > 0 && count[1] > 0;
    both += two ? 1u : 0u;
    expect_low += two ? count[0] : std::min<std::size_t>(count[0], 1);
    expect_high += two ? count[1] : std::min<std::size_t>(count[1], 1);
  }
  const Simplification s = SimplifyBarePositions(wall, 1.0);
  ASSERT_TRUE(s.Applied());
  EXPECT_EQ(s.cell, kDenseCellVoxels);
  std::size_t low = 0, high = 0;
  for (std::size_t i = 0; i < wall.positions.size(); ++i) {
    const double z = wall.positions[i].z();
    EXPECT_TRUE(std::abs(z) < 1e-12 || std::abs(z - 0.6) < 1e-12) << i << ": z = " << z;
    (z < 0.3 ? low : high) += 1;
    EXPECT_EQ(wall.normals[i], V3::UnitZ());  // placeholders
  }
  EXPECT_GT(both, 150u);  // of 14 x 14
  EXPECT_EQ(s.wall_cells, both);
  EXPECT_EQ(low, expect_low);
  EXPECT_EQ(high, expect_high);
  EXPECT_EQ(s.after, low + high);

  // A plane with Gaussian noise of half a voxel: no gap in it is a second side.
  PointSet noisy;
  std::normal_distribution<double> noise(0.0, 0.5);
  for (int i = 0; i < 4000; ++i) noisy.positions.emplace_back(20.0 * uniform(), 20.0 * uniform(), noise(rng));
  PointSet merged = noisy;  // one sample a wide cell, as without the layers
  merged.normals.assign(merged.positions.size(), V3::UnitZ());
  const Simplification whole = SimplifyDenseSamples(merged, kDenseCellVoxels);
  const Simplification layered = SimplifyBarePositions(noisy, 1.0);
  ASSERT_TRUE(layered.Applied());
  EXPECT_EQ(layered.cell, kDenseCellVoxels);
  EXPECT_EQ(layered.after, whole.after);
  EXPECT_EQ(layered.wall_cells, 0u);
  EXPECT_EQ(layered.fold_cells, 0u);
  EXPECT_EQ(noisy.positions, merged.positions);
}

// A wide cell wrapping round the rim of a part thinner than the cell would average to a point
// inside the part, bridging its two sides (a plate 1.2 voxels thick, 8,000 bare samples at 48
// cells: 43 % of the band wrong); averaged in half-voxel cells, its samples stay on the surface.
TEST(SimplifyBarePositions, ARimThinnerThanTheWideCellsIsAveragedInHalfVoxelCells) {
  // A clean box 20 x 20 x 1.2 voxels, sampled on each face at one random point in every square
  // of 0.5 voxels (4 per square voxel): under one per half-voxel cell, so the wide cells apply.
  const V3 centre(10.0, 10.0, 0.6), half(10.0, 10.0, 0.6);
  const auto box_distance = [&](const V3& p) {  // signed, exact
    const V3 q = (p - centre).cwiseAbs() - half;
    return q.cwiseMax(0.0).norm() + std::min(q.maxCoeff(), 0.0);
  };
  PointSet box;
  std::mt19937_64 rng(17);
  const auto uniform = [&] { return static_cast<double>(rng() >> 11) * 0x1p-53; };
  for (int axis = 0; axis < 3; ++axis) {
    const int u = (axis + 1) % 3, v = (axis + 2) % 3;
    const int nu = static_cast<int>(std::lround(4.0 * half[u])), nv = static_cast<int>(std::lround(4.0 * half[v]));
    for (const double side : {-1.0, 1.0})
      for (int a = 0; a < nu; ++a)
        for (int b = 0; b < nv; ++b) {
          V3 p = centre - half;
          p[axis] = centre[axis] + side * half[axis];
          p[u] += 2.0 * half[u] * (a + uniform()) / nu;
          p[v] += 2.0 * half[v] * (b + uniform()) / nv;
          box.positions.push_back(p);
        }
  }
  const Simplification s = SimplifyBarePositions(box, 1.0);
  ASSERT_TRUE(s.Applied());
  EXPECT_EQ(s.cell, kDenseCellVoxels);
  EXPECT_GT(s.wall_cells, 100u);  // the faces' cells hold both sides
  EXPECT_GT(s.fold_cells, 20u);   // the rims at x = 0 and y = 0 (the far ones' cells hold a strip)
  // A half-voxel cell's mean lies inside a crease by up to a quarter of the cell's diagonal with
  // a few samples (0.125 voxels with its arms evenly sampled); a rim cell's one mean would lie
  // about half the thickness inside.
  double deepest = 0;
  for (std::size_t i = 0; i < box.positions.size(); ++i) {
    deepest = std::max(deepest, std::abs(box_distance(box.positions[i])));
    EXPECT_EQ(box.normals[i], V3::UnitZ());  // placeholders
  }
  EXPECT_LT(deepest, 0.3);
  EXPECT_GT(deepest, 0.05);  // the creases' means do lie inside
}

TEST(SimplifyDenseSamples, TheTwoSidesOfAThinWallStayApart) {
  PointSet wall;
  for (int i = 0; i < 100; ++i) {
    for (int j = 0; j < 100; ++j) {
      for (const double side : {-1.0, 1.0}) {
        wall.positions.emplace_back(i * 0.1, j * 0.1, side * 0.05);
        wall.normals.emplace_back(0, 0, side);
      }
    }
  }
  wall.positions.emplace_back(1e30, 0, 0);  // a far outlier: its cell number must not overflow
  wall.normals.emplace_back(1, 0, 0);
  const Simplification s = SimplifyDenseSamples(wall, 1.0);  // both sides in every cell
  ASSERT_TRUE(s.Applied());
  EXPECT_EQ(s.after, 10u * 10u * 2u + 1u);
  std::size_t up = 0, down = 0, far = 0;
  for (std::size_t i = 0; i < wall.positions.size(); ++i) {
    if (wall.positions[i].x() > 1e29) {
      ++far;
      EXPECT_EQ(wall.normals[i], Eigen::Vector3d(1, 0, 0));
      continue;
    }
    const bool top = wall.normals[i].z() > 0;
    (top ? up : down) += 1;
    EXPECT_EQ(wall.normals[i], Eigen::Vector3d(0, 0, top ? 1 : -1));
    EXPECT_NEAR(wall.positions[i].z(), top ? 0.05 : -0.05, 1e-12);
  }
  EXPECT_EQ(up, 100u);
  EXPECT_EQ(down, 100u);
  EXPECT_EQ(far, 1u);
}

}  // namespace
}  // namespace palpa::field

namespace palpa::field {
namespace {

// Issue 20: outliers that FindStraySamples passes (near the surface, with a plausible normal)
// are found by the winding number's jump across them; true samples are not, on a smooth sphere,
// at a cube's sharp edges and corners, and on a plate thinner than its spacing.
TEST(FindWindingOutliers, NearSurfaceOutliersAreFoundAndTrueSamplesKept) {
  Oriented sphere = Sphere(4000, 1.0);
  const std::size_t n = sphere.positions.size();
  // Spacing: ~sqrt(4 pi / 4000) = 0.056; 16th neighbour ~0.13. Outliers 0.05-0.1 off the surface,
  // outside and inside, normals tilted 40-60 degrees from the radial direction.
  std::mt19937_64 rng(3);
  const auto uniform = [&] { return static_cast<double>(rng() >> 11) * 0x1p-53; };
  std::vector<std::size_t> planted;
  for (int o = 0; o < 20; ++o) {
    V3 u(uniform() - 0.5, uniform() - 0.5, uniform() - 0.5);
    u.normalize();
    const double r = (o % 2 == 0 ? 1.0 : -1.0) * (0.05 + 0.05 * uniform()) + 1.0;
    V3 t = u.cross(V3(0.3, 0.5, 0.8)).normalized();
    const double tilt = (40.0 + 20.0 * uniform()) * std::numbers::pi / 180;
    planted.push_back(sphere.positions.size());
    sphere.positions.push_back(r * u);
    sphere.normals.push_back(std::cos(tilt) * u + std::sin(tilt) * t);
  }
  const WindingOutliers found = FindWindingOutliers(sphere.positions, sphere.normals);
  for (const std::size_t i : found.indices) EXPECT_GE(i, n) << "a true sample was taken for an outlier: " << i;
  EXPECT_GE(found.indices.size(), 16u);  // most of the 20 (one just above the surface can pass)
  ASSERT_TRUE(found.worst.has_value());
  EXPECT_GE(*found.worst, n);
  EXPECT_LT(found.worst_jump, 0.5);

  const Oriented cube = Cube(24);
  EXPECT_TRUE(FindWindingOutliers(cube.positions, cube.normals).indices.empty());
  Oriented plate;
  for (int a = 0; a < 40; ++a) {
    for (int b = 0; b < 40; ++b) {
      for (const double side : {-1.0, 1.0}) {
        plate.positions.emplace_back(a * 1.0, b * 1.0, side * 0.45);
        plate.normals.emplace_back(0, 0, side);
      }
    }
  }
  EXPECT_TRUE(FindWindingOutliers(plate.positions, plate.normals).indices.empty());
}

TEST(FindWindingOutliers, AFlippedNormalIsAnOutlier) {
  Oriented sphere = Sphere(3000, 1.0);
  sphere.normals[1234] = -sphere.normals[1234];
  const WindingOutliers found = FindWindingOutliers(sphere.positions, sphere.normals);
  ASSERT_EQ(found.indices.size(), 1u);
  EXPECT_EQ(found.indices[0], 1234u);
  EXPECT_LT(found.worst_jump, 0.0);
}

// A stray point between two parts, facing the nearer one across a narrow gap (CGAL's pinion_small
// with a point moved 8 voxels out between two teeth, robustness.py seed 9: no warning and 13
// phantom nodes). The surface in front holds its probes within 0.4 of the gap, where its own disc
// makes most of the jump: J 0.58, of which the others' share is 0.11. Two spheres of 4,000
// samples (spacing ~0.056), 0.24 apart; the stray 0.21 in front of one (3.7 spacings), 0.03 from
// the other and facing it at 35 degrees: J ~0.54, the others' share ~0 (the same sums in numpy).
// With J alone it passes (checked: none found); every true sample, those facing the gap
// included, is kept.
TEST(FindWindingOutliers, AStrayPointFacingASurfaceAcrossANarrowGapIsAnOutlier) {
  Oriented two = Sphere(4000, 1.0);
  const Oriented other = Sphere(4000, 1.0, V3(2.24, 0.0, 0.0));
  two.positions.insert(two.positions.end(), other.positions.begin(), other.positions.end());
  two.normals.insert(two.normals.end(), other.normals.begin(), other.normals.end());
  const std::size_t stray = two.positions.size();
  two.positions.emplace_back(1.21, 0.011, 0.017);
  two.normals.emplace_back(std::cos(35.0 * std::numbers::pi / 180), std::sin(35.0 * std::numbers::pi / 180), 0.0);
  const WindingOutliers found = FindWindingOutliers(two.positions, two.normals);
  ASSERT_EQ(found.indices.size(), 1u);
  EXPECT_EQ(found.indices[0], stray);
}

// A wall thinner than the spacing whose one side is a narrow strip (a flange's top face, as on
// the spool): of each strip sample's 16 nearest, 2 lie on the strip and 14 on the wide side,
// facing away, each behind the other's tangent plane. Those support it as its own side's samples
// would (the spool's clean 5,000 samples lost 43 before, and the wide side's inner balls filled
// the flange's concave corner with phantom solid); the strip's two end samples, with one strip
// neighbour each, stay stray (an outlier buried under a surface, facing into it, has the surface
// behind it too, but none of its own side). A flipped normal on a convex or a concave sheet is
// still stray: its neighbours lie on or in front of its plane, or it in front of theirs.
TEST(FindStraySamples, TheNarrowSideOfAThinWallIsKeptAndFlippedNormalsAreNot) {
  Oriented wall;
  for (int a = 0; a < 40; ++a)
    for (int b = 0; b < 40; ++b) {
      wall.positions.emplace_back(a, b, 0.0);
      wall.normals.emplace_back(0, 0, -1);
    }
  const std::size_t strip = wall.positions.size();
  constexpr std::size_t kStrip = 20;
  for (std::size_t t = 0; t < kStrip; ++t) {
    wall.positions.emplace_back(5.0 + 1.5 * static_cast<double>(t), 20.5, 0.3);
    wall.normals.emplace_back(0, 0, 1);
  }
  const StraySamples kept = FindStraySamples(wall.positions, wall.normals);
  for (const std::size_t i : kept.indices)
    EXPECT_TRUE(i < strip || i == strip || i == strip + kStrip - 1)
        << "a sample inside the strip was taken for a stray one: " << i - strip;

  for (const double side : {1.0, -1.0}) {  // a ball, then a ball-shaped cavity (normals inward)
    Oriented sheet = Sphere(3000, 1.0);
    for (V3& normal : sheet.normals) normal *= side;
    sheet.normals[1234] = -sheet.normals[1234];
    const StraySamples found = FindStraySamples(sheet.positions, sheet.normals);
    ASSERT_EQ(found.indices.size(), 1u) << side;
    EXPECT_EQ(found.indices[0], 1234u) << side;
  }
}

// A convex corner whose one face is sampled sparsely near it (a cube with 1,000 random samples,
// exact normals: a pair of top-face samples beside the corner): of the sample's 16 nearest, one
// lies on its own face and the rest on the two other faces, each behind its tangent plane as it
// is behind theirs. They support it; before, with 2 own-face neighbours required, it was dropped,
// and the side face's patches carried the solid 7 voxels up past the top face (610 phantom nodes,
// and the build called the closed cube an open scan). A lone outlier buried under the same
// corner, facing into it, has none of its own side and stays stray.
TEST(FindStraySamples, ASparseFaceSampleAtAConvexCornerIsKeptAndABuriedOutlierIsNot) {
  Oriented corner;  // the solid x, y, z <= 0; faces sampled on a lattice of spacing 1
  for (int a = 0; a < 10; ++a)
    for (int b = 0; b < 10; ++b) {
      const double u = -(a + 0.5), v = -(b + 0.5);
      corner.positions.emplace_back(0.0, u, v);
      corner.normals.emplace_back(1, 0, 0);
      corner.positions.emplace_back(u, 0.0, v);
      corner.normals.emplace_back(0, 1, 0);
      if (u * u + v * v > 9.0) {  // the top face has no lattice sample within 3 of the corner
        corner.positions.emplace_back(u, v, 0.0);
        corner.normals.emplace_back(0, 0, 1);
      }
    }
  corner.positions.emplace_back(-0.4, -0.6, 0.0);
  corner.normals.emplace_back(0, 0, 1);
  corner.positions.emplace_back(-0.9, -0.3, 0.0);
  corner.normals.emplace_back(0, 0, 1);
  EXPECT_TRUE(FindStraySamples(corner.positions, corner.normals).indices.empty());

  const std::size_t buried = corner.positions.size();
  corner.positions.emplace_back(-0.5, -0.5, -0.3);  // beneath the pair, facing down into the solid
  corner.normals.emplace_back(0, 0, -1);
  const StraySamples found = FindStraySamples(corner.positions, corner.normals);
  ASSERT_EQ(found.indices.size(), 1u);
  EXPECT_EQ(found.indices[0], buried);
}

}  // namespace
}  // namespace palpa::field

// --- SmoothNoisyPositions (issue 20: position noise) -------------------------------------------

namespace palpa::field {
namespace {

// Distance to the surface of the cube [-1, 1]^3 (exact for points near it, inside or out).
double CubeDistance(const V3& p) {
  const V3 q = p.cwiseAbs() - V3::Ones();
  const double outside = q.cwiseMax(0.0).norm();
  const double inside = std::min(q.maxCoeff(), 0.0);
  return std::abs(outside + inside);
}

TEST(SmoothNoisyPositions, MeasuresTheNoiseAndAveragesItOnASphere) {
  Oriented sphere = Sphere(8000, 1.0);
  const double sigma = 0.01;  // ~ a third of the sample spacing (0.04)
  std::mt19937_64 rng(5);
  std::normal_distribution<double> gauss(0.0, sigma);
  for (V3& p : sphere.positions) p += V3(gauss(rng), gauss(rng), gauss(rng));
  const auto rms_radial = [&] {
    double s = 0.0;
    for (const V3& p : sphere.positions) s += (p.norm() - 1.0) * (p.norm() - 1.0);
    return std::sqrt(s / static_cast<double>(sphere.positions.size()));
  };
  const double before = rms_radial();
  EXPECT_NEAR(before, sigma, 0.1 * sigma);
  const NoiseSmoothing measured = MeasurePositionNoise(sphere.positions, sphere.normals, kDenoiseNeighbours);
  EXPECT_EQ(measured.moved, 0u);
  // As if fitted: normals that follow the shape pass the moves' discrepancy check.
  const NoiseSmoothing done = SmoothNoisyPositions(sphere.positions, sphere.normals, kDenoiseNeighbours, 0.5 * sigma,
                                                   kMovePasses, /*fitted_neighbours=*/kMostNormalNeighbours);
  ASSERT_TRUE(done.Applied());
  EXPECT_NEAR(done.noise, sigma, 0.2 * sigma);  // the residual of 16-neighbour quadrics, dof-corrected
  EXPECT_EQ(measured.noise, done.noise);        // the measure alone is the same measure
  EXPECT_EQ(measured.residual, done.residual);
  EXPECT_EQ(done.moved, sphere.positions.size());
  EXPECT_LT(rms_radial(), before / 3.0);  // kDenoiseNeighbours (48), twice: sigma / sqrt(48) ideally
  // The moves take out the noise, so their RMS is about the noise's; far beyond it they are undone.
  EXPECT_FALSE(done.withheld);
  EXPECT_NEAR(done.rms_move, sigma, 0.2 * sigma);
}

TEST(SmoothNoisyPositions, LeavesCleanSamplesAlone) {
  Oriented sphere = Sphere(2000, 1.0);
  const std::vector<V3> before = sphere.positions;
  const NoiseSmoothing done = SmoothNoisyPositions(sphere.positions, sphere.normals, kDenoiseNeighbours, 1e-3);
  EXPECT_FALSE(done.Applied());
  EXPECT_LT(done.noise, 1e-4);  // a sphere is a quadric to this order at 16 neighbours
  EXPECT_EQ(sphere.positions, before);
}

// Sparse clean samples of a detailed surface (a thin torus, ~6 samples round its tube) leave a
// large quadric residual, but one that grows with the fit's neighbourhood: shape, not noise. The
// same torus with noise of that size, densely sampled, is measured and averaged.
TEST(SmoothNoisyPositions, TellsASparseDetailedSurfaceFromNoise) {
  const auto torus = [](std::size_t n, std::uint64_t seed) {
    PointSet drawn = testing::TorusSamples(1.0, 0.25, n, seed);
    return Oriented{std::move(drawn.positions), std::move(drawn.normals)};
  };
  Oriented sparse = torus(400, 8);  // spacing ~0.16 against the tube's radius 0.25; residual 0.0015, noise 0
  const std::vector<V3> before = sparse.positions;
  const NoiseSmoothing clean = SmoothNoisyPositions(sparse.positions, sparse.normals, kDenoiseNeighbours, 1e-3);
  const double threshold = 0.5 * clean.residual;  // the 16-sample residual alone would move them
  sparse.positions = before;
  const NoiseSmoothing kept = SmoothNoisyPositions(sparse.positions, sparse.normals, kDenoiseNeighbours, threshold);
  EXPECT_GT(kept.residual, threshold);
  EXPECT_LT(kept.noise, 0.5 * threshold) << kept.residual;
  EXPECT_FALSE(kept.Applied());
  EXPECT_EQ(sparse.positions, before);

  Oriented noisy = torus(20000, 9);
  std::mt19937_64 rng(10);
  std::normal_distribution<double> gauss(0.0, threshold);
  for (V3& p : noisy.positions) p += V3(gauss(rng), gauss(rng), gauss(rng));
  const NoiseSmoothing smoothed =
      SmoothNoisyPositions(noisy.positions, noisy.normals, kDenoiseNeighbours, 0.5 * threshold);
  EXPECT_TRUE(smoothed.Applied());
  EXPECT_NEAR(smoothed.noise, threshold, 0.25 * threshold);
}

// Bare samples move no farther than their normals' fit reached: the fit widens only as far as the
// noise needs, and wider moves, whose confidence intervals are as wide as the first residual in
// every pass, let the shape's detail pass for noise. A noisy wavy sheet (a wavelength of 20
// spacings) with 18-neighbour jet lines: moved over its nearest 16 it ends nearer the surface
// than moved over 16-64 as given normals are.
TEST(SmoothNoisyPositions, FittedNormalsMoveNoFartherThanTheirFit) {
  constexpr double kAmp = 0.05, kWave = 2.0 * std::numbers::pi / 0.4, kSigma = 0.004;
  const auto height = [&](double x, double y) { return kAmp * std::sin(kWave * x) * std::sin(kWave * y); };
  std::mt19937_64 rng(13);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::normal_distribution<double> gauss(0.0, kSigma);
  std::vector<V3> noisy;
  for (int i = 0; i < 10000; ++i) {  // 2 x 2, spacing ~0.02
    const double x = 2 * unit(rng) - 1, y = 2 * unit(rng) - 1;
    noisy.push_back(V3(x, y, height(x, y)) + V3(gauss(rng), gauss(rng), gauss(rng)));
  }
  const auto rms_off = [&](const std::vector<V3>& positions) {
    double s = 0.0;
    std::size_t count = 0;
    for (const V3& p : positions) {
      if (std::max(std::abs(p.x()), std::abs(p.y())) > 0.8) continue;  // away from the rim
      s += std::pow(p.z() - height(p.x(), p.y()), 2);
      ++count;
    }
    return std::sqrt(s / static_cast<double>(count));
  };
  std::vector<V3> lines;
  const int fitted = EstimateNormalLines(noisy, lines, nullptr, /*noisy=*/true);
  ASSERT_EQ(fitted, kNormalNeighbours);
  for (V3& l : lines)
    if (l.z() < 0) l = -l;  // the signs are not in question here
  std::vector<V3> as_fitted = noisy, as_given = noisy;
  const NoiseSmoothing a =
      SmoothNoisyPositions(as_fitted, lines, kDenoiseNeighbours, 0.5 * kSigma, kMovePasses, fitted);
  const NoiseSmoothing b = SmoothNoisyPositions(as_given, lines, kDenoiseNeighbours, 0.5 * kSigma);
  ASSERT_TRUE(a.Applied());
  ASSERT_TRUE(b.Applied());
  EXPECT_EQ(a.widest, kMoveFewestNeighbours);
  EXPECT_EQ(b.widest, kMoveMostNeighbours);
  std::printf("[ wavy sheet ] height RMS off the surface %.5f; moved over 16 %.5f, over 16-64 %.5f\n", rms_off(noisy),
              rms_off(as_fitted), rms_off(as_given));
  // Measured: 0.00458 -> 0.00165 over 16, 0.00194 over 16-64.
  EXPECT_LT(rms_off(as_fitted), rms_off(noisy) / 2.5);
  EXPECT_LT(rms_off(as_fitted), 0.9 * rms_off(as_given));
}

// Where fitted lines do not follow the shape (a finger's, a thin part's rim, where the 18 nearest
// wrap round it), the bisector offsets along them scatter beyond the noise and their mean is not
// the surface: such a sample stays where it is. A thin noisy ellipsoid (semi-axes 1, 0.6 and
// 0.08; the rim's radius of curvature 0.0064 against a spacing of ~0.024) with its lines fitted
// from the noisy positions ends nearer the surface than moved everywhere.
TEST(SmoothNoisyPositions, FittedNormalsStayWhereTheirNeighboursOffsetsScatter) {
  constexpr double kSigma = 0.003;
  const V3 axes(1.0, 0.6, 0.08);
  std::mt19937_64 rng(19);
  std::normal_distribution<double> gauss(0.0, 1.0);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const auto gradient = [&](const V3& p) { return V3(p.cwiseQuotient(axes.cwiseProduct(axes))); };
  std::vector<V3> noisy, outward;
  while (noisy.size() < 6000) {
    const V3 p = axes.cwiseProduct(V3(gauss(rng), gauss(rng), gauss(rng)).normalized());
    // The sphere's map onto the ellipsoid stretches area by abc |p / axes^2|, at most ab.
    if (unit(rng) > axes.z() * gradient(p).norm()) continue;
    noisy.push_back(p + kSigma * V3(gauss(rng), gauss(rng), gauss(rng)));
    outward.push_back(gradient(p));
  }
  std::vector<V3> lines;
  const int fitted = EstimateNormalLines(noisy, lines, nullptr, /*noisy=*/true);
  for (std::size_t i = 0; i < lines.size(); ++i)
    if (lines[i].dot(outward[i]) < 0) lines[i] = -lines[i];  // the signs are not in question here
  // Distance to the ellipsoid to first order: (|p / axes|^2 - 1) / |gradient of it|.
  const auto rms_off = [&](const std::vector<V3>& positions) {
    double s = 0.0;
    for (const V3& p : positions)
      s += std::pow((p.cwiseQuotient(axes).squaredNorm() - 1.0) / (2.0 * gradient(p).norm()), 2);
    return std::sqrt(s / static_cast<double>(positions.size()));
  };
  std::vector<V3> bounded = noisy, unbounded = noisy;
  const NoiseSmoothing a = SmoothNoisyPositions(bounded, lines, kDenoiseNeighbours, 0.5 * kSigma, kMovePasses, fitted);
  const NoiseSmoothing b = SmoothNoisyPositions(unbounded, lines, kDenoiseNeighbours, 0.5 * kSigma, kMovePasses, fitted,
                                                std::numeric_limits<double>::infinity());
  ASSERT_TRUE(a.Applied());
  ASSERT_TRUE(b.Applied());
  // The samples that stayed in every pass lie on the rim: their mean |z| against everyone's.
  double z_stayed = 0.0, z_all = 0.0;
  std::size_t stayed = 0;
  for (std::size_t i = 0; i < noisy.size(); ++i) {
    const double z = std::abs(noisy[i].z());
    z_all += z;
    if (bounded[i] != noisy[i]) continue;
    z_stayed += z;
    ++stayed;
  }
  std::printf(
      "[ thin ellipsoid ] fit %d; first pass stayed %zu, all passes %zu; mean |z| %.4f of those, %.4f of all; "
      "RMS off the surface %.5f -> %.5f (moved everywhere %.5f)\n",
      fitted, a.scattered, stayed, z_stayed / static_cast<double>(stayed), z_all / static_cast<double>(noisy.size()),
      rms_off(noisy), rms_off(bounded), rms_off(unbounded));
  // Measured: 1,210 stayed in the first pass (1,050 in every pass), mean |z| 0.0215 against 0.0518;
  // RMS off 0.00298 -> 0.00163, moved everywhere 0.00196.
  EXPECT_EQ(b.scattered, 0u);
  EXPECT_GT(a.scattered, noisy.size() / 20);
  EXPECT_LT(z_stayed / static_cast<double>(stayed), 0.5 * z_all / static_cast<double>(noisy.size()));
  EXPECT_LT(rms_off(bounded), 0.9 * rms_off(unbounded));
  EXPECT_LT(rms_off(bounded), rms_off(noisy) / 1.5);
}

// A thin noisy cylinder (a leg, a horn): the 16 nearest of a sample wrap round it, fewer than 9
// with its normal, so a fitted height function has too few samples or a biased shape; the
// bisector move needs neither (on a cylinder (n_i + n_j) . (P_j - P_i) = 0 exactly).
TEST(SmoothNoisyPositions, MovesSamplesOfAThinPart) {
  constexpr double kRadius = 0.015, kLength = 4.0, kSigma = 0.001;
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::normal_distribution<double> gauss(0.0, kSigma);
  Oriented cylinder;
  for (int i = 0; i < 6000; ++i) {
    const double a = 2 * std::numbers::pi * unit(rng);
    const V3 normal(std::cos(a), std::sin(a), 0);
    cylinder.positions.push_back(kRadius * normal + V3(0, 0, kLength * unit(rng)) +
                                 V3(gauss(rng), gauss(rng), gauss(rng)));
    cylinder.normals.push_back(normal);
  }
  const auto rms_radial = [&] {
    double s = 0.0;
    for (const V3& p : cylinder.positions) s += std::pow(p.head<2>().norm() - kRadius, 2);
    return std::sqrt(s / static_cast<double>(cylinder.positions.size()));
  };
  const double before = rms_radial();
  const NoiseSmoothing done =
      SmoothNoisyPositions(cylinder.positions, cylinder.normals, kDenoiseNeighbours, 0.5 * kSigma);
  ASSERT_TRUE(done.Applied());
  // Measured: all 6,000 moved, radial RMS 0.00100 -> 0.00021; the 48-sample quadrics it
  // replaced moved 5,919 and left 0.00044.
  EXPECT_GT(done.moved, cylinder.positions.size() * 99 / 100) << done.moved;
  EXPECT_LT(rms_radial(), before / 3.0);
}

TEST(SmoothNoisyPositions, KeepsTheEdgesOfANoisyCubeSharp) {
  Oriented cube = Cube(40);  // spacing 0.05
  const double sigma = 0.015;
  std::mt19937_64 rng(6);
  std::normal_distribution<double> gauss(0.0, sigma);
  for (V3& p : cube.positions) p += V3(gauss(rng), gauss(rng), gauss(rng));
  const auto rms = [&](bool near_edge) {
    double s = 0.0;
    std::size_t count = 0;
    for (const V3& p : cube.positions) {
      const V3 a = p.cwiseAbs();
      // Near an edge: two coordinates within 2 spacings of the faces.
      const int close = (a.x() > 0.9) + (a.y() > 0.9) + (a.z() > 0.9);
      if ((close >= 2) != near_edge) continue;
      s += CubeDistance(p) * CubeDistance(p);
      ++count;
    }
    return std::sqrt(s / static_cast<double>(count));
  };
  const double edge_before = rms(true), face_before = rms(false);
  const NoiseSmoothing done = SmoothNoisyPositions(cube.positions, cube.normals, kDenoiseNeighbours, 0.5 * sigma);
  ASSERT_TRUE(done.Applied());
  // Only neighbours of the same face are fitted: a fit across the edge would round it and pull
  // the samples near it off both faces (CGAL's jet_smooth_point_set does).
  EXPECT_LT(rms(false), face_before / 3.0);
  EXPECT_LT(rms(true), edge_before / 2.0);
}

}  // namespace
}  // namespace palpa::field

// --- RefitNoisyNormalLines (issue 20: noisy for the grid, clean for the spacing) ----------------

namespace palpa::field {
namespace {

// Mean angle (degrees) between the lines and a sphere's radial lines.
double MeanRadialAngleDeg(const std::vector<V3>& positions, const std::vector<V3>& normals) {
  double sum = 0.0;
  for (std::size_t i = 0; i < positions.size(); ++i)
    sum += std::acos(std::min(1.0, std::abs(normals[i].dot(positions[i].normalized())))) * 180.0 / std::numbers::pi;
  return sum / static_cast<double>(positions.size());
}

// `n` samples of the unit sphere (Sphere) moved by Gaussian noise of `sigma` per axis (`seed`);
// the normals stay the exact ones.
Oriented NoisySphere(std::size_t n, double sigma, std::uint64_t seed) {
  Oriented sphere = Sphere(n, 1.0);
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> gauss(0.0, sigma);
  for (V3& p : sphere.positions) p += V3(gauss(rng), gauss(rng), gauss(rng));
  return sphere;
}

TEST(RefitNoisyNormalLines, FitsLinesAgainWhereTheNoiseExceedsTheThreshold) {
  const double sigma = 0.0025;  // clean for the spacing of ~0.04 (EstimateNormalLines' figure)
  const Oriented sphere = NoisySphere(8000, sigma, 11);
  std::vector<V3> normals;
  NormalsReport report;
  report.neighbours = EstimateNormalLines(sphere.positions, normals, &report.noise_figure);
  ASSERT_EQ(report.neighbours, kCleanNormalNeighbours) << report.noise_figure;
  // Signs as an orientation would leave them, except a few flipped to see that each keeps its own.
  for (std::size_t i = 0; i < normals.size(); ++i)
    if ((normals[i].dot(sphere.positions[i]) < 0) != (i % 7 == 0)) normals[i] = -normals[i];
  const std::vector<V3> clean_lines = normals;

  NormalsReport above = report;
  std::vector<V3> refitted = normals;
  ASSERT_TRUE(RefitNoisyNormalLines(sphere.positions, refitted, above, 0.5 * sigma, 48));
  EXPECT_GT(above.neighbours, kCleanNormalNeighbours);
  for (std::size_t i = 0; i < normals.size(); ++i) ASSERT_GT(refitted[i].dot(clean_lines[i]), 0.0) << i;
  // The wider fit averages the noise the 10-sample one carries.
  const double clean_deg = MeanRadialAngleDeg(sphere.positions, clean_lines);
  const double refit_deg = MeanRadialAngleDeg(sphere.positions, refitted);
  EXPECT_LT(refit_deg, 0.8 * clean_deg) << clean_deg;

  // Below the threshold, or lines already fitted as noisy: nothing changes.
  NormalsReport below = report;
  std::vector<V3> kept = normals;
  EXPECT_FALSE(RefitNoisyNormalLines(sphere.positions, kept, below, 2.0 * sigma, 48));
  EXPECT_EQ(kept, clean_lines);
  EXPECT_EQ(below.neighbours, kCleanNormalNeighbours);
  EXPECT_FALSE(RefitNoisyNormalLines(sphere.positions, refitted, above, 0.5 * sigma, 48));
}

// --- OrientEstimatedNormals: the build's sequence in one call ------------------------------------

TEST(OrientEstimatedNormals, IsTheBuildsSequenceAndPointsOutward) {
  // A noisy sphere's jet lines, signs scrambled: one call gives every normal outward (the
  // truth, independent of the code) and exactly what the four separate steps give, with the
  // refit above the noise and without it below.
  const double sigma = 0.0025;
  const Oriented sphere = NoisySphere(6000, sigma, 5);
  std::vector<V3> lines;
  NormalsReport fitted;
  fitted.neighbours = EstimateNormalLines(sphere.positions, lines, &fitted.noise_figure);
  ASSERT_EQ(fitted.neighbours, kCleanNormalNeighbours);
  for (std::size_t i = 0; i < lines.size(); ++i)
    if (i % 3 == 0) lines[i] = -lines[i];
  for (const double threshold : {0.5 * sigma, 4.0 * sigma}) {
    NormalsReport one = fitted, steps = fitted;
    std::vector<V3> by_one = lines, by_steps = lines;
    const bool refit = OrientEstimatedNormals(sphere.positions, by_one, one, threshold);
    OrientNormals(sphere.positions, by_steps, false, steps, true);
    EXPECT_EQ(RefitNoisyNormalLines(sphere.positions, by_steps, steps, threshold, kDenoiseNeighbours), refit);
    RefineNormalLines(sphere.positions, by_steps, steps.neighbours);
    FlipSheetsOnSharpenedLines(sphere.positions, by_steps, steps);
    EXPECT_EQ(refit, threshold < sigma) << threshold;
    EXPECT_EQ(by_one, by_steps) << threshold;
    EXPECT_EQ(one.Describe(), steps.Describe());
    for (std::size_t i = 0; i < by_one.size(); ++i) ASSERT_GT(by_one[i].dot(sphere.positions[i]), 0.0) << i;
  }
  std::vector<V3> mismatched(10, V3::UnitX());
  NormalsReport untouched = fitted;
  EXPECT_FALSE(OrientEstimatedNormals(sphere.positions, mismatched, untouched, sigma));
  EXPECT_EQ(mismatched, std::vector<V3>(10, V3::UnitX()));
}

}  // namespace
}  // namespace palpa::field
