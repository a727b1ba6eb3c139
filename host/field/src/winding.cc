#include "palpa/field/winding.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <numeric>

#include "point_cloud.h"

namespace palpa::field {
namespace {

using V3 = Eigen::Vector3d;
constexpr std::uint32_t kLeafSize = 8;
constexpr double kInv4Pi = 0.25 / std::numbers::pi;

// One dipole's term; 0 at the dipole itself (q on a sample: the term is undefined there).
inline double Dipole(const V3& at, const V3& weighted_normal, const V3& q) {
  const V3 d = at - q;
  const double r2 = d.squaredNorm();
  if (!(r2 > 0.0)) return 0.0;
  return weighted_normal.dot(d) * kInv4Pi / (r2 * std::sqrt(r2));
}

}  // namespace

std::vector<double> SampleAreas(const std::vector<V3>& positions, int k) {
  const std::size_t n = positions.size();
  std::vector<double> areas(n, 0.0);
  if (n < 2) return areas;
  const auto kth = static_cast<std::size_t>(std::clamp<std::size_t>(static_cast<std::size_t>(k), 1, n - 1));
  const detail::PointCloud cloud{&positions};
  const detail::KdTree tree(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(10));
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 256), [&](const auto& r) {
    std::vector<std::size_t> idx(kth + 1);
    std::vector<double> d2(kth + 1);
    for (std::size_t i = r.begin(); i != r.end(); ++i) {
      const std::size_t got = tree.knnSearch(positions[i].data(), kth + 1, idx.data(), d2.data());
      // The nearest is the sample itself (or an exact duplicate at distance 0).
      areas[i] = std::numbers::pi * d2[got - 1] / static_cast<double>(got - 1);
    }
  });
  return areas;
}

double WindingNumberBruteForce(const std::vector<V3>& positions, const std::vector<V3>& normals,
                               const std::vector<double>& areas, const V3& q) {
  double w = 0.0;
  for (std::size_t i = 0; i < positions.size(); ++i) w += Dipole(positions[i], areas[i] * normals[i], q);
  return w;
}

WindingNumber::WindingNumber(const std::vector<V3>& positions, const std::vector<V3>& normals,
                             const std::vector<double>& areas, double beta)
    : points_(positions), weighted_normals_(positions.size()), beta2_(beta * beta) {
  for (std::size_t i = 0; i < positions.size(); ++i) weighted_normals_[i] = areas[i] * normals[i];
  if (points_.empty()) return;
  nodes_.reserve(2 * (points_.size() / kLeafSize + 1));
  BuildNode(0, static_cast<std::uint32_t>(points_.size()));
}

std::int32_t WindingNumber::BuildNode(std::uint32_t begin, std::uint32_t end) {
  const auto id = static_cast<std::int32_t>(nodes_.size());
  nodes_.emplace_back();
  Node node;
  node.begin = begin;
  node.end = end;
  // Area-weighted centre (plain mean when every area is 0).
  V3 sum = V3::Zero();
  double total = 0.0;
  V3 lo = points_[begin];
  V3 hi = lo;
  node.dipole.setZero();
  for (std::uint32_t i = begin; i < end; ++i) {
    const double a = weighted_normals_[i].norm();
    sum += a * points_[i];
    total += a;
    node.dipole += weighted_normals_[i];
    lo = lo.cwiseMin(points_[i]);
    hi = hi.cwiseMax(points_[i]);
  }
  node.centre = total > 0.0 ? V3(sum / total) : V3(0.5 * (lo + hi));
  node.second.setZero();
  for (std::uint32_t i = begin; i < end; ++i) {
    node.radius = std::max(node.radius, (points_[i] - node.centre).norm());
    node.second += weighted_normals_[i] * (points_[i] - node.centre).transpose();
  }
  if (end - begin > kLeafSize) {
    // Median split on the longest side; points and their weighted normals move together.
    Eigen::Index axis = 0;
    (hi - lo).maxCoeff(&axis);
    const std::uint32_t mid = begin + (end - begin) / 2;
    std::vector<std::uint32_t> order(end - begin);
    std::iota(order.begin(), order.end(), begin);
    std::nth_element(order.begin(), order.begin() + (mid - begin), order.end(), [&](std::uint32_t a, std::uint32_t b) {
      return points_[a][axis] < points_[b][axis] || (points_[a][axis] == points_[b][axis] && a < b);
    });
    std::vector<V3> p(order.size());
    std::vector<V3> w(order.size());
    for (std::size_t m = 0; m < order.size(); ++m) {
      p[m] = points_[order[m]];
      w[m] = weighted_normals_[order[m]];
    }
    std::copy(p.begin(), p.end(), points_.begin() + begin);
    std::copy(w.begin(), w.end(), weighted_normals_.begin() + begin);
    node.left = BuildNode(begin, mid);
    node.right = BuildNode(mid, end);
  }
  nodes_[static_cast<std::size_t>(id)] = node;
  return id;
}

double WindingNumber::operator()(const V3& q) const {
  if (nodes_.empty()) return 0.0;
  double w = 0.0;
  std::array<std::int32_t, 128> stack{};
  std::size_t top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const Node& node = nodes_[static_cast<std::size_t>(stack[--top])];
    const double d2 = (node.centre - q).squaredNorm();
    if (d2 > beta2_ * node.radius * node.radius) {
      // N . K(x) + trace(grad K(x) B), x = c - q (winding.h).
      const V3 x = node.centre - q;
      const double inv_d = 1.0 / std::sqrt(d2);
      const double inv_d3 = inv_d * inv_d * inv_d;
      w += kInv4Pi * inv_d3 * (node.dipole.dot(x) + node.second.trace() - 3.0 * x.dot(node.second * x) / d2);
    } else if (node.left < 0) {
      for (std::uint32_t i = node.begin; i < node.end; ++i) w += Dipole(points_[i], weighted_normals_[i], q);
    } else {
      stack[top++] = node.left;
      stack[top++] = node.right;
    }
  }
  return w;
}

}  // namespace palpa::field
