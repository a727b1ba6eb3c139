// The k nearest samples of many query points that share one small box (the nodes of a brick, the
// centres of a block of bricks), found from one search per box instead of one tree search per
// point. With c the box's centre, r the farthest query's distance from c and d_k(c) the k-th
// nearest sample's distance from c, every query p has d_k(p) <= d_k(c) + |p - c|, so its k
// nearest lie within d_k(c) + 2 r of c: one k-nearest and one radius search at c give a list
// that holds them, and each query scans that list, sorted by distance from c, up to the first
// sample that can no longer be nearer than its k-th so far. Host only, non-RT.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <limits>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <nanoflann.hpp>

namespace palpa::field {

/// k-nearest queries within a box, over a nanoflann k-d tree `Tree` (3-D, double coordinates,
/// std::size_t indices, L2_Simple_Adaptor) built on `positions` (metres). The answer to Find is
/// the exact k nearest samples with nanoflann's squared distances (the same sum of squared
/// coordinate differences), ordered by (squared distance, index): independent of the tree's
/// shape, including ties. The tree and positions must outlive the object; one object per thread.
template <class Tree>
class BoxNearest {
 public:
  /// `k_max`: the largest k that Find will be asked for (the search at the centre's depth).
  BoxNearest(const Tree& tree, const std::vector<Eigen::Vector3d>& positions, std::size_t k_max)
      : tree_(tree), positions_(positions), k_max_(k_max) {}

  /// The box: every later query lies within `radius` (metres) of `centre`. Drops the previous
  /// box's list; the searches are made by the first Find.
  void Box(const Eigen::Vector3d& centre, double radius) {
    centre_ = centre;
    radius_ = radius;
    ready_ = false;
  }

  /// The min(k, n) samples nearest `p` (within the box; k <= k_max) into idx[0..) and d2[0..)
  /// (squared metres), nearest first, ties by lower index. Returns how many.
  std::size_t Find(const Eigen::Vector3d& p, std::size_t k, std::size_t* idx, double* d2) {
    if (!ready_) Prepare();
    if (k == 0) return 0;
    const double from_centre = (p - centre_).norm();
    const double px = p.x(), py = p.y(), pz = p.z();
    const std::size_t real = list_.size(), n = from_.size();  // from_, x_, y_, z_: padded to kBlock
    // L2_Simple_Adaptor::evalMetric's sum, term by term.
    const auto distance = [&](std::size_t m) {
      const double dx = px - x_[m], dy = py - y_[m], dz = pz - z_[m];
      return (dx * dx + dy * dy) + dz * dz;
    };
    std::size_t count = 0;
    const auto insert = [&](double dist, std::size_t j) {
      std::size_t i = count < k ? count++ : k - 1;
      for (; i > 0 && (d2[i - 1] > dist || (d2[i - 1] == dist && idx[i - 1] > j)); --i) {
        d2[i] = d2[i - 1];
        idx[i] = idx[i - 1];
      }
      d2[i] = dist;
      idx[i] = j;
    };
    // Sorted by distance from the centre: past p's distance from it plus the k-th distance so far,
    // no sample is nearer p (the margin covers rounding of the square roots).
    const auto past = [&](std::size_t m) { return from_[m] > (from_centre + std::sqrt(d2[k - 1])) * (1.0 + 1e-9); };
    const auto offer = [&](double dist, std::size_t j) {
      if (dist < d2[k - 1] || (dist == d2[k - 1] && j < idx[k - 1])) insert(dist, j);
    };
    std::size_t m = 0;
    for (; m < real && count < k; ++m) insert(distance(m), index_[m]);
    if (count < k) return count;
    for (; m % kBlock != 0; ++m) {
      if (past(m)) return count;
      offer(distance(m), index_[m]);
    }
    // Then a block at a time, up to the block that starts past the bound: a sample of that last
    // block past it lies farther than the k-th, so it is measured and dropped (padding too: +inf).
    for (; m < n; m += kBlock) {
      if (past(m)) break;
      std::array<double, kBlock> dist;
      for (std::size_t l = 0; l < kBlock; ++l) dist[l] = distance(m + l);
      const double worst = d2[k - 1];
      bool any = false;
      for (std::size_t l = 0; l < kBlock; ++l) any = any || !(dist[l] > worst);
      if (!any) continue;
      for (std::size_t l = 0; l < kBlock; ++l) offer(dist[l], index_[m + l]);
    }
    return count;
  }

 private:
  static constexpr std::size_t kBlock = 4;

  void Prepare() {
    ready_ = true;
    list_.clear();
    idx_.resize(k_max_);
    d2_.resize(k_max_);
    const std::size_t got = k_max_ > 0 ? tree_.knnSearch(centre_.data(), k_max_, idx_.data(), d2_.data()) : 0;
    if (got < k_max_) {  // no more than k_max samples: all of them
      for (std::size_t j = 0; j < positions_.size(); ++j) list_.emplace_back((positions_[j] - centre_).norm(), j);
    } else {
      const double reach = std::sqrt(d2_[got - 1]) + 2.0 * radius_;
      // A little wider than reach^2 (nanoflann keeps d^2 < bound), so that rounding drops none;
      // the scan measures each again.
      found_.clear();
      tree_.radiusSearch(centre_.data(), reach * reach * (1.0 + 1e-9) + 1e-300, found_,
                         nanoflann::SearchParams(32, 0, false));
      for (const auto& [j, dist] : found_) list_.emplace_back(std::sqrt(dist), j);
    }
    std::sort(list_.begin(), list_.end());
    // The list side by side, padded to whole blocks with samples at infinity (distance +inf: never
    // kept): the scan reads them in order instead of scattered through positions_, a block of
    // distances at a time (a far box's list holds thousands, and its scan was most of the time).
    const std::size_t n = list_.size();
    const std::size_t padded = (n + kBlock - 1) / kBlock * kBlock;
    constexpr double kFar = std::numeric_limits<double>::infinity();
    from_.assign(padded, kFar);
    x_.assign(padded, kFar);
    y_.assign(padded, kFar);
    z_.assign(padded, kFar);
    index_.resize(n);
    for (std::size_t m = 0; m < n; ++m) {
      const auto& [from, j] = list_[m];
      from_[m] = from;
      x_[m] = positions_[j].x();
      y_[m] = positions_[j].y();
      z_[m] = positions_[j].z();
      index_[m] = j;
    }
    index_.resize(padded, positions_.size());
  }

  const Tree& tree_;
  const std::vector<Eigen::Vector3d>& positions_;
  std::size_t k_max_;
  Eigen::Vector3d centre_ = Eigen::Vector3d::Zero();
  double radius_ = 0.0;
  bool ready_ = false;
  std::vector<std::pair<double, std::size_t>> list_;  // (distance from the centre, sample)
  std::vector<double> from_, x_, y_, z_;              // list_ in order: distance from the centre, position
  std::vector<std::size_t> index_;                    // and sample (padding: positions_.size())
  std::vector<std::size_t> idx_;
  std::vector<double> d2_;
  std::vector<std::pair<std::size_t, double>> found_;
};

}  // namespace palpa::field
