#include "palpa/field/grid.h"

#include <cmath>

#include <fmt/format.h>

namespace palpa::field {
namespace {

constexpr int kMinBand = 1;
constexpr int kMaxBand = 64;
constexpr int kMinInteriorCells = 8;
constexpr int kMaxDim = 4096;
// side / voxel is an integer for the longest axis in cells mode; absorb its rounding so that
// ceil() does not add a spurious node.
constexpr double kCeilSlack = 1e-9;

}  // namespace

std::expected<GridSpec, Error> MakeGrid(const std::vector<Eigen::Vector3d>& device_points, const GridOptions& options) {
  if (device_points.empty()) return std::unexpected(Error{"grid: no points"});
  if (options.band_voxels < kMinBand || options.band_voxels > kMaxBand) {
    return std::unexpected(
        Error{fmt::format("grid: band of {} voxels is outside [{}, {}]", options.band_voxels, kMinBand, kMaxBand)});
  }
  const int margin = GridMarginNodes(options.band_voxels);
  if (!std::isfinite(options.voxel_m) || options.voxel_m < 0.0) {
    return std::unexpected(Error{fmt::format("grid: voxel size {} m is not a finite value >= 0", options.voxel_m)});
  }
  const bool cells_mode = options.voxel_m == 0.0;
  if (cells_mode && options.cells < 2 * margin + kMinInteriorCells) {
    return std::unexpected(
        Error{fmt::format("grid: {} cells is too few for a band of {} voxels (need at least {} = 2*(band+2) + {})",
                          options.cells, options.band_voxels, 2 * margin + kMinInteriorCells, kMinInteriorCells)});
  }

  Eigen::Vector3d lo = device_points.front();
  Eigen::Vector3d hi = lo;
  for (const Eigen::Vector3d& p : device_points) {
    if (!p.allFinite()) return std::unexpected(Error{"grid: a point is not finite"});
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  const Eigen::Vector3d side = hi - lo;
  int longest_axis = 0;
  const double longest = side.maxCoeff(&longest_axis);

  GridSpec grid;
  grid.band_voxels = options.band_voxels;
  grid.voxel_m = cells_mode ? longest / (options.cells - 1 - 2 * margin) : options.voxel_m;
  if (!std::isfinite(grid.voxel_m) || !(grid.voxel_m > 0.0)) {
    return std::unexpected(Error{
        fmt::format("grid: voxel size {} m is not finite and positive (are all points the same?)", grid.voxel_m)});
  }
  for (int a = 0; a < 3; ++a) {
    double nodes = std::ceil(side[a] / grid.voxel_m - kCeilSlack) + 1.0 + 2.0 * margin;
    if (cells_mode && a == longest_axis) nodes = options.cells;
    if (!(nodes <= kMaxDim)) {
      return std::unexpected(
          Error{fmt::format("grid: {} nodes along axis {} exceeds the limit of {} (voxel {} m, side {} m)", nodes, a,
                            kMaxDim, grid.voxel_m, side[a])});
    }
    grid.dims[static_cast<std::size_t>(a)] = static_cast<int>(nodes);
  }
  const Eigen::Vector3d half_extent(0.5 * (grid.dims[0] - 1) * grid.voxel_m, 0.5 * (grid.dims[1] - 1) * grid.voxel_m,
                                    0.5 * (grid.dims[2] - 1) * grid.voxel_m);
  grid.origin_m = 0.5 * (lo + hi) - half_extent;
  return grid;
}

}  // namespace palpa::field
