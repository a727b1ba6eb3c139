// Float64 trilinear sampling of a verified blob on the host, in device metres: for trace
// synthesis and reports (never in the servo loop, which uses palpa/sampler/trilinear.h). Either
// version, read in place with the dense equivalent's values (mesh::PhiQ16).
#pragma once

#include <Eigen/Core>

#include "palpa/blob/blob.h"

namespace palpa::mesh {

class FieldSampler {
 public:
  explicit FieldSampler(const blob::FieldView& field) : f_(field) {}

  /// φ in metres at device point x (outside the grid: the boundary value extended outward, as
  /// sampler::TrilinearSampler).
  double Phi(const Eigen::Vector3d& x_m) const;
  /// ∇φ by central differences of the trilinear φ over ±½ voxel (dimensionless).
  Eigen::Vector3d Gradient(const Eigen::Vector3d& x_m) const;
  /// Projects x onto φ = 0 by Gauss–Newton steps; false if the gradient vanishes or it does not
  /// converge to within 1e-3 voxel in 20 steps.
  bool Project(Eigen::Vector3d& x_m) const;
  /// First crossing of φ from > 0 to ≤ 0 along the ray from `from_m` in unit direction `dir`,
  /// within `max_len_m`; false if none.
  bool RayHit(const Eigen::Vector3d& from_m, const Eigen::Vector3d& dir, double max_len_m, Eigen::Vector3d& hit) const;

  Eigen::Vector3d GridMin() const { return {f_.origin_m[0], f_.origin_m[1], f_.origin_m[2]}; }
  Eigen::Vector3d GridMax() const;
  double voxel_m() const { return f_.voxel_m; }

 private:
  blob::FieldView f_;
};

}  // namespace palpa::mesh
