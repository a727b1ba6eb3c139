// Scoring a signed distance field against the true signed distance of a known surface
// (`palpa eval`, issue 5). All errors are in voxels; the field is read from a verified blob.
// Non-RT; multi-threaded with TBB where it pays (the exact mesh distances).
//
// Typical use from a test:
//   auto mesh = palpa::mesh::ReadClosedMesh("data/knot1.off");          // model units
//   auto truth = palpa::mesh::TrueDistances(view, palpa::mesh::Truth::Mesh(*mesh));
//   auto score = palpa::mesh::Evaluate(view, *truth);                  // score->mean_abs_error
// Build the truth once and reuse it for every field on the same grid (same dims/origin/voxel).
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <expected>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "palpa/blob/blob.h"
#include "palpa/mesh/mesh_distance.h"
#include "palpa/mesh/triangle_mesh.h"

namespace palpa::mesh {

/// The surface a field is scored against, in MODEL units (the units of the points the field was
/// built from). It goes through the blob's fit transform, device = fit_scale·model +
/// fit_offset_m, exactly as the points did.
struct Truth {
  enum class Kind { kSphere, kMesh };
  Kind kind = Kind::kSphere;
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();  ///< sphere centre, model units
  double radius = 0;                                 ///< sphere radius, model units, > 0
  TriangleMesh mesh;                                 ///< closed, consistently oriented (unless open)
  /// A candidate that is not closed or not manifold (OpenMesh): signed by its generalized
  /// winding number instead of CGAL's Side_of_triangle_mesh (ExactMeshDistance).
  bool open = false;

  /// Sphere |x − centre| − radius (model units); e.g. sphere926.pwn is radius 10 at the origin.
  static Truth Sphere(double radius, const Eigen::Vector3d& centre = Eigen::Vector3d::Zero());
  /// A closed mesh, e.g. from ReadClosedMesh (orientation is fixed up if inward).
  static Truth Mesh(TriangleMesh mesh);
  /// Any triangle mesh, open or non-manifold (screened Poisson's on an open scan): the unsigned
  /// distance is exact as for a closed one; the sign is -1 where its generalized winding number
  /// (Jacobson, Kavan, Sorkine-Hornung 2013) is above 1/2, after the faces are wound outward by the
  /// sign of their signed volume (OrientOutward), as for a closed mesh.
  static Truth OpenMesh(TriangleMesh mesh);
};

/// True signed distance at every node of a field's grid.
struct TrueDistanceGrid {
  std::array<int, 3> dims{};                           ///< nodes nx, ny, nz (the blob's)
  Eigen::Vector3d origin_m = Eigen::Vector3d::Zero();  ///< device position of node (0,0,0), m
  double voxel_m = 0;                                  ///< node spacing, m
  double exact_within_voxels = 0;                      ///< see `voxels`
  /// Signed distance in voxels, negative inside, C order: node (i,j,k) at index (i·ny + j)·nz + k.
  /// Exact (to float rounding, ~1e-7 voxel) where |value| ≤ exact_within_voxels; farther nodes
  /// hold their exact value or ±infinity, and their SIGN is always exact.
  std::vector<float> voxels;
  /// Mesh truths: the mesh in node index coordinates (1 unit = 1 voxel), for exact distances
  /// beyond exact_within_voxels (Evaluate measures how deep the far wrong-sign nodes lie).
  /// Null for a sphere (its `voxels` are exact everywhere).
  std::shared_ptr<const ExactMeshDistance> mesh_in_voxels;
};

/// Computes the truth on `field`'s grid, through its fit transform.
/// Sphere: analytic everywhere. Mesh: CGAL closest point (ExactMeshDistance) at every node inside
/// some face's bounding box grown by exact_within_voxels. Signs: Side_of_triangle_mesh at each node
/// within ½ voxel of the surface; every other node takes the sign of its 6-connected component of
/// such far nodes, one Side query per component (a grid edge between two nodes more than ½ voxel
/// from the surface cannot cross it). Multi-threaded (TBB); the result does not depend on the
/// thread count.
/// Errors: exact_within_voxels < 1; a sphere radius ≤ 0; a mesh that is not closed and
/// consistently oriented (CheckClosedOriented, named "truth mesh").
std::expected<TrueDistanceGrid, Error> TrueDistances(const blob::FieldView& field, const Truth& truth,
                                                     double exact_within_voxels = 3);

struct EvalOptions {
  double band_voxels = 3;          ///< score nodes with |true| ≤ this (issue 5: 3 voxels)
  double gross_beyond_voxels = 1;  ///< a wrong sign is "gross" when |true| > this
  double far_beyond_voxels = 3;    ///< a wrong sign is "far" when |true| > this (issue 20)
  /// A node with |true| ≤ this lies on the surface: its sign is not scored (either is right).
  /// 1/1024 voxel: a quarter of the v2 payload's 1/256-voxel step, and far above what decides
  /// such a node's sign in practice — the 9 significant digits of a point file (~1e-7 voxel at
  /// 150 cells) when a flat face falls on a node plane, as a bounding face does under --fit.
  double on_surface_voxels = 1.0 / 1024;
  bool list_far_nodes = false;  ///< fill FarWrong::listed (palpa eval --far-out)
};

/// Far wrong-sign nodes on one side of the surface: phantom solid (φ ≤ 0 where the truth is
/// outside) or holes (φ > 0 where it is inside), more than far_beyond_voxels from the surface.
/// A hand feels a phantom as a wall in free air and a hole as a fall-through.
struct FarWrong {
  std::size_t nodes = 0;                  ///< how many
  double deepest_voxels = 0;              ///< the largest |true| among them (exact), voxels; 0 if none
  Eigen::Vector3d deepest_at_m{0, 0, 0};  ///< device position of that node, m
  struct Node {
    Eigen::Vector3d at_m;  ///< device position, m
    double depth_voxels;   ///< |true| (exact), voxels
  };
  /// With EvalOptions::list_far_nodes: every such node, in node order (x slowest); else empty.
  std::vector<Node> listed;
};

/// The score, in voxels (1 voxel = field.voxel_m metres). Error e = φ − true at a node.
/// A node has the wrong sign when φ ≤ 0 and true > 0, or φ > 0 and true < 0, and |true| >
/// EvalOptions::on_surface_voxels (nearer, never).
struct EvalResult {
  std::size_t nodes = 0;                    ///< all nodes of the grid
  std::size_t band_nodes = 0;               ///< nodes with |true| ≤ band_voxels
  double mean_abs_error = 0;                ///< mean |e| over the band, voxels
  double p99_abs_error = 0;                 ///< 99th percentile of |e| over the band (nearest rank), voxels
  double max_abs_error = 0;                 ///< max |e| over the band, voxels
  double mean_signed_error = 0;             ///< mean e over the band, voxels (> 0: field too far out)
  Eigen::Vector3d max_error_at_m{0, 0, 0};  ///< device position of the node with max |e|, m
  std::size_t wrong_sign_in_band = 0;       ///< band nodes with the wrong sign
  std::size_t on_surface_nodes = 0;         ///< band nodes with |true| ≤ on_surface_voxels (sign not scored)
  double wrong_sign_in_band_percent = 0;    ///< 100·wrong_sign_in_band / band_nodes
  std::size_t gross_wrong_sign = 0;         ///< nodes with |true| > gross_beyond_voxels and the wrong sign
  double gross_wrong_sign_percent = 0;      ///< 100·gross_wrong_sign / nodes (ALL nodes)
  FarWrong phantom_solid;                   ///< φ ≤ 0, true > far_beyond_voxels
  FarWrong holes;                           ///< φ > 0, true < −far_beyond_voxels
  /// phantom_solid.nodes + holes.nodes: the headline a band score must never hide.
  std::size_t far_wrong() const { return phantom_solid.nodes + holes.nodes; }
};

/// Voxels from the surface within which `field`'s stored φ is exact: the smaller of its inside
/// and outside bands (v1: its one band; v2: band_voxels and band_outside, 6 and 2 by default).
/// Beyond, φ is the clamp (or v2's free-space bound).
inline double ExactBandVoxels(const blob::FieldView& field) { return std::min(field.band_voxels, field.band_outside); }

/// Scores `field` (v1, or v2 read in place) against a truth computed on the same grid (dims,
/// origin and voxel must match exactly). Deterministic and independent of the thread count.
/// Errors: grid mismatch; band_voxels > truth.exact_within_voxels; band_voxels > the field's exact
/// band, the smaller of its inside and outside bands (φ is clamped beyond, so errors would be the
/// clamp's; a v2 blob's dense copy, blob::DenseV1, has a symmetric band and so cannot tell: score
/// the v2 view itself, or pass its bands as palpa eval does); no node in the band.
std::expected<EvalResult, Error> Evaluate(const blob::FieldView& field, const TrueDistanceGrid& truth,
                                          const EvalOptions& options = {});

/// Scores a candidate surface instead of a field (e.g. screened Poisson's mesh, issue 20): the
/// candidate's signed distance is `candidate` (TrueDistances of Truth::Mesh(candidate mesh) on the
/// same grid as `truth`: exact within its reach, beyond it the sign from CGAL Side_of_triangle_mesh,
/// so the candidate must be closed). Same figures as Evaluate, voxels. Errors: other grid, band
/// outside the truth's exact reach, empty band.
std::expected<EvalResult, Error> EvaluateCandidate(const TrueDistanceGrid& candidate, const TrueDistanceGrid& truth,
                                                   const EvalOptions& options = {});

/// TrueDistances, then Evaluate.
std::expected<EvalResult, Error> Evaluate(const blob::FieldView& field, const Truth& truth,
                                          const EvalOptions& options = {});

}  // namespace palpa::mesh
