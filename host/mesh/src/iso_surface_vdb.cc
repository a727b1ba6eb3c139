// The only translation unit that includes OpenVDB (slow to compile: keep it small), built as the
// module palpa_vdb.so that iso_surface.cc loads on first use (iso_surface_internal.h says why).
#include <openvdb/openvdb.h>
#include <openvdb/tools/Prune.h>
#include <openvdb/tools/VolumeToMesh.h>

#include <algorithm>
#include <array>
#include <mutex>
#include <optional>
#include <span>
#include <type_traits>

#include "iso_surface_internal.h"
#include "palpa/mesh/field_file.h"

namespace {

void VolumeToMesh(const palpa::blob::FieldView& field, std::vector<Eigen::Vector3d>& points,
                  std::vector<std::array<int, 3>>& triangles, std::vector<std::array<int, 4>>& quads) {
  static std::once_flag init;
  std::call_once(init, [] { openvdb::initialize(); });
  // Built block by block from the blob as stored (v2 read in place: no dense copy, so memory
  // follows the band). VDB's leaves are 8^3 nodes, as the blob's bricks, in index space (one VDB
  // voxel per node). As copyFromDense(tolerance 0) of the dense grid made it, but for the blocks no
  // crossing edge touches: every node inside the grid whose value is not the background (+band)
  // is an active voxel; a whole block inside the grid with one value below the background, or
  // with every value below -1.25 voxels, is an inactive tile; a block above +1.25 is left to the
  // background; outside the grid, the background. The mesh is byte for byte the dense grid's
  // (kitten and oni, v1 and v2, 300 and 1,200 cells).
  const auto background = static_cast<float>(std::max(field.band_voxels, field.band_outside));
  auto grid = openvdb::FloatGrid::create(background);
  grid->setGridClass(openvdb::GRID_LEVEL_SET);
  {
    constexpr int kB = palpa::blob::kBrick;
    constexpr std::int32_t kNoCrossing = 65536 + 65536 / 4;  // 1.25 voxels, Q16.16
    auto acc = grid->getAccessor();
    const auto to_float = [](std::int32_t q) { return static_cast<float>(q) / 65536.0f; };
    palpa::mesh::ForEachBlockQ16(field,
                                 [&](std::array<int, 3> block, std::array<int, 3> n, std::optional<std::int32_t> one,
                                     std::span<const std::int32_t, palpa::blob::kBrickNodes> q16) {
                                   const openvdb::Coord origin(kB * block[0], kB * block[1], kB * block[2]);
                                   const bool whole = n[0] == kB && n[1] == kB && n[2] == kB;
                                   if (one && to_float(*one) == background) return;
                                   if (one && whole) {
                                     grid->tree().addTile(1, origin, to_float(*one), false);
                                     return;
                                   }
                                   const auto value = [&](int a, int b, int c) {
                                     return one ? *one : q16[static_cast<std::size_t>((a * kB + b) * kB + c)];
                                   };
                                   if (!one) {
                                     // No edge of a block whose nodes are all farther than kNoCrossing from 0 on one
                                     // side crosses the surface: palpa's fields keep axis neighbours within 1 voxel
                                     // (the proxy needs it; FieldShape tests), 1 + 2/256 after v2's Q7.8. volumeToMesh
                                     // reads only the values at crossing edges' ends, so such a block needs no leaf
                                     // (half the leaves of the kitten's band, and with them half of volumeToMesh's work
                                     // space). A blob from elsewhere with steeper neighbours may mesh differently
                                     // beside one.
                                     bool far_in = true, far_out = true;
                                     for (int a = 0; a < n[0]; ++a)
                                       for (int b = 0; b < n[1]; ++b)
                                         for (int c = 0; c < n[2]; ++c) {
                                           far_in = far_in && value(a, b, c) < -kNoCrossing;
                                           far_out = far_out && value(a, b, c) > kNoCrossing;
                                         }
                                     if (far_out) return;
                                     if (far_in && whole) {
                                       grid->tree().addTile(1, origin, -background, false);
                                       return;
                                     }
                                   }
                                   for (int a = 0; a < n[0]; ++a)
                                     for (int b = 0; b < n[1]; ++b)
                                       for (int c = 0; c < n[2]; ++c)
                                         if (const float v = to_float(value(a, b, c)); v != background)
                                           acc.setValueOn(origin.offsetBy(a, b, c), v);
                                 });
  }
  openvdb::tools::pruneLevelSet(grid->tree());

  std::vector<openvdb::Vec3s> p;
  std::vector<openvdb::Vec3I> t;
  std::vector<openvdb::Vec4I> q;
  // Half a Q16.16 step above 0: nodes with φ exactly 0 are inside, as in φ ≤ 0 (eval's sign
  // rule); OpenVDB itself counts values below the isovalue as inside.
  constexpr double kIso = 0.5 / 65536.0;
  openvdb::tools::volumeToMesh(*grid, p, t, q, kIso, 0.0, true);
  grid.reset();  // before the copies below: the grid is the largest part of the peak
  points.resize(p.size());
  std::transform(p.begin(), p.end(), points.begin(), [](const openvdb::Vec3s& v) {
    return Eigen::Vector3d(static_cast<double>(v.x()), static_cast<double>(v.y()), static_cast<double>(v.z()));
  });
  p = {};
  triangles.resize(t.size());
  std::transform(t.begin(), t.end(), triangles.begin(), [](const openvdb::Vec3I& v) {
    return std::array<int, 3>{static_cast<int>(v.x()), static_cast<int>(v.y()), static_cast<int>(v.z())};
  });
  t = {};
  quads.resize(q.size());
  std::transform(q.begin(), q.end(), quads.begin(), [](const openvdb::Vec4I& v) {
    return std::array<int, 4>{static_cast<int>(v.x()), static_cast<int>(v.y()), static_cast<int>(v.z()),
                              static_cast<int>(v.w())};
  });
}

}  // namespace

extern "C" __attribute__((visibility("default"))) void palpa_vdb_volume_to_mesh(
    const palpa::blob::FieldView* field, std::vector<Eigen::Vector3d>* points,
    std::vector<std::array<int, 3>>* triangles, std::vector<std::array<int, 4>>* quads) {
  VolumeToMesh(*field, *points, *triangles, *quads);
}

// The loader's type and this definition must agree.
static_assert(std::is_same_v<decltype(&palpa_vdb_volume_to_mesh), palpa::mesh::internal::VolumeToMeshFn>);
