// nanoflann's dataset adaptor over a vector of Eigen points, and the 3-D k-d tree over it: the
// neighbour searches of packing (paper §3.1), the Hermite field and the orientation check.
// The cloud only points at the vector, which must outlive the tree. No bounding box is offered
// (nanoflann computes it).
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <cstddef>
#include <vector>

#include <nanoflann.hpp>

namespace palpa::field::detail {

struct PointCloud {
  const std::vector<Eigen::Vector3d>* points;
  std::size_t kdtree_get_point_count() const { return points->size(); }
  double kdtree_get_pt(std::size_t idx, std::size_t dim) const {
    return (*points)[idx][static_cast<Eigen::Index>(dim)];
  }
  template <class BBox>
  bool kdtree_get_bbox(BBox& /*bb*/) const {
    return false;
  }
};

using KdTree =
    nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<double, PointCloud>, PointCloud, 3, std::size_t>;

// Leaf size for searches whose result does not depend on the order the tree visits samples in
// (a minimum, a list sorted afterwards, whether any sample lies within a radius, the nearest
// distance): the packing's and the guard's wide balls visit fewer nodes than with leaves of 10
// (kitten, 300 cells, one thread: 69 -> 59 ms and 71 -> 65 ms). The k-nearest searches keep 10:
// a tie at the kth distance goes to the sample visited first, so their results follow the tree.
inline constexpr std::size_t kRangeLeaf = 24;

// The median of `values` (the upper one of an even count), 0 when there are none: the one scale
// of a sample set (spacing, noise) that a few outliers cannot move.
inline double Median(std::vector<double> values) {
  if (values.empty()) return 0.0;
  const auto mid = values.begin() + static_cast<std::ptrdiff_t>(values.size() / 2);
  std::nth_element(values.begin(), mid, values.end());
  return *mid;
}

}  // namespace palpa::field::detail
