// The normal-orientation check against orientations we set ourselves, and cube.pwn's normals
// read directly (each against the face of the bounding box it lies on).
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <random>

#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include "palpa/field/orientation.h"
#include "palpa/field/point_io.h"
#include "test_util.h"

namespace palpa::field {
namespace {

using testing::DataFile;

TEST(CheckOrientation, ConsistentBundledSetsPass) {
  for (const char* file : {"kitten.xyz", "oni.pwn", "sphere926.pwn", "sphere_20k_normal.xyz"}) {
    const auto points = ReadPoints(DataFile(file));
    ASSERT_TRUE(points.has_value()) << file;
    const OrientationReport r = CheckOrientation(points->positions, points->normals);
    std::printf("[ %s ] %s\n", file, r.Describe().c_str());
    EXPECT_EQ(r.support_directions, 26) << file;
    EXPECT_EQ(r.inward_support_directions, 0) << file;
    EXPECT_FALSE(r.Inconsistent()) << file;
  }
}

// Issue 20: an open, one-sided scan with consistent normals is not "inconsistent": along -z the
// outermost points of sphere926's cap z > 0 are its rim, whose normals are horizontal (before:
// 1 of 26 directions counted inward, and the build blamed the normals).
TEST(CheckOrientation, OpenScanRimIsNoEvidence) {
  const auto points = ReadPoints(DataFile("sphere926.pwn"));
  ASSERT_TRUE(points.has_value());
  std::vector<Eigen::Vector3d> p, n;
  for (std::size_t i = 0; i < points->positions.size(); ++i)
    if (points->positions[i].z() > 0) p.push_back(points->positions[i]), n.push_back(points->normals[i]);
  const OrientationReport r = CheckOrientation(p, n);
  EXPECT_EQ(r.inward_support_directions, 0) << r.Describe();
  EXPECT_FALSE(r.Inconsistent()) << r.Describe();
  // The same cap inside out is still caught.
  for (auto& x : n) x = -x;
  EXPECT_TRUE(CheckOrientation(p, n).Inconsistent());
}

TEST(CheckOrientation, FlippedNormalsAreFound) {
  const auto points = ReadPoints(DataFile("sphere926.pwn"));
  ASSERT_TRUE(points.has_value());
  // All flipped (inside out): every support direction is inward.
  std::vector<Eigen::Vector3d> all = points->normals;
  for (auto& n : all) n = -n;
  const OrientationReport inside_out = CheckOrientation(points->positions, all);
  EXPECT_EQ(inside_out.inward_support_directions, 26);
  EXPECT_TRUE(inside_out.Inconsistent());
  // One random point in ten flipped: opposite normals on one tangent plane.
  std::vector<Eigen::Vector3d> some = points->normals;
  std::mt19937_64 rng(3);
  for (auto& n : some) n = (rng() % 10 == 0) ? Eigen::Vector3d(-n) : n;
  const OrientationReport random = CheckOrientation(points->positions, some);
  std::printf("[ sphere926, 1 in 10 flipped ] %s\n", random.Describe().c_str());
  EXPECT_GT(random.flipped_flat_pairs, random.flat_pairs / 20);
  EXPECT_TRUE(random.Inconsistent());
  // The cube.pwn pattern on the sphere: normals made to point to +x, +y, +z's side (sign lost).
  std::vector<Eigen::Vector3d> unsigned_normals = points->normals;
  for (auto& n : unsigned_normals) {
    Eigen::Index axis = 0;
    n.cwiseAbs().maxCoeff(&axis);
    if (n[axis] < 0) n = -n;
  }
  const OrientationReport sign_lost = CheckOrientation(points->positions, unsigned_normals);
  EXPECT_GT(sign_lost.inward_support_directions, 0);
  EXPECT_TRUE(sign_lost.Inconsistent());
}

// cube.pwn, read as it is: on each face of its bounding box, the sign of n.(outward face normal)
// of the points lying on that face. The file's normals point to +x, +y or +z whatever the face,
// so they point inward on the three low faces: the data, not our reading, is inconsistent.
// A closed plate thinner than its sample spacing, tilted: at its rims the farthest samples along
// a direction are on both faces, half of them on the back face, whose correct normals point away.
// That is no evidence of flipped normals; one face flipped still is.
TEST(CheckOrientation, TheBackFaceOfAThinWallIsNotInward) {
  // 0.03: the farthest samples at the rims lie on both faces (3 inward directions without the
  // exemption); 0.008, far thinner than the spacing (~0.045): pairs across the wall lie within
  // 10 degrees of both tangent planes, flat and opposite (2,105 of 10,159 pairs without it).
  for (const double thick : {0.03, 0.008}) {
    constexpr double kHalf = 1.0, kTilt = 1.2;  // tilt in radians
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> unit(-1.0, 1.0);
    const Eigen::Matrix3d turn = Eigen::AngleAxisd(kTilt, Eigen::Vector3d::UnitX()).toRotationMatrix();
    std::vector<Eigen::Vector3d> p, n;
    for (int i = 0; i < 4000; ++i) {  // the two large faces; the rims (1 % of the area) left out
      const double side = i % 2 == 0 ? 1.0 : -1.0;
      p.push_back(turn * Eigen::Vector3d(kHalf * unit(rng), kHalf * unit(rng), side * thick / 2));
      n.push_back(turn * Eigen::Vector3d(0, 0, side));
    }
    const OrientationReport r = CheckOrientation(p, n);
    EXPECT_EQ(r.inward_support_directions, 0) << thick << ": " << r.Describe();
    EXPECT_EQ(r.flipped_flat_pairs, 0u) << thick << ": " << r.Describe();
    EXPECT_FALSE(r.Inconsistent()) << r.Describe();
    EXPECT_FALSE(r.OpenScanInconsistent()) << r.Describe();
    for (std::size_t i = 1; i < n.size(); i += 2) n[i] = -n[i];  // the back face's normals flipped
    const OrientationReport flipped = CheckOrientation(p, n);
    EXPECT_TRUE(flipped.Inconsistent()) << thick << ": " << flipped.Describe();
  }
}

// Issue 20: exact normals are consistent, also on thin curved walls sampled sparsely. CGAL's
// rotor (bundled) has blades about 0.6 sample spacings thick at 500 samples; across a blade one
// sample often lies on its partner's tangent plane while the partner lies clearly behind its own,
// so the pair is flat, opposite, and not "each behind the other": 13 of 811 flat pairs for this
// draw, over the 1 % bound, and the build blamed the normals. One clearly behind and the other on
// the plane is a thin wall too; a flipped normal on one smooth sheet lies the same way off its
// neighbour's plane as the neighbour off its own. Half the rotor's normals flipped is still caught.
TEST(CheckOrientation, ExactNormalsOfSparselySampledThinCurvedBladesAreConsistent) {
  const PointSet points = testing::SampledMesh("rotor.off", 500, 7);
  const OrientationReport r = CheckOrientation(points.positions, points.normals);
  EXPECT_EQ(r.inward_support_directions, 0) << r.Describe();
  EXPECT_FALSE(r.Inconsistent()) << r.Describe();
  std::vector<Eigen::Vector3d> some = points.normals;
  std::mt19937_64 rng(5);
  for (auto& n : some) n = (rng() % 2 == 0) ? Eigen::Vector3d(-n) : n;
  EXPECT_TRUE(CheckOrientation(points.positions, some).Inconsistent());
}

// `points`' normals with the `count` samples nearest sample `centre` (itself included) flipped.
std::vector<Eigen::Vector3d> NearestFlipped(const PointSet& points, std::size_t centre, std::size_t count) {
  std::vector<std::pair<double, std::size_t>> by_distance;
  for (std::size_t i = 0; i < points.positions.size(); ++i)
    by_distance.push_back({(points.positions[i] - points.positions[centre]).squaredNorm(), i});
  std::partial_sort(by_distance.begin(), by_distance.begin() + static_cast<std::ptrdiff_t>(count), by_distance.end());
  std::vector<Eigen::Vector3d> normals = points.normals;
  for (std::size_t m = 0; m < count; ++m) normals[by_distance[m].second] *= -1.0;
  return normals;
}

// Issue 20: a patch of flipped normals (a scan's view merged with the wrong sign) on a closed
// surface. Its boundary is a closed curve of flipped pairs, a small share of all flat pairs:
// knot1 with 40 of its 5,000 exact normals flipped (a patch 3 spacings across) has 0.2 % of
// them flipped, under the 1 % bound, and had no warning while its field grew ~2,000 far-wrong
// nodes. The patch is a sheet of its own, bounded by flipped pairs to a far larger sheet.
TEST(CheckOrientation, APatchOfFlippedNormalsIsFound) {
  const PointSet points = testing::SampledMesh("knot1.off", 5000, 3);
  const OrientationReport clean = CheckOrientation(points.positions, points.normals);
  EXPECT_FALSE(clean.Inconsistent()) << clean.Describe();
  EXPECT_EQ(clean.flipped_patch_pairs, 0u) << clean.Describe();
  for (const std::size_t centre : {0u, 1000u, 2500u}) {
    const std::vector<Eigen::Vector3d> normals = NearestFlipped(points, centre, 40);
    const OrientationReport r = CheckOrientation(points.positions, normals);
    std::printf("[ knot1, 40 flipped around %zu ] %s\n", centre, r.Describe().c_str());
    EXPECT_LE(r.flipped_flat_pairs * 100, r.flat_pairs) << "the 1 % bound alone would catch it";
    EXPECT_GE(r.flipped_patch_samples, 30u);  // the patch, but for a sample or two of its own
    EXPECT_LE(r.flipped_patch_samples, 40u);
    EXPECT_TRUE(r.Inconsistent()) << r.Describe();
    EXPECT_TRUE(r.OpenScanInconsistent()) << r.Describe();
  }
}

// A small patch on a sparse set: knot1 with 1,000 samples and the 20 nearest one sample flipped.
// Its rim has 6 flipped pairs at a seam, under the 1 % bound (6 of ~1,050 flat pairs), and
// the patch test needed 8 (consistent sets reach 3 at most: kMinPatchPairs' note).
TEST(CheckOrientation, ASmallPatchOnASparseSetIsFound) {
  const PointSet points = testing::SampledMesh("knot1.off", 1000, 1);
  const OrientationReport clean = CheckOrientation(points.positions, points.normals);
  EXPECT_FALSE(clean.Inconsistent()) << clean.Describe();
  for (const std::size_t centre : {325u, 725u}) {
    const std::vector<Eigen::Vector3d> normals = NearestFlipped(points, centre, 20);
    const OrientationReport r = CheckOrientation(points.positions, normals);
    std::printf("[ knot1, 1,000 samples, 20 flipped around %zu ] %s\n", centre, r.Describe().c_str());
    EXPECT_LE(r.flipped_flat_pairs * 100, r.flat_pairs) << "the 1 % bound alone would catch it";
    EXPECT_EQ(r.inward_support_directions, 0u);
    EXPECT_GE(r.flipped_patch_samples, 15u);
    EXPECT_LE(r.flipped_patch_samples, 20u);
    EXPECT_TRUE(r.Inconsistent()) << r.Describe();
  }
}

// A patch joined to the rest of its sheet elsewhere: CGAL's bull with 1,000 samples (the robustness
// benchmark's row, data/README.md) and the 80 nearest line 311 flipped. Where the patch reaches a
// thin part, its flipped normals agree with the far side's, and one neighbour pair there joins it
// to the sheet of the whole surface; its rim's opposite pairs were then read as touching parts
// (32 of 1,042 flat pairs, 3 %: no warning). They lie to one side of each end, the agreeing
// samples to the other: a seam.
TEST(CheckOrientation, APatchJoinedAcrossAThinPartIsFound) {
  const auto points = ReadPoints(DataFile("bull1000-flipped80.xyz"));
  ASSERT_TRUE(points.has_value());
  const OrientationReport r = CheckOrientation(points->positions, points->normals);
  std::printf("[ bull, 1,000 samples, 80 flipped ] %s; touching pairs %zu\n", r.Describe().c_str(), r.touching_pairs);
  EXPECT_GT(r.flipped_flat_pairs * 100, 2 * r.flat_pairs) << r.Describe();
  EXPECT_TRUE(r.Inconsistent()) << r.Describe();
  EXPECT_TRUE(r.OpenScanInconsistent()) << r.Describe();
}

// Two parts of one connected surface that touch, their normals facing across a gap far thinner
// than the spacing (CGAL's man: legs and arms within a third of a spacing; its open scan was
// blamed for 7 such pairs in 5,947). A U-shaped profile extruded along z: its slot is 0.1
// spacing wide, and the two slot walls join the rest through the rounded arm tops, one sheet.
// Their pairs are flat and opposite, a sixth of all flat pairs, and no evidence; a patch of an
// outer wall flipped still is. (One of a slot wall flipped would face the same way as the wall it
// touches, consistent with it: no test of normals alone can see it.)
TEST(CheckOrientation, TouchingPartsOfOneSurfaceAreNotFlipped) {
  constexpr double kSlot = 0.002, kArm = 0.2, kHeight = 0.6, kDepth = 0.6, kPi = 3.14159265358979323846;
  const double outer = kSlot / 2 + kArm;
  // The profile's pieces by length: 4 walls, the outer bottom arc, 2 arm tops.
  const std::array<double, 7> length = {kHeight,     kHeight,        kHeight,       kHeight,
                                        kPi * outer, kPi * kArm / 2, kPi * kArm / 2};
  double total = 0;
  for (const double l : length) total += l;
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::vector<Eigen::Vector3d> p, n;
  for (int s = 0; s < 4000; ++s) {
    double t = unit(rng) * total;
    std::size_t piece = 0;
    while (piece + 1 < length.size() && t > length[piece]) t -= length[piece++];
    const double z = unit(rng) * kDepth, u = t / length[piece];
    Eigen::Vector2d at, normal;
    switch (piece) {
      case 0:
        at = {-outer, u * kHeight}, normal = {-1, 0};
        break;  // left outer wall
      case 1:
        at = {outer, u * kHeight}, normal = {1, 0};
        break;  // right outer wall
      case 2:
        at = {-kSlot / 2, u * kHeight}, normal = {1, 0};
        break;  // slot walls, facing
      case 3:
        at = {kSlot / 2, u * kHeight}, normal = {-1, 0};
        break;
      case 4:
        normal = {std::cos(kPi + u * kPi), std::sin(kPi + u * kPi)}, at = outer * normal;
        break;
      default: {  // the arm tops, half circles
        const double side = piece == 5 ? -1.0 : 1.0;
        normal = {std::cos(u * kPi), std::sin(u * kPi)};
        at = Eigen::Vector2d(side * (kSlot + kArm) / 2, kHeight) + kArm / 2 * normal;
      }
    }
    p.push_back({at.x(), at.y(), z});
    n.push_back({normal.x(), normal.y(), 0.0});
  }
  const OrientationReport r = CheckOrientation(p, n);
  std::printf("[ U with a touching slot ] %s; touching pairs %zu\n", r.Describe().c_str(), r.touching_pairs);
  EXPECT_GT(r.touching_pairs * 100, r.flat_pairs) << "the 1 % bound would have blamed them";
  // A few pass the seam rule of APatchJoinedAcrossAThinPartIsFound (4 of 12,700): far under the bound.
  EXPECT_LE(r.flipped_flat_pairs * 1000, r.flat_pairs) << r.Describe();
  EXPECT_FALSE(r.Inconsistent()) << r.Describe();
  EXPECT_FALSE(r.OpenScanInconsistent()) << r.Describe();
  // A patch of the left outer wall flipped: 0.1 < y < 0.25, 0.2 < z < 0.35.
  for (std::size_t i = 0; i < p.size(); ++i)
    if (n[i].x() < -0.99 && p[i].y() > 0.1 && p[i].y() < 0.25 && p[i].z() > 0.2 && p[i].z() < 0.35) n[i] = -n[i];
  const OrientationReport flipped = CheckOrientation(p, n);
  std::printf("[ U, a patch of an outer wall flipped ] %s\n", flipped.Describe().c_str());
  EXPECT_TRUE(flipped.Inconsistent()) << flipped.Describe();
}

TEST(CheckOrientation, CubePwnNormalsPointInwardOnTheLowFaces) {
  const auto points = ReadPoints(DataFile("cube.pwn"));
  ASSERT_TRUE(points.has_value());
  Eigen::Vector3d lo = points->positions.front(), hi = lo;
  for (const auto& p : points->positions) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  for (int axis = 0; axis < 3; ++axis) {
    for (const int side : {-1, 1}) {
      const double plane = side < 0 ? lo[axis] : hi[axis];
      std::size_t on_face = 0, outward = 0, inward = 0;
      for (std::size_t i = 0; i < points->positions.size(); ++i) {
        if (std::abs(points->positions[i][axis] - plane) > 1e-4) continue;
        ++on_face;
        const double along = side * points->normals[i][axis];
        outward += along > 0.5 ? 1u : 0u;
        inward += along < -0.5 ? 1u : 0u;
      }
      std::printf("[ cube.pwn face %c%c ] %zu points: normals outward %zu, inward %zu\n", side < 0 ? '-' : '+',
                  "xyz"[axis], on_face, outward, inward);
      ASSERT_GT(on_face, 1000u);
      if (side < 0) {
        EXPECT_GT(inward, on_face * 98 / 100);
      } else {
        EXPECT_GT(outward, on_face * 98 / 100);
      }
    }
  }
  const OrientationReport r = CheckOrientation(points->positions, points->normals);
  std::printf("[ cube.pwn ] %s\n", r.Describe().c_str());
  EXPECT_GE(r.inward_support_directions, 7);  // at least the 7 directions with no + component
  EXPECT_TRUE(r.Inconsistent());
}

}  // namespace
}  // namespace palpa::field
