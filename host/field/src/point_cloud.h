// nanoflann's dataset adaptor over a vector of Eigen points, and the 3-D k-d tree over it: the
// neighbour searches of packing (paper §3.1), the Hermite field and the orientation check.
// The cloud only points at the vector, which must outlive the tree. No bounding box is offered
// (nanoflann computes it).
#pragma once

#include <Eigen/Core>
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

}  // namespace palpa::field::detail
