// Model-to-device similarity transform: puts a point set into the haptic device's workspace.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "palpa/field/point_io.h"

namespace palpa::field {

// device = scale * model + offset_m, in metres. Uniform scale (> 0) and no rotation, so normals
// are unchanged by the transform. The default is the identity.
struct Transform {
  double scale = 1.0;
  Eigen::Vector3d offset_m = Eigen::Vector3d::Zero();

  Eigen::Vector3d Apply(const Eigen::Vector3d& model) const { return scale * model + offset_m; }
  /// device -> model: scale 1 / scale, offset -offset_m / scale.
  Transform Inverse() const { return {1.0 / scale, -offset_m / scale}; }
};

// Scales so that the longest side of the axis-aligned bounding box of `points.positions` becomes
// `longest_side_m` metres, and moves the box centre to the origin. If the set is empty or all
// points coincide (no size to scale), scale is 1 and only the centring is applied.
Transform FitTransform(const PointSet& points, double longest_side_m);

// Returns `points` with Transform::Apply on every position; normals are copied unchanged.
PointSet ApplyTransform(const Transform& transform, const PointSet& points);

}  // namespace palpa::field
