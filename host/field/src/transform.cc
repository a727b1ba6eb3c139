#include "palpa/field/transform.h"

namespace palpa::field {

Transform FitTransform(const PointSet& points, double longest_side_m) {
  Transform t;
  if (points.positions.empty()) return t;
  Eigen::Vector3d lo = points.positions.front();
  Eigen::Vector3d hi = lo;
  for (const Eigen::Vector3d& p : points.positions) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  const double longest = (hi - lo).maxCoeff();
  if (longest > 0.0 && longest_side_m > 0.0) t.scale = longest_side_m / longest;
  t.offset_m = -t.scale * (0.5 * (lo + hi));
  return t;
}

PointSet ApplyTransform(const Transform& transform, const PointSet& points) {
  PointSet out;
  out.positions.reserve(points.positions.size());
  for (const Eigen::Vector3d& p : points.positions) out.positions.push_back(transform.Apply(p));
  out.normals = points.normals;
  out.lines = points.lines;
  out.has_normals = points.has_normals;
  return out;
}

}  // namespace palpa::field
