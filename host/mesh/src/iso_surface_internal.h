// Between iso_surface.cc and the OpenVDB module (palpa_vdb.so). OpenVDB is bound at load time
// (BIND_NOW, ~69,000 relocations: 60 ms on every palpa start), so only the commands that mesh load
// it, with dlopen, the first time they need it.
#pragma once

#include <array>
#include <expected>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "palpa/blob/blob.h"

namespace palpa::mesh::internal {

/// openvdb::tools::volumeToMesh at adaptivity 0 of the border between φ ≤ 0 and φ > 0 (isovalue
/// half a Q16.16 step), in node index coordinates, with the windings exactly as OpenVDB returns
/// them.
/// Loads the module on first use. Errors: the module was not found (naming every path tried) or
/// does not export the entry point.
std::expected<void, std::string> VolumeToMesh(const blob::FieldView& field, std::vector<Eigen::Vector3d>& points,
                                              std::vector<std::array<int, 3>>& triangles,
                                              std::vector<std::array<int, 4>>& quads);

/// The module's entry point (extern "C", so dlsym finds it by this name); arguments as above.
using VolumeToMeshFn = void (*)(const blob::FieldView* field, std::vector<Eigen::Vector3d>* points,
                                std::vector<std::array<int, 3>>* triangles, std::vector<std::array<int, 4>>* quads);
inline constexpr const char* kVolumeToMeshSymbol = "palpa_vdb_volume_to_mesh";

}  // namespace palpa::mesh::internal
