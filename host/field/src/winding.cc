#include "palpa/field/winding.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
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

// Two lanes of doubles: each lane's arithmetic is the scalar operation (IEEE, no contraction).
using V2 = double __attribute__((vector_size(16)));

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
  expansions_.reserve(nodes_.capacity());
  BuildNode(0, static_cast<std::uint32_t>(points_.size()));
}

std::int32_t WindingNumber::BuildNode(std::uint32_t begin, std::uint32_t end) {
  const auto id = static_cast<std::int32_t>(nodes_.size());
  nodes_.emplace_back();
  expansions_.emplace_back();
  BuildState node;
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
    BuildNode(begin, mid);  // id + 1
    nodes_[static_cast<std::size_t>(id)].right = BuildNode(mid, end);
  }
  Node& out = nodes_[static_cast<std::size_t>(id)];
  out.centre = node.centre;
  out.far2 = beta2_ * node.radius * node.radius;
  out.begin = begin;
  out.end = end;
  Expansion& e = expansions_[static_cast<std::size_t>(id)];
  e.dipole = node.dipole;
  e.trace = node.second.trace();
  e.second = node.second;
  return id;
}

// One node's far-field term at q, d2 = |centre - q|^2 (winding.h).
inline double FarTerm(const V3& centre, const V3& dipole, double trace, const Eigen::Matrix3d& second, const V3& q,
                      double d2) {
  // N . K(x) + trace(grad K(x) B), x = c - q.
  const V3 x = centre - q;
  const double inv_d = 1.0 / std::sqrt(d2);
  const double inv_d3 = inv_d * inv_d * inv_d;
  return kInv4Pi * inv_d3 * (dipole.dot(x) + trace - 3.0 * x.dot(second * x) / d2);
}

double WindingNumber::operator()(const V3& q) const {
  if (nodes_.empty()) return 0.0;
  double w = 0.0;
  std::array<std::int32_t, 128> stack;  // NOLINT(cppcoreguidelines-pro-type-member-init): written before read
  std::size_t top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const auto id = static_cast<std::size_t>(stack[--top]);
    const Node& node = nodes_[id];
    const double d2 = (node.centre - q).squaredNorm();
    if (d2 > node.far2) {
      const Expansion& e = expansions_[id];
      w += FarTerm(node.centre, e.dipole, e.trace, e.second, q, d2);
    } else if (node.right < 0) {
      for (std::uint32_t i = node.begin; i < node.end; ++i) w += Dipole(points_[i], weighted_normals_[i], q);
    } else {
      stack[top++] = static_cast<std::int32_t>(id + 1);
      stack[top++] = node.right;
    }
  }
  return w;
}

void WindingNumber::operator()(std::span<const V3> queries, std::span<double> out) const {
  const std::size_t m = std::min(queries.size(), out.size());
  std::fill(out.begin(), out.begin() + static_cast<std::ptrdiff_t>(m), 0.0);
  if (nodes_.empty() || m == 0) return;
  // Each query meets the nodes it reaches in the order operator() does (depth first, the right
  // child first) and adds the same terms in that order, so its sum is the same to the bit. A
  // stack entry is a node, the queries that reach it (a run of `active`, which grows and shrinks
  // with the stack: an entry's run lies below those of the entries pushed after it) and their
  // bounding box.
  struct Entry {
    V3 lo, hi;
    std::int32_t node;
    std::uint32_t begin, count;
  };
  std::vector<Entry> stack;
  stack.reserve(128);
  std::vector<std::uint32_t> active(m);
  std::iota(active.begin(), active.end(), 0U);
  std::vector<std::uint32_t> far(m);
  V3 lo = queries[0], hi = queries[0];
  for (std::size_t i = 1; i < m; ++i) lo = lo.cwiseMin(queries[i]), hi = hi.cwiseMax(queries[i]);
  stack.push_back({lo, hi, 0, 0, static_cast<std::uint32_t>(m)});

  // The far-field terms of `node` at the queries far[0, count), two at a time: each lane does
  // FarTerm's operations in the order of its Eigen expressions (x, then |x|^2 as squaredNorm;
  // checked bit for bit against it in tests/host/winding_test.cc).
  const auto far_terms = [&](const Node& node, const Expansion& e, const std::uint32_t* idx, std::size_t count) {
    const Eigen::Matrix3d& s = e.second;
    const V3& c = node.centre;
    // In locals: the stores to `out` could alias them (both double) and force a reload a pair.
    const auto both = [](double v) { return V2{v, v}; };
    const V2 c0 = both(c.x()), c1 = both(c.y()), c2 = both(c.z());
    const V2 n0 = both(e.dipole.x()), n1 = both(e.dipole.y()), n2 = both(e.dipole.z()), tr = both(e.trace);
    const V2 s00 = both(s(0, 0)), s01 = both(s(0, 1)), s02 = both(s(0, 2));
    const V2 s10 = both(s(1, 0)), s11 = both(s(1, 1)), s12 = both(s(1, 2));
    const V2 s20 = both(s(2, 0)), s21 = both(s(2, 1)), s22 = both(s(2, 2));
    std::size_t f = 0;
    for (; f + 1 < count; f += 2) {
      const V3& qa = queries[idx[f]];
      const V3& qb = queries[idx[f + 1]];
      const V2 x0 = c0 - V2{qa.x(), qb.x()};
      const V2 x1 = c1 - V2{qa.y(), qb.y()};
      const V2 x2 = c2 - V2{qa.z(), qb.z()};
      const V2 d2 = (x0 * x0 + x1 * x1) + x2 * x2;
      const V2 inv_d = 1.0 / V2{std::sqrt(d2[0]), std::sqrt(d2[1])};
      const V2 inv_d3 = inv_d * inv_d * inv_d;
      const V2 dot = (n0 * x0 + n1 * x1) + n2 * x2;
      const V2 b0 = (s00 * x0 + s01 * x1) + s02 * x2;
      const V2 b1 = (s10 * x0 + s11 * x1) + s12 * x2;
      const V2 b2 = s20 * x0 + (s21 * x1 + s22 * x2);
      const V2 xbx = (x0 * b0 + x1 * b1) + x2 * b2;
      const V2 term = kInv4Pi * inv_d3 * (dot + tr - 3.0 * xbx / d2);
      out[idx[f]] += term[0];
      out[idx[f + 1]] += term[1];
    }
    if (f < count) {
      const V3& q = queries[idx[f]];
      out[idx[f]] += FarTerm(c, e.dipole, e.trace, s, q, (c - q).squaredNorm());
    }
  };
  // A leaf's dipoles at the queries idx[0, count), two at a time, each lane as Dipole.
  const auto leaf_terms = [&](const Node& node, const std::uint32_t* idx, std::size_t count) {
    std::size_t f = 0;
    for (; f + 1 < count; f += 2) {
      const V3& qa = queries[idx[f]];
      const V3& qb = queries[idx[f + 1]];
      V2 w = {out[idx[f]], out[idx[f + 1]]};
      for (std::uint32_t k = node.begin; k < node.end; ++k) {
        const V3& p = points_[k];
        const V3& a = weighted_normals_[k];
        const V2 d0 = V2{p.x(), p.x()} - V2{qa.x(), qb.x()};
        const V2 d1 = V2{p.y(), p.y()} - V2{qa.y(), qb.y()};
        const V2 d2 = V2{p.z(), p.z()} - V2{qa.z(), qb.z()};
        const V2 r2 = (d0 * d0 + d1 * d1) + d2 * d2;
        const V2 term =
            (a.x() * d0 + a.y() * d1 + a.z() * d2) * kInv4Pi / (r2 * V2{std::sqrt(r2[0]), std::sqrt(r2[1])});
        w += r2 > 0.0 ? term : V2{0.0, 0.0};  // 0 at the dipole itself (NaN and infinity dropped)
      }
      out[idx[f]] = w[0];
      out[idx[f + 1]] = w[1];
    }
    if (f < count) {
      const V3& q = queries[idx[f]];
      double w = out[idx[f]];
      for (std::uint32_t k = node.begin; k < node.end; ++k) w += Dipole(points_[k], weighted_normals_[k], q);
      out[idx[f]] = w;
    }
  };

  while (!stack.empty()) {
    const Entry entry = stack.back();
    stack.pop_back();
    const auto id = static_cast<std::size_t>(entry.node);
    const Node& node = nodes_[id];
    const V3& c = node.centre;
    // Whole-run tests, exact: rounding is monotone, so a query's |c - q|^2, computed as in
    // operator(), lies between these bounds computed the same way from the box.
    V3 gap, reach;
    for (Eigen::Index a = 0; a < 3; ++a) {
      gap[a] = std::max({entry.lo[a] - c[a], c[a] - entry.hi[a], 0.0});
      reach[a] = std::max(std::abs(c[a] - entry.lo[a]), std::abs(entry.hi[a] - c[a]));
    }
    const double gap2 = (gap[0] * gap[0] + gap[1] * gap[1]) + gap[2] * gap[2];
    const double reach2 = (reach[0] * reach[0] + reach[1] * reach[1]) + reach[2] * reach[2];
    const std::uint32_t* run = active.data() + entry.begin;
    if (gap2 > node.far2) {  // every query is far
      far_terms(node, expansions_[id], run, entry.count);
      continue;
    }
    Entry near = entry;
    if (!(reach2 <= node.far2)) {  // some may be far: sort them out
      const std::size_t near_begin = entry.begin + entry.count;
      if (active.size() < near_begin + entry.count) active.resize(near_begin + entry.count);
      run = active.data() + entry.begin;
      std::size_t n_far = 0, n_near = 0;
      near.lo = V3::Constant(std::numeric_limits<double>::infinity());
      near.hi = -near.lo;
      for (std::size_t a = 0; a < entry.count; ++a) {
        const std::uint32_t i = run[a];
        const V3& q = queries[i];
        if ((c - q).squaredNorm() > node.far2) {
          far[n_far++] = i;
        } else {
          active[near_begin + n_near++] = i;
          near.lo = near.lo.cwiseMin(q);
          near.hi = near.hi.cwiseMax(q);
        }
      }
      if (n_far > 0) far_terms(node, expansions_[id], far.data(), n_far);
      if (n_near == 0) continue;
      near.begin = static_cast<std::uint32_t>(near_begin);
      near.count = static_cast<std::uint32_t>(n_near);
    }
    if (node.right < 0) {
      leaf_terms(node, active.data() + near.begin, near.count);
      continue;
    }
    near.node = static_cast<std::int32_t>(id + 1);
    stack.push_back(near);
    near.node = node.right;
    stack.push_back(near);
  }
}

}  // namespace palpa::field
