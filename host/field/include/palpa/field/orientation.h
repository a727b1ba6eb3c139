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
  // of consistently oriented points cannot be opposite; flipped = flat with n_i.n_j < -0.5, and
  // i and j on different sheets. A sheet is the samples joined by neighbour pairs whose normals
  // agree (n_i.n_j > 0.5) and whose chord lies within asin(0.25) of both tangent planes: a flipped
  // patch is a sheet of its own, bounded by flipped pairs; two parts of one connected surface
  // that touch (CGAL's man: legs and arms within a third of a spacing of each other, interior
  // sheets of a self-intersecting mesh) are one sheet, and their opposite pairs are
  // `touching_pairs`, no evidence, unless the samples with opposite normals around each end lie
  // to one side of it in its tangent plane (a seam: a flipped patch that joins the rest across a
  // gap or a thin part; touching layers lie over each other).
  std::size_t flat_pairs = 0;
  std::size_t flipped_flat_pairs = 0;
  std::size_t points_in_flipped_pairs = 0;
  std::size_t touching_pairs = 0;
  // Patch test. A patch of flipped normals (a scan's view merged with the wrong sign) is a sheet
  // bounded by flipped pairs that are few beside all flat pairs (a patch of 93 of knot1's 5,000
  // samples: 60 of 10,217, 0.6 %). The sheet of at least 8 samples with the most flipped pairs
  // to sheets at least twice its size: its samples and those pairs (0 when there is none).
  std::size_t flipped_patch_samples = 0;
  std::size_t flipped_patch_pairs = 0;

  // True when a test finds inconsistency: any inward support direction, flipped pairs above 1 %
  // of the flat pairs (a few can come from noise on thin, noisy sheets), or a flipped patch
  // bounded by at least 5 of them at a seam (8 until 2026-11-26).
  bool Inconsistent() const;
  // For an open scan (issue 20): the support test assumes a closed surface, and on a scan seen
  // from one side the farthest points away from the scanner face it, inward by that test. True
  // only with more than 9 of the 26 directions inward (the far side of one view), or by the
  // other two tests as on a closed set.
  bool OpenScanInconsistent() const;
  // One sentence with the counts, e.g. for a warning.
  std::string Describe() const;
};

// Runs both tests on `positions` (any units) with unit `normals` (same size; else an empty
// report). O(N log N) with a k-d tree, parallel with TBB; deterministic.
OrientationReport CheckOrientation(const std::vector<Eigen::Vector3d>& positions,
                                   const std::vector<Eigen::Vector3d>& normals);

}  // namespace palpa::field
