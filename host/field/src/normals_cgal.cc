// CGAL's jet fit, alone in this file: CGAL is slow to compile and brings its own flags.
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/jet_estimate_normals.h>
#include <CGAL/property_map.h>

#include <utility>
#include <vector>

#include "point_cloud.h"

namespace palpa::field::detail {

void JetNormalLines(const std::vector<Eigen::Vector3d>& positions, int neighbours,
                    std::vector<Eigen::Vector3d>& normals) {
  using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
  using PointWithNormal = std::pair<Kernel::Point_3, Kernel::Vector_3>;
  normals.assign(positions.size(), Eigen::Vector3d::UnitZ());
  if (positions.size() < 4) return;
  std::vector<PointWithNormal> points;
  points.reserve(positions.size());
  for (const Eigen::Vector3d& p : positions)
    points.emplace_back(Kernel::Point_3(p.x(), p.y(), p.z()), Kernel::Vector_3());
  const auto k =
      static_cast<unsigned>(std::min<std::size_t>(static_cast<std::size_t>(neighbours), positions.size() - 1));
  CGAL::jet_estimate_normals<CGAL::Parallel_if_available_tag>(
      points, k,
      CGAL::parameters::point_map(CGAL::First_of_pair_property_map<PointWithNormal>())
          .normal_map(CGAL::Second_of_pair_property_map<PointWithNormal>()));
  // CGAL keeps the range's order.
  for (std::size_t i = 0; i < points.size(); ++i) {
    const Kernel::Vector_3& v = points[i].second;
    const Eigen::Vector3d n(v.x(), v.y(), v.z());
    const double length = n.norm();
    normals[i] = length > 0 && std::isfinite(length) ? Eigen::Vector3d(n / length) : Eigen::Vector3d::UnitZ();
  }
}

}  // namespace palpa::field::detail
