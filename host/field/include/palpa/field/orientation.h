// Checks that oriented points' normals are consistently oriented (all outward), issue 5. Every
// method trusts the normals' sign: packed balls go to the side -n, and the quadric and the
// bracket take their sign from n. Points whose normals point inward build a field that is wrong
// near them (false inside or outside), silently. Non-RT, host only.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace palpa::field {

struct OrientationReport {
  // Support test. For each of the 26 directions u = (i, j, k)/|(i, j, k)|, i, j, k in {-1, 0, 1},
  // the 8 points farthest along u lie on the convex hull, where an outward normal has n.u > 0.
  // A direction counts as inward when most of those 8 normals point clearly inward,
  // n.u < -sin(10 deg) (a normal perpendicular to u, as on the rim of an open scan or on a
  // mesh face parallel to u, is no evidence either way).
  int support_directions = 0;
  int inward_support_directions = 0;
  // Flat-pair test. A pair (i, j), j among the 8 nearest neighbours of i, is flat when the chord
  // lies within 10 degrees of both tangent planes (the two points sit on one smooth sheet, not on
  // the two sides of a thin wall, whose chord runs along the normals). On one sheet the normals
  // of consistently oriented points cannot be opposite; flipped = flat with n_i.n_j < -0.5.
  std::size_t flat_pairs = 0;
  std::size_t flipped_flat_pairs = 0;
  std::size_t points_in_flipped_pairs = 0;

  // True when either test finds inconsistency: any inward support direction, or flipped pairs
  // above 1 % of the flat pairs (a few can come from noise on thin, noisy sheets).
  bool Inconsistent() const;
  // For an open scan (issue 20): the support test assumes a closed surface, and on a scan seen
  // from one side the farthest points away from the scanner face it, inward by that test. True
  // only with more than 9 of the 26 directions inward (the far side of one view) or flipped
  // pairs above 0.1 %.
  bool OpenScanInconsistent() const;
  // One sentence with the counts, e.g. for a warning.
  std::string Describe() const;
};

// Runs both tests on `positions` (any units) with unit `normals` (same size; else an empty
// report). O(N log N) with a k-d tree, parallel with TBB; deterministic.
OrientationReport CheckOrientation(const std::vector<Eigen::Vector3d>& positions,
                                   const std::vector<Eigen::Vector3d>& normals);

}  // namespace palpa::field
