// The generalized winding number of oriented points (issue 20, palpa/field/winding.h): against
// the analytic sphere (w = 1 inside, 0 outside) and the tree against the brute-force sum.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <numbers>
#include <random>
#include <vector>

#include "palpa/field/point_io.h"
#include "palpa/field/winding.h"
#include "test_util.h"

namespace palpa::field {
namespace {

using V3 = Eigen::Vector3d;

// n points on the sphere of radius r (Fibonacci lattice: near-uniform), outward normals.
void FibonacciSphere(std::size_t n, double r, std::vector<V3>& p, std::vector<V3>& nrm) {
  for (std::size_t i = 0; i < n; ++i) {
    const V3 u = testing::FibonacciPoint(i, n);
    p.push_back(r * u);
    nrm.push_back(u);
  }
}

TEST(SampleAreas, SumToTheSphereArea) {
  std::vector<V3> p, n;
  FibonacciSphere(4000, 2.0, p, n);
  const std::vector<double> a = SampleAreas(p, 16);
  double total = 0;
  for (const double x : a) total += x;
  EXPECT_NEAR(total, 4 * std::numbers::pi * 4.0, 0.05 * 4 * std::numbers::pi * 4.0);
}

// w rises by 1 across a closed surface: each sample's jump is 1 within the area estimate's bias
// (Fibonacci lattice: 3 %) and its neighbours' point dipoles' ripple at the probes (0.105 here). A sample whose normal
// is flipped has all its neighbours facing the other way, so its probes stay within 0.4 of the nearest's distance,
// where the others' dipoles cancel: its jump is near 0 (FindWindingOutliers' threshold is 0.5).
TEST(SampleProbes, JumpsOneAcrossASphereAndNearZeroAtAFlippedNormal) {
  std::vector<V3> p, n;
  FibonacciSphere(3000, 2.0, p, n);
  const SampleProbes probes(p, n);
  EXPECT_EQ(probes.areas(), SampleAreas(p, 16));  // the same k-nearest distances
  const std::vector<double> jump = probes.Jumps(n);
  ASSERT_EQ(jump.size(), p.size());
  double worst = 0;
  for (const double j : jump) worst = std::max(worst, std::abs(j - 1.0));
  EXPECT_LT(worst, 0.15);
  std::vector<double> sorted = jump;
  const auto mid = static_cast<std::ptrdiff_t>(sorted.size() / 2);
  std::nth_element(sorted.begin(), sorted.begin() + mid, sorted.end());
  EXPECT_NEAR(sorted[sorted.size() / 2], 1.0, 0.06);  // 0.950: the point dipoles read low between them
  n[100] = -n[100];
  EXPECT_LT(std::abs(SampleProbes(p, n).Jumps(n)[100]), 0.25);
  // Too few samples for the 16 neighbours: all 1 (nothing measured).
  const std::vector<V3> few(p.begin(), p.begin() + 10), few_n(n.begin(), n.begin() + 10);
  for (const double j : SampleProbes(few, few_n).Jumps(few_n)) EXPECT_EQ(j, 1.0);
}

TEST(SampleProbes, EitherSignWallsKeepProbesOnTheirSideOfAWallWhoseSidesTookOneSign) {
  // Two faces of a plate 1.75 spacings thick (samples 0.08 apart, faces at z = -+0.07), both
  // given +z (the bottom one wrong, as an orientation across the wall leaves it). The 16th
  // neighbour lies 0.18 away, so a probe at half of it (0.09) passes the wall's middle (0.07) into
  // the other side's field; counting the other side as a wall whatever its sign keeps it within
  // 0.4 x 0.14. With the signs right both rules agree (the other side is opposite already).
  std::vector<V3> p, wrong, right;
  for (int a = 0; a < 30; ++a)
    for (int b = 0; b < 30; ++b)
      for (const double side : {-1.0, 1.0}) {
        p.emplace_back(0.08 * a, 0.08 * b, 0.07 * side);
        wrong.emplace_back(0, 0, 1);
        right.emplace_back(0, 0, side);
      }
  const std::vector<double> opposite = SampleProbes(p, wrong).offsets();
  const std::vector<double> either = SampleProbes(p, wrong, SampleProbes::Walls::kEitherSign).offsets();
  const std::vector<double> opposite_right = SampleProbes(p, right).offsets();
  const std::vector<double> either_right = SampleProbes(p, right, SampleProbes::Walls::kEitherSign).offsets();
  ASSERT_EQ(either.size(), p.size());
  for (std::size_t i = 0; i < p.size(); ++i) {
    EXPECT_GT(opposite[i], 0.075) << i;
    EXPECT_GT(either[i], 0.0) << i;
    EXPECT_LE(either[i], 0.4 * 0.14 + 1e-12) << i;
    EXPECT_EQ(either_right[i], opposite_right[i]) << i;
    EXPECT_LE(opposite_right[i], 0.4 * 0.14 + 1e-12) << i;
  }
}

// The analytic answer: 1 strictly inside a closed surface, 0 outside. Sampled, w deviates near the
// samples (each is a singular dipole) and by the area estimate's bias; a few spacings away it is
// within 0.1 of the answer, and the tree matches the brute-force sum to 0.05.
TEST(WindingNumber, SphereIsOneInsideZeroOutsideAndTheTreeMatchesBruteForce) {
  std::vector<V3> p, n;
  FibonacciSphere(3000, 1.0, p, n);
  const std::vector<double> a = SampleAreas(p, 16);
  const WindingNumber w(p, n, a);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  int checked = 0;
  for (int t = 0; t < 2000; ++t) {
    const V3 q = 3.0 * V3(u(rng), u(rng), u(rng));
    const double d = q.norm() - 1.0;
    if (std::abs(d) < 0.15) continue;  // ~3 spacings (spacing ~ 0.065)
    const double brute = WindingNumberBruteForce(p, n, a, q);
    const double fast = w(q);
    ASSERT_NEAR(fast, brute, 0.05) << q.transpose();
    ASSERT_NEAR(brute, d < 0 ? 1.0 : 0.0, 0.1) << q.transpose();
    ++checked;
  }
  EXPECT_GT(checked, 1500);
  EXPECT_NEAR(w(V3::Zero()), 1.0, 0.05);
  EXPECT_NEAR(w(V3(10, 0, 0)), 0.0, 0.01);
}

// An open hemisphere (the cap z > 0 of the unit sphere, outward normals): w jumps by 1 across the
// cap and is 1/2 on the disc that closes it (by symmetry, the cap and the missing cap subtend
// equal solid angles from there): inside the half ball w > 1/2, below it w < 1/2.
TEST(WindingNumber, OpenHemisphereIsClosedByItsDisc) {
  std::vector<V3> p, n, cap_p, cap_n;
  FibonacciSphere(6000, 1.0, p, n);
  for (std::size_t i = 0; i < p.size(); ++i)
    if (p[i].z() > 0) cap_p.push_back(p[i]), cap_n.push_back(n[i]);
  const WindingNumber w(cap_p, cap_n, SampleAreas(cap_p, 16));
  EXPECT_GT(w(V3(0, 0, 0.3)), 0.6);
  EXPECT_GT(w(V3(0.4, 0.2, 0.5)), 0.6);
  EXPECT_LT(w(V3(0, 0, -0.5)), 0.4);
  EXPECT_LT(w(V3(0, 0, 1.5)), 0.1);
  EXPECT_NEAR(w(V3(0.3, 0, 0)), 0.5, 0.05);
  EXPECT_NEAR(w(V3(0, 0, 0)), 0.5, 0.05);
}

// A real scan (the bundled kitten): w is ~1 at the centroid of its inside and ~0 far away, and
// the tree agrees with the brute force on a grid of queries.
TEST(WindingNumber, KittenTreeMatchesBruteForce) {
  const auto pts = ReadPoints(testing::DataFile("kitten.xyz"));
  ASSERT_TRUE(pts) << pts.error().message;
  const std::vector<double> a = SampleAreas(pts->positions, 16);
  const WindingNumber w(pts->positions, pts->normals, a);
  V3 lo = pts->positions[0], hi = lo;
  for (const V3& x : pts->positions) lo = lo.cwiseMin(x), hi = hi.cwiseMax(x);
  // Queries on a 9^3 lattice over the bounding box, at least 3 typical spacings from every sample
  // (where the build asks: beyond the evaluated band).
  double mean_area = 0;
  for (const double x : a) mean_area += x / static_cast<double>(a.size());
  const double spacing = std::sqrt(mean_area);
  double worst = 0;
  int checked = 0;
  for (int i = 0; i <= 8; ++i)
    for (int j = 0; j <= 8; ++j)
      for (int k = 0; k <= 8; ++k) {
        const V3 q = lo + (hi - lo).cwiseProduct(V3(i, j, k) / 8.0);
        double nearest = 1e300;
        for (const V3& x : pts->positions) nearest = std::min(nearest, (x - q).norm());
        if (nearest < 3 * spacing) continue;
        worst = std::max(worst, std::abs(w(q) - WindingNumberBruteForce(pts->positions, pts->normals, a, q)));
        ++checked;
      }
  EXPECT_GT(checked, 300);
  EXPECT_LT(worst, 0.05);
  EXPECT_NEAR(w(lo - (hi - lo)), 0.0, 0.01);
}

// The batch evaluation (one walk of the tree for a set of queries, two or four far-field terms at
// a time) gives each query the single evaluation's value to the bit: the build's labels depend on it.
// Queries in clusters (a brick's nodes, as the build asks), on the samples themselves (the
// dipole's 0) and scattered over and beyond the bounding box; odd and even set sizes.
TEST(WindingNumber, BatchIsTheSingleEvaluationBitForBit) {
  const auto pts = ReadPoints(testing::DataFile("kitten.xyz"));
  ASSERT_TRUE(pts) << pts.error().message;
  const WindingNumber w(pts->positions, pts->normals, SampleAreas(pts->positions, 16));
  V3 lo = pts->positions[0], hi = lo;
  for (const V3& x : pts->positions) lo = lo.cwiseMin(x), hi = hi.cwiseMax(x);
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> unit(-0.2, 1.2);
  std::size_t compared = 0;
  for (int set = 0; set < 60; ++set) {
    std::vector<V3> q;
    const V3 centre = lo + (hi - lo).cwiseProduct(V3(unit(rng), unit(rng), unit(rng)));
    const double reach = (hi - lo).norm() * (set % 3 == 0 ? 0.5 : 0.02);
    const std::size_t count = 1 + static_cast<std::size_t>(set) * 17 % 301;
    for (std::size_t i = 0; i < count; ++i)
      q.push_back(centre + reach * V3(unit(rng) - 0.5, unit(rng) - 0.5, unit(rng) - 0.5));
    if (set % 4 == 1) q.push_back(pts->positions[static_cast<std::size_t>(set) * 83 % pts->positions.size()]);
    std::vector<double> batch(q.size()), two(q.size());
    w(q, batch);              // four lanes where the CPU has AVX2
    w.BatchTwoLanes(q, two);  // the portable path
    for (std::size_t i = 0; i < q.size(); ++i) {
      const double single = w(q[i]);
      ASSERT_EQ(std::memcmp(&single, &batch[i], sizeof(double)), 0)
          << "set " << set << " query " << i << ": " << single << " vs " << batch[i];
      ASSERT_EQ(std::memcmp(&single, &two[i], sizeof(double)), 0)
          << "set " << set << " query " << i << ": " << single << " vs " << two[i] << " (two lanes)";
      ++compared;
    }
  }
  EXPECT_GT(compared, 8000U);
  std::vector<double> none;
  w(std::span<const V3>(), none);
}

}  // namespace
}  // namespace palpa::field
