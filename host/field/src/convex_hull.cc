#include "palpa/field/convex_hull.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numeric>

namespace palpa::field {
namespace {

// Below this many faces the scan is as quick as the groups' bounds.
constexpr std::size_t kScanFaces = 64;
// Cube-map cells per face edge: at most 8 (6 x 8 x 8 groups, a cone of at most ~8 degrees about
// the cell's mean normal), fewer for smaller hulls (about 96 faces per cell face).
constexpr int kMaxCells = 8;
constexpr std::size_t kMaxGroups = 6 * kMaxCells * kMaxCells;

double Value(const Eigen::Vector4d& f, const Eigen::Vector3d& p) { return f.head<3>().dot(p) + f[3]; }

// The cube-map cell of unit normal n, k cells per edge of each of the 6 faces.
int Cell(const Eigen::Vector3d& n, int k) {
  Eigen::Index major = 0;
  n.cwiseAbs().maxCoeff(&major);
  const double a = std::abs(n[major]);
  const auto coord = [&](Eigen::Index axis) {
    const double u = a > 0.0 ? n[axis] / a : 0.0;
    return std::clamp(static_cast<int>(std::floor((u + 1.0) * 0.5 * k)), 0, k - 1);
  };
  const int side = static_cast<int>(major) * 2 + (n[major] < 0.0 ? 1 : 0);
  return (side * k + coord((major + 1) % 3)) * k + coord((major + 2) % 3);
}

}  // namespace

ConvexHull::ConvexHull(std::vector<Eigen::Vector4d> planes, const Eigen::Vector3d& centre)
    : planes_(std::move(planes)), centre_(centre) {
  double offset = 0.0;
  for (const Eigen::Vector4d& f : planes_) offset = std::max(offset, std::abs(f[3]));
  scale_ = centre_.norm() + offset;
  if (planes_.size() < kScanFaces) return;
  const int k =
      std::clamp(static_cast<int>(std::lround(std::sqrt(static_cast<double>(planes_.size()) / 96.0))), 1, kMaxCells);
  std::vector<int> cell(planes_.size());
  for (std::size_t f = 0; f < planes_.size(); ++f) cell[f] = Cell(planes_[f].head<3>(), k);
  std::vector<std::uint32_t> order(planes_.size());
  std::iota(order.begin(), order.end(), 0u);
  std::stable_sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) { return cell[a] < cell[b]; });
  std::vector<Eigen::Vector4d> grouped(planes_.size());
  for (std::size_t m = 0; m < order.size(); ++m) grouped[m] = planes_[order[m]];
  for (std::size_t begin = 0; begin < order.size();) {
    std::size_t end = begin;
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    while (end < order.size() && cell[order[end]] == cell[order[begin]]) sum += grouped[end++].head<3>();
    Group g;
    g.axis = sum.norm() > 0.0 ? Eigen::Vector3d(sum.normalized()) : Eigen::Vector3d(grouped[begin].head<3>());
    g.top = -std::numeric_limits<double>::infinity();
    double cos = 1.0;
    for (std::size_t m = begin; m < end; ++m) {
      cos = std::min(cos, g.axis.dot(grouped[m].head<3>()));
      g.top = std::max(g.top, Value(grouped[m], centre_));
    }
    // A cone a little wider than its faces' normals, so that rounding never narrows it.
    g.cos = std::clamp(cos - 1e-12, -1.0, 1.0);
    g.sin = std::sqrt(std::max(0.0, 1.0 - g.cos * g.cos)) + 1e-12;
    g.top += 1e-12 * scale_;
    g.begin = static_cast<std::uint32_t>(begin);
    g.end = static_cast<std::uint32_t>(end);
    groups_.push_back(g);
    begin = end;
  }
  planes_ = std::move(grouped);
}

double ConvexHull::Bound(const Group& g, const Eigen::Vector3d& v, double v2) {
  // n . v <= |v| cos(max(0, phi - theta)): phi the angle of v from the axis, theta the cone's.
  const double along = g.axis.dot(v);
  const double length = std::sqrt(v2);
  if (along >= g.cos * length) return g.top + length;
  return g.top + along * g.cos + std::sqrt(std::max(0.0, v2 - along * along)) * g.sin;
}

double ConvexHull::Slack(const Eigen::Vector3d& p) const { return 1e-9 * (1.0 + p.norm() + scale_); }

double ConvexHull::Distance(const Eigen::Vector3d& p) const {
  double best = -std::numeric_limits<double>::infinity();
  const auto scan = [&](std::uint32_t begin, std::uint32_t end) {
    for (std::uint32_t f = begin; f < end; ++f) best = std::max(best, Value(planes_[f], p));
  };
  if (groups_.empty()) {
    scan(0, static_cast<std::uint32_t>(planes_.size()));
    return best;
  }
  const Eigen::Vector3d v = p - centre_;
  const double v2 = v.squaredNorm();
  std::array<double, kMaxGroups> bound;
  std::size_t first = 0;
  for (std::size_t g = 0; g < groups_.size(); ++g) {
    bound[g] = Bound(groups_[g], v, v2);
    if (bound[g] > bound[first]) first = g;
  }
  // The likeliest group first, so that the best so far skips most of the others.
  scan(groups_[first].begin, groups_[first].end);
  const double slack = Slack(p);
  for (std::size_t g = 0; g < groups_.size(); ++g)
    if (g != first && bound[g] + slack > best) scan(groups_[g].begin, groups_[g].end);
  return best;
}

bool ConvexHull::Beyond(const Eigen::Vector3d& p, double limit) const {
  const auto any = [&](std::uint32_t begin, std::uint32_t end) {
    for (std::uint32_t f = begin; f < end; ++f)
      if (Value(planes_[f], p) > limit) return true;
    return false;
  };
  if (groups_.empty()) return any(0, static_cast<std::uint32_t>(planes_.size()));
  const Eigen::Vector3d v = p - centre_;
  const double v2 = v.squaredNorm();
  const double slack = Slack(p);
  for (const Group& g : groups_)
    if (Bound(g, v, v2) + slack > limit && any(g.begin, g.end)) return true;
  return false;
}

ConvexHull::BallSide ConvexHull::Ball(const Eigen::Vector3d& centre, double radius, double limit) const {
  const double distance = Distance(centre);
  // A point needs no slack: Distance is the scan's value, as Beyond's.
  if (radius == 0.0) return {distance > limit ? Side::kBeyond : Side::kWithin, distance};
  const double slack = Slack(centre) + 1e-9 * radius;
  if (distance + radius + slack <= limit) return {Side::kWithin, distance};
  if (distance - radius - slack > limit) return {Side::kBeyond, distance};
  return {Side::kAcross, distance};
}

}  // namespace palpa::field
