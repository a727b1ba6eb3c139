// BoxNearest (palpa/field/box_nearest.h) against brute force: the k nearest samples, their
// squared distances bit for bit, in (distance, index) order, for queries anywhere in the box
// (its surface included), with ties on a lattice and whatever the tree's leaf size.
#include "palpa/field/box_nearest.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstddef>
#include <random>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <nanoflann.hpp>

namespace {

using V3 = Eigen::Vector3d;

struct Cloud {
  const std::vector<V3>* points;
  std::size_t kdtree_get_point_count() const { return points->size(); }
  double kdtree_get_pt(std::size_t i, std::size_t d) const { return (*points)[i][static_cast<Eigen::Index>(d)]; }
  template <class B>
  bool kdtree_get_bbox(B& /*bb*/) const {
    return false;
  }
};
using Tree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<double, Cloud>, Cloud, 3, std::size_t>;

// Every sample's squared distance (the same sum as nanoflann's), sorted by (distance, index).
std::vector<std::pair<double, std::size_t>> BruteForce(const std::vector<V3>& points, const V3& p) {
  std::vector<std::pair<double, std::size_t>> all;
  for (std::size_t j = 0; j < points.size(); ++j) {
    double d = 0.0;
    for (Eigen::Index a = 0; a < 3; ++a) d += (p[a] - points[j][a]) * (p[a] - points[j][a]);
    all.emplace_back(d, j);
  }
  std::sort(all.begin(), all.end());
  return all;
}

// Queries inside the box and on its surface (the farthest a query may be), k up to k_max.
// Returns how many (query, k) pairs differed from brute force.
int Mismatches(const std::vector<V3>& points, std::size_t leaf, std::size_t k_max, double radius, int boxes,
               std::mt19937& rng, const V3& away = V3::Zero()) {
  const Cloud cloud{&points};
  const Tree tree(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(leaf));
  palpa::field::BoxNearest<Tree> box(tree, points, k_max);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  int wrong = 0;
  std::vector<std::size_t> idx(k_max);
  std::vector<double> d2(k_max);
  for (int b = 0; b < boxes; ++b) {
    const V3 centre = points[rng() % points.size()] + V3(unit(rng), unit(rng), unit(rng)) + away;
    box.Box(centre, radius);
    for (int q = 0; q < 40; ++q) {
      V3 dir(unit(rng), unit(rng), unit(rng));
      dir.normalize();
      const V3 p = centre + (q % 2 == 0 ? radius : radius * 0.5 * (1.0 + unit(rng))) * dir;
      const std::vector<std::pair<double, std::size_t>> truth = BruteForce(points, p);
      for (const std::size_t k : {std::size_t{1}, std::size_t{3}, std::size_t{8}, std::size_t{13}, k_max}) {
        const std::size_t got = box.Find(p, k, idx.data(), d2.data());
        bool same = got == std::min(k, points.size());
        for (std::size_t m = 0; same && m < got; ++m) same = idx[m] == truth[m].second && d2[m] == truth[m].first;
        wrong += same ? 0 : 1;
      }
    }
  }
  return wrong;
}

TEST(BoxNearest, FindsTheKNearestOfAnyPointInTheBox) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(0.0, 10.0);
  std::vector<V3> points(3000);
  for (V3& p : points) p = V3(u(rng), u(rng), 0.3 * u(rng));
  // Boxes from a fraction of the spacing to several spacings wide.
  for (const double radius : {0.05, 0.6, 2.5}) EXPECT_EQ(Mismatches(points, 10, 48, radius, 30, rng), 0) << radius;
  // Boxes far off the samples (the far pass's): long lists, scanned a block at a time.
  for (const double radius : {0.6, 2.5})
    EXPECT_EQ(Mismatches(points, 10, 48, radius, 10, rng, V3(0.0, 0.0, 12.0)), 0) << radius;
}

TEST(BoxNearest, BreaksTiesByIndexWhateverTheTree) {
  // A lattice: queries at lattice points and cell centres have many samples at equal distance;
  // the answer must not depend on the leaf size (the order the tree visits them in).
  std::vector<V3> points;
  for (int i = 0; i < 12; ++i)
    for (int j = 0; j < 12; ++j)
      for (int k = 0; k < 12; ++k) points.emplace_back(i, j, k);
  std::shuffle(points.begin(), points.end(), std::mt19937(3));
  for (const std::size_t leaf : {std::size_t{1}, std::size_t{10}, std::size_t{24}}) {
    const Cloud cloud{&points};
    const Tree tree(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(leaf));
    palpa::field::BoxNearest<Tree> box(tree, points, 32);
    box.Box(V3(5.5, 5.5, 5.5), 1.0);
    std::vector<std::size_t> idx(32);
    std::vector<double> d2(32);
    for (const V3& p : {V3(5.5, 5.5, 5.5), V3(5, 5, 5), V3(6, 5, 6), V3(5.5, 5, 6)}) {
      const auto truth = BruteForce(points, p);
      for (const std::size_t k : {std::size_t{6}, std::size_t{7}, std::size_t{19}, std::size_t{32}}) {
        ASSERT_EQ(box.Find(p, k, idx.data(), d2.data()), k);
        for (std::size_t m = 0; m < k; ++m) {
          EXPECT_EQ(idx[m], truth[m].second) << "leaf " << leaf << " k " << k << " rank " << m;
          EXPECT_EQ(d2[m], truth[m].first);
        }
      }
    }
  }
}

TEST(BoxNearest, ReturnsAllSamplesWhenThereAreFewerThanK) {
  const std::vector<V3> points = {V3(0, 0, 0), V3(3, 0, 0), V3(1, 0, 0), V3(0, 2, 0), V3(1, 0, 0)};
  const Cloud cloud{&points};
  const Tree tree(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(10));
  palpa::field::BoxNearest<Tree> box(tree, points, 48);
  box.Box(V3(0.5, 0, 0), 0.5);
  std::vector<std::size_t> idx(48);
  std::vector<double> d2(48);
  ASSERT_EQ(box.Find(V3(0.5, 0, 0), 48, idx.data(), d2.data()), 5u);
  // Distances 0.25 (samples 0, 2, 4: tie by index), 4.25, 6.25.
  EXPECT_EQ(std::vector<std::size_t>(idx.begin(), idx.begin() + 5), (std::vector<std::size_t>{0, 2, 4, 3, 1}));
  EXPECT_EQ(std::vector<double>(d2.begin(), d2.begin() + 5), (std::vector<double>{0.25, 0.25, 0.25, 4.25, 6.25}));
}

}  // namespace
