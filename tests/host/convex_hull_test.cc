// ConvexHull (palpa/field/convex_hull.h) against the scan over every face: Distance bit for bit and
// Beyond at limits set exactly at, just under and around the scan's value, on polytopes of 40 to
// 40,000 faces (an ellipsoid's support planes), at points inside, outside and on the faces, and
// with the bounds taken about a centre inside or outside.
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

TEST(ConvexHull, NoFacesHaveNoInside) {
  const ConvexHull none;
  EXPECT_TRUE(none.empty());
  EXPECT_EQ(none.Distance(V3(1.0, 2.0, 3.0)), -std::numeric_limits<double>::infinity());
  EXPECT_FALSE(none.Beyond(V3(1.0, 2.0, 3.0), -1e300));
}

}  // namespace
