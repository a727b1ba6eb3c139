// The samples' convex hull (CGAL's convex_hull_3), alone in this file for the same reason as
// normals_cgal.cc: CGAL is slow to compile and brings its own flags.
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/convex_hull_3.h>

#include <Eigen/Geometry>
#include <array>
#include <utility>
#include <vector>

#include "palpa/field/convex_hull.h"
#include "point_cloud.h"

namespace palpa::field::detail {

ConvexHull ConvexHullOf(const std::vector<Eigen::Vector3d>& points) {
  using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
  using Point = Kernel::Point_3;
  if (points.size() < 4) return {};
  std::vector<Point> in;
  in.reserve(points.size());
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  Eigen::AlignedBox3d box;
  for (const Eigen::Vector3d& p : points) {
    in.emplace_back(p.x(), p.y(), p.z());
    centroid += p;
    box.extend(p);
  }
  centroid /= static_cast<double>(points.size());
  // A flat or degenerate set has no inside: the centroid must lie behind every face by more than
  // rounding (CGAL gives a flat set's polygon as faces through it).
  const double margin = 1e-9 * box.diagonal().norm();
  CGAL::Surface_mesh<Point> hull;
  CGAL::convex_hull_3(in.begin(), in.end(), hull);
  std::vector<Eigen::Vector4d> planes;
  planes.reserve(hull.number_of_faces());
  for (const auto f : hull.faces()) {
    std::array<Eigen::Vector3d, 3> v;
    std::size_t m = 0;
    for (const auto vd : hull.vertices_around_face(hull.halfedge(f))) {
      if (m == 3) break;
      const Point& q = hull.point(vd);
      v[m++] = Eigen::Vector3d(q.x(), q.y(), q.z());
    }
    if (m < 3) continue;
    Eigen::Vector3d n = (v[1] - v[0]).cross(v[2] - v[0]);
    const double len = n.norm();
    if (!(len > 0.0)) continue;
    n /= len;
    const double d = -n.dot(v[0]);
    if (!(n.dot(centroid) + d < -margin)) return {};
    planes.emplace_back(n.x(), n.y(), n.z(), d);
  }
  return ConvexHull(std::move(planes), centroid);
}

}  // namespace palpa::field::detail
