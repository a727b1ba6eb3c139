// Between triangle_mesh.cc and the CGAL translation unit that triangulates polygon faces.
#pragma once

#include <array>
#include <vector>

#include <Eigen/Core>

namespace palpa::mesh::internal {

/// Triangulates one polygon face (n ≥ 4 corners, in the file's order) into n − 2 triangles of
/// indices into `corners`, wound as the corners are. CGAL's triangulate_hole_polyline: a
/// constrained Delaunay triangulation in the fitting plane, else the minimum-dihedral one.
/// False when CGAL finds no such triangulation, or only one with a triangle facing against the
/// polygon's area vector (a polygon that crosses itself).
bool TriangulatePolygon(const std::vector<Eigen::Vector3d>& corners, std::vector<std::array<int, 3>>& triangles);

}  // namespace palpa::mesh::internal
