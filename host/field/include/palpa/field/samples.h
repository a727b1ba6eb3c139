// Degenerate samples of a real point set (issue 20): a zero-length or non-finite normal (read with
// ReadOptions::keep_bad_normals, which stores it as (0, 0, 0)) and exact duplicates carry no
// orientation or no new information, and a duplicate gives the neighbour searches a zero spacing.
// They are dropped before the build, counted, and the first of each kind is named.
#pragma once

#include <cstddef>
#include <expected>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "palpa/field/error.h"
#include "palpa/field/point_io.h"

namespace palpa::field {

struct DroppedSamples {
  std::size_t bad_normals = 0;                  ///< normal (0, 0, 0): zero-length or non-finite in the file
  std::size_t duplicates = 0;                   ///< same position as an earlier point (bit for bit)
  std::optional<std::size_t> first_bad_normal;  ///< index in the points as read
  std::optional<std::size_t> first_duplicate;   ///< index in the points as read
  std::optional<std::size_t> duplicate_of;      ///< the earlier point first_duplicate repeats
  std::string first_bad_normal_place;           ///< PointPlace of first_bad_normal ("" if none)
  std::string first_duplicate_place;            ///< PointPlace of first_duplicate ("" if none)
  std::string duplicate_of_place;               ///< PointPlace of duplicate_of ("" if none)
  std::size_t kept = 0;                         ///< points left

  std::size_t Total() const { return bad_normals + duplicates; }
  /// "2 samples with a zero-length or non-finite normal (first: scan.xyz:17) and 1 exact duplicate
  /// (first: scan.xyz:40, the position of scan.xyz:12)"; empty when nothing was dropped.
  std::string Describe() const;
};

/// Removes from `points` every point whose normal is (0, 0, 0) and every point whose position
/// equals an earlier point's exactly (its normal is dropped with it), keeping the order of the
/// rest; `points.lines` follows. `file` names the points' file in the places (PointPlace).
/// O(n log n). Positions must be finite (ReadPoints ensures it).
DroppedSamples DropDegenerateSamples(PointSet& points, const std::string& file);

/// Samples their neighbours do not support (issue 20): a stray point off the surface, or an
/// outlier in free space. Each one's inner balls and patch would otherwise make solid where
/// there is none (a phantom wall), and one far point would collapse `--fit`.
struct StraySamples {
  std::vector<std::size_t> indices;     ///< ascending, into the positions given
  std::optional<std::size_t> farthest;  ///< the one farthest off its neighbours' surface
  double farthest_spacings = 0;         ///< how far (offset or nearest gap), in local spacings
  double spacing = 0;                   ///< median distance to the 8th neighbour, all samples
};

/// Finds the stray samples, scale-free (model units are fine: nothing depends on the units).
/// For each sample P (unit normal n): its 16 nearest others, their least-squares plane (centroid
/// c, normal v: the smallest principal axis), P's offset d = |v . (P - c)|, the neighbours' own
/// RMS offset r, and the local spacing s: the median over the neighbours of their distance to
/// their 8th nearest sample, clamped to [1, 2] x the median of that over all samples (a dense
/// ring of a regular lattice must not make s small, nor a crowd of outliers large).
/// P is stray when
///   d > 4 r + s / 2  (off the local surface by more than 4x its noise and half a spacing), or
///   its nearest other sample is more than 1.5 s away (isolated: ~4 typical nearest gaps; an
///   outlier inside a tube lies on its neighbours' mean plane but far from all of them), or
///   its 16th nearest is more than 3 s away (~1.4 s on a surface, ~2 s on an open rim: a pair
///   of outliers is not isolated, but its 16 neighbours are spread over a large region), or
///   fewer than 4 of the 16 neighbours support n: a normal with a positive dot product with n,
///   and, when at least 1 does and at least 4 lie on the other side of a wall thinner than the
///   spacing or of a convex edge (P and the neighbour each behind the other's tangent plane by
///   more than 2 degrees of the chord, normals apart), those too. A random or flipped normal has
///   few; on a sharp edge, a convex corner or a thin wall its own face's samples and the other
///   faces do (a flange's narrow face; a sparse face's sample beside a cube's corner).
/// Noise, curvature, sharp edges and thin walls raise r with d (noise of 1 voxel per axis keeps
/// d under ~3 r); open rims lie on their plane; a sparse region has a large s. Deterministic,
/// parallel; O(n log n). Needs at least 17 samples (fewer: none is stray).
StraySamples FindStraySamples(const std::vector<Eigen::Vector3d>& positions,
                              const std::vector<Eigen::Vector3d>& normals);

/// Removes `indices` (ascending) from points (positions, normals, and lines when present).
void RemoveSamples(PointSet& points, const std::vector<std::size_t>& indices);

/// Samples that disagree with the inside and outside of the surface the others make (issue 20):
/// an outlier near the surface with a plausible normal passes FindStraySamples, and its packed
/// balls and patch then make phantom solid several voxels deep.
struct WindingOutliers {
  std::vector<std::size_t> indices;  ///< ascending, into the positions given
  std::optional<std::size_t> worst;  ///< the one with the smallest jump (or others' share of it)
  double worst_jump = 1.0;
};

/// The generalized winding number w of all samples (winding.h; areas from the 16th neighbour, as
/// the build uses) should rise by about 1 across each sample, from outside to inside, along its
/// normal. For sample i (area a_i, 16th-neighbour distance s_i) the jump
///   J_i = w(P_i - d n_i) - w(P_i + d n_i),  d = min(s_i / 2, 0.4 t_i),
/// t_i the distance to its nearest sample with an opposite normal (n . n_j < -0.5: the other side
/// of a thin wall, which the inner probe must not pass), with the sample's own dipole counted as
/// the disc of area a_i it stands for (a dipole's 1/d^2 would decide the jump alone at small d).
/// On a sampled surface J ~ 0.8-1 (noise of 1 voxel and 15-degree normal noise keep it above
/// 0.5); an outlier off the surface sees the same side of it from both probes, J ~ 0.1-0.3, and a
/// flipped one J < 0. A sample is an outlier when J < min_jump, or when the others' share of J
/// (J minus its own disc's) is under 0.2, the nearest opposite normal among its 16 nearest lies
/// in front of it (a narrow gap holds its probes close, and its own disc makes the jump), and the
/// nearest of its 64 nearest facing its way (n . n_j >= 0.8) lies more behind it than beside it:
/// a stray point in front of its own side. Either way not when it lies on the plane of its 16
/// nearest that face its way (a sharp edge's or a fin's true sample). Deterministic, parallel,
/// O(n log n); fewer than 17 samples: none.
WindingOutliers FindWindingOutliers(const std::vector<Eigen::Vector3d>& positions,
                                    const std::vector<Eigen::Vector3d>& normals, double min_jump = 0.5);

/// What SimplifyDenseSamples did.
struct Simplification {
  std::size_t before = 0;
  std::size_t after = 0;  ///< == before when the set was left as it was
  double cell = 0;        ///< cell side, units of the positions
  /// SimplifyBarePositions' wide cells that held a thin wall's two sides and kept every sample
  std::size_t wall_cells = 0;
  /// SimplifyBarePositions' wide cells whose samples wrapped round a thin part's rim and were
  /// averaged in half-voxel cells instead
  std::size_t fold_cells = 0;
  bool Applied() const { return after < before; }
};

/// Points denser than the grid carry no more information at its resolution (issue 20: a phone or
/// tabletop scanner's 2,000,000 points, whose packing alone ran for minutes). Groups the samples
/// by cube cell of side `cell` (the voxel) and, within a cell, by normal: a sample joins the
/// first group whose first normal is within 45 degrees of its own (n . n_g >= 0.7), so the two
/// sides of a thin wall and the faces of a sharp edge stay apart. Each group becomes one sample:
/// the mean position and the normalised mean normal; its file line is its first sample's.
/// Applied only when it at least halves the count (on average two samples a cell or more), so a
/// set at or below the grid's resolution is left bit for bit as it was. Order: by cell (z, y, x),
/// then first sample. Deterministic. O(n log n). Positions finite, normals unit.
Simplification SimplifyDenseSamples(PointSet& points, double cell);

/// A dense scan keeps one sample per cell of this many voxels (and normal side). Knot1, 2,000,000
/// samples at 300 cells: mean |error| 0.013 / 0.016 / 0.024 voxels and wrong sign in the band
/// 0.30 / 0.38 / 0.57 % at 1 / 1.5 / 2 voxels; the packing's time falls with the count.
inline constexpr double kDenseCellVoxels = 1.5;

/// A dense scan whose normals are to be estimated, thinned by position alone first (issue 20: the
/// jet fit, orientation and edge refinement of 2,000,000 points took a minute, for samples the
/// build merges per cell anyway). SimplifyDenseSamples with every normal set to +z (one group a
/// cell) and cells of half `voxel`; where those do not halve the count (a noisy scan spreads over
/// a shell too thick: knot1, 2,000,000 samples with 1 voxel of noise, whose jet fits then followed
/// the noise, 48 % of the band wrong), cells of kDenseCellVoxels voxels, whose averages also
/// shrink the noise. A wide cell whose samples fall in two layers along the normal of the cells
/// around it (PCA over 3 x 3 x 3 cells), split by a gap wider than 0.3 voxels, than twice each
/// layer's own spread (2 samples a layer or more) and than 4 times the set's noise (the median
/// RMS offset within the layers of those neighbourhoods), holds both sides of a wall thinner than
/// the cell, and keeps every sample as it is: averaged, the samples there would be spaced as the
/// wall is thick, and the orientation would cross it (CGAL's rotor, 200,000 bare samples at 150
/// cells: 44.5 % of the band wrong with its fins averaged mid-wall, 0.55 % now; 60,000 at 100
/// cells: 3-5 % with one sample per side, 1.3-1.5 % now). A wide cell whose samples lie more than
/// 0.15 of the cell off their own plane (RMS) and 3 times the set's noise wraps round a thin
/// part's rim (two creases in one cell; one 90-degree crease gives 0.10): its mean would lie inside
/// the part, so its samples are averaged in half-voxel cells (a plate 1.2 voxels thick: 43 % of the
/// band wrong with its rims averaged whole, 0.58 % now). A noisy shell, with no clean gap and no
/// fold above its noise, is averaged as before. Order: the wide cells' means, the half-voxel
/// cells' means, then the kept samples in file order. The normals are
/// placeholders (+z) afterwards, applied or not (estimate them); `cell` of the result is the side
/// tried last. `voxel` in the units of the positions, > 0. Deterministic.
Simplification SimplifyBarePositions(PointSet& points, double voxel);

/// SmoothNoisyPositions' move: its neighbourhoods (the nearest 16, 32 or 64) and default passes.
inline constexpr std::size_t kMoveFewestNeighbours = 16;
inline constexpr std::size_t kMoveMostNeighbours = 64;
inline constexpr int kMovePasses = 3;
/// SmoothNoisyPositions' discrepancy bound: with fitted normals, moves whose RMS exceeds this x the
/// measured noise are undone (docs/field-methods.md § Moves larger than the noise).
inline constexpr double kMoveDiscrepancy = 1.4;
/// SmoothNoisyPositions' scatter bound: with fitted normals, a sample whose 16 nearest agreeing
/// neighbours' bisector offsets scatter (RMS about their mean) by more than this x the 16-sample
/// residual stays in place in that pass (docs/field-methods.md § Bare noisy samples: a sample
/// moves only where its neighbours' offsets agree).
inline constexpr double kMoveScatter = 1.41421356237309515;  // sqrt(2)

/// `palpa build --denoise auto` (issue 20): the noise measure's wider fit (the `neighbours` of
/// MeasurePositionNoise and SmoothNoisyPositions) and the threshold, in voxels of the grid, above
/// which the samples move (clean samples, sparse or faceted ones included, measure below 0.21
/// voxel; docs/field-methods.md § Noise). Also the threshold of RefitNoisyNormalLines.
inline constexpr std::size_t kDenoiseNeighbours = 48;
inline constexpr double kDenoiseVoxels = 0.25;

/// What SmoothNoisyPositions found and did.
struct NoiseSmoothing {
  double noise = 0;           ///< the position noise (RMS, units of the positions): the residual's part that
                              ///< does not grow from the 16- to the `neighbours`-sample fits
  double residual = 0;        ///< median RMS height residual of the samples' 16-sample quadric fits, same units
  std::size_t moved = 0;      ///< samples moved (0 when the noise was below the threshold)
  double mean_move = 0;       ///< mean |move| over the moved samples, all passes, units of the positions
  int passes = 0;             ///< move passes run (0 when the noise was below the threshold)
  double rms_move = 0;        ///< RMS |move| over all samples, all passes, units of the positions (also when withheld)
  bool withheld = false;      ///< the passes ran, but fitted normals' moves exceeded 1.4 x `noise` RMS: undone
  std::size_t widest = 0;     ///< the most neighbours a move took: kMoveMostNeighbours, or fewer for fitted normals
  std::size_t scattered = 0;  ///< fitted normals: samples left in place in the first pass, their neighbours'
                              ///< offsets scattered beyond `scatter` x `residual` (0 for given normals)
  bool Applied() const { return moved > 0; }
};

/// SmoothNoisyPositions' measure alone, nothing moved: `noise` and `residual` as it finds them
/// for the same arguments (`moved`, `passes` 0). For deciding on the noise before the moves, e.g.
/// whether estimated normals should be fitted as a noisy set (palpa build). Same shapes and
/// limits; deterministic.
NoiseSmoothing MeasurePositionNoise(const std::vector<Eigen::Vector3d>& positions,
                                    const std::vector<Eigen::Vector3d>& normals, std::size_t neighbours);

/// Position noise (issue 20): a sample's own noise reaches the field whole, through its patch and
/// its balls. Measures the noise first: for every sample a quadric height function z(u, v) along
/// its normal, fitted by least squares to its nearest samples whose normals agree with it
/// (n_j . n_i >= 0.8), over the 16 nearest and over the `neighbours` nearest; noise leaves the
/// same median RMS residual at both scales, a shape finer than the fit (sparse samples of a
/// detailed surface) a growing one, and the noise is the part that does not grow
/// (`NoiseSmoothing::noise`). When it exceeds `threshold` (units of the positions; clean samples,
/// sparse ones included, stay far below), every sample moves along its normal, in `passes` Jacobi
/// passes, by half the mean over its nearest samples j with n_j . n_i >= 0.5 (at least 2) of
///   t_ij = (n_i + n_j) . (P_j - P_i) / (1 + n_i . n_j),
/// capped at 2.5 x the 16-sample residual; the nearest 16, 32 or 64 (kMove*Neighbours), the largest whose mean's
/// interval (+- 1.25 x the residual / sqrt(count)) meets the smaller ones' (LPA-ICI: a larger
/// neighbourhood averages more noise until the surface turns within it). On a smooth surface the chord between two
/// samples is perpendicular to the sum of their normals to second order at any curvature (exactly on a sphere), so t_ij
/// is minus P_i's offset from the surface plus P_j's noise: an estimate without the bias a fitted height function has
/// where the surface turns within the neighbourhood (the legs and horns of CGAL's bull: 0.41-0.53 voxel of 0.5 left by
/// 48-sample quadrics, where the normals turn by more than 37 degrees within 16 samples) and without mixing the faces
/// of a sharp edge or the two sides of a thin wall (CGAL's jet_smooth_point_set rounds fandisk's edges,
/// bilateral_smooth_point_set shrinks curved parts). It needs the normals' direction: 15-degree
/// normal noise costs it about as much as it gains (docs/field-methods.md § Noise).
/// `fitted_neighbours` > 0: the normals were estimated from these positions, each over its nearest
/// `fitted_neighbours` (EstimateNormalLines' result; 0: given normals). Then the moves must look
/// like the noise they remove: when their RMS over all samples exceeds kMoveDiscrepancy x `noise`,
/// the lines were fitted across the shape (bare samples of creases and walls as fine as the
/// neighbourhoods) and every position is restored (`withheld`; the discrepancy principle,
/// docs/field-methods.md § Moves larger than the noise). Otherwise the moves are made again over
/// neighbourhoods no wider than the fit's (the nearest 16, 32 or 64, at least 16): the fit widens
/// only as far as the noise needs (EstimateNormalLines), and wider moves round off the shape's
/// detail (docs/field-methods.md § Bare noisy samples: moves no wider than the normals' fit;
/// CGAL's bear, cactus, diplodocus and eight, 5,000 bare samples with 0.3 voxel of noise,
/// 18-neighbour lines: band mean 0.144-0.184 -> 0.136-0.162 voxel). In those moves a sample moves
/// in a pass only where its 16 nearest agreeing neighbours' offsets scatter by at most `scatter` x
/// the residual: more scatter is lines that do not follow the shape there, a finger or a leg a few
/// spacings across (CGAL's hand, 0.3 voxel, bare: 0.235 -> 0.189 voxel; `scattered` counts the
/// first pass's; `scatter` > 0, and infinity lifts the bound).
/// `rms_move` is then the moves made. Normals are kept. Shapes: positions and normals of equal
/// length, normals unit; fewer than `neighbours` + 1 samples or `neighbours` < 8: nothing measured
/// or moved. Deterministic.
NoiseSmoothing SmoothNoisyPositions(std::vector<Eigen::Vector3d>& positions,
                                    const std::vector<Eigen::Vector3d>& normals, std::size_t neighbours,
                                    double threshold, int passes = kMovePasses, int fitted_neighbours = 0,
                                    double scatter = kMoveScatter);

}  // namespace palpa::field
