// The default field method (`palpa build --method hermite`, issue 5): sub-voxel signed distances
// in the narrow band, straight from the oriented points (Hermite data) and the packed balls.
//
// At a node x (docs/field-methods.md has the measurements that chose this):
//  1. Osculating quadrics. Every sample P_i carries a height field z = A u^2 + B uv + C v^2 + b u
//     + c v over its tangent frame (u, v, n_i), fitted by least squares to the positions and
//     normals of its 16 nearest samples whose normals agree (n_i . n_j >= 0.8, so a patch never
//     spans a sharp edge). Q(x) = inverse-distance^2 blend, over the 4 samples nearest x that agree
//     with the nearest one, of (w - z(u, v)) / sqrt(1 + |grad z|^2): the distance to the patch to
//     first order. Exact on planes, O(h^4) on spheres.
//  2. Packed-ball bracket. Inner balls (paper eq. 2-3) lie inside the object and outer balls (the
//     same packing with -n) outside it, so with U_in, U_out their unions, the true signed
//     distance lies in [-f_out(x), f_in(x)], f(x) = min_i |x - c_i| - r_i over the balls of the
//     48 samples nearest the centre of x's 8^3 brick (any subset of the balls gives valid
//     bounds). phi = clamp(Q, lo - 0.1, hi + 0.1) voxels: the bracket removes the
//     quadrics' far-field errors (the wrong side of a sharp edge) without touching their
//     sub-voxel accuracy.
//  3. Leak guard (paper Fig. 4): a ball tangent at P_i may not cross the tangent disc of another
//     sample P_j (radius = P_j's 8th-neighbour spacing) by more than 0.25 voxel; such a ball is
//     shrunk (still tangent at P_i) until it does not. Without it a ball pokes through the gaps of
//     a sparse sampling and the bracket certifies a false inside.
// Work follows the surface: only 8^3 bricks within band + spacing of a sample are evaluated (those
// whose centre value says they can hold band nodes, plus any such brick that an evaluated node
// below band - 1 faces). Inside each brick the candidate samples are culled exactly per brick,
// 4^3 and 2^3 block (same values as with all 48), so a node costs a handful of distances; a block
// that the bracket alone, or its centre value as for bricks, puts beyond the band is filled with
// +-band at once. The other bricks take their side from the generalized winding number of the
// samples (winding.h, issue 20): uniform where w is on one side of 1/2 at all 8 corners, else
// phi = (1/2 - w) / |grad w| per node (the smooth closure of a hole or an unscanned side);
// evaluated nodes clamped to the band edge take w's side where all 8 corners are sure of it
// (< 0.3 or > 0.7), nodes farther than a trust distance from every sample take a clear w's side
// (or, w unclear, a dropped sample's: HermiteOptions::guard_positions; or, w unclear on a closed
// set (normals' flux under 0.1 of the area, rim samples fewer than 0.4 sqrt(n)), outside where
// w is below the level it takes at the 8 nearest samples (SampleProbes::Levels) and none of them
// is a rim sample, and inside where w is above 1/2, when w's surface at that level lies
// farther than the estimate's own and than a voxel: sparse sets' phantoms and holes,
// docs/field-methods.md § Sparse closed sets; and inside where w is at least 0.55 and the node,
// in front of its nearest sample, lies behind one of its 8 nearest that faces that one with an
// opposed normal: parts that touch, § Parts that touch), and no node on a grid face stays inside. Where
// w is unclear (0.3 <= w < 1/2, or down to 0.1 behind a rim sample: an open scan's missing side)
// the inner balls of the nearest samples decide (or, where none holds the node, any ball that
// continues its surface and touches it again at its antipode; on an open set this overrules the
// estimate's outside too, there up to w < 0.7), so the closure continues the scanned curvature
// (closure_beyond_grid); and on an open set, where no ball holds a node the estimate holds inside
// and its nearest sample is a rim sample 1.5 of its spacings away or more, or the node lies beyond
// the samples' convex hull as below, w's outside decides (the estimate carried the scanned patches,
// or a ball that does not continue the surface, on past the scan's edge). On an open set the
// nodes beyond the trust distance then take the side of most of their 3 x 3 x 3 block, for 5
// rounds (smooth_closure): those rules, node by node, left the closure ragged.
// Last SparseField::ProjectLipschitz makes every axis neighbour difference <= 1 voxel, as the
// proxy's sphere tracing needs: the per-node formula alone breaks that by up to ~2.5 voxels where
// patches meet or the bracket clamps.
// Deterministic for any thread count (every node is computed independently, ties broken by
// sample index; the projection's result does not depend on its order).
#pragma once

#include <cstddef>
#include <memory>
#include <optional>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "palpa/field/grid.h"
#include "palpa/field/packing.h"
#include "palpa/field/sparse_field.h"

namespace palpa::field {

struct HermiteStats;
struct HermiteSideRules;  // opaque (hermite_field.cc): HermiteStats::side_rules

struct HermiteOptions {
  // Step 3 above. Off only to measure what it prevents (tests, docs/field-methods.md).
  bool leak_guard = true;
  // Inside/outside of the bricks left unevaluated from the samples' winding number (issue 20;
  // winding.h). false: the former majority vote (SparseField::LabelUnallocatedBricks), kept to
  // measure the difference.
  bool winding_labels = true;
  // On a closed set, inside nodes more than max(3 voxels, 0.3 sample spacings) outside the samples'
  // convex hull (the guards' positions included) are set outside (issue 20; HermiteStats::
  // hull_cut_nodes): the estimate had carried a sparse part on past its last samples. On an open
  // set, such a node where w is unclear and no ball of the closing rule holds it takes w's side.
  // Off only to measure what it prevents.
  bool hull_cut = true;
  // On an open set, the nodes with no sample within the trust distance take the side of most of
  // the 27 nodes about them, for 5 rounds (HermiteStats::closure_side_changes): the far pass
  // decides those nodes one by one and left an unscanned side's closure ragged (spikes, notches,
  // floating specks of solid, pockets). Off only to measure what it prevents.
  bool smooth_closure = true;
  // Outside pockets enclosed in the solid and inside islands apart from the rest that no sample
  // bounds are filled and cut, last (HermiteStats::pockets_filled, islands_cut; pockets.h). Off
  // only to measure what it prevents.
  bool sampleless_components = true;
  // The closing rule's ball search ends at the first ball deep enough for its caller: below the
  // band where the depth is clamped to it, below 0 where only the side is read. false: every ball
  // is visited and the deepest taken, only to show the early stop changes no node (tests).
  bool balls_stop_early = true;
  // > 0 (metres): before any node is evaluated, find whether an open scan's closure goes on past
  // the grid, within this reach of the grid's box, with the winding number and closing rule the
  // labelling uses (HermiteStats::closure_beyond_grid). If it does, HermiteField returns at once
  // with an unbuilt field (no brick allocated) and the caller grows the grid to hold the box and
  // calls again (BuildField): each node is evaluated once. 0: not searched, always built.
  double closure_reach_m = 0.0;
  // The guarded packings (inner, outer and their shrink counts) of an earlier HermiteField on the
  // same samples, normals, r_max, leak_guard and voxel, to use instead of packing again: they do not
  // depend on the grid's extent (a grid grown to hold an open scan's closure). nullptr: pack. Its
  // side_rules too, when set and made from equal positions, normals, guards (compared by value;
  // the rules hold their own copies), voxel and hull_cut.
  const HermiteStats* packed = nullptr;
  // Samples dropped as outliers (palpa build: FindWindingOutliers), metres, with their outward
  // normals (any length > 0): no patch, no balls, no share of the winding number, but each one's
  // tangent disc still bounds the packed balls as a sample's does (step 3), and where the winding
  // number is unclear a guard that a node lies in front of (beyond the trust distance) puts it
  // outside, against the estimate, when the guard is nearer than the node's 8th nearest sample
  // and none of those 8 faces the guard with the node behind it (a surface between them: the
  // node is in the part across a gap). A sparse set's true samples are
  // dropped too (the unseen bull with 500 samples: 1-2 %, such as the lone sample on a hoof's
  // sole), and their neighbours' balls and patches then carried the part on past where they
  // stood, making phantom solid 3-9 voxels deep; an outlier's disc can only shrink balls. The
  // packing part is skipped without leak_guard or with `packed`.
  std::vector<Eigen::Vector3d> guard_positions;
  std::vector<Eigen::Vector3d> guard_normals;
};

struct HermiteStats {
  std::size_t inner_balls_shrunk = 0;  // by the leak guard
  std::size_t outer_balls_shrunk = 0;
  std::size_t bricks_evaluated = 0;       // including bricks_added
  std::size_t bricks_added = 0;           // evaluated because a neighbour's face was below band - 1
  std::size_t label_minority_votes = 0;   // winding_labels = false only: LabelUnallocatedBricks' minority
  std::size_t winding_bricks = 0;         // unevaluated bricks holding w = 1/2, given values from w
  std::size_t winding_flipped_nodes = 0;  // clamped evaluated nodes given w's side
  std::size_t winding_far_nodes = 0;      // evaluated nodes far from every sample given w's side
  // Open sets: side changes of the majority vote that smooths the closure beyond the trust
  // distance of every sample, over its rounds (a node may change more than once; 3 x 3 x 3
  // blocks, 5 rounds; docs/field-methods.md § Open sides: the closure smoothed).
  std::size_t closure_side_changes = 0;
  // Closed sets: inside nodes more than hull_cut_beyond_m (metres) outside the samples' convex hull,
  // set outside (a part the estimate carried past its last samples).
  std::size_t hull_cut_nodes = 0;
  double hull_cut_beyond_m = 0.0;
  // Enclosed outside pockets (no path of outside nodes to a grid face) that no sample bounds
  // (FillSamplelessPockets: none within 3 voxels, every one within its spacing has them behind),
  // filled (set inside), and their nodes: hollows a closure left, which no sample shows
  // (docs/field-methods.md § Enclosed pockets and floating islands that no sample bounds).
  std::size_t pockets_filled = 0;
  std::size_t pocket_nodes_filled = 0;
  // Inside islands that no sample within 3 voxels or 1 spacing bounds, cut (set outside), and
  // their nodes: solid floating where nothing was scanned (CutSamplelessIslands).
  std::size_t islands_cut = 0;
  std::size_t island_nodes_cut = 0;
  std::size_t face_nodes_closed = 0;  // inside nodes on a grid face set outside
  std::size_t face_nodes_open = 0;    // of which no sample near faces that grid face: an open side's
  // Area of the w = 1/2 surface in the bricks no sample reaches (winding_bricks), m^2: what the
  // winding number closed where nothing was scanned (an open scan or a hole). Estimated from the
  // grid edges it crosses (area ~ crossings h^2 / 1.5); 0 for a closed, well-sampled surface.
  double closed_area_m2 = 0.0;
  // Whether the samples themselves show an open side (issue 20): their normals' flux |sum a_i n_i|
  // is at least 0.1 of their area (a closed surface's is 0), or their rim samples, across whose
  // widest neighbour gap w falls, number 0.4 sqrt(n) or more. False for a closed set however
  // sparse, whose field may still span gaps (closed_area_m2) or reach a grid face: that is no
  // open scan. A clean CAD part's sharp edges may count as rims (true, with no gap to report).
  bool samples_open = false;
  // The samples' surface area, m^2: the sum of the winding number's area weights.
  double sample_area_m2 = 0.0;
  // An open scan's closure beyond the grid (issue 20; HermiteOptions::closure_reach_m; when set,
  // the field returned is unbuilt). Where w is unclear (0.3 <= w < 1/2) the inner balls of the 16
  // samples nearest decide, so the closure follows the scanned part's curvature and may reach past
  // the grid fitted to the samples, where the grid faces would cut it flat. The box (metres) holds
  // every node of a lattice of half a brick (4 voxels) outside the grid that the rule puts inside,
  // widened by one lattice step; empty (std::nullopt) when there is none or it was not searched.
  std::optional<Eigen::AlignedBox3d> closure_beyond_grid;
  // Set with closure_beyond_grid: what the unbuilt call made that does not depend on the grid (the
  // samples' spacing and k-d tree, their winding number, rims, hull and closing rule), for the
  // next call to reuse through HermiteOptions::packed (hippo1: 0.03 s of a 1.0 s build).
  std::shared_ptr<const HermiteSideRules> side_rules;
  bool side_rules_reused = false;  // this call used HermiteOptions::packed's side_rules
  SparseField::LipschitzStats lipschitz;
  Packing inner;                  // guarded, metres
  Packing outer;                  // guarded, metres (balls outside the object)
  double seconds_packing = 0.0;   // spacing, inner and outer packing, leak guard
  double seconds_distance = 0.0;  // everything after packing; of which:
  double seconds_patches = 0.0;   //   osculating patch fits
  double seconds_active = 0.0;    //   marking and centre tests
  double seconds_evaluate = 0.0;  //   per-node evaluation (incl. added bricks)
  double seconds_project = 0.0;   //   labelling and Lipschitz projection
};

// Distance to the kth nearest other sample of every sample (kth = 8, fewer if there are fewer
// samples), in the units of `positions`. Deterministic.
std::vector<double> SampleSpacing(const std::vector<Eigen::Vector3d>& positions, int kth = 8);

// Leak guard (see above): shrinks the balls of `packing` (tangent at positions[i] with ball-side
// normal -ball_normals[i], i.e. c_i = P_i - r_i * ball_normals[i]) so that no ball crosses the
// tangent disc of radius disc_spacings * spacing[j] at any other sample P_j by more than
// `tolerance` (same units). Discs of samples whose plane passes above P_i (concave there) are
// not barriers. positions, ball_normals and spacing may run past the packing's balls: the entries
// beyond packing.radii.size() are discs only (samples dropped as outliers, HermiteOptions::
// guard_positions). Returns the number of balls shrunk. Deterministic, parallel.
std::size_t GuardPacking(Packing& packing, const std::vector<Eigen::Vector3d>& positions,
                         const std::vector<Eigen::Vector3d>& ball_normals, const std::vector<double>& spacing,
                         double disc_spacings, double tolerance);

// The default method's field on `grid` from unit-normal oriented points in grid units (metres).
// r_max caps the packed balls as in PackSpheres. Values in voxels, clamped to +-band, axis
// neighbour differences <= SparseField::kLipschitzStep.
SparseField HermiteField(const GridSpec& grid, const std::vector<Eigen::Vector3d>& positions,
                         const std::vector<Eigen::Vector3d>& normals, double r_max, const HermiteOptions& options = {},
                         HermiteStats* stats = nullptr);

}  // namespace palpa::field
