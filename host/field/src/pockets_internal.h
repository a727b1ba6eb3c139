// FillSamplelessPockets and CutSamplelessIslands on a k-d tree the caller already holds over the
// same samples (HermiteField's), with the default reaches (kPocketReachVoxels, kPocketReachSpacings). Host only.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "palpa/field/pockets.h"
#include "point_cloud.h"

namespace palpa::field::detail {

// palpa/field/pockets.h's FillSamplelessPockets; `tree`: a KdTree over `positions` (any leaf size).
PocketFill FillSamplelessPockets(SparseField& field, const std::vector<Eigen::Vector3d>& positions,
                                 const std::vector<Eigen::Vector3d>& normals, const std::vector<double>& spacing,
                                 const KdTree& tree);

// palpa/field/pockets.h's CutSamplelessIslands; `tree` as above.
PocketFill CutSamplelessIslands(SparseField& field, const std::vector<Eigen::Vector3d>& positions,
                                const std::vector<Eigen::Vector3d>& normals, const std::vector<double>& spacing,
                                const KdTree& tree);

}  // namespace palpa::field::detail
