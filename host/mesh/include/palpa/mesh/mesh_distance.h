// Exact distance and inside/outside queries against a closed triangle mesh, with CGAL (AABB tree
// closest point; Side_of_triangle_mesh ray casting). The ground truth of `palpa eval`. Non-RT.
#pragma once

#include <optional>

#include <memory>

#include <Eigen/Core>

#include "palpa/mesh/triangle_mesh.h"

namespace palpa::mesh {

/// Builds the search trees once (O(F log F)); afterwards every query is const and thread-safe,
/// so callers may run them from many TBB tasks. Units are the mesh's.
///
/// The mesh must be closed and consistently oriented (CheckClosedOriented) for Side() to be
/// meaningful; self-intersections are not detected (CGAL's Side_of_triangle_mesh precondition).
class ExactMeshDistance {
 public:
  /// `closed` false: any triangle mesh (open, or with non-manifold edges, whose extra faces CGAL's
  /// Surface_mesh cannot hold and leaves out); Side() is then NearSide(), the sign from the closest
  /// face's normal, meaningful near the surface only (eval signs the rest by the mesh's winding
  /// number, field::WindingNumber over its faces).
  explicit ExactMeshDistance(const TriangleMesh& mesh, bool closed = true);
  ~ExactMeshDistance();
  ExactMeshDistance(const ExactMeshDistance&) = delete;
  ExactMeshDistance& operator=(const ExactMeshDistance&) = delete;

  /// Euclidean distance from p to the nearest point of the surface (CGAL AABB_tree::closest_point).
  double UnsignedDistance(const Eigen::Vector3d& p) const;
  /// The same with a hint: `hint` is a surface point believed near p's closest point (e.g. the
  /// previous query's answer for a neighbouring p), which bounds the tree search from the start.
  /// On return `hint` holds p's closest point. Any surface point is a valid hint; the result is
  /// exact either way.
  double UnsignedDistance(const Eigen::Vector3d& p, Eigen::Vector3d& hint) const;
  /// A point of the surface (the first vertex), to start a chain of hinted queries.
  Eigen::Vector3d AnySurfacePoint() const;
  /// First intersection of the ray origin + t dir (t > 0) with the mesh: the point and the index
  /// of the face hit (the input mesh's face order), or nothing (CGAL AABB_tree::first_intersection).
  struct RayHit {
    Eigen::Vector3d point;
    std::size_t face = 0;
  };
  std::optional<RayHit> FirstHit(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir) const;
  /// −1 strictly inside, 0 on the surface, +1 outside (CGAL::Side_of_triangle_mesh, exact
  /// predicates on the Epick kernel); NearSide() for a mesh built with closed = false.
  int Side(const Eigen::Vector3d& p) const;
  /// For a mesh built with closed = false: -1 where (p - c) . n < 0 for the closest point c and
  /// its face's normal n, +1 where > 0, 0 on the surface. For points within a fraction of a face
  /// of the surface, where the winding number of the faces is not accurate.
  int NearSide(const Eigen::Vector3d& p) const;
  /// Side(p)·UnsignedDistance(p): negative inside, the convention of the field.
  double SignedDistance(const Eigen::Vector3d& p) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace palpa::mesh
