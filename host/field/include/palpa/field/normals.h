// Normals for point sets that have none, or whose signs cannot be trusted (issue 20,
// `palpa build --normals keep|orient|estimate`). Every field method takes the inside from the
// normals' sign, so a scanner's bare positions, or a file whose normals flip from patch to patch,
// need outward unit normals first. Host only, non-RT.
//
//  estimate: the normal line of each sample from a jet fit (CGAL::jet_estimate_normals, Cazals &
//            Pouget 2003: a degree-2 height function fitted to the 10 nearest samples when they
//            are clean, to the 18 nearest when noisy, up to 96 when the noise exceeds their
//            spacing), then oriented as below, then sharpened at edges (RefineNormalLines).
//  orient:   keeps each normal's line and chooses its sign as below.
// Orientation: Hoppe et al. 1992 ("Surface reconstruction from unorganized points", §3.3): a
// minimum spanning tree of the k-nearest-neighbour graph with edge cost 1 - |n_i . n_j| carries one
// sign along the smoothest paths. Our own, not CGAL::mst_orient_normals: that orients only the
// connected component of the topmost point and leaves the rest unoriented, and real scans come
// in many pieces. Each component then takes its outward sign globally:
//   closed (|sum a_i n_i| < 0.2 sum a_i, a_i the sample's area share): the divergence theorem,
//     sum a_i n_i . (P_i - c) = 3 V > 0 for outward normals (c: the area-weighted centre of all
//     samples, which drops out of the sum for a closed component);
//   open (a one-sided scan, a hole): under `orient`, the majority (by area) of the file's own
//     signs, which were mostly right; under `estimate`, the same divergence sum about c, then
//     reversed where the samples' mean winding level (SampleProbes::Levels, winding.h) is below 0: the
//     level is positive for a scan seen from outside whatever its shape, the divergence sum only
//     for a convex part (a dome, a one-sided range scan of one).
// Then parts of any piece that the tree oriented inward as a whole are turned (FlipInvertedParts).
// Limits: an open scan of a concave sheet seen from inside (a bowl's inner face alone) gets the
// inward sign under `estimate`; the inner wall of a cavity (a closed component inside another)
// is oriented as a separate solid. Deterministic for any thread count.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace palpa::field {

enum class NormalsMode {
  kKeep,      ///< use the file's normals as they are (default)
  kOrient,    ///< keep the normals' lines, choose their signs (Hoppe MST + global sign)
  kEstimate,  ///< estimate the lines (jet fit), then orient
};

struct NormalsReport {
  std::size_t estimated = 0;                 ///< normals estimated (estimate, or a file without normals)
  std::size_t flipped = 0;                   ///< orient: normals whose sign was changed from the file's
  std::size_t components = 0;                ///< connected pieces of the neighbour graph
  std::size_t open_components = 0;           ///< of which open (sign from the majority or the divergence sum)
  int neighbours = 0;                        ///< of the jet fit (EstimateNormalLines' result), when estimated
  double noise_figure = -1;                  ///< EstimateNormalLines' median noise over spacing, when measured
  std::size_t inverted_parts = 0;            ///< parts of closed pieces turned outward (FlipInvertedParts)
  std::size_t inverted_samples = 0;          ///< their samples
  std::size_t open_level_flipped = 0;        ///< estimate: open pieces whose sign the winding level reversed
  std::size_t sheets = 0;                    ///< estimate: sheets turned by the winding energy (FlipSheetsByWinding)
  std::size_t sheet_samples = 0;             ///< their samples
  std::size_t closed_by_tree = 0;            ///< estimate: open pieces a tree across thin walls closed
  std::size_t closed_by_sheets = 0;          ///< estimate: open pieces that turning large sheets closed
  std::size_t closed_by_sheets_samples = 0;  ///< the normals turned there
  std::size_t refined_sheets = 0;            ///< estimate: sheets turned again on the sharpened lines
  std::size_t refined_sheet_samples = 0;     ///< their samples (FlipSheetsOnSharpenedLines)
  /// "5210 normals estimated (jet fit, 10 neighbours: the samples are clean) and oriented: 1 piece
  /// (1 closed, 0 open)", then "; 1 open piece turned outward by the winding number" and "; 1 part
  /// oriented inward as a whole turned outward (109 normals)" and "; 23 sheets turned to agree with
  /// the winding number (102 normals)" when they happened
  std::string Describe() const;
};

/// Number of neighbours of the jet fit (noisy samples; clean ones) and of the orientation graph.
inline constexpr int kNormalNeighbours = 18;
inline constexpr int kCleanNormalNeighbours = 10;
/// FlipSheetsByWinding's largest sheet, as a fraction 1 / this of the samples, on closed pieces.
inline constexpr std::size_t kSheetCoarseFraction = 8;
inline constexpr int kOrientNeighbours = 12;
/// Samples are clean when the median over them (at most 20,000) of (RMS residual of a quadric
/// fitted to the 10 nearest along their 10-neighbour jet normal) / (distance to the 8th nearest)
/// is below this: 0.004-0.033 on exact samples of 13 meshes, 0.007 and 0.045 on the real kitten
/// and oni scans, 0.046-0.096 at 0.25 voxel of position noise (5,000 samples, 150 cells),
/// 0.090-0.18 at 0.5 voxel, 0.17-0.29 at 1 voxel.
/// A sample whose nearest fit two parallel sheets far better than one quadric (a wall thinner
/// than the spacing) counts that fit's residual (normals.cc, kTwoSheetShare).
inline constexpr double kCleanNoise = 0.075;
/// A noisy set whose 18-neighbour lines of nearest neighbours differ by more than kRoughNormalsDeg
/// on the median is fitted again over 1.5x as many (up to kMostNormalNeighbours) until they
/// differ by kSmoothNormalsDeg at most: 2.3-10.1 degrees with 18 neighbours at 0.5-1 voxel of
/// position noise on 5,000 samples at 150 cells (curvature included), 26.6 on CGAL's sphere_20k
/// (noise 1.6 sample spacings), 10.2 / 5.9 / 3.5 there with 40 / 60 / 90.
inline constexpr double kRoughNormalsDeg = 15.0;
inline constexpr double kSmoothNormalsDeg = 5.0;
/// ... and each wider fit is kept only while it lowers that median to this fraction or less (noise:
/// 0.58-0.64 per step on sphere_20k; CGAL's blobby.xyz, a noisy scan of a curved shape, 0.78,
/// and stays at 18 neighbours).
inline constexpr double kNoiseFall = 0.7;
inline constexpr int kMostNormalNeighbours = 96;

/// Replaces `normals` (resized to positions.size()) by unit normal lines from a degree-2 jet fit
/// (CGAL::jet_estimate_normals); signs arbitrary until OrientNormals. Fits the
/// kCleanNormalNeighbours nearest samples and keeps them where the set is clean (kCleanNoise);
/// else fits the kNormalNeighbours nearest, and more while the lines are rough
/// (kRoughNormalsDeg; CGAL's sphere_20k, without normals: 90 neighbours, band mean 0.612 -> 0.353
/// voxel, 1,385 far-wrong nodes -> 0). 18 average the noise of a scan, but on clean samples span both
/// sides of parts a few spacings thick and blend the facets of low-polygon meshes (10 CGAL meshes
/// never tuned on, exact samples, normals stripped: wrong sign in the band 1.18-5.54x that with
/// exact normals with 18, 1.18-2.27x with 10; bench/field/robustness.py --seed 2). Returns the
/// neighbour count of the normals given; `noise_figure`, when given, receives the median noise over
/// spacing that decided clean or noisy (kCleanNoise), or is left as it was when too few samples.
/// `noisy`: fit as a noisy set whatever the figure (`palpa build` sets it when the positions' noise
/// is over a quarter of the grid's voxel, where the figure, relative to the spacing, called them
/// clean: docs/field-methods.md § Noisy for the grid, clean for the spacing; the figure is then not
/// measured and `noise_figure` left as it was).
/// Positions in any units, finite; at least 4 of them (else normals are (0, 0, 1)). Parallel,
/// deterministic.
int EstimateNormalLines(const std::vector<Eigen::Vector3d>& positions, std::vector<Eigen::Vector3d>& normals,
                        double* noise_figure = nullptr, bool noisy = false);

/// Sharpens estimated normals at edges, keeping each one's sign. Per sample: of the planes through
/// P_i with its 16 nearest samples' normals or through P_i and two of its 12 nearest, the one most
/// of them lie on within a narrow width (support exp(-(d/s)^2), s = max(0.01 x the 16th
/// neighbour's distance, 2 x the noise of quadric fits; on a clean set the first alone): a plane
/// cutting through the edge passes within a wider width of both faces' first rows), then two
/// rounds of weighted PCA of its supporters within w = 0.1 x that distance (iteratively
/// reweighted least squares); on a clean set, then, the normal at P_i of a quadric height function
/// through P_i fitted to those supporters, and again to the neighbours within s of that fit (a
/// plane is the tangent at the supporters' centroid: a sphere's lines 0.93 -> 0.005 degrees on the
/// median, a cylinder's first rows next to a cap 1.81 -> 0.29 degrees). A jet fit
/// blends the two faces of a sharp edge; this gives each sample its face's normal (a cube sampled
/// 20 x 20 per face: exact from the second row off each edge; fandisk, 5,000 samples: wrong sign
/// in the band 1.27 % (jet) -> 0.82 % (width w) -> 0.49 %, exact normals 0.36 %). Where the noise
/// (one figure for the set: the median offset of neighbours from the smooth planes / 0.674) is
/// over w/2, the sample keeps its jet normal, the better average there, unless that plane holds
/// 40 % of its neighbourhood within the narrow width itself: a facet of a low-polygon mesh, whose
/// creases the noise figure counts (CGAL's pinion and elk, wrong sign in the band 2.29x / 1.78x
/// that with exact normals -> 1.98x / 1.50x); so does a sample on a rim
/// (its neighbours leave an angular gap over 150 degrees in its tangent plane: every plane through
/// it extrapolates from one side and tilts, and an open side's closure magnifies the tilt; range
/// scans without normals: far-wrong nodes 3,248 -> 0 on the sphere). Run after OrientNormals:
/// the tree crosses edges reliably only on smooth normals. On a clean set (`jet_neighbours`,
/// EstimateNormalLines' result, is kCleanNormalNeighbours) such a sample instead takes the normal of a
/// quadric through P_i fitted robustly to its 16 nearest (Tukey's biweight, cut at 0.06 x the 16th
/// neighbour's distance), from whichever of their normals' frames most of them support, when it
/// gathers 2 neighbours' weight more than the sample's own frame: a jet fit weighs a thin part's
/// other side and the next face over a crease as much as its own surface. Then, on a clean set,
/// first rows take a flat neighbour's plane (TakeFacePlanes); last, the plane through P_i and two
/// of its 12 nearest that 5 or more of its 16 nearest lie on to 1e-4 x the 16th one's distance,
/// with 90 % of the rest on one side of it (a ring's plane cuts the surface), is its normal: a flat
/// face's exact plane (docs/field-methods.md § Exact facets). On a noisy set (`jet_neighbours`
/// above kCleanNormalNeighbours), last, a sample whose plane fit over its `jet_neighbours`
/// nearest leaves over 1.6 x the set's median RMS residual takes the plane of whichever
/// neighbourhood among its 2 x `jet_neighbours` nearest samples' own leaves the least residual,
/// under half its own, when it lies within 2 x max(that residual, the median) of that plane and
/// the plane turns its line by under 50 degrees: a neighbour's fit that stays on one face of a
/// crease (shifted neighbourhoods; fandisk, 5,000 bare samples with 0.5 voxel of noise: band mean
/// 0.357 -> 0.214 voxel, docs/field-methods.md § Noisy bare samples: crease planes).
/// Parallel, deterministic.
void RefineNormalLines(const std::vector<Eigen::Vector3d>& positions, std::vector<Eigen::Vector3d>& normals,
                       int jet_neighbours);

/// The sheet pass (FlipSheetsByWinding) once more, on the lines RefineNormalLines sharpened, over
/// every sample, where OrientNormals ran it on a clean set's jet lines (`report.neighbours` is
/// kCleanNormalNeighbours) and left no piece open (`report.open_components` 0; an open piece's
/// w is no truth, see OrientNormals). The jet lines of a shell a couple of spacings thick lean
/// across it (CGAL's rotor, 5,000 bare samples: 13.6 degrees off the exact lines on the median,
/// 47 degrees on the tree's cheapest wrong edges; the sharpened lines 0.0), so the first pass's
/// sheets join the shell's two sides and its inner side's wrong sign stays (116 normals inward,
/// 953 far-wrong nodes); on the sharpened lines the two sides part into sheets of their own: 23
/// inward, 0 far-wrong nodes (docs/field-methods.md § Thin shells: the sheet pass on sharpened
/// lines). Counts into `report` (refined_sheets, refined_sheet_samples); returns the samples
/// turned. Unit normals in, same lines out; deterministic, parallel.
std::size_t FlipSheetsOnSharpenedLines(const std::vector<Eigen::Vector3d>& positions,
                                       std::vector<Eigen::Vector3d>& normals, NormalsReport& report);

/// Turns outward the parts of a piece that an orientation left inward as a whole. A closed
/// surface oriented outward has a winding number w (winding.h) near 1 just inside each sample and
/// near 0 just outside: the level (w(P - d n) + w(P + d n)) / 2 is near 1/2. A part of it oriented
/// inward as a whole (the MST reached a thin tail across its tip) is a closed sheet of its own
/// with w near -1 inside it, and its samples' level is near -1/2. Groups of samples connected in
/// the 10-nearest graph whose level is below 0 flip when they hold 16 samples or more and their
/// mean level is below -1/4, and the flip stands when their mean level, measured again, is above
/// +1/4 (a part too thin for its lines stays mixed); then the samples of and beside a flipped group
/// take their tangent-plane neighbours' side. Up to three passes. d is half the distance to the
/// 16th nearest, within 0.4 of the nearest facing the other way (SampleProbes, winding.h). `eligible`
/// (size n, 0 or 1): the samples that may flip (OrientNormals: all; an open sheet's own level is
/// 0 to 1/2, and a flip of a piece of it does not lift its level, so does not stand).
/// CGAL's cow, 5,000 samples, normals estimated: 210 signs against the exact normals -> 109 (its
/// tail), wrong sign in the band 3.05 -> 2.12 % (exact normals 1.35 %); 21 other meshes, three
/// draws: the elk's and the bull's too, nothing else (docs/field-methods.md). Returns the samples
/// whose sign changed; `parts` the groups that stood. Parallel, deterministic.
std::size_t FlipInvertedParts(const std::vector<Eigen::Vector3d>& positions, std::vector<Eigen::Vector3d>& normals,
                              const std::vector<std::uint8_t>& eligible, std::size_t& parts);

/// The smoothed-disc winding number of one sheet of FlipSheetsByWinding at a sample's two probes,
/// summed through a tree of the sheet's dipoles (all of the sheet's current sign, +1): each
/// sample j contributes a_j n_j . (P_j - q) / (4 pi (|P_j - q|^2 + a_j / pi)^(3/2)), the sample k
/// itself, when it is one of the sheet's, its disc (SampleProbes::OwnDisc, +- at the two probes).
/// The sheet is split at the median of its box's longest axis down to leaves of kLeaf samples; a
/// cluster of radius r about its area-weighted centre c, seen from probes farther than kFarField r,
/// counts as one dipole of moment sum_j a_j n_j at c, smoothed over the cluster's mean disc
/// (Barill, Dickson, Schmidt, Levin, Jacobson 2018, Fast Winding Numbers for Soups and Clouds,
/// §3.2's criterion, with the zeroth-order term only: the first-order term did not lower the
/// error on a sphere cap at kFarField 3, tests/host/normals_test.cc). Exact sums cost probes x
/// samples, which on dense bare scans made the sheet pass most of a build (docs/field-methods.md §
/// Bare dense sets). Units: those of `positions`; `positions`, `normals` (unit) and `areas` are
/// the whole set's, indexed by `samples`, and must outlive the tree. Deterministic.
class SheetDipoles {
 public:
  static constexpr std::uint32_t kLeaf = 16;
  static constexpr double kFarField = 3.0;

  SheetDipoles(std::span<const std::uint32_t> samples, const std::vector<Eigen::Vector3d>& positions,
               const std::vector<Eigen::Vector3d>& normals, const std::vector<double>& areas);

  struct Terms {
    double in = 0.0, out = 0.0;  ///< w at P_k - offset n_k and at P_k + offset n_k
    bool own = false;            ///< sample k is one of the sheet's
    std::size_t exact = 0;       ///< samples summed one by one
    std::size_t far = 0;         ///< clusters summed as one dipole
  };
  /// The sheet's terms at sample k's probes, `offset` from P_k along n_k (> 0, SampleProbes::offsets).
  Terms At(std::size_t k, double offset) const;

 private:
  struct Node {
    Eigen::Vector3d centre = Eigen::Vector3d::Zero(), moment = Eigen::Vector3d::Zero();
    double area = 0.0, radius = 0.0;
    std::uint32_t begin = 0, end = 0;
    std::int32_t left = -1, right = -1;
  };
  std::int32_t Build(std::uint32_t begin, std::uint32_t end);
  std::vector<std::uint32_t> order_;
  std::vector<Node> nodes_;
  const std::vector<Eigen::Vector3d>& positions_;
  const std::vector<Eigen::Vector3d>& normals_;
  const std::vector<double>& areas_;
};

/// Turns the sheets whose sign disagrees with the winding number w of all the samples (winding.h):
/// the sides of walls thinner than the sample spacing (ears, horns, fins) that an orientation gave
/// one sign, which FlipInvertedParts' level cannot see (its probes cross both sides). A sheet is
/// the samples joined in the 10-nearest graph by normals within 30 degrees, signs included, and
/// chords within asin(0.25) of both tangent planes, so a wall's two sides and a sign boundary
/// separate sheets. Energy: sum_i a_i (min((w(P_i - d_i n_i) - 1)^2, 1) + min(w(P_i + d_i n_i)^2,
/// 1)), each sample's probes (SampleProbes, Walls::kEitherSign) wanting 1 inside and 0 outside,
/// w there with the 32 nearest samples' dipoles smoothed over their discs (a n . d / (4 pi (|d|^2
/// + a / pi)^(3/2)); a point dipole's 1/r^2 at a probe near a thin wall's other side scored right
/// signs as losses); a sheet's flip adds -2 w_sheet at every probe (its own samples' as discs)
/// and swaps its samples' targets. Sheets of at most 4,096 samples and n / 8 whose flip lowers
/// the energy (measured on the probes within twice their radius plus 6 d_i) flip, best first,
/// apart from one another, round after round until no flip lowers it (each sheet at most once; a
/// round re-scores only the sheets a flip reached; a sheet of more than 256 samples is scored
/// through SheetDipoles, its flip applied with exact sums). Then a second pass with a finer cut (15
/// degrees, asin(0.125), sheets of at most n / 8 as well) for the wrong samples the first cut had
/// joined to right ones. OrientNormals runs it on
/// the estimated lines of clean samples (NormalsReport::neighbours == kCleanNormalNeighbours), and
/// of mildly noisy ones (kNormalNeighbours, NormalsReport::noise_figure under 0.2: a part a few
/// spacings thick with a little noise; CGAL's rotor, 5,000 bare samples, 0.2-0.5 voxels of noise:
/// 31-33 % -> 9.5-13 % of the band wrong): on noisier ones sheets break into single samples whose
/// probes lie in the noise. `eligible` (size n,
/// 0 or 1): the samples whose sheets may flip (OrientNormals: those of closed pieces; every
/// sample's dipole counts in w).
/// CGAL's bull, 5,000 samples, normals stripped: 136 signs against the exact normals -> 36, wrong
/// sign in the band 1.84x -> 1.38x the exact normals'; the elk (seed 6) 2.07x -> 1.85x, far-wrong
/// nodes 211 -> 45 with the smoothed dipoles and the fine pass (docs/field-methods.md § Normals).
/// `coarse_fraction`: the coarse cut's sheets hold at most n / coarse_fraction samples (8: the body
/// is no candidate; OrientNormals' retry on pieces open by their flux allows 4).
/// `clean_lines`: the lines are a clean set's (OrientNormals: NormalsReport::neighbours is
/// kCleanNormalNeighbours; FlipSheetsOnSharpenedLines), and the energy adds a facing term: a
/// wall's two sides face apart or together, never the same way, so each pair of samples that a
/// two-sheet fit puts on a thin wall's two sides, stacked across it, with parallel lines, costs
/// its share of their areas while both face the same way (sheets of 8 samples or more). On a
/// wall a spacing or less thick the probes straddle the wall and score a patch that took the
/// other side's sign about even (CGAL's rotor, normals stripped, seeds 1-6: far-wrong nodes up to
/// 1,772 without the term, at most 1 with it; docs/field-methods.md § Thin walls: the two sides
/// face apart or together). Noisy lines' two-sheet fits pair samples of one surface, so they go
/// without it.
/// Returns the samples flipped over both passes; `sheets` the sheets. Unit normals in, same lines out. Deterministic.
std::size_t FlipSheetsByWinding(const std::vector<Eigen::Vector3d>& positions, std::vector<Eigen::Vector3d>& normals,
                                const std::vector<std::uint8_t>& eligible, std::size_t& sheets,
                                std::size_t coarse_fraction = kSheetCoarseFraction, bool clean_lines = false);

/// Chooses the sign of every normal (see above): MST propagation per connected component of the
/// kOrientNeighbours-nearest graph, run on the jet normals (EstimateNormalLines; across a sharp
/// edge exact face normals are near perpendicular and carry no sign), then the component's outward
/// sign (under estimate, a piece the tree leaves open by its flux is oriented again by a tree that
/// prefers the pairs facing each other across thin walls, kept where it closes the piece: a disc
/// thinner than the spacing that the first tree crossed round its rim), then each given normal
/// takes the sign of its oriented jet normal, then FlipInvertedParts
/// over all samples. `keep_file_majority` (orient mode) decides open components by the majority of
/// the signs given; without it an open component whose mean winding level (SampleProbes::Levels, by area)
/// is below 0 is reversed, and FlipSheetsByWinding runs last: on closed pieces, then on pieces
/// open by their flux (at most 0.6 of the area) with sheets of up to n / 4, kept where it closes
/// them (a sheet the tree turned inward as a whole). `given_are_jet_lines`: the normals are
/// EstimateNormalLines' already (estimate mode; not fitted twice). Unit normals in, same lines out. Counts into
/// `report` (flipped, components, open_components, closed_by_tree, open_level_flipped, inverted_parts,
/// inverted_samples, sheets, sheet_samples, closed_by_sheets, closed_by_sheets_samples). O(n log n); parallel and
/// deterministic.
void OrientNormals(const std::vector<Eigen::Vector3d>& positions, std::vector<Eigen::Vector3d>& normals,
                   bool keep_file_majority, NormalsReport& report, bool given_are_jet_lines = false);

/// Estimated, oriented normals of samples clean for their spacing but noisy for the grid (issue 20;
/// docs/field-methods.md § Noisy for the grid, clean for the spacing): when the lines are the clean
/// fit (`report.neighbours` is kCleanNormalNeighbours) and the position noise (MeasurePositionNoise
/// over the `noise_neighbours` nearest, samples.h) exceeds `noise_threshold` (units of the
/// positions), the lines are fitted again as a noisy set's (EstimateNormalLines with `noisy`: 18
/// neighbours and up), each taking the sign its clean line was oriented to, and
/// `report.neighbours` becomes the new fit's. 10-sample lines carry such noise into the denoiser's
/// moves (CGAL's joint, 5,000 bare samples with 0.3 voxel of noise: band mean 0.248 -> 0.145 voxel
/// with the refit). Run after OrientNormals, before RefineNormalLines. Returns whether the lines
/// were refitted; otherwise nothing changes. Shapes as EstimateNormalLines; deterministic.
bool RefitNoisyNormalLines(const std::vector<Eigen::Vector3d>& positions, std::vector<Eigen::Vector3d>& normals,
                           NormalsReport& report, double noise_threshold, std::size_t noise_neighbours);

/// The signs and final lines of normals that EstimateNormalLines fitted, as `palpa build
/// --normals estimate` gives them: OrientNormals (estimate mode), RefitNoisyNormalLines when
/// `refit_noise_threshold` > 0 (units of the positions; --denoise auto passes kDenoiseVoxels x the
/// provisional voxel, samples.h) with kDenoiseNeighbours, RefineNormalLines, then
/// FlipSheetsOnSharpenedLines; the sheet passes share one neighbour graph. `report.neighbours`
/// must hold the fit's neighbours on entry. Returns whether the lines were fitted again as noisy.
/// Shapes as OrientNormals; a size mismatch or no samples changes nothing and returns false.
bool OrientEstimatedNormals(const std::vector<Eigen::Vector3d>& positions, std::vector<Eigen::Vector3d>& normals,
                            NormalsReport& report, double refit_noise_threshold);

}  // namespace palpa::field
