// The only translation unit that includes OpenVDB (slow to compile: keep it small), built as the
// module palpa_vdb.so that iso_surface.cc loads on first use (iso_surface_internal.h says why).
#include <openvdb/openvdb.h>
#include <openvdb/tools/Dense.h>
#include <openvdb/tools/Prune.h>
#include <openvdb/tools/VolumeToMesh.h>

#include <algorithm>
#include <mutex>
#include <type_traits>

#include "iso_surface_internal.h"

namespace {

void VolumeToMesh(const palpa::blob::FieldView& field, std::vector<Eigen::Vector3d>& points,
                  std::vector<std::array<int, 3>>& triangles, std::vector<std::array<int, 4>>& quads) {
  static std::once_flag init;
  std::call_once(init, [] { openvdb::initialize(); });
  const auto [nx, ny, nz] = field.dims;
  const std::size_t count = static_cast<std::size_t>(nx) * static_cast<std::size_t>(ny) * static_cast<std::size_t>(nz);
  // The blob's layout is VDB's LayoutZYX (z fastest), so a float copy wraps as a Dense volume.
  std::vector<float> values(count);
  for (std::size_t n = 0; n < count; ++n) values[n] = static_cast<float>(field.phi[n]) / 65536.0f;
  const openvdb::CoordBBox box(openvdb::Coord(0, 0, 0), openvdb::Coord(nx - 1, ny - 1, nz - 1));
  openvdb::tools::Dense<float, openvdb::tools::LayoutZYX> dense(box, values.data());
  const auto background = static_cast<float>(field.band_voxels);
  auto grid = openvdb::FloatGrid::create(background);
  grid->setGridClass(openvdb::GRID_LEVEL_SET);  // index space: one VDB voxel per node
  openvdb::tools::copyFromDense(dense, *grid, 0.0f);
  openvdb::tools::pruneLevelSet(grid->tree());
  values = {};

  std::vector<openvdb::Vec3s> p;
  std::vector<openvdb::Vec3I> t;
  std::vector<openvdb::Vec4I> q;
  // Half a Q16.16 step above 0: nodes with φ exactly 0 are inside, as in φ ≤ 0 (eval's sign
  // rule); OpenVDB itself counts values below the isovalue as inside.
  constexpr double kIso = 0.5 / 65536.0;
  openvdb::tools::volumeToMesh(*grid, p, t, q, kIso, 0.0, true);
  points.resize(p.size());
  std::transform(p.begin(), p.end(), points.begin(), [](const openvdb::Vec3s& v) {
    return Eigen::Vector3d(static_cast<double>(v.x()), static_cast<double>(v.y()), static_cast<double>(v.z()));
  });
  triangles.resize(t.size());
  std::transform(t.begin(), t.end(), triangles.begin(), [](const openvdb::Vec3I& v) {
    return std::array<int, 3>{static_cast<int>(v.x()), static_cast<int>(v.y()), static_cast<int>(v.z())};
  });
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
