// Between iso_surface.cc and the OpenVDB translation unit.
#pragma once

#include <array>
#include <vector>

#include <Eigen/Core>

#include "palpa/blob/blob.h"

namespace palpa::mesh::internal {

/// openvdb::tools::volumeToMesh at adaptivity 0 of the border between φ ≤ 0 and φ > 0 (isovalue
/// half a Q16.16 step), in node index coordinates, with the windings exactly as OpenVDB returns
/// them.
void VolumeToMesh(const blob::FieldView& field, std::vector<Eigen::Vector3d>& points,
                  std::vector<std::array<int, 3>>& triangles, std::vector<std::array<int, 4>>& quads);

}  // namespace palpa::mesh::internal
