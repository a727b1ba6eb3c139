#include "palpa/field/winding.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>

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
constexpr std::uint32_t kParallelBuild = 1024;  // points of a node whose halves build in parallel
// Batch's per-thread buffers are kept for the next call up to this many queries' worth (a plane
// of a 1,200-cell grid); a larger batch frees them.
constexpr std::size_t kKeptQueries = std::size_t{1} << 20;
constexpr double kInv4Pi = 0.25 / std::numbers::pi;

// One dipole's term; 0 at the dipole itself (q on a sample: the term is undefined there).
inline double Dipole(const V3& at, const V3& weighted_normal, const V3& q) {
  const V3 d = at - q;
  const double r2 = d.squaredNorm();
  if (!(r2 > 0.0)) return 0.0;
  return weighted_normal.dot(d) * kInv4Pi / (r2 * std::sqrt(r2));
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

// L lanes of doubles: each lane's arithmetic is the scalar operation (IEEE, no contraction), so
// a lane gives the bits the scalar code gives.
template <int L>
struct LanesOf;
template <>
struct LanesOf<2> {
  using type = double __attribute__((vector_size(16)));
};
template <>
struct LanesOf<4> {
  using type = double __attribute__((vector_size(32)));
};
template <int L>
using Lanes = typename LanesOf<L>::type;

// The far-field terms of a node at the queries idx[f, count), L at a time, each lane doing
// FarTerm's operations in the order of its Eigen expressions (x, then |x|^2 as squaredNorm;
// checked bit for bit against it in tests/host/winding_test.cc). Returns where it stopped.
template <int L>
[[gnu::always_inline]] inline std::size_t FarLanes(const V3& c, const V3& n, double trace, const Eigen::Matrix3d& s,
                                                   std::span<const V3> queries, const std::uint32_t* idx, std::size_t f,
                                                   std::size_t count, std::span<double> out) {
  using V = Lanes<L>;
  // In locals: the stores to `out` could alias them (both double) and force a reload a group.
  // A scalar in an expression with lanes stands for itself on every lane.
  const double c0 = c.x(), c1 = c.y(), c2 = c.z();
  const double n0 = n.x(), n1 = n.y(), n2 = n.z(), tr = trace;
  const double s00 = s(0, 0), s01 = s(0, 1), s02 = s(0, 2);
  const double s10 = s(1, 0), s11 = s(1, 1), s12 = s(1, 2);
  const double s20 = s(2, 0), s21 = s(2, 1), s22 = s(2, 2);
  for (; f + L <= count; f += L) {
    V q0, q1, q2;
    for (int l = 0; l < L; ++l) {
      const V3& q = queries[idx[f + static_cast<std::size_t>(l)]];
      q0[l] = q.x(), q1[l] = q.y(), q2[l] = q.z();
    }
    const V x0 = c0 - q0, x1 = c1 - q1, x2 = c2 - q2;
    const V d2 = (x0 * x0 + x1 * x1) + x2 * x2;
    V root;
    for (int l = 0; l < L; ++l) root[l] = std::sqrt(d2[l]);
    const V inv_d = 1.0 / root;
    const V inv_d3 = inv_d * inv_d * inv_d;
    const V dot = (n0 * x0 + n1 * x1) + n2 * x2;
    const V b0 = (s00 * x0 + s01 * x1) + s02 * x2;
    const V b1 = (s10 * x0 + s11 * x1) + s12 * x2;
    const V b2 = s20 * x0 + (s21 * x1 + s22 * x2);
    const V xbx = (x0 * b0 + x1 * b1) + x2 * b2;
    const V term = kInv4Pi * inv_d3 * (dot + tr - 3.0 * xbx / d2);
    for (int l = 0; l < L; ++l) out[idx[f + static_cast<std::size_t>(l)]] += term[l];
  }
  return f;
}

// A leaf's dipoles [begin, end) at the queries idx[f, count), L at a time, each lane as Dipole.
// Returns where it stopped.
template <int L>
[[gnu::always_inline]] inline std::size_t LeafLanes(const V3* points, const V3* weighted_normals, std::uint32_t begin,
                                                    std::uint32_t end, std::span<const V3> queries,
                                                    const std::uint32_t* idx, std::size_t f, std::size_t count,
                                                    std::span<double> out) {
  using V = Lanes<L>;
  for (; f + L <= count; f += L) {
    V q0, q1, q2, w;
    for (int l = 0; l < L; ++l) {
      const V3& q = queries[idx[f + static_cast<std::size_t>(l)]];
      q0[l] = q.x(), q1[l] = q.y(), q2[l] = q.z();
      w[l] = out[idx[f + static_cast<std::size_t>(l)]];
    }
    for (std::uint32_t k = begin; k < end; ++k) {
      const V3& p = points[k];
      const V3& a = weighted_normals[k];
      const V d0 = p.x() - q0, d1 = p.y() - q1, d2 = p.z() - q2;
      const V r2 = (d0 * d0 + d1 * d1) + d2 * d2;
      V root;
      for (int l = 0; l < L; ++l) root[l] = std::sqrt(r2[l]);
      const V term = (a.x() * d0 + a.y() * d1 + a.z() * d2) * kInv4Pi / (r2 * root);
      w += r2 > 0.0 ? term : V{};  // 0 at the dipole itself (NaN and infinity dropped)
    }
    for (int l = 0; l < L; ++l) out[idx[f + static_cast<std::size_t>(l)]] = w[l];
  }
  return f;
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

SampleProbes::SampleProbes(const std::vector<V3>& positions, const std::vector<V3>& normals, Walls walls,
                           std::span<const std::uint8_t> thin_walls)
    : positions_(positions) {
  const std::size_t n = positions.size();
  if (n <= kNeighbours || normals.size() != n) return;
  areas_.assign(n, 0.0);
  offsets_.assign(n, 0.0);
  const detail::PointCloud cloud{&positions};
  const detail::KdTree tree(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(10));
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 256), [&](const auto& r) {
    std::array<std::size_t, kNeighbours + 1> idx{};
    std::array<double, kNeighbours + 1> d2{};
    for (std::size_t i = r.begin(); i != r.end(); ++i) {
      const std::size_t got = tree.knnSearch(positions[i].data(), kNeighbours + 1, idx.data(), d2.data());
      areas_[i] = std::numbers::pi * d2[got - 1] / static_cast<double>(got - 1);  // as SampleAreas
      double d = 0.5 * std::sqrt(d2[got - 1]);
      double nearest2 = 0.0;  // the nearest other sample's squared distance
      const bool thin = thin_walls.size() == n && thin_walls[i] != 0;
      for (std::size_t m = 0; m < got; ++m) {
        if (idx[m] == i) continue;
        if (nearest2 == 0.0) nearest2 = d2[m];
        const double facing = normals[idx[m]].dot(normals[i]);
        // Not a wall thinner than the spacing (its other side the nearest samples) unless the
        // caller found it (thin_walls): elsewhere a stacked neighbour that near is a facet's step
        // or a fin's root, and a probe held within 0.4 of it turned CGAL's pinion's facets and the
        // fin's root row (FlipSheetsByWinding's tests) for nothing.
        const bool stacked = walls == Walls::kEitherSign && std::abs(facing) > 0.5 &&
                             (thin || d2[m] > kStackedFromNearest * kStackedFromNearest * nearest2) &&
                             std::abs(normals[i].dot(positions[idx[m]] - positions[i])) > 0.5 * std::sqrt(d2[m]);
        if (facing < -0.5 || stacked) {
          d = std::min(d, 0.4 * std::sqrt(d2[m]));
          break;
        }
      }
      offsets_[i] = d;
    }
  });
  order_.assign(tree.vAcc.begin(), tree.vAcc.end());
}

void SampleProbes::Winding(const std::vector<V3>& normals, std::vector<double>& inside,
                           std::vector<double>& outside) const {
  const std::size_t n = positions_.size();
  inside.assign(n, 0.0);
  outside.assign(n, 0.0);
  const WindingNumber winding(positions_, normals, areas_);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 64), [&](const auto& r) {
    std::vector<V3> probes;
    std::vector<double> w;
    for (std::size_t at = r.begin(); at != r.end(); ++at) {
      const std::size_t i = order_[at];
      if (!(offsets_[i] > 0)) continue;
      probes.push_back(positions_[i] - offsets_[i] * normals[i]);
      probes.push_back(positions_[i] + offsets_[i] * normals[i]);
    }
    w.resize(probes.size());
    winding(probes, w);
    std::size_t probe = 0;
    for (std::size_t at = r.begin(); at != r.end(); ++at) {
      const std::size_t i = order_[at];
      if (!(offsets_[i] > 0)) continue;
      inside[i] = w[probe];
      outside[i] = w[probe + 1];
      probe += 2;
    }
  });
}

double SampleProbes::OwnDisc(double a, double d) { return 0.5 * (1.0 - d / std::sqrt(d * d + a / std::numbers::pi)); }

void SampleProbes::InsideOutside(const std::vector<V3>& normals, std::vector<double>& inside,
                                 std::vector<double>& outside) const {
  const std::size_t n = positions_.size();
  inside.assign(n, 0.0);
  outside.assign(n, 0.0);
  if (order_.empty() || normals.size() != n) return;
  Winding(normals, inside, outside);
  for (std::size_t i = 0; i < n; ++i) {
    const double d = offsets_[i];
    if (!(d > 0)) continue;
    const double own = OwnDisc(areas_[i], d) - areas_[i] * kInv4Pi / (d * d);  // the disc for the point dipole
    inside[i] += own;
    outside[i] -= own;
  }
}

std::vector<double> SampleProbes::Jumps(const std::vector<V3>& normals) const {
  const std::size_t n = positions_.size();
  std::vector<double> jump(n, 1.0);
  if (order_.empty() || normals.size() != n) return jump;
  std::vector<double> inside, outside;
  Winding(normals, inside, outside);
  for (std::size_t i = 0; i < n; ++i) {
    const double d = offsets_[i];
    if (!(d > 0)) continue;
    const double a = areas_[i];
    const double own_dipole = a * kInv4Pi / (d * d);  // at each probe, +inside -outside
    const double own_disc = OwnDisc(a, d);
    jump[i] = inside[i] - outside[i] - 2.0 * own_dipole + 2.0 * own_disc;
  }
  return jump;
}

std::vector<double> SampleProbes::Levels(const std::vector<V3>& normals) const {
  const std::size_t n = positions_.size();
  std::vector<double> level(n, 0.5);
  if (order_.empty() || normals.size() != n) return level;
  std::vector<double> inside, outside;
  Winding(normals, inside, outside);
  for (std::size_t i = 0; i < n; ++i)
    if (offsets_[i] > 0) level[i] = 0.5 * (inside[i] + outside[i]);
  return level;
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
  const auto n = static_cast<std::uint32_t>(points_.size());
  nodes_.resize(SubtreeNodes(n));
  expansions_.resize(nodes_.size());
  BuildNode(0, 0, n);
}

std::uint32_t WindingNumber::SubtreeNodes(std::uint32_t count) {
  if (count <= kLeafSize) return 1;
  return 1 + SubtreeNodes(count / 2) + SubtreeNodes(count - count / 2);
}

void WindingNumber::BuildNode(std::uint32_t id, std::uint32_t begin, std::uint32_t end) {
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
    // The halves own disjoint ranges of points and of nodes: the same tree, built in parallel
    // where they are large (a serial build was 2 ms of the kitten's build, twice).
    const std::uint32_t right = id + 1 + SubtreeNodes(mid - begin);
    nodes_[id].right = static_cast<std::int32_t>(right);
    if (end - begin >= kParallelBuild) {
      tbb::parallel_invoke([&] { BuildNode(id + 1, begin, mid); }, [&] { BuildNode(right, mid, end); });
    } else {
      BuildNode(id + 1, begin, mid);
      BuildNode(right, mid, end);
    }
  }
  Node& out = nodes_[id];
  out.centre = node.centre;
  out.far2 = beta2_ * node.radius * node.radius;
  out.begin = begin;
  out.end = end;
  Expansion& e = expansions_[id];
  e.dipole = node.dipole;
  e.trace = node.second.trace();
  e.second = node.second;
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

template <int kLanes>
[[gnu::always_inline]] inline void WindingNumber::Batch(std::span<const V3> queries, std::span<double> out) const {
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
  // Kept per thread (kKeptQueries): callers batch a plane or a brick at a time, thousands of
  // calls, and a plane's fresh buffers were mapped and unmapped by malloc at every call (fin90's
  // closure search, 1.2 million points: half its time).
  thread_local std::vector<Entry> stack;
  thread_local std::vector<std::uint32_t> active;
  thread_local std::vector<std::uint32_t> far;
  stack.clear();
  active.resize(m);
  std::iota(active.begin(), active.end(), 0U);
  far.resize(m);
  V3 lo = queries[0], hi = queries[0];
  for (std::size_t i = 1; i < m; ++i) lo = lo.cwiseMin(queries[i]), hi = hi.cwiseMax(queries[i]);
  stack.push_back({lo, hi, 0, 0, static_cast<std::uint32_t>(m)});

  const auto far_terms = [&](const Node& node, const Expansion& e, const std::uint32_t* idx, std::size_t count)
      __attribute__((always_inline)) {
    std::size_t f = FarLanes<kLanes>(node.centre, e.dipole, e.trace, e.second, queries, idx, 0, count, out);
    if constexpr (kLanes > 2) f = FarLanes<2>(node.centre, e.dipole, e.trace, e.second, queries, idx, f, count, out);
    if (f < count) {
      const V3& q = queries[idx[f]];
      out[idx[f]] += FarTerm(node.centre, e.dipole, e.trace, e.second, q, (node.centre - q).squaredNorm());
    }
  };
  const auto leaf_terms = [&](const Node& node, const std::uint32_t* idx, std::size_t count)
      __attribute__((always_inline)) {
    const V3* p = points_.data();
    const V3* a = weighted_normals_.data();
    std::size_t f = LeafLanes<kLanes>(p, a, node.begin, node.end, queries, idx, 0, count, out);
    if constexpr (kLanes > 2) f = LeafLanes<2>(p, a, node.begin, node.end, queries, idx, f, count, out);
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
  if (active.capacity() > 2 * kKeptQueries) active = {};
  if (far.capacity() > kKeptQueries) far = {};
}

void WindingNumber::operator()(std::span<const V3> queries, std::span<double> out) const {
#if defined(__x86_64__)
  // Four lanes where the CPU has AVX2 (the same operations on each lane: the same bits).
  static const bool avx2 = __builtin_cpu_supports("avx2") != 0;
  if (avx2) {
    BatchAvx2(queries, out);
    return;
  }
#endif
  Batch<2>(queries, out);
}

void WindingNumber::BatchTwoLanes(std::span<const V3> queries, std::span<double> out) const { Batch<2>(queries, out); }

#if defined(__x86_64__)
__attribute__((target("avx2"))) void WindingNumber::BatchAvx2(std::span<const V3> queries,
                                                              std::span<double> out) const {
  Batch<4>(queries, out);
}
#else
void WindingNumber::BatchAvx2(std::span<const V3> queries, std::span<double> out) const { Batch<2>(queries, out); }
#endif

}  // namespace palpa::field
