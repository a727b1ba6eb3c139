#include <cmath>
#include <limits>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "palpa/field/grid.h"

namespace palpa::field {
namespace {

using ::testing::HasSubstr;

// Bounding box [0,1] x [0,0.5] x [0,0.25] (plus an interior point).
const std::vector<Eigen::Vector3d> kBox = {{0, 0, 0}, {1, 0.5, 0.25}, {0.3, 0.2, 0.1}};

TEST(MakeGrid, CellsMode) {
  const auto grid = MakeGrid(kBox, GridOptions{.cells = 100, .voxel_m = 0, .band_voxels = 6});
  ASSERT_TRUE(grid.has_value()) << grid.error().message;
  // margin m = 8: 100 - 1 - 16 = 83 voxels span the longest side.
  EXPECT_DOUBLE_EQ(grid->voxel_m, 1.0 / 83.0);
  // y: 0.5 * 83 = 41.5 -> 42 voxels + 1 + 16 = 59; z: 20.75 -> 21 + 17 = 38.
  EXPECT_EQ(grid->dims, (std::array<int, 3>{100, 59, 38}));
  EXPECT_EQ(grid->band_voxels, 6);
  // The bbox min corner sits m nodes in along x, and the bbox is centred on every axis.
  EXPECT_NEAR(grid->origin_m.x(), -8.0 / 83.0, 1e-15);
  for (int a = 0; a < 3; ++a) {
    const int dim = grid->dims[static_cast<std::size_t>(a)];
    const double grid_centre = grid->origin_m[a] + 0.5 * (dim - 1) * grid->voxel_m;
    EXPECT_NEAR(grid_centre, 0.5 * (kBox[0][a] + kBox[1][a]), 1e-15);
  }
  EXPECT_EQ(grid->NodeCount(), 100u * 59u * 38u);
  EXPECT_EQ(grid->Index(1, 2, 3), (1u * 59u + 2u) * 38u + 3u);
  EXPECT_NEAR(grid->Node(8, 0, 0).x(), 0.0, 1e-15);   // bbox min is node 8 along x
  EXPECT_NEAR(grid->Node(91, 0, 0).x(), 1.0, 1e-14);  // bbox max is node 99 - 8
}

TEST(MakeGrid, CubeHasEqualDims) {
  const std::vector<Eigen::Vector3d> cube = {{-0.03, -0.03, -0.03}, {0.03, 0.03, 0.03}};
  const auto grid = MakeGrid(cube, GridOptions{.cells = 300, .voxel_m = 0, .band_voxels = 6});
  ASSERT_TRUE(grid.has_value()) << grid.error().message;
  EXPECT_EQ(grid->dims, (std::array<int, 3>{300, 300, 300}));
  EXPECT_DOUBLE_EQ(grid->voxel_m, 0.06 / 283.0);
}

TEST(MakeGrid, VoxelMode) {
  const auto grid = MakeGrid(kBox, GridOptions{.cells = 0, .voxel_m = 0.1, .band_voxels = 2});
  ASSERT_TRUE(grid.has_value()) << grid.error().message;
  // m = 4: x 10 + 1 + 8 = 19, y 5 + 9 = 14, z ceil(2.5) = 3 + 9 = 12.
  EXPECT_EQ(grid->dims, (std::array<int, 3>{19, 14, 12}));
  EXPECT_DOUBLE_EQ(grid->voxel_m, 0.1);
  EXPECT_NEAR(grid->origin_m.x(), -0.4, 1e-15);
}

TEST(MakeGrid, Errors) {
  const auto expect_error = [](const std::vector<Eigen::Vector3d>& points, GridOptions options, const char* fragment) {
    const auto grid = MakeGrid(points, options);
    ASSERT_FALSE(grid.has_value()) << fragment;
    EXPECT_THAT(grid.error().message, HasSubstr(fragment));
  };
  expect_error({}, GridOptions{}, "no points");
  expect_error(kBox, GridOptions{.cells = 23, .voxel_m = 0, .band_voxels = 6}, "too few");
  EXPECT_TRUE(MakeGrid(kBox, GridOptions{.cells = 24, .voxel_m = 0, .band_voxels = 6}));
  expect_error(kBox, GridOptions{.cells = 300, .voxel_m = 0, .band_voxels = 0}, "band");
  expect_error(kBox, GridOptions{.cells = 300, .voxel_m = 0, .band_voxels = 65}, "band");
  expect_error(kBox, GridOptions{.cells = 5000, .voxel_m = 0, .band_voxels = 6}, "exceeds");
  expect_error(kBox, GridOptions{.cells = 300, .voxel_m = 1e-5, .band_voxels = 6}, "exceeds");
  expect_error(kBox, GridOptions{.cells = 300, .voxel_m = std::nan(""), .band_voxels = 6}, "voxel");
  expect_error(kBox, GridOptions{.cells = 300, .voxel_m = -1, .band_voxels = 6}, "voxel");
  expect_error({{1, 1, 1}, {1, 1, 1}}, GridOptions{}, "voxel");
  expect_error({{1, 1, 1}, {std::numeric_limits<double>::infinity(), 0, 0}}, GridOptions{}, "not finite");
}

}  // namespace
}  // namespace palpa::field
