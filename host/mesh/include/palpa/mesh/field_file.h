// Reading a field blob for the tools (eval, mesh, slice, view), and reading its nodes in place as
// the dense grid they see.
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <expected>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "palpa/blob/blob.h"
#include "palpa/field/transform.h"
#include "palpa/mesh/triangle_mesh.h"

namespace palpa::mesh {

/// blob::LoadFile: the verified blob, used in place (v2 is never made dense: the tools read it
/// through PhiQ16 and BlockQ16 below). Errors name the file, and the blob's field and byte
/// ("f.palpa: version at byte 8: 7 is not supported ...").
std::expected<blob::VerifiedField, Error> LoadField(const std::string& path);

/// The blob's fit as the transform it was built with: device = fit_scale·model + fit_offset_m
/// (docs/blob-format.md; `Inverse()` maps device metres back to model units).
inline field::Transform ModelToDevice(const blob::FieldView& f) {
  return {f.fit_scale, Eigen::Vector3d(f.fit_offset_m[0], f.fit_offset_m[1], f.fit_offset_m[2])};
}

/// Position of node (i, j, k) in device metres: origin + (i, j, k)·voxel.
inline Eigen::Vector3d NodePosition(const blob::FieldView& f, int i, int j, int k) {
  return {f.origin_m[0] + i * f.voxel_m, f.origin_m[1] + j * f.voxel_m, f.origin_m[2] + k * f.voxel_m};
}

/// φ at node (i, j, k), Q16.16 voxels, read in place from either version as the dense v1 grid
/// the host tools see (docs/blob-format.md § Tools and v2): v2 values clamped to
/// ±max(band_inside, band_outside), blob::DenseV1's rule, so free-space bounds read as the band.
/// Indices must be inside the grid.
inline std::int32_t PhiQ16(const blob::FieldView& f, int i, int j, int k) {
  const std::int32_t band = std::max(f.band_voxels, f.band_outside) * 65536;
  return std::clamp(f.NodeQ16(i, j, k), -band, band);
}

/// PhiQ16 in voxels (Q16.16 → double).
inline double PhiVoxels(const blob::FieldView& f, int i, int j, int k) {
  return static_cast<double>(PhiQ16(f, i, j, k)) / 65536.0;
}

/// The nodes of the 8³ block (8·bi .. 8·bi + 7, ...) as PhiQ16 reads them, without a dense copy:
/// `n` nodes along each axis lie inside the grid (8 but at the far faces). Returns the one value
/// of those nodes when they all have it (a v2 uniform slot at once; a v1 block after comparing
/// them), else writes them to `q16` (local index (a·8 + b)·8 + c; the rest left as it was) and
/// returns nullopt.
inline std::optional<std::int32_t> BlockQ16(const blob::FieldView& f, std::array<int, 3> block, std::array<int, 3> n,
                                            std::span<std::int32_t, blob::kBrickNodes> q16) {
  constexpr int kB = blob::kBrick;
  const std::int32_t band = std::max(f.band_voxels, f.band_outside) * 65536;
  if (const blob::BrickAccessor* bricks = f.bricks()) {
    const std::size_t slot = (static_cast<std::size_t>(block[0]) * static_cast<std::size_t>(bricks->brick_dims()[1]) +
                              static_cast<std::size_t>(block[1])) *
                                 static_cast<std::size_t>(bricks->brick_dims()[2]) +
                             static_cast<std::size_t>(block[2]);
    const std::uint32_t e = bricks->index()[slot];
    if ((e & blob::kSlotEmpty) != 0)
      return std::clamp(std::int32_t{static_cast<std::int16_t>(e & 0xFFFFU)} * 256, -band, band);
  }
  bool uniform = true;
  const std::int32_t first = PhiQ16(f, kB * block[0], kB * block[1], kB * block[2]);
  for (int a = 0; a < n[0]; ++a)
    for (int b = 0; b < n[1]; ++b)
      for (int c = 0; c < n[2]; ++c) {
        const std::int32_t v = PhiQ16(f, kB * block[0] + a, kB * block[1] + b, kB * block[2] + c);
        q16[static_cast<std::size_t>((a * kB + b) * kB + c)] = v;
        uniform = uniform && v == first;
      }
  if (uniform && f.dense() != nullptr) return first;
  return std::nullopt;
}

/// Every 8³ block of the grid, x slowest: fn(block, n, one, q16) with BlockQ16's `n`, result and
/// values (q16 is valid when `one` is empty).
template <typename Fn>
void ForEachBlockQ16(const blob::FieldView& f, Fn&& fn) {
  constexpr int kB = blob::kBrick;
  std::array<std::int32_t, blob::kBrickNodes> q16{};
  for (int bi = 0; kB * bi < f.dims[0]; ++bi)
    for (int bj = 0; kB * bj < f.dims[1]; ++bj)
      for (int bk = 0; kB * bk < f.dims[2]; ++bk) {
        const std::array<int, 3> block{bi, bj, bk};
        const std::array<int, 3> n{std::min(kB, f.dims[0] - kB * bi), std::min(kB, f.dims[1] - kB * bj),
                                   std::min(kB, f.dims[2] - kB * bk)};
        const std::optional<std::int32_t> one = BlockQ16(f, block, n, q16);
        fn(block, n, one, std::span<const std::int32_t, blob::kBrickNodes>(q16));
      }
}

/// The smallest and largest PhiQ16 over the grid, block by block (BlockQ16).
std::pair<std::int32_t, std::int32_t> PhiRangeQ16(const blob::FieldView& f);

}  // namespace palpa::mesh
