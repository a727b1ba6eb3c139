#include "palpa/field/packing.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <limits>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <nanoflann.hpp>

#include "point_cloud.h"

namespace palpa::field {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kCoincidentRelEps = 1e-12;  // relative to the longest bounding-box side
constexpr std::size_t kNeighbours = 16;
constexpr std::size_t kProbeNeighbours = 4;  // a few, so P_i itself and duplicates do not fill it
constexpr int kShrinkSteps = 8;
// The radius search is inflated by this factor so that rounding in |P_j - c|^2 < r0^2 can never
// drop a point with r_ij < r0 (its true margin is 2 (-n.a) (r0 - r_ij), far above the rounding).
constexpr double kSearchInflation = 1.0 + 1e-6;
// Above this many extents r0 is effectively unbounded and the ball test loses precision: fall
// back to the exhaustive loop for that point.
constexpr double kMaxSearchRadiusRel = 1e6;

double LongestSide(const std::vector<Eigen::Vector3d>& positions) {
  if (positions.empty()) return 0.0;
  Eigen::Vector3d lo = positions.front();
  Eigen::Vector3d hi = lo;
  for (const Eigen::Vector3d& p : positions) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  return (hi - lo).maxCoeff();
}

// Squared distance below which two points count as the same point.
double CoincidentSquared(double longest_side) {
  const double eps = kCoincidentRelEps * longest_side;
  return eps * eps;
}

// r_ij of eq. 2, or +inf when P_j does not constrain the ball at P_i. Both the brute force and
// the tree search call this one function, so they agree bit for bit.
inline double PairRadius(const Eigen::Vector3d& p, const Eigen::Vector3d& n, const Eigen::Vector3d& q,
                         double coincident_sq) {
  const Eigen::Vector3d a = q - p;
  const double a2 = a.squaredNorm();
  if (a2 <= coincident_sq) return kInf;
  const double depth = -n.dot(a);
  if (!(depth > 0.0)) return kInf;
  return a2 / (2.0 * depth);
}

double BruteForceRadius(const std::vector<Eigen::Vector3d>& positions, const std::vector<Eigen::Vector3d>& normals,
                        std::size_t i, double r_max, double coincident_sq) {
  double r = r_max;
  for (std::size_t j = 0; j < positions.size(); ++j) {
    if (j == i) continue;
    r = std::min(r, PairRadius(positions[i], normals[i], positions[j], coincident_sq));
  }
  return r;
}

using detail::KdTree;
using detail::PointCloud;

// nanoflann result set that keeps only min_j r_ij over the points it is offered, avoiding a
// result vector per query.
class MinRadiusResult {
 public:
  MinRadiusResult(double search_radius_sq, const std::vector<Eigen::Vector3d>& positions, const Eigen::Vector3d& p,
                  const Eigen::Vector3d& n, double coincident_sq, double r0)
      : search_radius_sq_(search_radius_sq),
        positions_(positions),
        p_(p),
        n_(n),
        coincident_sq_(coincident_sq),
        r_(r0) {}

  void init() {}
  void clear() {}
  std::size_t size() const { return 0; }
  bool full() const { return true; }
  double worstDist() const { return search_radius_sq_; }
  bool addPoint(double dist_sq, std::size_t index) {
    if (dist_sq < search_radius_sq_) {
      r_ = std::min(r_, PairRadius(p_, n_, positions_[index], coincident_sq_));
    }
    return true;
  }
  double radius() const { return r_; }

 private:
  double search_radius_sq_;
  const std::vector<Eigen::Vector3d>& positions_;
  const Eigen::Vector3d& p_;
  const Eigen::Vector3d& n_;
  double coincident_sq_;
  double r_;
};

}  // namespace

std::vector<double> PackingRadiiBruteForce(const std::vector<Eigen::Vector3d>& positions,
                                           const std::vector<Eigen::Vector3d>& normals, double r_max) {
  if (positions.size() != normals.size()) return {};
  const double coincident_sq = CoincidentSquared(LongestSide(positions));
  std::vector<double> radii(positions.size());
  for (std::size_t i = 0; i < positions.size(); ++i) {
    radii[i] = BruteForceRadius(positions, normals, i, r_max, coincident_sq);
  }
  return radii;
}

std::vector<double> PackingRadii(const std::vector<Eigen::Vector3d>& positions,
                                 const std::vector<Eigen::Vector3d>& normals, double r_max) {
  if (positions.size() != normals.size()) return {};
  const std::size_t n = positions.size();
  std::vector<double> radii(n, r_max);
  if (n < 2) return radii;

  const double extent = LongestSide(positions);
  const double coincident_sq = CoincidentSquared(extent);
  const PointCloud cloud{&positions};
  // The radius is the minimum over every sample, whichever the tree visits first (its k-nearest
  // searches only bound the last search's ball).
  const KdTree tree(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(detail::kRangeLeaf));
  const std::size_t k = std::min(kNeighbours, n);

  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 64), [&](const tbb::blocked_range<std::size_t>& range) {
    std::array<std::size_t, kNeighbours> nn_index{};
    std::array<double, kNeighbours> nn_dist_sq{};
    for (std::size_t i = range.begin(); i != range.end(); ++i) {
      const Eigen::Vector3d& p = positions[i];
      const Eigen::Vector3d& normal = normals[i];
      // Upper bound from the nearest neighbours: r_i <= r_ij for any j.
      double r0 = r_max;
      const std::size_t found = tree.knnSearch(p.data(), k, nn_index.data(), nn_dist_sq.data());
      for (std::size_t m = 0; m < found; ++m) {
        r0 = std::min(r0, PairRadius(p, normal, positions[nn_index[m]], coincident_sq));
      }
      // Shrink r0 by probing the nearest neighbours of the current centre: if the ball holds any
      // point, the one nearest its centre is inside. Cheap, and keeps the final search small on
      // flat regions where the neighbours of P_i give no bound.
      for (int step = 0; step < kShrinkSteps && r0 <= kMaxSearchRadiusRel * extent; ++step) {
        const Eigen::Vector3d probe = p - r0 * normal;
        const std::size_t got = tree.knnSearch(probe.data(), kProbeNeighbours, nn_index.data(), nn_dist_sq.data());
        double r_new = r0;
        for (std::size_t m = 0; m < got; ++m) {
          r_new = std::min(r_new, PairRadius(p, normal, positions[nn_index[m]], coincident_sq));
        }
        if (!(r_new < r0)) break;
        r0 = r_new;
      }
      if (!(r0 <= kMaxSearchRadiusRel * extent)) {
        radii[i] = BruteForceRadius(positions, normals, i, r_max, coincident_sq);
        continue;
      }
      // Every j with r_ij < r0 lies strictly inside the ball (P_i - r0 n_i, r0).
      const Eigen::Vector3d centre = p - r0 * normal;
      const double search = r0 * kSearchInflation;
      MinRadiusResult result(search * search, positions, p, normal, coincident_sq, r0);
      tree.findNeighbors(result, centre.data(), nanoflann::SearchParams());
      radii[i] = result.radius();
    }
  });
  return radii;
}

Packing PackSpheres(const std::vector<Eigen::Vector3d>& positions, const std::vector<Eigen::Vector3d>& normals,
                    double r_max) {
  Packing packing;
  packing.radii = PackingRadii(positions, normals, r_max);
  packing.centres.resize(packing.radii.size());
  for (std::size_t i = 0; i < packing.radii.size(); ++i) {
    packing.centres[i] = positions[i] - packing.radii[i] * normals[i];
  }
  return packing;
}

}  // namespace palpa::field
