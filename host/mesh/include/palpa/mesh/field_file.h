// Reading a field blob for the tools (eval, mesh, slice): the bytes and the verified view on them.
#pragma once

#include <cstddef>
#include <cstdint>
#include <expected>
#include <string>
#include <vector>

#include "palpa/blob/blob.h"
#include "palpa/mesh/triangle_mesh.h"

namespace palpa::mesh {

/// A verified blob and its view. Move-only: `view` points into `bytes`' heap buffer, which a
/// move keeps in place and a copy would not.
struct LoadedField {
  std::vector<std::byte> bytes;
  blob::FieldView view;  ///< Load::kDense: a v2 file re-encoded by blob::DenseV1; else as stored
  /// The file as stored (what palpad loads and reports), whatever `load` made of it: its header's
  /// CRC-32C and its size in bytes.
  std::uint32_t file_crc32c = 0;
  std::size_t file_bytes = 0;

  LoadedField() = default;
  LoadedField(LoadedField&&) = default;
  LoadedField& operator=(LoadedField&&) = default;
  LoadedField(const LoadedField&) = delete;
  LoadedField& operator=(const LoadedField&) = delete;
};

/// blob::ReadFile (as stored) and blob::Verify, then with Load::kDense (the tools that index φ
/// densely: mesh, slice, view) a v2 blob re-encoded by blob::DenseV1, whose symmetric band is the
/// larger of v2's two. Errors name the file, and the blob's field and byte ("f.palpa: version at
/// byte 8: 7 is not supported ...").
std::expected<LoadedField, Error> LoadField(const std::string& path, blob::Load load = blob::Load::kDense);

/// Position of node (i, j, k) in device metres: origin + (i, j, k)·voxel.
inline Eigen::Vector3d NodePosition(const blob::FieldView& f, int i, int j, int k) {
  return {f.origin_m[0] + i * f.voxel_m, f.origin_m[1] + j * f.voxel_m, f.origin_m[2] + k * f.voxel_m};
}

/// φ at node (i, j, k) in voxels (Q16.16 → double). Indices must be inside the grid.
inline double PhiVoxels(const blob::FieldView& f, int i, int j, int k) {
  const std::size_t n =
      (static_cast<std::size_t>(i) * static_cast<std::size_t>(f.dims[1]) + static_cast<std::size_t>(j)) *
          static_cast<std::size_t>(f.dims[2]) +
      static_cast<std::size_t>(k);
  return static_cast<double>(f.phi[n]) / 65536.0;
}

}  // namespace palpa::mesh
