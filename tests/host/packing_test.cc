#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "palpa/field/packing.h"
#include "palpa/field/point_io.h"
#include "test_util.h"

namespace palpa::field {
namespace {

using testing::DataFile;

struct Oriented {
  std::vector<Eigen::Vector3d> positions;
  std::vector<Eigen::Vector3d> normals;
};

double LongestSide(const std::vector<Eigen::Vector3d>& points) {
  Eigen::Vector3d lo = points.front();
  Eigen::Vector3d hi = lo;
  for (const auto& p : points) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  return (hi - lo).maxCoeff();
}

Eigen::Vector3d RandomUnit(std::mt19937_64& rng) {
  std::normal_distribution<double> g(0.0, 1.0);
  Eigen::Vector3d v;
  do {
    v = Eigen::Vector3d(g(rng), g(rng), g(rng));
  } while (v.norm() < 1e-6);
  return v.normalized();
}

// A noisy closed surface: ellipsoid (semi-axes 3, 2, 1.2) with 2% radial bumps and normals that
// are the ellipsoid's gradient tilted by up to a few degrees; plus a few exact duplicates.
Oriented NoisyEllipsoid(std::size_t n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const Eigen::Vector3d axes(3.0, 2.0, 1.2);
  Oriented out;
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d dir = RandomUnit(rng);
    const Eigen::Vector3d p = axes.cwiseProduct(dir) * (1.0 + 0.02 * u(rng));
    const Eigen::Vector3d grad = p.cwiseQuotient(axes.cwiseProduct(axes)).normalized();
    out.positions.push_back(p);
    out.normals.push_back((grad + 0.05 * RandomUnit(rng)).normalized());
  }
  for (std::size_t i = 0; i < 20; ++i) {  // duplicates must be skipped, not give r = 0
    out.positions.push_back(out.positions[i * 7]);
    out.normals.push_back(out.normals[i * 7]);
  }
  return out;
}

Oriented UniformRandom(std::size_t n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Oriented out;
  for (std::size_t i = 0; i < n; ++i) {
    out.positions.emplace_back(u(rng), u(rng), u(rng));
    out.normals.push_back(RandomUnit(rng));
  }
  return out;
}

void ExpectTreeEqualsBruteForce(const Oriented& data, double r_max) {
  const std::vector<double> brute = PackingRadiiBruteForce(data.positions, data.normals, r_max);
  const std::vector<double> tree = PackingRadii(data.positions, data.normals, r_max);
  ASSERT_EQ(brute.size(), data.positions.size());
  ASSERT_EQ(tree.size(), brute.size());
  std::size_t mismatches = 0;
  std::size_t capped = 0;
  for (std::size_t i = 0; i < brute.size(); ++i) {
    if (tree[i] != brute[i]) ++mismatches;  // the same formula on the same pairs: bit-identical
    if (brute[i] == r_max) ++capped;
    ASSERT_GT(brute[i], 0.0) << i;
  }
  EXPECT_EQ(mismatches, 0u);
  std::printf("[ packing ] %zu points, %zu capped at r_max, %zu mismatches\n", brute.size(), capped, mismatches);
}

TEST(PackingRadii, EqualsBruteForceOnNoisyEllipsoid) {
  const Oriented data = NoisyEllipsoid(2000, 17);
  ExpectTreeEqualsBruteForce(data, LongestSide(data.positions));
}

TEST(PackingRadii, EqualsBruteForceOnUniformRandomPoints) {
  const Oriented data = UniformRandom(2000, 29);
  ExpectTreeEqualsBruteForce(data, LongestSide(data.positions));
  // Unbounded r_max exercises the no-bound fallback.
  ExpectTreeEqualsBruteForce(data, std::numeric_limits<double>::infinity());
}

TEST(PackingRadii, ExactSphereGivesSphereRadiusAndCentre) {
  // On a sphere every other point gives r_ij = R exactly (eq. 2: |a|^2 = 2R^2(1 - cos),
  // -n.a = R(1 - cos)), so every packed ball is the sphere itself.
  const Eigen::Vector3d centre(1.0, -2.0, 0.5);
  const double radius = 3.0;
  std::mt19937_64 rng(5);
  Oriented data;
  for (int i = 0; i < 600; ++i) {
    const Eigen::Vector3d u = RandomUnit(rng);
    data.positions.push_back(centre + radius * u);
    data.normals.push_back(u);
  }
  const double r_max = LongestSide(data.positions);
  ASSERT_GT(r_max, radius * 1.5);
  const std::vector<double> brute = PackingRadiiBruteForce(data.positions, data.normals, r_max);
  const Packing packing = PackSpheres(data.positions, data.normals, r_max);
  ASSERT_EQ(packing.radii.size(), data.positions.size());
  ASSERT_EQ(packing.centres.size(), data.positions.size());
  for (std::size_t i = 0; i < brute.size(); ++i) {
    ASSERT_NEAR(brute[i], radius, 1e-9 * radius) << i;
    ASSERT_NEAR(packing.radii[i], radius, 1e-9 * radius) << i;
    ASSERT_LT((packing.centres[i] - centre).norm(), 1e-9 * radius) << i;
  }
}

TEST(PackingRadii, Sphere926BruteForceSpan) {
  const auto points = ReadPoints(DataFile("sphere926.pwn"));
  ASSERT_TRUE(points.has_value()) << points.error().message;
  const double r_max = LongestSide(points->positions);
  std::vector<double> radii = PackingRadiiBruteForce(points->positions, points->normals, r_max);
  EXPECT_EQ(PackingRadii(points->positions, points->normals, r_max), radii);
  std::sort(radii.begin(), radii.end());
  const double median = radii[radii.size() / 2];
  std::printf("[ sphere926 ] packing radii: min %.4f  median %.4f  max %.6f  (r_max %.4f)\n", radii.front(), median,
              radii.back(), r_max);
  EXPECT_GE(radii.front(), 7.0);
  EXPECT_LE(radii.front(), 7.3);
  EXPECT_LE(radii.back(), 10.0 + 1e-9);
  EXPECT_GE(radii.back(), 9.9);
  EXPECT_GE(median, 8.2);
  EXPECT_LE(median, 8.45);
}

TEST(PackingRadii, MismatchedSizesGiveEmpty) {
  const std::vector<Eigen::Vector3d> p(5, Eigen::Vector3d::Zero());
  const std::vector<Eigen::Vector3d> n(4, Eigen::Vector3d::UnitX());
  EXPECT_TRUE(PackingRadii(p, n, 1.0).empty());
  EXPECT_TRUE(PackingRadiiBruteForce(p, n, 1.0).empty());
}

}  // namespace
}  // namespace palpa::field
