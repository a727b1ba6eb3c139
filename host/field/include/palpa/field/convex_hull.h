// A convex hull given as its faces' planes, with the two queries the side rules ask of it at
// millions of points (issue 20: the samples' hull, docs/field-methods.md § Sparse closed sets:
// nodes beyond the samples' hull): how far a point lies outside, and whether it lies beyond a
// limit. A scan over every face costs as many faces as the hull has, and a hull of scattered
// samples on a curved surface has about twice as many faces as samples (CGAL's radar.xyz: 20,378
// samples on a sphere, 40,748 faces). Here the faces are grouped by the direction of their normals
// (a cube map), each group bounded by a cone, and a group is read only when its bound reaches the
// value asked: the answers are the scan's, bit for bit. Host only, non-RT; const queries are
// thread-safe.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

namespace palpa::field {

class ConvexHull {
 public:
  /// No faces: no inside (Distance is -infinity, Beyond false).
  ConvexHull() = default;
  /// `planes`: the faces as (n, d), n unit and outward, n . p + d > 0 outside (ConvexHullPlanes);
  /// `centre`: any point, best one inside (the points' centroid): the bounds are taken about it.
  ConvexHull(std::vector<Eigen::Vector4d> planes, const Eigen::Vector3d& centre);

  bool empty() const { return planes_.empty(); }
  std::size_t size() const { return planes_.size(); }
  /// How far p lies outside: max over the faces of n . p + d (metres, or the planes' units), a
  /// lower bound on the distance to the hull (exact where the nearest point is on a face),
  /// 1-Lipschitz; -infinity without faces. Bit for bit the scan over every face.
  double Distance(const Eigen::Vector3d& p) const;
  /// Distance(p) > limit, as the scan answers it.
  bool Beyond(const Eigen::Vector3d& p, double limit) const;

  /// Where a ball lies against `limit`: no point of it beyond (kWithin), every point beyond
  /// (kBeyond), or not known without asking point by point (kAcross).
  enum class Side { kWithin, kAcross, kBeyond };
  struct BallSide {
    Side side;
    double distance;  ///< Distance(centre), for a caller that needs it too
  };
  /// The ball of `radius` (>= 0, the planes' units) about `centre` against `limit`, from
  /// Distance(centre) and its 1-Lipschitz bound with a rounding slack: kWithin and kBeyond never
  /// contradict Beyond(p, limit) at a point p of the ball. A ball of radius 0 is decided exactly,
  /// as Beyond(centre, limit). Without faces: kWithin.
  BallSide Ball(const Eigen::Vector3d& centre, double radius, double limit) const;

 private:
  // Faces whose normals lie within a cone: axis (unit), cos and sin of its half angle (rounded
  // towards a wider cone), and the largest n . centre + d among them.
  struct Group {
    Eigen::Vector3d axis;
    double cos = 1.0, sin = 0.0;
    double top = 0.0;
    std::uint32_t begin = 0, end = 0;  // planes_[begin, end)
  };
  // An upper bound on n . p + d over the group's faces, v = p - centre, |v|^2 = v2.
  static double Bound(const Group& g, const Eigen::Vector3d& v, double v2);
  // The rounding the bounds allow for: a face is skipped only when its bound is below the value
  // asked by more than this.
  double Slack(const Eigen::Vector3d& p) const;

  std::vector<Eigen::Vector4d> planes_;  // grouped
  std::vector<Group> groups_;            // empty: every face is scanned (a small hull)
  Eigen::Vector3d centre_ = Eigen::Vector3d::Zero();
  double scale_ = 0.0;  // the largest |d| and |centre|: the rounding's scale
};

}  // namespace palpa::field
