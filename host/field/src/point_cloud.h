// nanoflann's dataset adaptor over a vector of Eigen points, and the 3-D k-d tree over it: the
// neighbour searches of packing (paper §3.1), the Hermite field and the orientation check.
// The cloud only points at the vector, which must outlive the tree. No bounding box is offered
// (nanoflann computes it).
#pragma once

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <numbers>
#include <numeric>
#include <utility>
#include <vector>

#include <nanoflann.hpp>

#include "palpa/field/convex_hull.h"

namespace palpa::field::detail {

struct PointCloud {
  const std::vector<Eigen::Vector3d>* points;
  std::size_t kdtree_get_point_count() const { return points->size(); }
  double kdtree_get_pt(std::size_t idx, std::size_t dim) const {
    return (*points)[idx][static_cast<Eigen::Index>(dim)];
  }
  template <class BBox>
  bool kdtree_get_bbox(BBox& /*bb*/) const {
    return false;
  }
};

using KdTree =
    nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<double, PointCloud>, PointCloud, 3, std::size_t>;

// nanoflann result set: is any sample within `radius` of the query (sqrt(d^2) <= radius, the test
// the nearest sample's distance would take)? The search stops at the first; the bound the tree
// prunes with is a little wider than radius^2, so that none is missed by rounding.
class AnyWithin {
 public:
  explicit AnyWithin(double radius) : radius_(radius), bound_sq_(radius * radius * (1.0 + 1e-9)) {}
  void init() {}
  void clear() {}
  std::size_t size() const { return found_ ? 1 : 0; }
  bool full() const { return true; }
  double worstDist() const { return bound_sq_; }
  bool addPoint(double dist_sq, std::size_t /*j*/) {
    found_ = std::sqrt(dist_sq) <= radius_;
    return !found_;
  }
  bool found() const { return found_; }

 private:
  double radius_, bound_sq_;
  bool found_ = false;
};

// Leaf size for searches whose result does not depend on the order the tree visits samples in
// (a minimum, a list sorted afterwards, whether any sample lies within a radius, the nearest
// distance): the packing's and the guard's wide balls visit fewer nodes than with leaves of 10
// (kitten, 300 cells, one thread: 69 -> 59 ms and 71 -> 65 ms). The k-nearest searches keep 10:
// a tie at the kth distance goes to the sample visited first, so their results follow the tree
// (BoxNearest's do not: it breaks ties by index, palpa/field/box_nearest.h).
inline constexpr std::size_t kRangeLeaf = 24;

// A sample on a rim (an open scan's edge, a hole's): its nearest samples leave an angular gap
// wider than this around it in its tangent plane; on a surface it is ~23 degrees for 16 random
// neighbours (RimSamples in hermite_field.cc, RefineNormalLines in normals.cc).
inline constexpr double kRimGap = 150.0 * std::numbers::pi / 180.0;

// The frame (u, v) = (normal.unitOrthogonal(), normal x u) of the plane normal to unit `normal`
// in which angles round a sample are measured: WidestTangentGap's, RimSamples' direction across
// the gap and the closing rule's sectors (hermite_field.cc). Height fits use TangentFrame (below);
// the two are kept apart because each one's angles are stored and read back in its own frame.
inline std::pair<Eigen::Vector3d, Eigen::Vector3d> AngleFrame(const Eigen::Vector3d& normal) {
  const Eigen::Vector3d u = normal.unitOrthogonal();
  return {u, normal.cross(u)};
}

// The widest angle between consecutive neighbours of P_i (idx[0, count), i itself and any
// neighbour on the line through P_i along `normal` skipped) projected on the plane through P_i
// normal to `normal`, the direction (angle) across its middle in AngleFrame(normal), and how many
// neighbours were projected. At most `Capacity` neighbours are used.
struct TangentGap {
  double gap = 0.0;
  double mid = 0.0;
  std::size_t count = 0;
};
template <std::size_t Capacity>
TangentGap WidestTangentGap(const std::vector<Eigen::Vector3d>& positions, const std::size_t* idx, std::size_t count,
                            std::size_t i, const Eigen::Vector3d& normal) {
  const auto [u, v] = AngleFrame(normal);
  std::array<double, Capacity> angle{};
  std::size_t m = 0;
  for (std::size_t q = 0; q < count && m < Capacity; ++q) {
    if (idx[q] == i) continue;
    const Eigen::Vector3d d = positions[idx[q]] - positions[i];
    const double x = d.dot(u), y = d.dot(v);
    if (x * x + y * y > 0.0) angle[m++] = std::atan2(y, x);
  }
  TangentGap out;
  out.count = m;
  if (m == 0) return out;
  std::sort(angle.begin(), angle.begin() + static_cast<std::ptrdiff_t>(m));
  out.gap = angle[0] + 2.0 * std::numbers::pi - angle[m - 1];
  out.mid = angle[m - 1] + 0.5 * out.gap;
  for (std::size_t q = 1; q < m; ++q)
    if (angle[q] - angle[q - 1] > out.gap) {
      out.gap = angle[q] - angle[q - 1];
      out.mid = angle[q - 1] + 0.5 * out.gap;
    }
  return out;
}

// Unit normal lines from CGAL::jet_estimate_normals over the `neighbours` nearest samples (signs
// arbitrary); (0, 0, 1) where the fit fails, and for fewer than 4 positions. normals_cgal.cc.
void JetNormalLines(const std::vector<Eigen::Vector3d>& positions, int neighbours,
                    std::vector<Eigen::Vector3d>& normals);

// The convex hull of `points` as its outward face planes (unit normal, offset: n . p + d > 0
// outside), its bounds taken about the points' centroid (CGAL's convex_hull_3, hull_cgal.cc); no
// faces for fewer than 4 points or a flat set.
ConvexHull ConvexHullOf(const std::vector<Eigen::Vector3d>& points);

// EachBehindTheOther's `min_sin` for the flat-pair test (orientation.cc) and the stray test
// (samples.cc): sin(2 degrees), so that neighbours on one flat sheet, noise aside, are not a wall.
inline constexpr double kThinWallSin = 0.034899496702500969;

// A sample set, or a piece of one, is closed when its normals' flux |sum_i a_i n_i| is under this
// fraction of its area (0 for a closed surface, by the divergence theorem): 0.001-0.078 on closed
// meshes' sparse, outlier and estimated-normal draws, 0.14-0.51 on their open and range scans.
// Used by FlipSheetsByWinding (normals.cc) and LabelByWinding's ClosedSet (hermite_field.cc).
inline constexpr double kClosedFlux = 0.1;

// Whether P_i and P_j, chord = P_j - P_i (false when zero), each lie behind the other's tangent plane
// (unit normals n_i, n_j) by more than `min_sin` of the chord: the two sides of a wall thinner
// than the spacing (an ear, a flange). A flipped normal's neighbour on its own smooth sheet lies
// on its tangent plane, or in front of it where the sheet is convex, or has it in front of its
// own where the sheet is concave (orientation.cc's flat pairs, samples.cc's stray test). A
// negative `min_sin` lets each lie up to that fraction of the chord in front instead (a convex
// edge's two faces, hermite_field.cc's EdgeSide; with both normals negated, a concave edge's).
inline bool EachBehindTheOther(const Eigen::Vector3d& chord, const Eigen::Vector3d& n_i, const Eigen::Vector3d& n_j,
                               double min_sin) {
  const double length = chord.norm();
  return n_i.dot(chord) < -min_sin * length && n_j.dot(chord) > min_sin * length;
}

// OneSheet's `max_sin` for a coarse sheet: FlipSheetsByWinding's first cut (normals.cc) and the
// orientation check's sheets (orientation.cc), wider than the flat test's 10 degrees so that a
// curved part sampled coarsely stays one sheet.
inline constexpr double kCoarseSheetSin = 0.25;

// Whether P_i and P_j (chord = P_j - P_i) lie on one sheet: normals within acos(min_dot) of each
// other, signs included, and the chord within asin(max_sin) of both tangent planes, so that a
// sign boundary and the two sides of a thin wall separate sheets (false for a zero chord).
// FlipSheetsByWinding's cuts (normals.cc) and the orientation check's sheets (orientation.cc).
inline bool OneSheet(const Eigen::Vector3d& chord, const Eigen::Vector3d& n_i, const Eigen::Vector3d& n_j,
                     double min_dot, double max_sin) {
  const Eigen::Vector3d along = chord.normalized();
  return n_i.dot(n_j) > min_dot && std::abs(n_i.dot(along)) < max_sin && std::abs(n_j.dot(along)) < max_sin;
}

// Disjoint sets over 0..n-1 with path halving; the smaller index is the root, so the sets and
// their roots do not depend on the order of unions (FlipSheetsByWinding's sheets, the MST of
// OrientNormals, the orientation check's sheets).
struct UnionFind {
  std::vector<std::uint32_t> parent;
  explicit UnionFind(std::size_t n) : parent(n) { std::iota(parent.begin(), parent.end(), std::uint32_t{0}); }
  std::uint32_t Find(std::uint32_t x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  }
  bool Unite(std::uint32_t a, std::uint32_t b) {
    a = Find(a);
    b = Find(b);
    if (a == b) return false;
    if (a > b) std::swap(a, b);
    parent[b] = a;
    return true;
  }
};

// The median of `values` (the upper one of an even count), 0 when there are none: the one scale
// of a sample set (spacing, noise) that a few outliers cannot move.
inline double Median(std::vector<double> values) {
  if (values.empty()) return 0.0;
  const auto mid = values.begin() + static_cast<std::ptrdiff_t>(values.size() / 2);
  std::nth_element(values.begin(), mid, values.end());
  return *mid;
}

// Adds to `scatter` the weighted scatter matrix of the points point(0..count) (Eigen::Vector3d,
// model units) about their weighted mean, sum of weight(m) d d^T with d = point(m) - mean, and
// returns that mean (weights' total > 0). One accumulation for every PCA here, so that the same
// points give the same bits: FitLeastVariancePlane, ThinWallCells' layers, FoldedCells
// (samples.cc), WallResidual (normals.cc).
template <class Point, class Weight>
Eigen::Vector3d AddScatter(std::size_t count, Point point, Weight weight, Eigen::Matrix3d& scatter) {
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  double total = 0;
  for (std::size_t m = 0; m < count; ++m) {
    const double w = weight(m);
    centre += w * point(m);
    total += w;
  }
  centre /= total;
  for (std::size_t m = 0; m < count; ++m) {
    const Eigen::Vector3d d = point(m) - centre;
    scatter += weight(m) * d * d.transpose();
  }
  return centre;
}
inline double UnitWeight(std::size_t) { return 1.0; }

// The plane of least variance of the samples idx[0..count) weighted by weight(m) (total > 0):
// through their weighted centre, its normal the scatter matrix's eigenvector of least eigenvalue
// (sign arbitrary), `variance` that eigenvalue (the weighted sum of squared offsets from the plane,
// model units squared). The stray test's plane (samples.cc), the edge refinement's weighted PCA and
// TwoSheetResidual's frame (normals.cc).
struct LeastVariancePlane {
  Eigen::Vector3d centre;
  Eigen::Vector3d normal;
  double variance;
  // The RMS offset of the `count` (unit-weight) samples fitted from the plane, model units.
  double Rms(std::size_t count) const { return std::sqrt(std::max(variance, 0.0) / static_cast<double>(count)); }
};
template <class Weight>
LeastVariancePlane FitLeastVariancePlane(const std::vector<Eigen::Vector3d>& positions, const std::size_t* idx,
                                         std::size_t count, Weight weight) {
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
  const Eigen::Vector3d centre = AddScatter(
      count, [&](std::size_t m) -> const Eigen::Vector3d& { return positions[idx[m]]; }, weight, scatter);
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(scatter);
  return {centre, solver.eigenvectors().col(0), solver.eigenvalues()[0]};
}

// An orthonormal frame (t1, t2) of the plane normal to unit `normal`, with (t1, t2, normal)
// right-handed: the one frame of every height fit here (a fit's coefficients depend on it).
inline std::pair<Eigen::Vector3d, Eigen::Vector3d> TangentFrame(const Eigen::Vector3d& normal) {
  const Eigen::Vector3d axis = std::abs(normal.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  const Eigen::Vector3d t1 = axis.cross(normal).normalized();
  return {t1, normal.cross(t1)};
}

// The RMS residual of a least-squares quadric height over the tangent plane of `normal` at `p`,
// h(u, v) = c0 + c1 u + c2 v + c3 u^2 + c4 uv + c5 v^2, through the samples idx[0..count) that
// `use(j)` accepts (u, v and h in units of `scale`: a well-conditioned fit), over (used - 6)
// degrees of freedom, in model units; < 0 when fewer than `min_used` samples were accepted or the
// fit is not finite. A smooth surface leaves ~0, noise the noise: the normal estimate's noise
// figure and the denoiser's noise measure (normals.cc, samples.cc).
template <class Use>
double QuadricResidual(const std::vector<Eigen::Vector3d>& positions, const std::size_t* idx, std::size_t count,
                       const Eigen::Vector3d& p, const Eigen::Vector3d& normal, double scale, int min_used, Use use) {
  using M6 = Eigen::Matrix<double, 6, 6>;
  using V6 = Eigen::Matrix<double, 6, 1>;
  const auto [t1, t2] = TangentFrame(normal);
  M6 m = M6::Zero();
  V6 rhs = V6::Zero();
  int used = 0;
  for (std::size_t a = 0; a < count; ++a) {
    if (!use(idx[a])) continue;
    const Eigen::Vector3d d = (positions[idx[a]] - p) / scale;
    const double u = d.dot(t1), v = d.dot(t2);
    V6 row;
    row << 1, u, v, u * u, u * v, v * v;
    m += row * row.transpose();
    rhs += row * d.dot(normal);
    ++used;
  }
  if (used < min_used) return -1.0;
  m.diagonal().array() += 1e-9;
  const V6 c = m.ldlt().solve(rhs);
  if (!c.allFinite()) return -1.0;
  double sum2 = 0.0;
  for (std::size_t a = 0; a < count; ++a) {
    if (!use(idx[a])) continue;
    const Eigen::Vector3d d = (positions[idx[a]] - p) / scale;
    const double u = d.dot(t1), v = d.dot(t2);
    const double e = d.dot(normal) - (c[0] + c[1] * u + c[2] * v + c[3] * u * u + c[4] * u * v + c[5] * v * v);
    sum2 += e * e;
  }
  return std::sqrt(sum2 / std::max(used - 6, 1)) * scale;
}

}  // namespace palpa::field::detail
