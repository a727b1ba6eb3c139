// Polygon faces of OFF files, triangulated with CGAL's hole filling (slow to compile): its own
// translation unit, declared in triangle_mesh_internal.h.
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_mesh_processing/triangulate_hole.h>

#include <cstddef>
#include <iterator>
#include <vector>

#include "triangle_mesh_internal.h"

namespace palpa::mesh::internal {

bool TriangulatePolygon(const std::vector<Eigen::Vector3d>& corners, std::vector<std::array<int, 3>>& triangles) {
  using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
  struct Triple {
    Triple(int a, int b, int c) : first(a), second(b), third(c) {}
    int first, second, third;
  };
  std::vector<Kernel::Point_3> points;
  points.reserve(corners.size());
  for (const auto& c : corners) points.emplace_back(c.x(), c.y(), c.z());
  std::vector<Triple> out;
  // A planar polygon gets a constrained Delaunay triangulation in its plane (exact for any simple
  // polygon, convex or not); a non-planar one the minimum-dihedral, minimum-area triangulation of
  // its boundary (Liepa 2003).
  CGAL::Polygon_mesh_processing::triangulate_hole_polyline(
      points, std::back_inserter(out), CGAL::parameters::use_2d_constrained_delaunay_triangulation(true));
  triangles.clear();
  if (out.size() + 2 != corners.size()) return false;
  // The hole filler's winding is the reverse of a hole's border; orient by the polygon's own area
  // vector (Newell), so that the triangles keep the file's winding.
  Eigen::Vector3d polygon_area = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; i < corners.size(); ++i) polygon_area += corners[i].cross(corners[(i + 1) % corners.size()]);
  Eigen::Vector3d area = Eigen::Vector3d::Zero();
  for (const Triple& t : out) {
    const auto& a = corners[static_cast<std::size_t>(t.first)];
    area += (corners[static_cast<std::size_t>(t.second)] - a).cross(corners[static_cast<std::size_t>(t.third)] - a);
  }
  const bool flip = area.dot(polygon_area) < 0;
  for (const Triple& t : out) {
    const std::array<int, 3> tri =
        flip ? std::array<int, 3>{t.first, t.third, t.second} : std::array<int, 3>{t.first, t.second, t.third};
    // Every triangle of a simple polygon faces the polygon's way; one facing back means the polygon
    // crosses itself (a pentagram: the hole filler still returns n − 2 triangles, folded).
    const auto& a = corners[static_cast<std::size_t>(tri[0])];
    const Eigen::Vector3d n =
        (corners[static_cast<std::size_t>(tri[1])] - a).cross(corners[static_cast<std::size_t>(tri[2])] - a);
    if (!(n.dot(polygon_area) > 0)) {
      triangles.clear();
      return false;
    }
    triangles.push_back(tri);
  }
  return true;
}

}  // namespace palpa::mesh::internal
