// Generalized winding number of oriented points (Barill, Dickson, Schmidt, Levin, Jacobson 2018,
// "Fast Winding Numbers for Soups and Clouds", ACM TOG 37(4)): each sample P_i with outward unit
// normal n_i and area a_i is a dipole, and
//     w(q) = sum_i a_i n_i . (P_i - q) / (4 pi |P_i - q|^3),
// which is ~1 inside a closed sampled surface, ~0 outside, and for an open or one-sided scan
// changes by ~1 across the samples and smoothly elsewhere: w = 1/2 is a surface that closes the
// holes. It is a global inside/outside measure that survives holes, noise and outliers (one
// stray sample adds a dipole of its own small area only). Issue 20.
//
// Fast evaluation: a binary tree over the samples; a node far from q (|q - c| > beta r, c the
// area-weighted centre, r the node's radius about c) contributes the first two terms of the
// Taylor expansion of its dipoles about c (as the paper): with K(x) = x / (4 pi |x|^3),
// x = c - q, N = sum a_i n_i and B = sum a_i n_i (P_i - c)^T,
//     N . K(x) + trace(grad K(x) B),  grad K(x) = (I / |x|^3 - 3 x x^T / |x|^5) / (4 pi),
// with error ~ (r / |x|)^2 of the node's area term. Host only, non-RT; const queries are
// thread-safe.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Dense>

namespace palpa::field {

/// Area of each sample's share of the surface: pi s_i^2 / k, s_i the distance to its k-th nearest
/// other sample (k samples share a disc of radius s_i on a uniformly sampled surface). Unbiased
/// for random samples; on regular lattices within 3 % for k = 16, up to 14 % for k = 8 (total
/// over the sphere, tests/host/winding_test.cc). Units of `positions` squared. Parallel.
std::vector<double> SampleAreas(const std::vector<Eigen::Vector3d>& positions, int k = 8);

/// Two probes per sample, P_i -+ d_i n_i, and w there: the winding-outlier test's jump
/// (FindWindingOutliers, samples.h) and the orientation repair's level (FlipInvertedParts,
/// normals.h). d_i = min(s_i / 2, 0.4 t_i): s_i the distance to the 16th nearest other sample,
/// t_i to the nearest of those 16 whose normal is opposite (n . n_j < -0.5: a thin wall's other
/// side, which a probe must not pass), fixed by the normals given here; areas as SampleAreas with
/// k = 16. One k-d tree gives both and an order that keeps neighbours' probes in one batch; each
/// call then takes the current normals (same size; a flip moves its probes to the other side).
/// With 16 samples or fewer, or normals of another size, nothing is measured (jumps 1, levels
/// 1/2). `positions` must outlive the object. Host only, non-RT; parallel, deterministic.
class SampleProbes {
 public:
  /// Which neighbours count as a wall's other side for t_i.
  enum class Walls {
    kOppositeNormals,  ///< n . n_j < -0.5 (as above)
    /// also a neighbour stacked along the normal whatever its sign: |n . n_j| > 0.5, the chord
    /// more than 30 degrees off the tangent plane, and farther than 1.5 x the nearest sample (a
    /// wall thinner than that keeps the far probes), or at any distance from a sample marked in
    /// `thin_walls`. For sign searches, where a wall's two sides may hold one sign: the elk's palms
    /// (2-3 spacings thick), whose wrong side's probes otherwise reach past the wall's middle and
    /// read the flip of that side as a loss.
    kEitherSign,
  };
  /// thin_walls (Walls::kEitherSign only; empty, or one flag per sample): samples on a wall thinner
  /// than the spacing, whose other side was found by the caller (FlipSheetsByWinding: a two-sheet
  /// fit of the nearest). Their probes stay within 0.4 of a stacked neighbour however near: the
  /// sheet energy reads the dipoles nearest a probe as smoothed discs, and probes beyond the wall's
  /// middle score a flip of either side the same (CGAL's rotor, blades 0.6 spacings thick).
  SampleProbes(const std::vector<Eigen::Vector3d>& positions, const std::vector<Eigen::Vector3d>& normals,
               Walls walls = Walls::kOppositeNormals, std::span<const std::uint8_t> thin_walls = {});
  /// J_i = w(P_i - d_i n_i) - w(P_i + d_i n_i), the sample's own dipole counted as the disc of
  /// area a_i it stands for (a dipole's 1/d^2 would decide the jump alone at small d): about 1 on
  /// a surface sampled with the right areas (a sphere: within 0.15, median 0.95); near 0 where the
  /// sample disagrees with the others.
  std::vector<double> Jumps(const std::vector<Eigen::Vector3d>& normals) const;
  /// (w(P_i - d_i n_i) + w(P_i + d_i n_i)) / 2: about +1/2 on a closed surface oriented outward
  /// (w 1 inside, 0 outside), -1/2 on a closed part of it oriented inward as a whole (w -1 inside
  /// that part), 0 on a flat open sheet, between 0 and +1/2 on an open scan seen from outside
  /// (knot1, fandisk, sphere, bull, cow, femur, elk, camel scanned from 1, 3 or 6 views or without
  /// their -z side: mean 0.07-0.45; mean -0.15 for a one-view scan oriented inward).
  std::vector<double> Levels(const std::vector<Eigen::Vector3d>& normals) const;
  /// w at P_i - d_i n_i (`inside`) and at P_i + d_i n_i (`outside`), size n, the sample's own
  /// dipole counted as the disc of area a_i (as Jumps); 0 where d_i is 0. For the sheet-sign
  /// energy (FlipSheetsByWinding, normals.h), which moves w by whole sheets' terms.
  void InsideOutside(const std::vector<Eigen::Vector3d>& normals, std::vector<double>& inside,
                     std::vector<double>& outside) const;
  /// Whether the probes were placed (more than 16 samples, normals of the same size).
  bool measured() const { return !areas_.empty(); }
  /// a_i (SampleAreas, k = 16); empty when nothing is measured.
  const std::vector<double>& areas() const { return areas_; }
  /// d_i, the probes' distance from P_i (model units); 0 where the sample has no probes.
  const std::vector<double>& offsets() const { return offsets_; }
  /// The disc of area a seen from a distance d along its axis: its w, 1/2 (1 - d / sqrt(d^2 + a / pi)).
  static double OwnDisc(double a, double d);

 private:
  static constexpr std::size_t kNeighbours = 16;
  // Walls::kEitherSign counts a stacked neighbour only beyond this many nearest-sample distances.
  static constexpr double kStackedFromNearest = 1.5;
  // w at each sample's inside and outside probe (0 where d_i is 0).
  void Winding(const std::vector<Eigen::Vector3d>& normals, std::vector<double>& inside,
               std::vector<double>& outside) const;
  const std::vector<Eigen::Vector3d>& positions_;
  std::vector<double> areas_, offsets_;
  std::vector<std::size_t> order_;  // the k-d tree's leaf order
};

/// w(q) summed over every sample: O(n) per query, the reference for the tree.
double WindingNumberBruteForce(const std::vector<Eigen::Vector3d>& positions,
                               const std::vector<Eigen::Vector3d>& normals, const std::vector<double>& areas,
                               const Eigen::Vector3d& q);

class WindingNumber {
 public:
  /// positions, unit normals (outward) and areas (SampleAreas), same size; copied.
  /// beta: the far-field criterion |q - c| > beta r (3: |error| < 0.05 a few spacings from the
  /// samples on the sets tried, tests/host/winding_test.cc).
  WindingNumber(const std::vector<Eigen::Vector3d>& positions, const std::vector<Eigen::Vector3d>& normals,
                const std::vector<double>& areas, double beta = 3.0);
  /// w at q, in the units of the positions. ~O(log n) away from the samples.
  double operator()(const Eigen::Vector3d& q) const;
  /// w at each of `queries` into `out` (same size), bit for bit what operator() gives each: one
  /// walk of the tree for the whole set (a node is read once for every query that reaches it) and
  /// two queries at a time (four on x86-64 with AVX2) through the far-field and leaf terms. For
  /// queries near one another (a brick).
  void operator()(std::span<const Eigen::Vector3d> queries, std::span<double> out) const;
  /// The batch with two lanes whatever the CPU (what operator() runs without AVX2), for the tests.
  void BatchTwoLanes(std::span<const Eigen::Vector3d> queries, std::span<double> out) const;

 private:
  // Tree build state of a node.
  struct BuildState {
    Eigen::Vector3d centre;  // area-weighted mean position
    Eigen::Vector3d dipole;  // sum a_i n_i
    Eigen::Matrix3d second;  // sum a_i n_i (P_i - centre)^T
    double radius = 0;       // max |P_i - centre|
  };
  // What a query reads at every node it visits (48 bytes); the left child is the next node.
  struct Node {
    Eigen::Vector3d centre;
    double far2 = 0;  // beta^2 r^2: q is far when |q - centre|^2 exceeds it
    std::uint32_t begin = 0, end = 0;
    std::int32_t right = -1;  // -1: a leaf
  };
  // What a query reads only where it takes the node's far-field expansion.
  struct Expansion {
    Eigen::Vector3d dipole;  // sum a_i n_i
    double trace = 0;        // trace of `second`
    Eigen::Matrix3d second;  // sum a_i n_i (P_i - centre)^T
  };
  // Nodes of the subtree over `count` points; builds node `id` over [begin, end) and its subtree
  // (left child id + 1, then the right one after the left's subtree; large halves in parallel).
  static std::uint32_t SubtreeNodes(std::uint32_t count);
  void BuildNode(std::uint32_t id, std::uint32_t begin, std::uint32_t end);
  // The batch evaluation, kLanes (2 or 4) queries at a time through the far-field and leaf terms.
  template <int kLanes>
  void Batch(std::span<const Eigen::Vector3d> queries, std::span<double> out) const;
  void BatchAvx2(std::span<const Eigen::Vector3d> queries, std::span<double> out) const;  // 4 lanes (x86-64 AVX2)

  std::vector<Eigen::Vector3d> points_;            // in tree order
  std::vector<Eigen::Vector3d> weighted_normals_;  // a_i n_i, in tree order
  std::vector<Node> nodes_;
  std::vector<Expansion> expansions_;  // per node
  double beta2_ = 9.0;
};

}  // namespace palpa::field
