// ConvexHull (palpa/field/convex_hull.h) against the scan over every face: Distance bit for bit and
// Beyond at limits set exactly at, just under and around the scan's value, on polytopes of 40 to
// 40,000 faces (an ellipsoid's support planes), at points inside, outside and on the faces, and
// with the bounds taken about a centre inside or outside; a ball's side never contradicting Beyond.
#include "palpa/field/convex_hull.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstddef>
#include <limits>
#include <random>
#include <vector>

#include <Eigen/Core>

namespace {

using V3 = Eigen::Vector3d;
using V4 = Eigen::Vector4d;
using palpa::field::ConvexHull;

// n . p + d = 0 touching the ellipsoid of semi-axes `axes` (n unit, d = -h(n), its support).
std::vector<V4> EllipsoidPlanes(std::size_t count, const V3& axes, std::mt19937& rng) {
  std::normal_distribution<double> normal(0.0, 1.0);
  std::vector<V4> planes;
  for (std::size_t f = 0; f < count; ++f) {
    const V3 n = V3(normal(rng), normal(rng), normal(rng)).normalized();
    planes.emplace_back(n.x(), n.y(), n.z(), -n.cwiseProduct(axes).norm());
  }
  return planes;
}

double Scan(const std::vector<V4>& planes, const V3& p) {
  double best = -std::numeric_limits<double>::infinity();
  for (const V4& f : planes) best = std::max(best, f.head<3>().dot(p) + f[3]);
  return best;
}

TEST(ConvexHull, DistanceAndBeyondAreTheScans) {
  std::mt19937 rng(11);
  const V3 axes(0.05, 0.03, 0.012);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  std::normal_distribution<double> normal(0.0, 1.0);
  for (const std::size_t faces : {40u, 700u, 40000u}) {
    const std::vector<V4> planes = EllipsoidPlanes(faces, axes, rng);
    for (const V3& centre : {V3(0.001, -0.002, 0.0), V3(0.2, 0.1, -0.05)}) {
      const ConvexHull hull(planes, centre);
      ASSERT_EQ(hull.size(), faces);
      std::size_t outside = 0;
      for (int q = 0; q < 3000; ++q) {
        // Anywhere in a box twice the ellipsoid's, or on its surface, pushed off by up to 1 %.
        const V3 p = q % 2 == 0 ? V3(2.0 * unit(rng) * axes.x(), 2.0 * unit(rng) * axes.y(), 2.0 * unit(rng) * axes.z())
                                : V3(V3(normal(rng), normal(rng), normal(rng)).normalized().cwiseProduct(axes) *
                                     (1.0 + 0.01 * unit(rng)));
        const double truth = Scan(planes, p);
        ASSERT_EQ(hull.Distance(p), truth) << faces << " faces, query " << q;
        outside += truth > 0.0 ? 1u : 0u;
        EXPECT_FALSE(hull.Beyond(p, truth)) << faces << " faces, query " << q;
        EXPECT_TRUE(hull.Beyond(p, std::nextafter(truth, -1.0))) << faces << " faces, query " << q;
        for (const double limit : {0.0, 0.002, -0.004, truth + 1e-4, truth - 1e-4})
          EXPECT_EQ(hull.Beyond(p, limit), truth > limit) << faces << " faces, query " << q << ", limit " << limit;
      }
      EXPECT_GT(outside, 1000u);  // both sides of the faces are asked
      EXPECT_LT(outside, 2500u);
    }
  }
}

// Ball: a ball said within (beyond) has no point beyond (within) it, its farthest point towards the
// nearest face included; at the exact edge (limit = Distance(centre) + radius) it is not decided.
TEST(ConvexHull, BallSidesNeverContradictBeyond) {
  std::mt19937 rng(5);
  const V3 axes(0.05, 0.03, 0.012);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  std::normal_distribution<double> normal(0.0, 1.0);
  const std::vector<V4> planes = EllipsoidPlanes(4000, axes, rng);
  const ConvexHull hull(planes, V3::Zero());
  std::size_t within = 0, beyond = 0, across = 0;
  for (int q = 0; q < 400; ++q) {
    const V3 centre(2.0 * unit(rng) * axes.x(), 2.0 * unit(rng) * axes.y(), 2.0 * unit(rng) * axes.z());
    const double radius = 0.01 * (1.0 + unit(rng));
    const double d = Scan(planes, centre);
    // The face that sets Distance(centre): the ball's point farthest out along it.
    std::size_t top = 0;
    for (std::size_t f = 0; f < planes.size(); ++f)
      if (planes[f].head<3>().dot(centre) + planes[f][3] == d) top = f;
    std::vector<V3> points{centre + radius * planes[top].head<3>(), centre - radius * planes[top].head<3>()};
    for (int m = 0; m < 40; ++m)
      points.push_back(centre + radius * std::cbrt(0.5 * (1.0 + unit(rng))) *
                                    V3(normal(rng), normal(rng), normal(rng)).normalized());
    for (const double limit : {d + radius, d - radius, d + radius + 1e-4, d - radius - 1e-4, d, 0.0, 0.004}) {
      const ConvexHull::BallSide ball = hull.Ball(centre, radius, limit);
      ASSERT_EQ(ball.distance, d);
      within += ball.side == ConvexHull::Side::kWithin ? 1u : 0u;
      beyond += ball.side == ConvexHull::Side::kBeyond ? 1u : 0u;
      across += ball.side == ConvexHull::Side::kAcross ? 1u : 0u;
      const auto expected = limit == d + radius || limit == d - radius ? ConvexHull::Side::kAcross
                            : limit == d + radius + 1e-4               ? ConvexHull::Side::kWithin
                            : limit == d - radius - 1e-4               ? ConvexHull::Side::kBeyond
                                                                       : ball.side;
      EXPECT_EQ(ball.side, expected) << q << ", limit " << limit;
      for (const V3& p : points) {
        if (ball.side != ConvexHull::Side::kAcross) {
          EXPECT_EQ(hull.Beyond(p, limit), ball.side == ConvexHull::Side::kBeyond) << q << ", limit " << limit;
        }
      }
    }
  }
  EXPECT_GT(within, 400u);
  EXPECT_GT(beyond, 400u);
  EXPECT_GT(across, 800u);
  // A point (radius 0) is decided exactly, as Beyond decides it, at its own distance too.
  EXPECT_EQ(hull.Ball(V3::Zero(), 0.0, 0.0).side, ConvexHull::Side::kWithin);
  EXPECT_EQ(hull.Ball(V3(1.0, 0.0, 0.0), 0.0, 0.0).side, ConvexHull::Side::kBeyond);
  const V3 on(0.05, 0.0, 0.0);
  const double at = Scan(planes, on);
  EXPECT_EQ(hull.Ball(on, 0.0, at).side, ConvexHull::Side::kWithin);
  EXPECT_EQ(hull.Ball(on, 0.0, std::nextafter(at, -1.0)).side, ConvexHull::Side::kBeyond);
  EXPECT_EQ(ConvexHull().Ball(V3(1.0, 2.0, 3.0), 5.0, -1e300).side, ConvexHull::Side::kWithin);
}

TEST(ConvexHull, NoFacesHaveNoInside) {
  const ConvexHull none;
  EXPECT_TRUE(none.empty());
  EXPECT_EQ(none.Distance(V3(1.0, 2.0, 3.0)), -std::numeric_limits<double>::infinity());
  EXPECT_FALSE(none.Beyond(V3(1.0, 2.0, 3.0), -1e300));
}

}  // namespace
