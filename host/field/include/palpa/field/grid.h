// The regular grid of voxel nodes on which the signed distance field is sampled.
#pragma once

#include <array>
#include <cstddef>
#include <expected>
#include <vector>

#include <Eigen/Core>

#include "palpa/field/error.h"

namespace palpa::field {

// Grid of dims[0] x dims[1] x dims[2] nodes; node (i, j, k) is at origin_m + (i, j, k) * voxel_m
// (metres). Dense arrays over the grid are in C order with k fastest: index (i*ny + j)*nz + k.
// band_voxels is the narrow-band half-width (in voxels) of fields built on this grid.
struct GridSpec {
  std::array<int, 3> dims{};
  Eigen::Vector3d origin_m = Eigen::Vector3d::Zero();
  double voxel_m = 0.0;
  int band_voxels = 0;

  std::size_t NodeCount() const {
    return static_cast<std::size_t>(dims[0]) * static_cast<std::size_t>(dims[1]) * static_cast<std::size_t>(dims[2]);
  }
  std::size_t Index(int i, int j, int k) const {
    return (static_cast<std::size_t>(i) * static_cast<std::size_t>(dims[1]) + static_cast<std::size_t>(j)) *
               static_cast<std::size_t>(dims[2]) +
           static_cast<std::size_t>(k);
  }
  // Whether node (i, j, k) lies on one of the grid's six faces.
  bool OnFace(int i, int j, int k) const {
    return i == 0 || j == 0 || k == 0 || i == dims[0] - 1 || j == dims[1] - 1 || k == dims[2] - 1;
  }
  // Position of node (i, j, k) in metres.
  Eigen::Vector3d Node(int i, int j, int k) const {
    return {origin_m.x() + i * voxel_m, origin_m.y() + j * voxel_m, origin_m.z() + k * voxel_m};
  }
};

struct GridOptions {
  int cells = 300;       // nodes along the longest bounding-box axis (paper §4 uses 300^3)
  double voxel_m = 0.0;  // > 0: use this node spacing instead of `cells`
  int band_voxels = 6;   // narrow band; paper §4: 5-6 voxels inside suffice for stable haptics
};

// Margin (in nodes) left on every side of the points' bounding box: the band plus 2, so that the
// band around the points (and balls tangent there) never touches the grid faces.
inline int GridMarginNodes(int band_voxels) { return band_voxels + 2; }

// Builds the grid around `device_points` (metres). With m = GridMarginNodes(band):
//   cells mode (voxel_m == 0): exactly `cells` nodes on the longest bbox axis,
//     voxel = longest_side / (cells - 1 - 2m); other axes ceil(side/voxel) + 1 + 2m nodes;
//   voxel mode (voxel_m > 0): ceil(side/voxel) + 1 + 2m nodes on every axis.
// The bounding box is centred in the grid.
// Errors: no points or a non-finite point; band < 1 or > 64; cells < 2m + 8; negative or
// non-finite voxel_m; zero-size bounding box in cells mode (non-finite voxel); any dim > 4096.
std::expected<GridSpec, Error> MakeGrid(const std::vector<Eigen::Vector3d>& device_points, const GridOptions& options);

}  // namespace palpa::field
