// The zero iso-surface of a field as a triangle mesh (`palpa mesh`), and mesh file formats.
// Non-RT.
#pragma once

#include <cstddef>
#include <expected>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "palpa/blob/blob.h"
#include "palpa/mesh/triangle_mesh.h"

namespace palpa::mesh {

/// Extracts φ = 0 with OpenVDB's tools::volumeToMesh (adaptivity 0: one vertex per cell the
/// surface crosses, at the mean of the cell's edge crossings; quads between them). Quads are split
/// along their shorter diagonal. Vertices are in device-frame metres; faces are counter-clockwise
/// seen from outside (φ > 0); `normals` holds the normalised trilinear gradient ∇φ at each vertex
/// (TrilinearGradient), or the mean of the adjacent face normals where the gradient vanishes.
/// Inside is φ ≤ 0, as in eval's sign rule: the isovalue is half a Q16.16 step (2^-17 voxel), so
/// nodes holding exactly 0 are inside and a plateau of zeros makes no surface of its own.
/// Outside the grid the field reads +band (free space), so the mesh is closed. Either version is
/// read in place, node values as PhiQ16 gives them (a v2 blob needs no dense copy: memory follows
/// the band), with the same mesh as from the blob::DenseV1 grid of the same field.
/// Errors: the field has no node with φ ≤ 0, or none with φ > 0 ("no zero crossing").
std::expected<TriangleMesh, Error> ExtractZeroSurface(const blob::FieldView& field);

/// Gradient of the trilinear interpolant of φ at `index_point` (node index coordinates: node
/// (i,j,k) is at (i,j,k)), in voxels per voxel (dimensionless, so also metres per metre). The
/// point is clamped into the grid. Paper eq. 9's force direction is −this, normalised.
Eigen::Vector3d TrilinearGradient(const blob::FieldView& field, const Eigen::Vector3d& index_point);

/// φ by trilinear interpolation at `index_point`, voxels (clamped into the grid).
double TrilinearPhi(const blob::FieldView& field, const Eigen::Vector3d& index_point);

/// Binary little-endian PLY 1.0: float x y z nx ny nz per vertex (nx.. only if the mesh has
/// normals), `list uchar int vertex_indices` per face.
std::vector<std::byte> ToPly(const TriangleMesh& mesh);

/// ToPly's bytes handed to `sink` in pieces of about 1 MiB, in order, without the whole file in
/// memory (palpa mesh writes them to the output as they come). False when the sink returns false
/// (then no further piece is handed).
bool WritePly(const TriangleMesh& mesh, const std::function<bool(std::span<const std::byte>)>& sink);

/// Wavefront OBJ text: `v`, `vn` (if normals), `f a//a b//b c//c` (1-based).
std::string ToObj(const TriangleMesh& mesh);

}  // namespace palpa::mesh
