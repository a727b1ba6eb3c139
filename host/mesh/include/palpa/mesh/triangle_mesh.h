// Closed triangle meshes: the ground truth that `palpa sample` and `palpa eval` measure fields
// against, and the shape `palpa mesh` writes. Non-RT.
#pragma once

#include <array>
#include <cstddef>
#include <expected>
#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "palpa/field/error.h"

namespace palpa::mesh {

using Error = field::Error;

/// An indexed triangle mesh. `faces[f]` holds three indices into `vertices`, counter-clockwise
/// seen from outside once the mesh is oriented (see OrientOutward). Units are the caller's: model
/// units for meshes read from files, metres for meshes extracted from a field.
struct TriangleMesh {
  std::vector<Eigen::Vector3d> vertices;
  std::vector<std::array<int, 3>> faces;
  /// Optional per-vertex unit normals (same size as `vertices`, or empty).
  std::vector<Eigen::Vector3d> normals;
  /// Optional source line of each face (1-based, same size as `faces`, or empty): lets topology
  /// errors point at the file line.
  std::vector<int> face_lines;
};

/// Reads an ASCII OFF file (Geomview Object File Format, OFF(5)): a `[ST][C][N]OFF` header, a
/// counts line `nv nf [ne]` (or the counts on the header line), nv vertex lines `x y z` (further
/// numbers, e.g. colours or normals, are ignored), then nf face lines `n i0 … i(n−1)` (further
/// numbers ignored). A polygon (3 < n ≤ 256) becomes n − 2 triangles wound as it is, by CGAL's
/// triangulate_hole_polyline (constrained Delaunay in its plane: concave polygons keep their
/// shape); every triangle keeps its face's line in `face_lines`. `#` starts a comment; blank lines
/// are skipped.
///
/// Errors (message starts with "FILE:" or "FILE:LINE:"): missing or unreadable file; missing
/// `OFF` header; 4OFF, nOFF or binary OFF; bad counts (nv < 4 or nf < 4); a token that is not a
/// number; a non-finite coordinate; a face of fewer than 3 or more than 256 vertices; a vertex
/// index out of range or repeated within a face; a polygon that crosses itself; too few lines;
/// data after the last face.
std::expected<TriangleMesh, Error> ReadOff(const std::filesystem::path& path);

/// Checks that the mesh is closed, edge-manifold and consistently oriented: every directed edge
/// a→b occurs in exactly one face and its reverse b→a in exactly one other face.
/// Errors (prefixed with `name` and, when `face_lines` is set, the face's line):
///   "edge 3-7 of face 12 has no opposite face: the mesh must be closed";
///   "edge 3→7 is used by faces 12 and 40: the mesh is non-manifold or inconsistently oriented".
std::expected<void, Error> CheckClosedOriented(const TriangleMesh& mesh, const std::string& name);

/// Signed enclosed volume Σ det(v0, v1, v2) / 6 over faces, in cubed mesh units: positive when the
/// faces are counter-clockwise seen from outside (outward normals). Meaningful for closed meshes.
double SignedVolume(const TriangleMesh& mesh);

/// Total surface area, squared mesh units.
double SurfaceArea(const TriangleMesh& mesh);

/// For a closed, consistently oriented mesh: reverses every face if SignedVolume < 0, so that
/// face normals point outward. Returns true if it flipped. Vertex normals, if any, are negated too.
bool OrientOutward(TriangleMesh& mesh);

/// Reads an OFF file and makes it a valid ground truth: ReadOff, CheckClosedOriented,
/// OrientOutward. Error also when the enclosed volume is zero ("encloses no volume").
/// `flipped`, if not null, receives whether the faces were reversed.
std::expected<TriangleMesh, Error> ReadClosedMesh(const std::filesystem::path& path, bool* flipped = nullptr);

/// Unit outward normal of face f (zero vector for a degenerate face).
Eigen::Vector3d FaceNormal(const TriangleMesh& mesh, std::size_t f);

}  // namespace palpa::mesh
