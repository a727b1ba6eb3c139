#include "palpa/field/normals.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <numeric>
#include <optional>
#include <span>
#include <tuple>
#include <vector>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include "palpa/field/samples.h"
#include "palpa/field/winding.h"
#include "point_cloud.h"

namespace palpa::field {
namespace {

using V3 = Eigen::Vector3d;

// QuadricResidual's fit over all of idx[0..count) as two parallel sheets: one quadric height along
// `normal` (unit) plus a constant offset for the samples above a cut in height, at the cut (at
// least `least_sheet` samples on each side) that leaves the least RMS residual, over (count - 7)
// degrees of freedom, in model units; < 0 when count is under 2 least_sheet + 1 or over 64. A wall
// thinner than the spacing puts its other side among a sample's nearest: one quadric counts that
// side as noise (CGAL's rotor, blades 0.6 spacings thick, exact samples: 0.149 of the 8th
// neighbour's distance, over kCleanNoise), two sheets leave ~0. Noise, split anywhere, keeps most
// of its residual. `other_sheet`, when given, receives the best cut's rows (bit a for idx[a]) that
// lie on the other sheet than p.
double TwoSheetResidualAlong(const std::vector<V3>& positions, const std::size_t* idx, std::size_t count, const V3& p,
                             double scale, const V3& normal, std::size_t least_sheet, std::uint64_t* other_sheet) {
  using M7 = Eigen::Matrix<double, 7, 7>;
  using V7 = Eigen::Matrix<double, 7, 1>;
  if (count < 2 * least_sheet + 1 || count > 64) return -1.0;
  const auto [t1, t2] = detail::TangentFrame(normal);
  std::array<V7, 64> rows;
  std::array<double, 64> h;
  std::array<std::size_t, 64> order;
  for (std::size_t a = 0; a < count; ++a) {
    const V3 d = (positions[idx[a]] - p) / scale;
    const double u = d.dot(t1), v = d.dot(t2);
    rows[a] << 1, u, v, u * u, u * v, v * v, 0;
    h[a] = d.dot(normal);
    order[a] = a;
  }
  std::sort(order.begin(), order.begin() + static_cast<std::ptrdiff_t>(count),
            [&](std::size_t x, std::size_t y) { return h[x] < h[y]; });
  // The quadric's block of the normal equations is the same at every cut; only the offset's row
  // and column (sums over the samples above the cut, in index order as before) change.
  M7 quadric = M7::Zero();
  V7 quadric_rhs = V7::Zero();
  for (std::size_t a = 0; a < count; ++a) {
    quadric += rows[a] * rows[a].transpose();
    quadric_rhs += rows[a] * h[a];
  }
  // p's own row: the last one at p (p is one of the samples, or no row is and row 0 stands in).
  std::size_t own_row = 0;
  for (std::size_t a = 0; a < count; ++a)
    if ((positions[idx[a]] - p).squaredNorm() == 0.0) own_row = a;
  double best = -1.0;
  for (std::size_t cut = least_sheet; cut + least_sheet <= count; ++cut) {
    for (std::size_t r = 0; r < count; ++r) rows[order[r]][6] = r >= cut ? 1.0 : 0.0;
    M7 m = quadric;
    V7 rhs = quadric_rhs;
    for (std::size_t a = 0; a < count; ++a) {
      if (rows[a][6] == 0.0) continue;
      m.row(6) += rows[a].transpose();
      m.col(6).head<6>() += rows[a].head<6>();
      rhs[6] += h[a];
    }
    m.diagonal().array() += 1e-9;
    const V7 c = m.ldlt().solve(rhs);
    if (!c.allFinite()) continue;
    double sum2 = 0.0;
    for (std::size_t a = 0; a < count; ++a) {
      const double e = h[a] - rows[a].dot(c);
      sum2 += e * e;
    }
    const double residual = std::sqrt(sum2 / static_cast<double>(count - 7)) * scale;
    if (best < 0.0 || residual < best) {
      best = residual;
      if (other_sheet != nullptr) {
        const double own = rows[own_row][6];
        *other_sheet = 0;
        for (std::size_t a = 0; a < count; ++a)
          if (rows[a][6] != own) *other_sheet |= std::uint64_t{1} << a;
      }
    }
  }
  return best;
}

// TwoSheetResidualAlong the normal of the samples' plane of least variance (both sheets' normal: a
// jet normal fitted through two sheets can tilt by 70 degrees), 3 samples a sheet or more.
double TwoSheetResidual(const std::vector<V3>& positions, const std::size_t* idx, std::size_t count, const V3& p,
                        double scale, std::uint64_t* other_sheet = nullptr) {
  const V3 normal = detail::FitLeastVariancePlane(positions, idx, count, detail::UnitWeight).normal;
  return TwoSheetResidualAlong(positions, idx, count, p, scale, normal, 3, other_sheet);
}

// EstimateNormalLines' noise figure for a wall: TwoSheetResidual's fit, whose other sheet may hold
// a single sample, along whichever axis of the neighbours' scatter leaves the least residual. A
// wall about one spacing thick puts only one or two of its other side among a sample's 10 nearest,
// or spreads them as far across as along it, so that the least-variance axis lies in the wall (a
// plate 1.2 voxels thick, 2,200-8,000 bare samples at 40-80 cells: read as very noisy, 43-47 % of
// the band wrong). Noise keeps most of its residual along every axis, however split.
double WallResidual(const std::vector<V3>& positions, const std::size_t* idx, std::size_t count, const V3& p,
                    double scale) {
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
  detail::AddScatter(
      count, [&](std::size_t a) -> const V3& { return positions[idx[a]]; }, detail::UnitWeight, scatter);
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(scatter);
  if (eigen.info() != Eigen::Success) return -1.0;
  double best = -1.0;
  for (Eigen::Index axis = 0; axis < 3; ++axis) {
    const double r =
        TwoSheetResidualAlong(positions, idx, count, p, scale, V3(eigen.eigenvectors().col(axis)), 1, nullptr);
    if (r >= 0.0 && (best < 0.0 || r < best)) best = r;
  }
  return best;
}

// EstimateNormalLines' noise figure takes a sample's fit as two parallel sheets (a wall thinner
// than the spacing: TwoSheetResidual) where that leaves under this share of one quadric's
// residual. Noise, split anywhere, keeps most of its residual; a clean thin wall keeps ~0 (CGAL's
// rotor, blades 0.6 spacings thick, was read as noisy). At 0.2 CGAL's building.ply, an aerial scan
// whose roofs step in parallel levels, was also called clean; at 0.1 it is not.
constexpr double kTwoSheetShare = 0.1;
constexpr std::size_t kRefineNeighbours = 16;
constexpr double kRefineWidth =
    0.1;  // x the distance to the 16th neighbour (tried 0.1-0.5 on fandisk, knot, sphere, a cube)
// The candidate planes are told apart by a narrower support: x kRefineWidth, and at least twice the
// samples' own noise (tried 0.05-1 on fandisk; 1 was the support above: a plane cutting
// diagonally through an edge gathered as many neighbours within w as either face).
constexpr double kSelectWidth = 0.1;
constexpr double kSelectNoise = 2.0;
// ... on a noisy set only. On a clean set the quadric fits' residual is creases and thin walls'
// other sides, not noise (CGAL's spool: twice its median is 0.4 spacings, about twenty times the
// narrow width), and it widened the selection to a blend's plane (normals stripped, wrong sign in
// the band, seed 1, this alone: the spool 1.90 -> 1.76 %, the pinion 1.44 -> 1.38 %).
// Then the supporters' quadric: a clean sample's normal is that of a quadric height function
// through P_i fitted to the neighbours within the support width of its plane, when there are
// kSupportQuadric or more. A plane fitted to them is the tangent plane at their centroid, not at
// P_i: tilted by the curvature times the centroid's offset (a sphere of 3,000 samples: median
// 0.93 degrees, 1,374 lines over 1 degree; with the quadric 0.005 degrees and 11), most of all in a
// first row, whose supporters lie on one side. Both, normals stripped, wrong sign in the band,
// seeds 1 / 5 / 9: the spool 1.90 / 1.77 / 1.82 -> 1.73 / 1.64 / 1.71 %, the pinion 1.44 / 1.41 /
// 1.41 -> 1.40 / 1.36 / 1.40 %, fandisk 0.48 / 0.44 / 0.63 -> 0.48 / 0.38 / 0.54 %, the rotor
// 3.91 / 4.15 / 4.01 -> 3.82 / 4.04 / 3.87 %; CGAL's anchor (seed 9) 1.01 -> 0.91 %; couplingdown
// and the organic meshes within 0.03 point.
constexpr std::size_t kSupportQuadric = 8;
// Where the set's offsets from its jet planes exceed the width (a smooth curved surface, or a
// low-polygon one), a sample is refined only when the best plane holds this share of its
// neighbourhood within the selection width itself (not widened by the noise): a facet, which its
// jet fit bends towards the next one, not a curve or a noisy patch. Estimated normals, wrong sign
// in the band against exact normals, two draws (issue 20, bench/field/robustness.py): CGAL's pinion
// 2.29x / 2.05x -> 1.98x / 1.71x, the elk 1.78x / 1.81x -> 1.50x / 1.55x, the double torus (466
// faces) 2.00x / 1.84x -> 1.66x / 1.59x; 0.3 took knot1 (a tube of facets) 0.96x -> 1.10x, 0.5-0.6
// gained half as much.
constexpr double kFacetShare = 0.4;
// Triples of P_i and two of its kTripleNeighbours nearest: a face met by only a thin row of
// samples near P_i still has a non-collinear pair among them (9 -> 13: fandisk 0.52 -> 0.49 %).
constexpr std::size_t kTripleNeighbours = 12;
// A clean set's sample that is neither a facet nor rim: a quadric through P_i fitted to its
// neighbours by iteratively reweighted least squares (Tukey's biweight, cut at 3 x this share of
// the 16th neighbour's distance, kQuadricRounds rounds), started from each candidate's frame; the
// fit most neighbours support wins. A jet fit gives equal weight to a thin part's other side and
// to the next face over a crease (CGAL's couplingdown and turbine, exact samples: 640 / 635
// normals off by over 30 degrees). Tried 0.02-0.05 x 10-24 neighbours on couplingdown: 0.02 x 16
// fewest off by over 10 degrees.
constexpr double kQuadricScale = 0.02;
constexpr int kQuadricRounds = 4;
// ... and replaces the jet normal only when another frame's fit gathers this many neighbours'
// weight more than its own frame's: on smooth organic meshes a near tie moved normals for nothing
// (unseen CGAL meshes, normals stripped, wrong sign: homer 1.48 -> 1.53 %, knot2 4.18 -> 4.39 %
// without the margin; 1.48 and 4.19 with 2).
constexpr double kQuadricMargin = 2.0;
// Last, a clean set's first rows take a face's plane: a sample whose refined plane holds under
// kConfidentShare of its neighbourhood within the support width takes the normal of a neighbour
// among its kFaceNeighbours nearest whose plane holds kConfidentShare or more (within a face),
// turns by over kFaceMinDeg from its own (a curved surface's neighbours differ by less and are
// left alone), and passes within asin(kFaceChordSin) of it along the chord (a face's plane passes
// through its own samples; the next face's misses them by their distance from the edge): the one
// that passes nearest. On faces a few spacings wide (a gear tooth's) a sample's 16 nearest span
// three faces, and the plane most of them lie on is as often a blend or the next face. Lines more
// than 30 degrees off among CGAL's pinion's 5,000 samples 328 -> 200 (nearly all within 2 spacings
// of a 90-degree edge, 269 of the 328 blends); wrong sign in the band, normals stripped, with
// kFlatFace: 1.88 -> 1.70 % on the pinion, 2.19 -> 2.01 % couplingdown, 4.72 -> 4.00 % rotor;
// no organic mesh worse. Tried: shares 0.5-0.7, 8-16 neighbours, a distance rather than an angle
// (0.02-0.1 of the nearest-sample distance), every sample rather than the unsupported ones (the
// joint 1.42 -> 1.57 %), no least turn (knot1 0.88 -> 0.89 %).
constexpr double kConfidentShare = 0.5;
// ... and only from a flat face: the neighbour's supporters lie within this share of the width of
// its plane, by RMS. On organic meshes a confident neighbour's tangent plane can pass through a
// sample at a saddle; the lines it moved there that got worse had medians of 0.37-0.44, the CAD
// parts' that got better 0.24-0.28. Without it the camel (CGAL, seed 5) 1.33 -> 1.38 %, the cow,
// bull and elephant 0.02-0.04 point worse; with it none worse, at a third of the CAD parts' gain
// (the pinion 1.60 -> 1.70 % on seed 1).
constexpr double kFlatFace = 0.3;
constexpr std::size_t kFaceNeighbours = 12;
static_assert(kFaceNeighbours <= kRefineNeighbours + 1, "TakeFacePlanes reads the searched neighbourhood");
constexpr double kFaceMinDeg = 10.0;
constexpr double kFaceChordSin = 0.03;
// And after that, a clean set's facets: the plane through P_i and two of its kTripleNeighbours
// nearest that the most of its 16 nearest lie on to within kExactFacetWidth x the 16th one's
// distance, when that is kExactFacetCount samples or more (P_i, the two, and two more), is the
// sample's normal. Samples of a flat face are coplanar to the file's rounding; those of a curved
// surface, or of the next face over an edge, miss such a plane by the surface's sagitta or the
// distance from the edge, both ~1e-2 of the spacing or more. TakeFacePlanes' widths (0.01-0.1 of
// the distance) cannot tell a first row's face from its neighbour's; this one can. Normals
// stripped, wrong sign in the band, seeds 1 / 5 / 9: the pinion 1.70 / 1.60 / 1.57 -> 1.44 / 1.41 /
// 1.41 %, the spool 2.10 / 2.01 / 1.97 -> 1.90 / 1.77 / 1.82 %, CGAL's turbine 1.27 -> 1.19 % and
// anchor 1.34 -> 1.01 %; organic meshes within 0.02 point. Tried: 1e-5 (the pinion 1.49 %), 1e-3
// (coincidences on organic meshes: the camel 1.35 -> 1.38 %, the elephant 1.30 -> 1.32 %); 4
// samples (coincidences: 1,270 of the camel's 1,938 changed lines got worse), 6 (the pinion 1.48 %,
// the rotor 3.73 % against 3.59 %).
constexpr double kExactFacetWidth = 1e-4;
constexpr std::size_t kExactFacetCount = 5;
// ... and only a plane that has the rest of the neighbourhood on one side (kFacetOneSide of the
// samples off it), as a face's plane has next to an edge, or that one of its samples' own lines
// already lies within kFacetAgreeDeg of. Samples in rings (a UV sphere's vertices: data/sphere926,
// 192 of 926 samples on a ring plane up to 16 degrees off the sphere's normal) are coplanar too,
// but their plane cuts the surface. The guard costs the pinion 0.01-0.05 point (1.44 / 1.41 / 1.41 %
// at seeds 1 / 5 / 9); of a synthetic UV sphere's 912 samples away from its poles, 96 took
// their ring's plane (up to 22.5 degrees off) and none does.
constexpr double kFacetOneSide = 0.9;
constexpr double kFacetAgreeDeg = 3.0;

// FlipInvertedParts: a group is the samples connected in the kInvertedGraph-nearest graph; it
// flips when it has kInvertedMinSamples or more (fewer are one neighbourhood's noise: a sharp
// edge's 1-2 samples reach -1 on fandisk) and a mean level below kInvertedLevel (an inverted
// part's is near -1/2: the cow's tail -0.33; a thin part correctly oriented but mixed with its
// other side: the bull's horn -0.15).
constexpr std::size_t kInvertedGraph = 10;
constexpr std::size_t kInvertedMinSamples = 16;
constexpr double kInvertedLevel = -0.25;
constexpr int kRepairSweeps = 3;
constexpr int kInvertedPasses = 4;  // the last one only repairs the edges of the groups flipped before it

// FlipSheetsByWinding: sheets are joined over the kSheetGraph nearest with normals within an
// angle and chords within asin(chord) of both tangent planes (SheetCut; 0.5 joined the two sides
// of a fin 0.8 spacings thick at its rim); a sheet of at most kSheetMostSamples (and n / 8: the
// body is not a candidate, its sign is the piece's) is measured on the probes within twice its
// radius plus kSheetReach x 2 d_i, and flips when that lowers the energy, until no flip does (each
// sheet flips at most once; only the sheets whose probes a flip reached are scored again).
constexpr std::size_t kSheetGraph = 10;
constexpr std::size_t kSheetMostSamples = 4096;
constexpr double kSheetReach = 3.0;
// The energy's dipoles are discs, smoothed over their radius sqrt(a_j / pi), at the probes'
// kSheetNearField nearest samples (beyond them the kernels differ by under 5 %): a point dipole's
// 1/r^2 at a probe 0.6 spacings from a thin wall's other side made right signs score as losses and
// wrong ones as gains (the elk, seed 6: the exact signs' energy above the orientation's).
constexpr std::size_t kSheetNearField = 32;
// Sheets of more samples than this keep their own terms at their probes between rounds (TurnSheets).
constexpr std::size_t kKeptTermsSamples = 16;
// A sheet of more samples than this is first scored through a tree of its dipoles (SheetDipoles):
// the exact sum costs probes x samples, and on dense bare sets the 161 sheets of 257-4,096 samples
// (of 47,686 scored), reaching 11,000-53,000 probes each on the mean, were 95 % of the scoring's
// pairs (fandisk, 2,000,000 bare samples thinned to 702,290). A flip still moves w by exact sums.
// The same blob payloads on every input measured (docs/field-methods.md § Bare dense sets: big
// sheets through a dipole tree).
constexpr std::size_t kSheetTreeSamples = 256;
struct SheetCut {
  double angle_deg;
  double chord;
  std::size_t most_fraction;  // a candidate has at most n / most_fraction samples
};
// The coarse cut, then a fine one (half the angle and the chord, sheets of up to n / 8 as
// the coarse cut's): after the coarse pass the wrong signs left sit in samples that the coarse
// cut joined to right ones (the elk's seed 6: 8 wrong and 1 right, a loss as one sheet). Those
// can be a whole face: CGAL's 3torus without normals (seed 8) kept a face of 118 samples inward,
// a sheet of its own under the fine cut but over its old limit of n / 100 (9,490 far-wrong nodes;
// 31 with n / 8; docs/field-methods.md § Thin walls: the two sides face apart or together).
constexpr std::array<SheetCut, 2> kSheetCuts{
    {{30.0, detail::kCoarseSheetSin, 8}, {15.0, detail::kCoarseSheetSin / 2, 8}}};
// The largest sheet, as a fraction 1 / kOpenSheetFraction of the samples, that the sheet pass may
// turn on a piece open by its flux (OrientNormals).
constexpr std::size_t kOpenSheetFraction = 4;
// ... on a piece whose flux is at most this fraction of its area: turning a sheet of up to a
// quarter of its samples changes the flux by up to half the area, so a piece above 0.1 + 0.5 is
// open whatever one such sheet's sign (an aerial or one-sided scan: 0.x; the trial cost
// b9_training 11 -> 28 s without this gate, for no change).
constexpr double kOpenSheetMostFlux = detail::kClosedFlux + 2.0 / static_cast<double>(kOpenSheetFraction);
// The largest sheet, 1 / kWideOpenSheetFraction of the samples, turned on a piece that the trial
// above left open (OrientNormals)...
constexpr std::size_t kWideOpenSheetFraction = 2;
// ... and only on a piece with fewer rim samples than kWideOpenMostRims sqrt(its samples), found
// over their kPieceRimNeighbours nearest.
constexpr std::size_t kPieceRimNeighbours = 16;
constexpr double kWideOpenMostRims = 4.0;
// ... and where the sheet pass did not close it, the one sheet turned alone stands when the
// piece's mean winding level reaches this (1/2 on a closed surface oriented outward).
constexpr double kWideOpenLevel = 0.4;

// The sheet pass also runs on samples fitted over kNormalNeighbours whose noise figure
// (EstimateNormalLines') is under this. A part thinner than a few spacings with a little noise is
// called noisy (the two-sheet fit no longer leaves ~0), and the tree alone then orients across it:
// CGAL's rotor, 5,000 bare samples with 0.2-0.5 voxels of noise (figures 0.12-0.19), 31-33 % of
// the band wrong and ~148,000 far-wrong nodes without the pass, 9.5-13 % and 113-7,118 with it.
// The noisy dense sphere of NoisyDenseBarePositions... (0.42) stays out.
constexpr double kSheetPassNoise = 0.2;

// OrientNormals: a piece is open when its flux (sum of a_i n_i) is at least this fraction of its
// area.
constexpr double kOpenPieceFlux = 0.2;
// The spanning tree's cost of an edge between two samples facing each other (the chord within
// acos(0.8) of both lines): kFacingBase - |n . chord|, above every edge along a sheet, so that the
// tree crosses a gap between sheets only where the sheet offers no path. The retry of a piece left
// open takes kFacingRetryBase, level with a noisy sheet's edges (1 - |n_i . n_j| + the chord's
// sine off the planes, 0.1-0.4 at 0.25 voxel of noise): 1.35 and 1.5 left the turbine's two draws
// open.
constexpr double kFacingBase = 2.0;
constexpr double kFacingRetryBase = 1.2;

// A sheet pass keeps apart two samples that a two-sheet fit of either's kCleanNormalNeighbours
// nearest (TwoSheetResidual) puts on the wall's two sides, where that fit leaves under this share
// of one quadric's residual. The two sides of a wall thinner than the spacing are each other's
// nearest samples; once one side has taken the other's sign, their chords pass SheetCut's test
// (CGAL's rotor, normals stripped: the largest sheet held 100 wrong samples). Tried 0.1-1 on the
// rotor, spool, couplingdown, pinion: 0.3-0.5 best; 0.1 leaves most walls joined, 0.7 joins
// across creases.
constexpr double kThinWallShare = 0.5;
// The sheet energy's facing term, on a clean set's lines: a wall's two sides face apart (a solid
// wall) or together (a gap), never the same way. A pair of samples that a two-sheet fit puts on
// the two sides (kThinWallShare), stacked (the chord steeper than kStackedSin off the first one's
// tangent plane) with lines within acos(kStackedLinesCos) of parallel, costs kFacingWeight x the
// pair's weight while its normals face the same way; the pair's weight is a_i / |O_i| + a_j /
// |O_j|, O the other-sides lists that name it (each list shares its sample's area). On a wall a
// spacing or less thick the probes straddle the wall whichever side is wrong, and the winding
// energy scores a patch turned to the other side's sign about even (CGAL's rotor, 5,000 samples,
// normals stripped: the ring's inner wall, 0.4-1.5 spacings thick, 73 samples, +0.11 per unit
// of area; far-wrong nodes 0-1,772 over seeds 1-6 with the winding energy alone, 0-1 with the
// term; docs/field-methods.md § Thin walls: the two sides face apart or together). Only sheets of
// kFacingLeastSamples or more take the term: a sheet of one or two samples at a CAD part's edge
// has lines a two-sheet fit pairs with a step's other level (couplingdown: 27 more wrong signs
// with the term on every sheet). Weights 0.75-2 gave the same rotor fields but for one draw;
// above 1, couplingdown lost 0.08 % of its band.
constexpr double kFacingWeight = 1.0;
constexpr double kStackedSin = 0.5;
constexpr double kStackedLinesCos = 0.5;
constexpr std::size_t kFacingLeastSamples = 8;
using OtherSides = std::vector<std::array<std::uint32_t, kCleanNormalNeighbours>>;

// For each sample, the neighbours on a thin wall's other side (kThinWallShare), UINT32_MAX after
// the last. `lines`: the normals' lines (their signs do not matter).
// `tree`: the k-d tree of `positions` (leaves of 10).
OtherSides ThinWallOtherSides(const std::vector<V3>& positions, const std::vector<V3>& lines,
                              const detail::KdTree& tree) {
  const std::size_t n = positions.size();
  OtherSides other(n);
  for (auto& o : other) o.fill(UINT32_MAX);
  constexpr auto k = static_cast<std::size_t>(kCleanNormalNeighbours);
  if (n <= k) return other;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 256), [&](const auto& r) {
    std::array<std::size_t, k + 1> idx{};
    std::array<double, k + 1> d2{};
    for (std::size_t i = r.begin(); i != r.end(); ++i) {
      const std::size_t got = tree.knnSearch(positions[i].data(), k + 1, idx.data(), d2.data());
      const double scale = std::sqrt(d2[got - 1]);
      const double one = detail::QuadricResidual(positions, idx.data(), got, positions[i], lines[i], scale, 8,
                                                 [](std::size_t) { return true; });
      std::uint64_t across = 0;
      const double two = TwoSheetResidual(positions, idx.data(), got, positions[i], scale, &across);
      if (!(two >= 0.0 && two < kThinWallShare * one)) continue;
      std::size_t m = 0;
      for (std::size_t a = 0; a < got && m < k; ++a)
        if (((across >> a) & 1u) != 0) other[i][m++] = static_cast<std::uint32_t>(idx[a]);
    }
  });
  return other;
}

bool OnOtherSides(const OtherSides& other, std::uint32_t i, std::uint32_t j) {
  const auto lists = [](const std::array<std::uint32_t, kCleanNormalNeighbours>& o, std::uint32_t x) {
    return std::find(o.begin(), o.end(), x) != o.end();
  };
  return lists(other[i], j) || lists(other[j], i);
}

struct Edge {
  float cost;  // the MST follows the smoothest, flattest paths (OrientNormals)
  std::uint32_t a, b;
  bool same;  // the given normals of a and b are consistent as they are (else one must flip)
};

// The K nearest other samples of each sample (fewer found: the sample itself fills the row), from
// a k-d tree with leaves of 10 (ties at the Kth distance follow the tree: kRangeLeaf's note).
template <std::size_t K>
std::vector<std::array<std::uint32_t, K>> NearestGraph(const detail::KdTree& tree, const std::vector<V3>& positions) {
  std::vector<std::array<std::uint32_t, K>> graph(positions.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, positions.size(), 256), [&](const auto& r) {
    std::array<std::size_t, K + 1> idx{};
    std::array<double, K + 1> d2{};
    for (std::size_t i = r.begin(); i != r.end(); ++i) {
      const std::size_t got = tree.knnSearch(positions[i].data(), K + 1, idx.data(), d2.data());
      std::size_t e = 0;
      for (std::size_t m = 0; m < got && e < K; ++m)
        if (idx[m] != i) graph[i][e++] = static_cast<std::uint32_t>(idx[m]);
      for (; e < K; ++e) graph[i][e] = static_cast<std::uint32_t>(i);
    }
  });
  return graph;
}
template <std::size_t K>
std::vector<std::array<std::uint32_t, K>> NearestGraph(const std::vector<V3>& positions) {
  const detail::PointCloud cloud{&positions};
  const detail::KdTree tree(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(10));
  return NearestGraph<K>(tree, positions);
}
// A probe's miss, capped: a probe beside another sample reads that sample's point dipole (1/r^2,
// unbounded), and one such probe must not outweigh a sheet (a fin 0.8 spacings thick: both of its
// sides' flips raised the energy without the cap, its wrong side's lowers it with).
double Miss(double e) { return std::min(e * e, 1.0); }

struct QuadricFit {
  double support = -1;  // the sum of the biweights
  V3 normal = V3::UnitZ();
};

// The height function h = c1 u + c2 v + c3 u^2 + c4 uv + c5 v^2 over the tangent plane of `axis`
// at p (through p: a clean sample is on its surface), in units of `scale`: the rows (u, v, u^2, uv,
// v^2) and heights of idx[0..count), at most kRefineNeighbours + 1 of them.
struct HeightRows {
  using V5 = Eigen::Matrix<double, 5, 1>;
  using Weights = std::array<double, kRefineNeighbours + 1>;  // one per row
  HeightRows(const std::vector<V3>& positions, const std::size_t* idx, std::size_t n, const V3& p, const V3& axis_in,
             double scale)
      : axis(axis_in), count(std::min(n, rows.size())) {
    std::tie(t1, t2) = detail::TangentFrame(axis);
    for (std::size_t m = 0; m < count; ++m) {
      const V3 d = (positions[idx[m]] - p) / scale;
      const double u = d.dot(t1), v = d.dot(t2);
      rows[m] << u, v, u * u, u * v, v * v;
      heights[m] = d.dot(axis);
    }
  }
  // Weighted least squares; false if singular.
  bool Solve(const Weights& weights, V5& c) const {
    Eigen::Matrix<double, 5, 5> normal_matrix = Eigen::Matrix<double, 5, 5>::Zero();
    V5 rhs = V5::Zero();
    for (std::size_t m = 0; m < count; ++m) {
      normal_matrix += weights[m] * rows[m] * rows[m].transpose();
      rhs += weights[m] * heights[m] * rows[m];
    }
    normal_matrix.diagonal().array() += 1e-9;
    c = normal_matrix.ldlt().solve(rhs);
    return c.allFinite();
  }
  // Row m's offset from the function c, in units of scale.
  double Residual(std::size_t m, const V5& c) const { return heights[m] - rows[m].dot(c); }
  // The fit's unit normal at p (u = v = 0).
  V3 NormalAtP(const V5& c) const { return V3(axis - c[0] * t1 - c[1] * t2).normalized(); }

  V3 axis, t1, t2;
  std::array<V5, kRefineNeighbours + 1> rows{};
  std::array<double, kRefineNeighbours + 1> heights{};
  std::size_t count;
};

// HeightRows' function fitted robustly to idx[0..count) (P_i among them or not); the normal is the
// fit's at P_i.
QuadricFit RobustQuadricThrough(const std::vector<V3>& positions, const std::size_t* idx, std::size_t count,
                                const V3& p, const V3& axis, double scale) {
  const HeightRows h(positions, idx, count, p, axis, scale);
  HeightRows::Weights weights{};
  std::fill_n(weights.begin(), h.count, 1.0);
  QuadricFit fit;
  HeightRows::V5 c = HeightRows::V5::Zero();
  for (int round = 0; round < kQuadricRounds; ++round) {
    if (!h.Solve(weights, c)) return fit;
    fit.support = 0;
    for (std::size_t m = 0; m < h.count; ++m) {
      const double r = h.Residual(m, c) / 3.0;  // heights are in scales; the cut is 3
      const double t = std::max(0.0, 1.0 - r * r);
      weights[m] = t * t;
      fit.support += weights[m];
    }
  }
  fit.normal = h.NormalAtP(c);
  return fit;
}

// RefineNormalLines' clean-set fit (kSupportQuadric): the normal at p of HeightRows' function over
// the frame of `plane`, fitted to the neighbours within `width` of that plane, then again to those
// within kSelectWidth x width of the first fit, which drops the next face's nearest samples that
// it bent towards (a cylinder's first rows next to a flat cap: median 1.33 -> 0.29 degrees).
// `plane` itself when either fit has fewer than kSupportQuadric neighbours or is singular.
V3 SupportersQuadricNormal(const std::vector<V3>& positions, const std::size_t* idx, std::size_t count, const V3& p,
                           const V3& plane, double scale, double width) {
  const HeightRows h(positions, idx, count, p, plane, scale);
  HeightRows::Weights inside{};
  // The neighbours within `cut` of the function c (zero: the plane) as 0/1 weights; their count.
  const auto within = [&](const HeightRows::V5& c, double cut) {
    std::size_t on = 0;
    for (std::size_t m = 0; m < h.count; ++m) {
      inside[m] = std::abs(h.Residual(m, c)) * scale < cut ? 1.0 : 0.0;
      on += inside[m] > 0 ? 1u : 0u;
    }
    return on;
  };
  HeightRows::V5 c = HeightRows::V5::Zero();
  if (within(c, width) >= kSupportQuadric && h.Solve(inside, c) && within(c, kSelectWidth * width) >= kSupportQuadric &&
      h.Solve(inside, c))
    return h.NormalAtP(c);
  return plane;
}

}  // namespace

int EstimateNormalLines(const std::vector<V3>& positions, std::vector<V3>& normals, double* noise_figure, bool noisy) {
  const std::size_t n = positions.size();
  if (!noisy || n <= static_cast<std::size_t>(kCleanNormalNeighbours))
    detail::JetNormalLines(positions, kCleanNormalNeighbours, normals);
  // Too few to measure the noise: the fit took them all (n - 1 neighbours).
  if (n <= static_cast<std::size_t>(kCleanNormalNeighbours)) return n > 0 ? static_cast<int>(n - 1) : 0;
  // The noise relative to the spacing, over the same 10 nearest (wider, the fit of a sample on a
  // thin part would count the part's other side as noise), on at most 20,000 samples.
  const std::size_t stride = (n + 19'999) / 20'000;
  const std::size_t count = (n + stride - 1) / stride;
  const detail::PointCloud cloud{&positions};
  const detail::KdTree tree(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(10));
  constexpr auto k = static_cast<std::size_t>(kCleanNormalNeighbours);
  // A fit forced noisy (`noisy`) skips the measure: its result would be thrown away.
  if (!noisy) {
    std::vector<double> relative(count);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, 256), [&](const auto& r) {
      std::vector<std::size_t> idx(k + 1);
      std::vector<double> d2(k + 1);
      for (std::size_t s = r.begin(); s != r.end(); ++s) {
        const std::size_t i = s * stride;
        const std::size_t got = tree.knnSearch(positions[i].data(), k + 1, idx.data(), d2.data());
        const double eighth = std::sqrt(d2[std::min<std::size_t>(8, got - 1)]);
        const double scale = std::sqrt(d2[got - 1]);
        double residual = detail::QuadricResidual(positions, idx.data(), got, positions[i], normals[i], scale, 8,
                                                  [](std::size_t) { return true; });
        const double sheets = WallResidual(positions, idx.data(), got, positions[i], scale);
        if (sheets >= 0.0 && sheets < kTwoSheetShare * residual) residual = sheets;
        relative[s] = eighth > 0 ? std::max(residual, 0.0) / eighth : 0.0;
      }
    });
    const double figure = detail::Median(std::move(relative));
    if (noise_figure != nullptr) *noise_figure = figure;
    if (figure < kCleanNoise) return kCleanNormalNeighbours;
  }
  // Noisy: 18 neighbours; where the lines of nearest neighbours still differ by more than
  // kRoughNormalsDeg on the median (noise, not curvature, at that spacing), more, until they
  // differ by kSmoothNormalsDeg at most.
  const auto rough_deg = [&] {
    std::vector<double> angle(count);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, 256), [&](const auto& r) {
      std::array<std::size_t, 2> idx{};
      std::array<double, 2> d2{};
      for (std::size_t s = r.begin(); s != r.end(); ++s) {
        const std::size_t i = s * stride;
        const std::size_t got = tree.knnSearch(positions[i].data(), 2, idx.data(), d2.data());
        const std::size_t j = got > 1 && idx[0] == i ? idx[1] : idx[0];
        angle[s] = std::acos(std::min(1.0, std::abs(normals[i].dot(normals[j])))) * 180.0 / std::numbers::pi;
      }
    });
    return detail::Median(std::move(angle));
  };
  int neighbours = kNormalNeighbours;
  detail::JetNormalLines(positions, neighbours, normals);
  double rough = rough_deg();
  if (rough <= kRoughNormalsDeg) return neighbours;
  std::vector<V3> wider;
  while (rough > kSmoothNormalsDeg && neighbours < kMostNormalNeighbours &&
         static_cast<std::size_t>(neighbours) < n - 1) {
    const int more = std::min(kMostNormalNeighbours, neighbours * 3 / 2);
    detail::JetNormalLines(positions, more, wider);
    std::swap(wider, normals);
    const double wider_rough = rough_deg();
    // Noise falls as 1 / (radius x sqrt(count)), by a third per step; a smaller fall is the
    // surface's own curvature, which a wider fit blurs.
    if (wider_rough > kNoiseFall * rough) {
      std::swap(wider, normals);
      break;
    }
    neighbours = more;
    rough = wider_rough;
  }
  return neighbours;
}

namespace {

// Calls plane(n) with the unit normal of each plane through P_i (idx[0] == i) and two of its
// kTripleNeighbours nearest, skipping near-collinear triples (under 17 degrees at P_i).
template <class Plane>
void ForEachTriplePlane(const std::vector<V3>& positions, const std::size_t* idx, std::size_t got, std::size_t i,
                        Plane&& plane) {
  const std::size_t near = std::min<std::size_t>(got, kTripleNeighbours + 1);
  for (std::size_t a = 1; a < near; ++a) {
    for (std::size_t b = a + 1; b < near; ++b) {
      const V3 u = positions[idx[a]] - positions[i];
      const V3 v = positions[idx[b]] - positions[i];
      const V3 cross = u.cross(v);
      const double area = cross.norm();
      if (area > 0.3 * u.norm() * v.norm()) plane(V3(cross / area));
    }
  }
}

// Each sample's k + 1 nearest samples (itself first, k <= kRefineNeighbours) and the distance to
// the last: the steps of RefineNormalLines all read this neighbourhood, searched once.
struct Neighbourhoods {
  Neighbourhoods(const std::vector<V3>& positions, const detail::KdTree& tree, std::size_t k)
      : idx(positions.size()), got(positions.size()), radius(positions.size()) {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, positions.size(), 256), [&](const auto& r) {
      std::array<double, kRefineNeighbours + 1> d2{};
      for (std::size_t i = r.begin(); i != r.end(); ++i) {
        got[i] = tree.knnSearch(positions[i].data(), k + 1, idx[i].data(), d2.data());
        radius[i] = std::sqrt(d2[got[i] - 1]);
      }
    });
  }
  std::vector<std::array<std::size_t, kRefineNeighbours + 1>> idx;
  std::vector<std::size_t> got;
  std::vector<double> radius;
};

// RefineNormalLines' next-to-last step (kConfidentShare): first rows take a face's plane. Rim
// samples (kept as their jet fit) neither take nor give one.
void TakeFacePlanes(const std::vector<V3>& positions, const Neighbourhoods& near, const std::vector<std::uint8_t>& rim,
                    std::vector<V3>& normals) {
  const std::size_t n = positions.size();
  const std::vector<V3> refined = normals;
  std::vector<double> share(n, 0.0), flat(n, 1.0);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 256), [&](const auto& r) {
    for (std::size_t i = r.begin(); i != r.end(); ++i) {
      const auto& idx = near.idx[i];
      const std::size_t got = near.got[i];
      const double width = kRefineWidth * near.radius[i];
      std::size_t on = 0;
      double sum2 = 0.0;
      for (std::size_t m = 0; m < got; ++m) {
        const double offset = std::abs(refined[i].dot(positions[idx[m]] - positions[i]));
        if (offset < width) {
          ++on;
          sum2 += offset * offset;
        }
      }
      share[i] = static_cast<double>(on) / static_cast<double>(got);
      flat[i] = on > 0 ? std::sqrt(sum2 / static_cast<double>(on)) / width : 1.0;
    }
  });
  const double turn = std::cos(kFaceMinDeg * std::numbers::pi / 180.0);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 256), [&](const auto& r) {
    for (std::size_t i = r.begin(); i != r.end(); ++i) {
      if (rim[i] != 0 || share[i] >= kConfidentShare) continue;
      // The kFaceNeighbours nearest: the first of the searched neighbourhood.
      const auto& idx = near.idx[i];
      const std::size_t got = std::min(near.got[i], kFaceNeighbours);
      double nearest = kFaceChordSin;
      std::size_t face = n;
      for (std::size_t m = 0; m < got; ++m) {
        const std::size_t j = idx[m];
        const V3 chord = positions[i] - positions[j];
        if (j == i || rim[j] != 0 || share[j] < kConfidentShare || !(chord.squaredNorm() > 0) || flat[j] > kFlatFace)
          continue;
        if (std::abs(refined[j].dot(refined[i])) > turn) continue;
        const double off = std::abs(refined[j].dot(chord)) / chord.norm();
        if (off < nearest || (off == nearest && face < n && share[j] > share[face])) {
          nearest = off;
          face = j;
        }
      }
      if (face < n) normals[i] = refined[face].dot(refined[i]) < 0 ? V3(-refined[face]) : refined[face];
    }
  });
}

// RefineNormalLines' very last step on a clean set (kExactFacetWidth): a sample on a facet takes
// the facet's plane. The sign is kept.
void TakeExactFacets(const std::vector<V3>& positions, const Neighbourhoods& near, std::vector<V3>& normals) {
  const std::size_t n = positions.size();
  const std::vector<V3> lines = normals;  // the supporters' lines as they came, whatever this step does
  const double agree = std::cos(kFacetAgreeDeg * std::numbers::pi / 180.0);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 256), [&](const auto& r) {
    for (std::size_t i = r.begin(); i != r.end(); ++i) {
      const auto& idx = near.idx[i];
      const std::size_t got = near.got[i];
      const double exact = kExactFacetWidth * near.radius[i];
      std::size_t best = 0;
      V3 facet = normals[i];
      ForEachTriplePlane(positions, idx.data(), got, i, [&](const V3& plane) {
        std::size_t on = 0, above = 0, below = 0;
        bool agreed = false;
        for (std::size_t m = 0; m < got; ++m) {
          const double offset = plane.dot(positions[idx[m]] - positions[i]);
          if (std::abs(offset) < exact) {
            ++on;
            agreed = agreed || (idx[m] != i && std::abs(lines[idx[m]].dot(plane)) > agree);
          } else {
            ++(offset > 0 ? above : below);
          }
        }
        if (on <= best) return;  // ties: the first
        // A plane through a ring of samples (a turned part's, a UV sphere's) cuts the surface:
        // the rest lie on both sides of it, and none of the ring's own lines is its normal.
        const double one_side = static_cast<double>(std::max(above, below));
        if (!(agreed || one_side >= kFacetOneSide * static_cast<double>(above + below))) return;
        best = on;
        facet = plane;
      });
      if (best >= kExactFacetCount) normals[i] = facet.dot(normals[i]) < 0 ? V3(-facet) : facet;
    }
  });
}

}  // namespace

// RefineNormalLines' last step on a noisy set (TakeCleanestPlanes): a sample whose own plane fit
// leaves over kCreaseResidual x the set's median residual straddles a crease (or a thin part's
// two sides); it takes the plane of the neighbourhood with the least residual, under
// kCleanerShare x its own, that it lies on to within kOnPlaneResiduals x max(that residual, the
// median) and that turns its normal by under 50 degrees (|cos| >= kTakenTurnCos: a face narrower
// than a neighbourhood, whose every neighbourhood holds a crease, must not take the next face's
// plane; CGAL's joint, 5,000 noisy samples: 101 phantom nodes without it). Measured on 5,000
// samples, 0.5 voxel of noise, at 150 cells (docs/field-methods.md § Noisy bare samples: crease
// planes).
constexpr double kCreaseResidual = 1.6;
constexpr double kCleanerShare = 0.5;
constexpr double kOnPlaneResiduals = 2.0;
constexpr double kTakenTurnCos = 0.64;

// A jet fit, and the edge refinement's supporters on a noisy set, blend the faces of a crease;
// noise then hides which face a sample lies on from any fit centred on it, but not from its
// neighbours' fits: those centred on one face leave only the noise (shifted neighbourhoods, as
// in Fleishman, Cohen-Or & Silva 2005, robust moving least squares). `k` samples a plane (the jet
// fit's count), the candidates its 2k nearest. Keeps each normal's sign.
void TakeCleanestPlanes(const std::vector<V3>& positions, const detail::KdTree& tree, std::size_t k,
                        std::vector<V3>& normals) {
  const std::size_t n = positions.size();
  const std::size_t fit = std::min(k, n), reach = std::min(2 * k, n);
  if (fit < 4) return;
  std::vector<V3> centre(n), plane(n);
  std::vector<double> residual(n);  // RMS offset from the fitted plane, model units
  // The `count` nearest samples to sample i, nearest first.
  const auto nearest = [&](std::size_t i, std::size_t count, std::vector<std::size_t>& idx, std::vector<double>& d2) {
    idx.resize(count);
    d2.resize(count);
    idx.resize(tree.knnSearch(positions[i].data(), count, idx.data(), d2.data()));
  };
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 256), [&](const auto& r) {
    std::vector<std::size_t> idx;
    std::vector<double> d2;
    for (std::size_t i = r.begin(); i != r.end(); ++i) {
      nearest(i, fit, idx, d2);
      const detail::LeastVariancePlane p =
          detail::FitLeastVariancePlane(positions, idx.data(), idx.size(), detail::UnitWeight);
      centre[i] = p.centre;
      plane[i] = p.normal;
      residual[i] = p.Rms(idx.size());
    }
  });
  const double median = detail::Median(residual);
  const std::vector<V3> start = normals;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 256), [&](const auto& r) {
    std::vector<std::size_t> idx;
    std::vector<double> d2;
    for (std::size_t i = r.begin(); i != r.end(); ++i) {
      if (!(residual[i] > kCreaseResidual * median)) continue;
      nearest(i, reach, idx, d2);
      double least = kCleanerShare * residual[i];
      std::size_t taken = n;
      for (const std::size_t j : idx) {
        if (!(residual[j] < least)) continue;
        if (std::abs(plane[j].dot(positions[i] - centre[j])) > kOnPlaneResiduals * std::max(residual[j], median))
          continue;
        if (std::abs(plane[j].dot(start[i])) < kTakenTurnCos) continue;
        least = residual[j];
        taken = j;
      }
      if (taken != n) normals[i] = plane[taken].dot(start[i]) < 0 ? V3(-plane[taken]) : plane[taken];
    }
  });
}

void RefineNormalLines(const std::vector<V3>& positions, std::vector<V3>& normals, int jet_neighbours) {
  const std::size_t n = positions.size();
  if (n < 8 || normals.size() != n) return;
  const std::size_t k = std::min<std::size_t>(kRefineNeighbours, n - 1);
  const detail::PointCloud cloud{&positions};
  const detail::KdTree tree(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(10));
  const Neighbourhoods near(positions, tree, k);
  const std::vector<V3> start = normals;
  // The noise, one figure for the whole set (a scanner's noise is much the same everywhere): the
  // median over the samples of the median offset of their neighbours from their smooth plane,
  // / 0.674 (the median of |N(0, sigma)|). Per sample, the offsets next to an edge would count
  // the other face as noise. It counts curvature too (the knot's whole set keeps its jet normals);
  // `fit_noise`, the median RMS residual of quadric fits, does not, and sets the selection width.
  std::vector<double> offset(n);
  std::vector<double> quadric(n);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 256), [&](const auto& r) {
    std::vector<double> residual(k + 1);
    for (std::size_t i = r.begin(); i != r.end(); ++i) {
      const auto& idx = near.idx[i];
      const std::size_t got = near.got[i];
      for (std::size_t m = 0; m < got; ++m) residual[m] = std::abs(start[i].dot(positions[idx[m]] - positions[i]));
      std::nth_element(residual.begin(), residual.begin() + static_cast<std::ptrdiff_t>(got / 2),
                       residual.begin() + static_cast<std::ptrdiff_t>(got));
      offset[i] = residual[got / 2];
      // Every neighbour: the residual of a surface's own curvature is ~0, of noise the noise.
      quadric[i] = std::max(detail::QuadricResidual(positions, idx.data(), got, positions[i], start[i], near.radius[i],
                                                    8, [](std::size_t) { return true; }),
                            0.0);
    }
  });
  const double sigma = detail::Median(std::move(offset)) / 0.674;
  const double fit_noise = detail::Median(std::move(quadric));
  const bool clean = jet_neighbours == kCleanNormalNeighbours;
  std::vector<std::uint8_t> rim(n, 0);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 256), [&](const auto& r) {
    std::vector<double> weight(k + 1);
    for (std::size_t i = r.begin(); i != r.end(); ++i) {
      const auto& idx = near.idx[i];
      const std::size_t got = near.got[i];
      // The width of a plane's support: a tenth of the neighbourhood's radius. Where the noise
      // is larger than that, the jet fit's average is the better normal: kept, unless the
      // neighbourhood is a facet (kFacetShare, below): sigma counts curvature and creases too.
      const double width = kRefineWidth * near.radius[i];
      const bool rough = 2.0 * sigma > width;
      // A rim sample (detail::kRimGap) keeps its jet fit: the planes through it extrapolate from
      // one side and tilt (a dome's rim: 1.7 degrees on the median against the jet fit's 0.0),
      // and an open side's closure magnifies the tilt by the part's radius.
      if (const detail::TangentGap widest =
              detail::WidestTangentGap<kRefineNeighbours + 1>(positions, idx.data(), got, i, start[i]);
          widest.count < 2 || widest.gap > detail::kRimGap) {
        rim[i] = 1;
        continue;
      }
      const auto support = [&](const V3& normal, std::size_t m) {
        const double t = normal.dot(positions[idx[m]] - positions[i]) / width;
        return std::exp(-t * t);
      };
      // The plane through P_i that most neighbours lie on, among their smooth normals and the
      // planes through P_i and two of its 12 nearest: near an edge a face's own plane, where the
      // smooth fit blends both faces (a first-row sample has no neighbour whose smooth normal is
      // its face's, hence the triples; near-collinear ones are skipped). Counted within the
      // narrow width: a plane through the edge's diagonal passes within w of both faces' rows.
      const double select = clean ? kSelectWidth * width : std::max(kSelectWidth * width, kSelectNoise * fit_noise);
      V3 normal = start[i];
      double best = -1;
      // The neighbours on the plane through P_i with this normal, within width s (soft count).
      const auto on_plane = [&](const V3& plane, double s) {
        double count = 0;
        for (std::size_t m = 0; m < got; ++m) {
          const double t = plane.dot(positions[idx[m]] - positions[i]) / s;
          count += std::exp(-t * t);
        }
        return count;
      };
      const auto consider = [&](V3 candidate) {
        if (candidate.dot(start[i]) < 0) candidate = -candidate;
        const double score = on_plane(candidate, select);
        if (score > best) {  // ties: the first candidate
          best = score;
          normal = candidate;
        }
      };
      for (std::size_t c = 0; c < got; ++c) consider(start[idx[c]]);
      ForEachTriplePlane(positions, idx.data(), got, i, consider);
      // A facet is counted at the narrow width itself, not widened by the noise: a noisy patch is
      // no facet.
      if (rough && on_plane(normal, kSelectWidth * width) < kFacetShare * static_cast<double>(got)) {
        // Here the noise figure counted curvature and creases; on a clean set they are no noise.
        if (!clean) continue;
        const double scale = kQuadricScale * near.radius[i];
        QuadricFit fitted;
        double own = 0;  // the support from its own jet normal's frame (idx[0] is i)
        for (std::size_t c = 0; c < got; ++c) {
          const QuadricFit fit = RobustQuadricThrough(positions, idx.data(), got, positions[i], start[idx[c]], scale);
          if (c == 0) own = fit.support;
          if (fit.support > fitted.support + 1e-9) fitted = fit;  // ties: the first candidate
        }
        if (fitted.support >= own + kQuadricMargin)  // own >= -1, so a failed fit never passes
          normals[i] = fitted.normal.dot(start[i]) < 0 ? V3(-fitted.normal) : fitted.normal;
        continue;
      }
      // Then a weighted PCA plane of its supporters, twice (iteratively reweighted least squares).
      for (int iteration = 0; iteration < 2; ++iteration) {
        for (std::size_t m = 0; m < got; ++m) weight[m] = support(normal, m);
        const V3 line =
            detail::FitLeastVariancePlane(positions, idx.data(), got, [&](std::size_t m) { return weight[m]; }).normal;
        normal = line.dot(normal) < 0 ? V3(-line) : line;
      }
      if (clean)
        normal = SupportersQuadricNormal(positions, idx.data(), got, positions[i], normal, near.radius[i], width);
      normals[i] = normal;
    }
  });
  if (clean) {
    TakeFacePlanes(positions, near, rim, normals);
    TakeExactFacets(positions, near, normals);
  } else if (jet_neighbours > 0) {
    TakeCleanestPlanes(positions, tree, static_cast<std::size_t>(jet_neighbours), normals);
  }
}

std::string NormalsReport::Describe() const {
  std::string what =
      estimated > 0 ? fmt::format("{} normals estimated (jet fit, {} neighbours{}) and oriented", estimated, neighbours,
                                  neighbours == kCleanNormalNeighbours ? ": the samples are clean"
                                  : neighbours > kNormalNeighbours     ? ": the samples are very noisy"
                                                                       : "")
                    : fmt::format("normals oriented, {} sign{} changed", flipped, flipped == 1 ? "" : "s");
  std::string out = fmt::format("{}: {} piece{} ({} closed, {} open)", what, components, components == 1 ? "" : "s",
                                components - open_components, open_components);
  if (closed_by_tree > 0)
    out += fmt::format("; {} piece{} that the spanning tree left open closed by a second tree across thin walls",
                       closed_by_tree, closed_by_tree == 1 ? "" : "s");
  if (open_level_flipped > 0)
    out += fmt::format("; {} open piece{} turned outward by the winding number", open_level_flipped,
                       open_level_flipped == 1 ? "" : "s");
  if (inverted_parts > 0)
    out += fmt::format("; {} part{} oriented inward as a whole turned outward ({} normals)", inverted_parts,
                       inverted_parts == 1 ? "" : "s", inverted_samples);
  if (sheets > 0)
    out += fmt::format("; {} sheet{} turned to agree with the winding number ({} normals)", sheets,
                       sheets == 1 ? "" : "s", sheet_samples);
  if (closed_by_sheets > 0)
    out += fmt::format("; {} open piece{} closed by turning inverted sheets ({} normals)", closed_by_sheets,
                       closed_by_sheets == 1 ? "" : "s", closed_by_sheets_samples);
  if (refined_sheets > 0)
    out += fmt::format("; {} sheet{} turned again on the sharpened normals ({} normals)", refined_sheets,
                       refined_sheets == 1 ? "" : "s", refined_sheet_samples);
  return out;
}

std::size_t FlipInvertedParts(const std::vector<V3>& positions, std::vector<V3>& normals,
                              const std::vector<std::uint8_t>& eligible, std::size_t& parts) {
  parts = 0;
  const std::size_t n = positions.size();
  if (normals.size() != n || eligible.size() != n) return 0;
  // The probes stay where the first normals put them (a flip moves a probe to the other side).
  const SampleProbes probes(positions, normals);
  if (!probes.measured()) return 0;
  const std::vector<std::array<std::uint32_t, kInvertedGraph>> graph = NearestGraph<kInvertedGraph>(positions);
  std::vector<double> level;
  const auto measure = [&] { level = probes.Levels(normals); };
  std::vector<std::uint8_t> changed(n, 0);  // the parity of each sample's flips
  std::vector<std::uint8_t> near_group(n, 0);
  std::vector<std::int32_t> group(n);
  std::vector<std::uint32_t> members;
  for (int pass = 0; pass < kInvertedPasses; ++pass) {
    // A group's edge is blurred by its own field: next to an inverted part, correctly oriented
    // samples reach a level below 0 too and join it, and its own samples at the edge stay out
    // (at a concave crease the probes reach into the other part, so w cannot tell). After the
    // flip each such sample takes the side of its neighbours along its tangent plane (chords
    // within 30 degrees of it: a thin wall's other side does not vote), a few sweeps, before the
    // levels are measured again.
    for (int sweep = 0; sweep < kRepairSweeps; ++sweep) {
      std::vector<std::uint32_t> turn;
      for (std::size_t i = 0; i < n; ++i) {
        if (near_group[i] == 0 || eligible[i] == 0) continue;
        double vote = 0.0;
        for (const std::uint32_t j : graph[i]) {
          if (j == i) continue;
          const V3 chord = (positions[j] - positions[i]).normalized();
          if (std::abs(normals[i].dot(chord)) < 0.5) vote += normals[i].dot(normals[j]);
        }
        if (vote < 0.0) turn.push_back(static_cast<std::uint32_t>(i));
      }
      for (const std::uint32_t i : turn) {
        normals[i] = -normals[i];
        changed[i] ^= 1;
      }
      if (turn.empty()) break;
    }
    std::fill(near_group.begin(), near_group.end(), 0);
    if (pass == kInvertedPasses - 1) break;  // the last pass only repairs
    measure();
    // Connected groups of eligible samples below level 0 (breadth first from the smallest index):
    // a whole group flips when it is large and its mean level is clearly below 0.
    std::fill(group.begin(), group.end(), -1);
    std::vector<std::vector<std::uint32_t>> flips;
    for (std::size_t root = 0; root < n; ++root) {
      if (group[root] >= 0 || eligible[root] == 0 || !(level[root] < 0.0)) continue;
      group[root] = 1;
      members.assign(1, static_cast<std::uint32_t>(root));
      double sum = 0.0;
      for (std::size_t q = 0; q < members.size(); ++q) {
        const std::uint32_t u = members[q];
        sum += level[u];
        for (const std::uint32_t v : graph[u])
          if (group[v] < 0 && eligible[v] != 0 && level[v] < 0.0) {
            group[v] = 1;
            members.push_back(v);
          }
      }
      if (members.size() < kInvertedMinSamples || !(sum < kInvertedLevel * static_cast<double>(members.size())))
        continue;
      for (const std::uint32_t u : members) normals[u] = -normals[u];
      flips.push_back(members);
    }
    if (flips.empty()) break;
    // A flip stands when it lifts the group's mean level as far above 0 as it was below: an
    // inverted part's does (the cow's tail -0.33 -> +0.4); a part too thin for its samples'
    // lines (a tail a spacing across, its samples all round it) stays mixed, and is left.
    measure();
    std::size_t stood = 0;
    for (const std::vector<std::uint32_t>& g : flips) {
      double sum = 0.0;
      for (const std::uint32_t u : g) sum += level[u];
      const bool stands = sum > -kInvertedLevel * static_cast<double>(g.size());
      for (const std::uint32_t u : g) {
        if (!stands) {
          normals[u] = -normals[u];
          continue;
        }
        changed[u] ^= 1;
        near_group[u] = 1;
        for (const std::uint32_t v : graph[u]) near_group[v] = 1;
      }
      stood += stands ? 1 : 0;
    }
    parts += stood;
    if (stood == 0) break;  // the same groups would be found again
  }
  std::size_t flipped = 0;
  for (const std::uint8_t c : changed) flipped += c;
  return flipped;
}

namespace {

// A dipole of area a and unit normal n at p, seen from q, smoothed over the disc's radius
// sqrt(a / pi): a n . d / (4 pi (|d|^2 + a / pi)^(3/2)), d = p - q (the point dipole's far field,
// bounded by 1 / (4 pi) x a / (a / pi)^(3/2) near the disc).
double SmoothedDipole(const V3& p, double a, const V3& n, const V3& q) {
  const V3 d = p - q;
  const double r2 = d.squaredNorm() + a / std::numbers::pi;
  return a * n.dot(d) / (4.0 * std::numbers::pi * r2 * std::sqrt(r2));
}

// Sample j's share, of sign s (+-1), of a sheet's w at sample k's probes q_in and q_out (`offset`
// from P_k): its smoothed dipole, or its disc when j is k (SampleProbes::OwnDisc).
void AddSampleTerms(SheetDipoles::Terms& t, std::uint32_t j, std::size_t k, double s, double offset, const V3& q_in,
                    const V3& q_out, const std::vector<V3>& positions, const std::vector<V3>& normals,
                    const std::vector<double>& areas) {
  if (j == k) {
    const double own = SampleProbes::OwnDisc(areas[j], offset);
    t.in += s * own;
    t.out += s * -own;
    t.own = true;
    return;
  }
  t.in += s * SmoothedDipole(positions[j], areas[j], normals[j], q_in);
  t.out += s * SmoothedDipole(positions[j], areas[j], normals[j], q_out);
}

// The positions' k-d tree (leaves of 10) and kSheetGraph-nearest graph, which every pass of
// FlipSheetsByWinding reads: they depend on the positions only.
struct SheetNeighbours {
  const detail::KdTree& tree;
  const std::vector<std::array<std::uint32_t, kSheetGraph>>& graph;
};

// SheetNeighbours built on first use and kept for later sheet passes over the same positions
// (OrientEstimatedNormals runs up to three; a 2,000,000-sample bare build spends about 1 % of its
// time on each graph, within its run-to-run spread).
class SheetGraph {
 public:
  explicit SheetGraph(const std::vector<V3>& positions) : cloud_{&positions} {}
  SheetGraph(const SheetGraph&) = delete;
  SheetGraph& operator=(const SheetGraph&) = delete;
  const std::vector<V3>& positions() const { return *cloud_.points; }
  SheetNeighbours Get() {
    if (!tree_) {
      tree_.emplace(3, cloud_, nanoflann::KDTreeSingleIndexAdaptorParams(10));
      graph_ = NearestGraph<kSheetGraph>(*tree_, *cloud_.points);
    }
    return SheetNeighbours{*tree_, graph_};
  }

 private:
  detail::PointCloud cloud_;
  std::optional<detail::KdTree> tree_;
  std::vector<std::array<std::uint32_t, kSheetGraph>> graph_;
};

// w at every sample's probes for the normals as they stand (SampleProbes::InsideOutside), with the
// near field smoothed (kSheetNearField) only at the samples some candidate sheet reaches: only
// those are read, and the smoothing's nearest-sample searches were most of a pass's time (a
// 2,000,000-sample bare scan thinned to 800,000: 6.4 of 7.5 s a pass). Kept across
// FlipSheetsByWinding's passes while no sign changes, so a second pass pays only for samples the
// first did not reach.
struct SheetProbeWinding {
  std::optional<SampleProbes> probes;
  std::vector<double> inside, outside;
  std::vector<std::uint8_t> smoothed;  // the near field done at this sample
  // The facing term's pairs (kFacingWeight), listed at both samples with their weight. They read
  // only positions, lines and areas, none of which a flip changes, so they outlive `probes`.
  struct StackedPair {
    std::uint32_t j;
    double weight;
  };
  std::vector<std::vector<StackedPair>> stacked;
};

// Sheets: samples joined in the kSheetGraph-nearest graph by chords along both tangent planes
// and normals within `cut`'s angle of each other, signs included (a sign boundary on one smooth
// sheet, or the two sides of a thin wall, separate them), over the pairs `apart(i, j)` does not
// keep apart.
template <typename Apart>
detail::UnionFind JoinSheets(const std::vector<V3>& positions, const std::vector<V3>& normals,
                             const std::vector<std::array<std::uint32_t, kSheetGraph>>& graph, const SheetCut& cut,
                             Apart apart) {
  const double min_dot = std::cos(cut.angle_deg * std::numbers::pi / 180.0);
  detail::UnionFind joined(positions.size());
  for (std::size_t i = 0; i < positions.size(); ++i)
    for (const std::uint32_t j : graph[i]) {
      if (j == i || apart(static_cast<std::uint32_t>(i), j)) continue;
      if (detail::OneSheet(positions[j] - positions[i], normals[i], normals[j], min_dot, cut.chord))
        joined.Unite(static_cast<std::uint32_t>(i), j);
    }
  return joined;
}

// One pass of FlipSheetsByWinding with the sheets of `cut`.
// `facing`: the energy has the facing term (kFacingWeight; clean lines only).
std::size_t TurnSheets(const std::vector<V3>& positions, std::vector<V3>& normals,
                       const std::vector<std::uint8_t>& eligible, const SheetCut& cut, const OtherSides& other_sides,
                       const std::vector<std::uint8_t>& thin_walls, const SheetNeighbours& neighbours,
                       SheetProbeWinding& cache, bool facing, std::size_t& sheets) {
  sheets = 0;
  const std::size_t n = positions.size();
  if (!cache.probes) {
    cache.probes.emplace(positions, normals, SampleProbes::Walls::kEitherSign, thin_walls);
    if (cache.probes->measured()) cache.probes->InsideOutside(normals, cache.inside, cache.outside);
    cache.smoothed.assign(n, 0);
  }
  const SampleProbes& probes = *cache.probes;
  if (!probes.measured()) return 0;
  const std::vector<double>& areas = probes.areas();
  const std::vector<double>& offsets = probes.offsets();
  const detail::KdTree& tree = neighbours.tree;

  // Sheets (JoinSheets), not across a thin wall (kThinWallShare).
  detail::UnionFind joined =
      JoinSheets(positions, normals, neighbours.graph, cut,
                 [&](std::uint32_t i, std::uint32_t j) { return OnOtherSides(other_sides, i, j); });
  std::vector<std::vector<std::uint32_t>> members(n);
  for (std::size_t i = 0; i < n; ++i)
    members[joined.Find(static_cast<std::uint32_t>(i))].push_back(static_cast<std::uint32_t>(i));
  struct Sheet {
    std::vector<std::uint32_t> samples;
    V3 centre;
    double reach = 0;  // the radius of the probes the sheet's flip is measured on
    double area = 0;
  };
  std::vector<Sheet> candidates;
  const std::size_t largest = std::min<std::size_t>(kSheetMostSamples, n / cut.most_fraction);
  for (std::vector<std::uint32_t>& m : members) {
    if (m.empty() || m.size() > largest || eligible[m.front()] == 0) continue;
    Sheet sheet;
    sheet.centre = V3::Zero();
    for (const std::uint32_t i : m) sheet.centre += positions[i];
    sheet.centre /= static_cast<double>(m.size());
    double radius = 0, spacing = 0;
    for (const std::uint32_t i : m) {
      radius = std::max(radius, (positions[i] - sheet.centre).norm());
      spacing = std::max(spacing, offsets[i]);
      sheet.area += areas[i];
    }
    sheet.reach = 2.0 * radius + kSheetReach * 2.0 * spacing;  // 2 d_i: the 16th neighbour's distance
    sheet.samples = std::move(m);
    candidates.push_back(std::move(sheet));
  }
  members = {};
  if (candidates.empty()) return 0;
  // Each sample's candidate sheet (-1: none), to tell the facing term's pairs that a sheet's flip turns.
  using StackedPair = SheetProbeWinding::StackedPair;
  std::vector<std::vector<StackedPair>>& stacked = cache.stacked;
  std::vector<std::int32_t> candidate_of(facing ? n : 0, -1);
  if (facing) {
    for (std::size_t c = 0; c < candidates.size(); ++c)
      for (const std::uint32_t i : candidates[c].samples) candidate_of[i] = static_cast<std::int32_t>(c);
  }
  if (facing && stacked.empty()) {
    stacked.resize(n);
    const auto add = [&](std::uint32_t a, std::uint32_t b, double weight) {
      for (StackedPair& pair : stacked[a])
        if (pair.j == b) {
          pair.weight += weight;
          return;
        }
      stacked[a].push_back(StackedPair{b, weight});
    };
    for (std::size_t i = 0; i < n; ++i) {
      const auto listed = static_cast<std::size_t>(
          std::count_if(other_sides[i].begin(), other_sides[i].end(), [](std::uint32_t j) { return j != UINT32_MAX; }));
      for (std::size_t m = 0; m < listed; ++m) {
        const std::uint32_t j = other_sides[i][m];
        const V3 chord = positions[j] - positions[i];
        if (std::abs(chord.dot(normals[i])) < kStackedSin * chord.norm() ||
            std::abs(normals[i].dot(normals[j])) < kStackedLinesCos)
          continue;
        const double weight = areas[i] / static_cast<double>(listed);
        add(static_cast<std::uint32_t>(i), j, weight);
        add(j, static_cast<std::uint32_t>(i), weight);
      }
    }
  }
  // The samples whose probes some candidate's reach holds (the searches below, the same calls).
  tbb::enumerable_thread_specific<std::vector<std::uint32_t>> reached_lists;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, candidates.size(), 1), [&](const auto& r) {
    std::vector<std::pair<std::size_t, double>> near;
    std::vector<std::uint32_t>& reached = reached_lists.local();
    for (std::size_t c = r.begin(); c != r.end(); ++c) {
      near.clear();
      tree.radiusSearch(candidates[c].centre.data(), candidates[c].reach * candidates[c].reach, near,
                        nanoflann::SearchParams(32, 0, false));
      for (const auto& [k, unused] : near)
        if (cache.smoothed[k] == 0) reached.push_back(static_cast<std::uint32_t>(k));
    }
  });
  std::vector<std::uint8_t> smooth_now(n, 0);
  for (const std::vector<std::uint32_t>& reached : reached_lists)
    for (const std::uint32_t k : reached) smooth_now[k] = 1;
  // The winding tree's point dipoles near each probe become smoothed ones (its own sample's is
  // already the disc).
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 64), [&](const auto& r) {
    std::array<std::size_t, kSheetNearField> idx{};
    std::array<double, kSheetNearField> d2{};
    for (std::size_t i = r.begin(); i != r.end(); ++i) {
      if (smooth_now[i] == 0 || !(offsets[i] > 0)) continue;
      for (const bool at_inside : {true, false}) {
        const V3 q =
            at_inside ? V3(positions[i] - offsets[i] * normals[i]) : V3(positions[i] + offsets[i] * normals[i]);
        const std::size_t got = tree.knnSearch(q.data(), kSheetNearField, idx.data(), d2.data());
        double change = 0;
        for (std::size_t m = 0; m < got; ++m) {
          const std::size_t j = idx[m];
          if (j == i || !(d2[m] > 0)) continue;
          const double point =
              areas[j] * normals[j].dot(positions[j] - q) / (4.0 * std::numbers::pi * d2[m] * std::sqrt(d2[m]));
          change += SmoothedDipole(positions[j], areas[j], normals[j], q) - point;
        }
        (at_inside ? cache.inside[i] : cache.outside[i]) += change;
      }
    }
  });
  for (std::size_t i = 0; i < n; ++i) cache.smoothed[i] = cache.smoothed[i] | smooth_now[i];
  // Changed only by a flip, after which the cache is measured afresh.
  std::vector<double>& inside = cache.inside;
  std::vector<double>& outside = cache.outside;
  // side[i]: the sample's sign against the normals measured (+1 kept, -1 flipped); the probes stay
  // where they are. Energy: sum_i a_i ((w_in - t_in)^2 + (w_out - t_out)^2), the targets 1 inside
  // and 0 outside the sample's current sign. A sheet's flip adds -2 w_Q at every probe, w_Q the
  // sheet's own dipoles (the disc for a sample's own probes).
  std::vector<std::int8_t> side(n, 1);
  // w_Q at both of sample k's probes, in one pass over the sheet, and whether k is one of the
  // sheet's own samples.
  using BothTerms = SheetDipoles::Terms;
  const auto sheet_terms = [&](const Sheet& sheet, std::size_t k) {
    const V3 q_in = positions[k] - offsets[k] * normals[k];
    const V3 q_out = positions[k] + offsets[k] * normals[k];
    BothTerms t;
    for (const std::uint32_t j : sheet.samples)
      AddSampleTerms(t, j, k, side[j], offsets[k], q_in, q_out, positions, normals, areas);
    return t;
  };
  std::size_t flipped = 0;
  std::vector<std::uint8_t> done(candidates.size(), 0);
  // A sheet's gain depends only on the probes within its reach and on its own samples' sides, so
  // after a round only the sheets whose reach meets a flipped one's are scored again. 32 rounds of
  // every sheet stopped the elk's antlers half-way (the elk, 3 draws: 350, 2,868 and 1,107
  // far-wrong nodes after 32 rounds, 8, 50 and 30 at convergence); every round flips at least one
  // sheet, once, so at most candidates.size() rounds.
  // Whether two sheets' probe balls meet: flipping one changes the other's gain.
  const auto reaches_meet = [&](std::size_t a, std::size_t b) {
    return (candidates[a].centre - candidates[b].centre).norm() <= candidates[a].reach + candidates[b].reach;
  };
  std::vector<double> gain(candidates.size(), 0.0);
  std::vector<std::uint8_t> stale(candidates.size(), 1);
  // A sheet not yet flipped has every sample's side +1 (sides change only with a whole sheet's
  // flip, and that sheet is then done), so its own term at each probe in its reach never changes:
  // a sheet of more than kKeptTermsSamples keeps those terms (in the search's order) from its first
  // scoring, and a rescoring costs a pass over its probes instead of probes x samples (the rotor's
  // 60,000 bare samples at 300 cells: 188 s of rescoring in 27 rounds). The same sums, in the same
  // order: the same gains.
  struct ProbeTerm {
    std::uint32_t k;
    bool own;
    double in, out;
  };
  std::vector<std::vector<ProbeTerm>> kept_terms(candidates.size());
  std::vector<std::uint8_t> terms_kept(candidates.size(), 0);
  for (;;) {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, candidates.size(), 1), [&](const auto& r) {
      std::vector<std::pair<std::size_t, double>> near;
      std::vector<ProbeTerm> fresh;
      for (std::size_t c = r.begin(); c != r.end(); ++c) {
        if (done[c] != 0 || stale[c] == 0) continue;
        stale[c] = 0;
        const Sheet& sheet = candidates[c];
        std::vector<ProbeTerm>& terms = terms_kept[c] != 0 ? kept_terms[c] : fresh;
        if (terms_kept[c] == 0) {
          near.clear();
          tree.radiusSearch(sheet.centre.data(), sheet.reach * sheet.reach, near,
                            nanoflann::SearchParams(32, 0, false));
          terms.clear();
          // A sheet not yet flipped: every side +1, as SheetDipoles sums.
          std::optional<SheetDipoles> tree_sum;
          if (sheet.samples.size() > kSheetTreeSamples) tree_sum.emplace(sheet.samples, positions, normals, areas);
          for (const auto& [k, unused] : near) {
            if (!(offsets[k] > 0)) continue;
            if (tree_sum) {
              const SheetDipoles::Terms t = tree_sum->At(k, offsets[k]);
              terms.push_back(ProbeTerm{static_cast<std::uint32_t>(k), t.own, t.in, t.out});
              continue;
            }
            const BothTerms t = sheet_terms(sheet, k);
            terms.push_back(ProbeTerm{static_cast<std::uint32_t>(k), t.own, t.in, t.out});
          }
        }
        double delta = 0;
        for (const ProbeTerm& term : terms) {
          const std::size_t k = term.k;
          const double s = side[k];
          // Targets before (t_in, t_out) and after the flip.
          const double t_in = s > 0 ? 1.0 : 0.0, t_out = 1.0 - t_in;
          const double u_in = term.own ? t_out : t_in, u_out = term.own ? t_in : t_out;
          const double w_in = inside[k] - 2.0 * term.in;
          const double w_out = outside[k] - 2.0 * term.out;
          delta +=
              areas[k] * (Miss(w_in - u_in) + Miss(w_out - u_out) - Miss(inside[k] - t_in) - Miss(outside[k] - t_out));
        }
        // The facing term of the stacked pairs across the sheet's edge, which its flip turns.
        if (facing && sheet.samples.size() >= kFacingLeastSamples)
          for (const std::uint32_t i : sheet.samples)
            for (const StackedPair& pair : stacked[i]) {
              if (candidate_of[pair.j] == static_cast<std::int32_t>(c)) continue;
              const bool same_way = side[i] * side[pair.j] * normals[i].dot(normals[pair.j]) > 0.0;
              delta += kFacingWeight * pair.weight * (same_way ? -1.0 : 1.0);
            }
        gain[c] = delta / sheet.area;
        if (terms_kept[c] == 0 && sheet.samples.size() > kKeptTermsSamples) {
          kept_terms[c] = std::move(fresh);
          fresh = {};
          terms_kept[c] = 1;
        }
      }
    });
    // The best flips, each far enough from the others taken this round to be measured alone.
    std::vector<std::size_t> order;
    for (std::size_t c = 0; c < candidates.size(); ++c)
      if (done[c] == 0 && gain[c] < 0.0) order.push_back(c);
    if (order.empty()) break;
    std::sort(order.begin(), order.end(),
              [&](std::size_t a, std::size_t b) { return gain[a] != gain[b] ? gain[a] < gain[b] : a < b; });
    std::vector<std::size_t> taken;
    for (const std::size_t c : order) {
      if (std::none_of(taken.begin(), taken.end(), [&](std::size_t t) { return reaches_meet(c, t); }))
        taken.push_back(c);
    }
    for (const std::size_t c : taken) {
      const Sheet& sheet = candidates[c];
      std::vector<std::pair<std::size_t, double>> near;
      tree.radiusSearch(sheet.centre.data(), sheet.reach * sheet.reach, near, nanoflann::SearchParams(32, 0, false));
      std::vector<BothTerms> terms(near.size());
      for (std::size_t m = 0; m < near.size(); ++m)
        if (offsets[near[m].first] > 0) terms[m] = sheet_terms(sheet, near[m].first);
      for (std::size_t m = 0; m < near.size(); ++m) {
        inside[near[m].first] -= 2.0 * terms[m].in;
        outside[near[m].first] -= 2.0 * terms[m].out;
      }
      for (const std::uint32_t j : sheet.samples) side[j] = static_cast<std::int8_t>(-side[j]);
      done[c] = 1;
      kept_terms[c] = {};
      ++sheets;
      flipped += sheet.samples.size();
    }
    for (std::size_t c = 0; c < candidates.size(); ++c)
      if (done[c] == 0 && std::any_of(taken.begin(), taken.end(), [&](std::size_t t) { return reaches_meet(c, t); }))
        stale[c] = 1;
  }
  for (std::size_t i = 0; i < n; ++i)
    if (side[i] < 0) normals[i] = -normals[i];
  if (flipped > 0) cache.probes.reset();  // signs changed: the next pass measures afresh
  return flipped;
}

// FlipSheetsByWinding over the positions of `shared`.
std::size_t FlipSheetsOn(SheetGraph& shared, std::vector<V3>& normals, const std::vector<std::uint8_t>& eligible,
                         std::size_t& sheets, std::size_t coarse_fraction, bool clean_lines) {
  const std::vector<V3>& positions = shared.positions();
  sheets = 0;
  const std::size_t n = positions.size();
  if (normals.size() != n || eligible.size() != n || coarse_fraction < 2) return 0;
  std::size_t flipped = 0;
  const SheetNeighbours neighbours = shared.Get();
  const OtherSides other_sides = ThinWallOtherSides(positions, normals, neighbours.tree);  // lines: every pass's
  std::vector<std::uint8_t> thin_walls(n, 0);  // samples with another side (SampleProbes' thin_walls)
  for (std::size_t i = 0; i < n; ++i) thin_walls[i] = other_sides[i][0] != UINT32_MAX ? 1 : 0;
  SheetProbeWinding cache;
  for (std::size_t pass = 0; pass < kSheetCuts.size(); ++pass) {
    SheetCut cut = kSheetCuts[pass];
    if (pass == 0) cut.most_fraction = coarse_fraction;
    std::size_t turned = 0;
    flipped +=
        TurnSheets(positions, normals, eligible, cut, other_sides, thin_walls, neighbours, cache, clean_lines, turned);
    sheets += turned;
  }
  return flipped;
}

}  // namespace

std::size_t FlipSheetsByWinding(const std::vector<V3>& positions, std::vector<V3>& normals,
                                const std::vector<std::uint8_t>& eligible, std::size_t& sheets,
                                std::size_t coarse_fraction, bool clean_lines) {
  SheetGraph shared(positions);
  return FlipSheetsOn(shared, normals, eligible, sheets, coarse_fraction, clean_lines);
}

SheetDipoles::SheetDipoles(std::span<const std::uint32_t> samples, const std::vector<V3>& positions,
                           const std::vector<V3>& normals, const std::vector<double>& areas)
    : order_(samples.begin(), samples.end()), positions_(positions), normals_(normals), areas_(areas) {
  if (order_.empty()) return;
  nodes_.reserve(2 * (order_.size() / kLeaf + 1));
  Build(0, static_cast<std::uint32_t>(order_.size()));
}

std::int32_t SheetDipoles::Build(std::uint32_t begin, std::uint32_t end) {
  const auto at = static_cast<std::int32_t>(nodes_.size());
  nodes_.emplace_back();
  Node node;
  node.begin = begin;
  node.end = end;
  Eigen::AlignedBox3d box;
  for (std::uint32_t m = begin; m < end; ++m) {
    const std::uint32_t j = order_[m];
    node.centre += areas_[j] * positions_[j];
    node.moment += areas_[j] * normals_[j];
    node.area += areas_[j];
    box.extend(positions_[j]);
  }
  node.centre = node.area > 0 ? V3(node.centre / node.area) : box.center();
  for (std::uint32_t m = begin; m < end; ++m)
    node.radius = std::max(node.radius, (positions_[order_[m]] - node.centre).norm());
  if (end - begin > kLeaf) {
    Eigen::Index axis = 0;
    box.sizes().maxCoeff(&axis);
    const std::uint32_t mid = begin + (end - begin) / 2;
    std::nth_element(order_.begin() + begin, order_.begin() + mid, order_.begin() + end,
                     [&](std::uint32_t a, std::uint32_t b) {
                       const double pa = positions_[a][axis], pb = positions_[b][axis];
                       return pa != pb ? pa < pb : a < b;
                     });
    node.left = Build(begin, mid);
    node.right = Build(mid, end);
  }
  nodes_[static_cast<std::size_t>(at)] = node;
  return at;
}

SheetDipoles::Terms SheetDipoles::At(std::size_t k, double offset) const {
  Terms t;
  if (nodes_.empty()) return t;
  const V3& pk = positions_[k];
  const V3 q_in = pk - offset * normals_[k];
  const V3 q_out = pk + offset * normals_[k];
  const auto dipole = [](const Node& node, const V3& q, double smooth) {
    const V3 d = node.centre - q;
    const double r2 = d.squaredNorm() + smooth;
    return node.moment.dot(d) / (4.0 * std::numbers::pi * r2 * std::sqrt(r2));
  };
  // Depth-first, right child pushed first; the depth is log2(samples / kLeaf) + 1.
  std::array<std::uint32_t, 64> stack{};
  std::size_t top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const Node& node = nodes_[stack[--top]];
    const double far = kFarField * node.radius + offset;  // both probes beyond kFarField r
    if ((node.centre - pk).squaredNorm() > far * far) {
      const double smooth = node.area / (static_cast<double>(node.end - node.begin) * std::numbers::pi);
      t.in += dipole(node, q_in, smooth);
      t.out += dipole(node, q_out, smooth);
      ++t.far;
      continue;
    }
    if (node.left < 0) {
      for (std::uint32_t m = node.begin; m < node.end; ++m)
        AddSampleTerms(t, order_[m], k, 1.0, offset, q_in, q_out, positions_, normals_, areas_);
      t.exact += node.end - node.begin;
      continue;
    }
    stack[top++] = static_cast<std::uint32_t>(node.right);
    stack[top++] = static_cast<std::uint32_t>(node.left);
  }
  return t;
}

// OrientNormals' spanning tree: each sample's piece (the connected parts of the kOrientNeighbours
// graph, numbered from the smallest index up) and whether its given normal keeps its sign.
// `facing_base`: a facing pair's edge costs facing_base - along (kFacingBase, or kFacingRetryBase
// for the retry of a piece the first tree left open).
struct TreeSigns {
  std::vector<std::uint32_t> component;
  std::vector<std::uint8_t> keep;
  std::size_t pieces = 0;
};

TreeSigns SignsByTree(const std::vector<V3>& positions, const std::vector<V3>& given, const std::vector<V3>& smooth,
                      bool given_are_jet_lines, double facing_base) {
  const std::size_t n = positions.size();
  // The symmetric k-nearest-neighbour graph's edges, each once per direction found, sorted by
  // cost then endpoints: Kruskal's MST is then the same for any thread count. Each edge knows
  // whether its ends' given normals agree (`same`): from the given normals where they are clearly
  // parallel or antiparallel, else (a sharp edge, where exact face normals are near perpendicular
  // and their dot product's sign is noise) from the smooth jet normals, carried back through each
  // end's given-to-smooth sign. fandisk with 5 % of its normals flipped: 27 % of the band wrong
  // when the tree compared exact face normals alone, 0.37 % (as the clean file) with this.
  const auto k = static_cast<std::size_t>(std::min<std::size_t>(kOrientNeighbours, n - 1));
  std::vector<Edge> edges(n * k);
  {
    const detail::PointCloud cloud{&positions};
    const detail::KdTree tree(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(10));
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 512), [&](const auto& r) {
      std::vector<std::size_t> idx(k + 1);
      std::vector<double> d2(k + 1);
      for (std::size_t i = r.begin(); i != r.end(); ++i) {
        const std::size_t got = tree.knnSearch(positions[i].data(), k + 1, idx.data(), d2.data());
        std::size_t e = 0;
        for (std::size_t m = 0; m < got && e < k; ++m) {
          const std::size_t j = idx[m];
          if (j == i) continue;
          const double given_dot = given[i].dot(given[j]);
          const bool sharp = std::abs(given_dot) < 0.5;
          const V3& ni = sharp ? smooth[i] : given[i];
          const V3& nj = sharp ? smooth[j] : given[j];
          const V3 chord = (positions[j] - positions[i]).normalized();
          const double along = std::min(std::abs(ni.dot(chord)), std::abs(nj.dot(chord)));
          const double off_plane = std::max(std::abs(ni.dot(chord)), std::abs(nj.dot(chord)));
          // Two sheets facing each other (the two sides of a thin wall, or of a narrow gap): the
          // chord leaves both tangent planes, and consistent normals there are antiparallel.
          // Given signs that are already antiparallel (orient mode: the file's) say so as soon as
          // the chord leaves the planes by 11.5 degrees (a diagonal across a wall thinner than
          // the spacing); jet lines, whose signs are arbitrary, only when it runs along them.
          const bool facing = !sharp && along > (given_dot < 0 && !given_are_jet_lines ? 0.2 : 0.8);
          bool same = facing ? given_dot < 0 : given_dot >= 0;
          if (sharp)
            same =
                ((smooth[i].dot(smooth[j]) >= 0) == (given[i].dot(smooth[i]) >= 0)) == (given[j].dot(smooth[j]) >= 0);
          // Hoppe's 1 - |n_i . n_j|, plus how far the chord leaves the tangent planes: the tree
          // crosses a sharp edge (0.5 more: the smooth normals there are the blend of two faces)
          // or a gap between sheets only where the sheet itself offers no path, and a gap where
          // the chord runs most nearly along the normals.
          // File signs that disagree on one sheet (a flipped normal) cost 1 more: a sheet joins
          // the tree through its agreeing pairs, and a flipped sample through one of its own.
          const bool disagree = !sharp && !facing && given_dot < 0 && !given_are_jet_lines;
          const double cost =
              facing ? facing_base - along
                     : 1.0 - std::abs(ni.dot(nj)) + off_plane + (sharp ? 0.5 : 0.0) + (disagree ? 1.0 : 0.0);
          edges[i * k + e++] = Edge{static_cast<float>(cost), static_cast<std::uint32_t>(std::min(i, j)),
                                    static_cast<std::uint32_t>(std::max(i, j)), same};
        }
        for (; e < k; ++e) edges[i * k + e] = Edge{9.0f, 0, 0, true};  // a self-loop: never in the tree
      }
    });
  }
  std::sort(edges.begin(), edges.end(), [](const Edge& x, const Edge& y) {
    if (x.cost != y.cost) return x.cost < y.cost;
    if (x.a != y.a) return x.a < y.a;
    return x.b < y.b;
  });
  detail::UnionFind forest(n);
  struct Link {
    std::uint32_t to;
    bool same;
  };
  std::vector<std::vector<Link>> tree_adjacent(n);
  for (const Edge& e : edges) {
    if (e.a == e.b || !forest.Unite(e.a, e.b)) continue;
    tree_adjacent[e.a].push_back({e.b, e.same});
    tree_adjacent[e.b].push_back({e.a, e.same});
  }
  edges = {};

  // Carry each root's sign along its tree (breadth first from the smallest index of the piece):
  // keep[v] says whether v's given normal keeps its sign.
  std::vector<std::uint32_t> component(n, UINT32_MAX);
  std::vector<std::uint8_t> keep(n, 1);
  std::vector<std::uint32_t> roots;
  std::vector<std::uint32_t> queue;
  for (std::uint32_t root = 0; root < n; ++root) {
    if (component[root] != UINT32_MAX) continue;
    const auto id = static_cast<std::uint32_t>(roots.size());
    roots.push_back(root);
    component[root] = id;
    queue.assign(1, root);
    for (std::size_t q = 0; q < queue.size(); ++q) {
      const std::uint32_t u = queue[q];
      for (const Link& link : tree_adjacent[u]) {
        if (component[link.to] != UINT32_MAX) continue;
        component[link.to] = id;
        keep[link.to] = link.same ? keep[u] : !keep[u];
        queue.push_back(link.to);
      }
    }
  }
  tree_adjacent = {};
  return {std::move(component), std::move(keep), roots.size()};
}

namespace {

// OrientNormals over the positions of `shared`, whose graph its sheet passes read.
void OrientOn(SheetGraph& shared, std::vector<V3>& normals, bool keep_file_majority, NormalsReport& report,
              bool given_are_jet_lines) {
  const std::vector<V3>& positions = shared.positions();
  const std::size_t n = positions.size();
  if (n == 0 || normals.size() != n) return;
  const std::vector<V3>& given = normals;
  std::vector<V3> smooth_storage;
  if (!given_are_jet_lines) EstimateNormalLines(positions, smooth_storage);
  const std::vector<V3>& smooth = given_are_jet_lines ? normals : smooth_storage;

  TreeSigns tree = SignsByTree(positions, given, smooth, given_are_jet_lines, kFacingBase);
  const std::vector<double> areas = SampleAreas(positions);
  const std::size_t pieces = tree.pieces;
  std::vector<double> area(pieces, 0.0);
  for (std::size_t i = 0; i < n; ++i) area[tree.component[i]] += areas[i];
  const auto piece_flux = [&](const TreeSigns& signs) {
    std::vector<V3> sum(pieces, V3::Zero());
    for (std::size_t i = 0; i < n; ++i)
      sum[signs.component[i]] += areas[i] * (signs.keep[i] ? given[i] : V3(-given[i]));
    return sum;
  };
  std::vector<V3> flux = piece_flux(tree);
  const auto is_open = [&](const std::vector<V3>& sums, std::size_t c) {
    return sums[c].norm() >= kOpenPieceFlux * area[c];
  };
  // A tree over estimated lines may cross a wall thinner than the spacing round its rim, where
  // noisy lines blend, and turn one side inward as a whole: the piece comes out open by its flux.
  // A second tree that prefers the pairs facing each other across the wall (kFacingRetryBase)
  // stands for such a piece where it closes it (CGAL's turbine, a disc 4 voxels thick, 5,000 bare
  // samples with 0.25 voxel of noise: seeds 22 and 24 had 43 % of the normals inward). Only there:
  // as the first tree it would blend facing pairs into noisy sheets (the cow at 1 voxel of noise,
  // band mean 0.38 -> 0.80 voxel).
  bool any_open = false;
  for (std::size_t c = 0; c < pieces; ++c) any_open = any_open || is_open(flux, c);
  if (given_are_jet_lines && any_open) {
    // The same neighbour graph: the same pieces, numbered alike; only the edges' costs differ.
    const TreeSigns retry = SignsByTree(positions, given, smooth, given_are_jet_lines, kFacingRetryBase);
    const std::vector<V3> second = piece_flux(retry);
    std::vector<std::uint8_t> closes(pieces, 0);
    std::size_t closed = 0;
    for (std::size_t c = 0; c < pieces; ++c) {
      closes[c] = is_open(flux, c) && second[c].norm() < detail::kClosedFlux * area[c];
      closed += closes[c];
    }
    for (std::size_t i = 0; i < n; ++i)
      if (closes[tree.component[i]] != 0) tree.keep[i] = retry.keep[i];
    report.closed_by_tree += closed;
    if (closed > 0) flux = piece_flux(tree);
  }
  const std::vector<std::uint32_t>& component = tree.component;
  const std::vector<std::uint8_t>& keep = tree.keep;
  std::vector<V3> oriented(n);
  for (std::size_t i = 0; i < n; ++i) oriented[i] = keep[i] ? given[i] : V3(-given[i]);

  // Each piece's outward sign (see normals.h).
  V3 centre = V3::Zero();
  double total_area = 0;
  for (std::size_t i = 0; i < n; ++i) {
    centre += areas[i] * positions[i];
    total_area += areas[i];
  }
  centre = total_area > 0 ? V3(centre / total_area) : positions[0];
  std::vector<double> divergence(pieces, 0.0), agreement(pieces, 0.0);
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint32_t c = component[i];
    divergence[c] += areas[i] * oriented[i].dot(positions[i] - centre);
    agreement[c] += keep[i] ? areas[i] : -areas[i];
  }
  std::vector<std::uint8_t> flip(pieces, 0);
  report.components = pieces;
  report.open_components = 0;
  for (std::size_t c = 0; c < pieces; ++c) {
    const bool open = is_open(flux, c);
    report.open_components += open ? 1 : 0;
    flip[c] = (open && keep_file_majority) ? agreement[c] < 0 : divergence[c] < 0;
  }
  for (std::size_t i = 0; i < n; ++i) normals[i] = flip[component[i]] ? V3(-oriented[i]) : oriented[i];
  // Under estimate, an open piece takes the sign of its samples' mean level (SampleProbes::Levels, by
  // area): positive for a scan seen from outside whatever its shape, where the divergence sum
  // about c assumes a convex part (one-view scans: the camel's came out wholly inward, 54 % of the
  // band wrong; knot1's second piece, the bull's).
  if (!keep_file_majority && report.open_components > 0) {
    const std::vector<double> level = SampleProbes(positions, normals).Levels(normals);
    std::vector<double> level_sum(pieces, 0.0);  // the mean's sign: sum_i a_i level_i
    for (std::size_t i = 0; i < n; ++i) level_sum[component[i]] += areas[i] * level[i];
    for (std::size_t c = 0; c < pieces; ++c) {
      if (is_open(flux, c) && level_sum[c] < 0.0) {
        flip[c] = flip[c] != 0 ? 0 : 1;
        ++report.open_level_flipped;
      }
    }
    for (std::size_t i = 0; i < n; ++i) normals[i] = flip[component[i]] ? V3(-oriented[i]) : oriented[i];
  }
  // A part that the tree oriented inward as a whole (a thin tail reached across its tip): the
  // divergence sum of a closed piece is still positive, so only the winding number sees it.
  report.inverted_samples =
      FlipInvertedParts(positions, normals, std::vector<std::uint8_t>(n, 1), report.inverted_parts);
  // Estimated lines of clean or mildly noisy samples only (the file's are the scanner's). With more
  // noise the chords leave the tangent planes, sheets break into single samples whose probes lie in
  // the noise: a sphere with noise of half a spacing had 183 normals turned inward
  // (NoisyDenseBarePositions..., noise figure 0.42), CGAL's sphere_20k (noise 1.6 spacings) 1,750
  // of 21,000 (kSheetPassNoise).
  // Closed pieces only: an open sheet's w is near 1/2 on both sides, so the energy's 1 inside and
  // 0 outside are no truth there (CGAL's b9_training, an aerial scan of 6 open pieces: 1,068 of
  // 9,579 normals turned, and the closure's area halved). Closed by the flux of the normals as
  // they now stand, under detail::kClosedFlux of the area: the camel without its -z side (0.19, under
  // the 0.2 that calls a piece open) lost 16,200 -> 17,800 far-wrong nodes to 145 turned normals.
  if (given_are_jet_lines &&
      (report.neighbours == kCleanNormalNeighbours ||
       (report.neighbours == kNormalNeighbours && report.noise_figure >= 0 && report.noise_figure < kSheetPassNoise))) {
    // Each piece's flux sum_i a_i m_i.
    const auto piece_flux_of = [&](const std::vector<V3>& m) {
      std::vector<V3> sum(pieces, V3::Zero());
      for (std::size_t i = 0; i < n; ++i) sum[component[i]] += areas[i] * m[i];
      return sum;
    };
    std::vector<V3> now = piece_flux_of(normals);
    std::vector<std::uint8_t> closed(n, 0);
    bool any = false;
    for (std::size_t i = 0; i < n; ++i) {
      const std::uint32_t c = component[i];
      closed[i] = now[c].norm() < detail::kClosedFlux * area[c] ? 1 : 0;
      any = any || closed[i] != 0;
    }
    const bool clean_lines = report.neighbours == kCleanNormalNeighbours;
    if (any)
      report.sheet_samples = FlipSheetsOn(shared, normals, closed, report.sheets, kSheetCoarseFraction, clean_lines);
    // A piece open by its flux may be a closed surface with a sheet inverted as a whole, too large
    // for the pass above (CGAL's spool: one flange's face, 929 of 5,000 samples, reached across
    // its rim 2.5 spacings thick; flux 0.33 of the area, 0.013 once turned). The pass runs again on
    // such pieces with sheets of up to a quarter of the samples, and stands only on a piece it
    // closes (flux under detail::kClosedFlux): an open scan's flux is its opening's, which no sign of
    // its sheets removes (b9_training, hippo1, building, half.xyz: unchanged).
    // The trial on `open_piece`'s samples with sheets of up to n / `fraction`, standing only where
    // it closes a piece.
    const auto close_by_sheets = [&](const std::vector<std::uint8_t>& open_piece, std::size_t fraction) {
      if (std::find(open_piece.begin(), open_piece.end(), 1) == open_piece.end()) return;
      std::vector<V3> trial = normals;
      std::size_t trial_sheets = 0;
      if (FlipSheetsOn(shared, trial, open_piece, trial_sheets, fraction, clean_lines) == 0) return;
      const std::vector<V3> after = piece_flux_of(trial);
      std::vector<std::uint8_t> stands(pieces, 0);  // an open piece the trial closes
      for (std::size_t i = 0; i < n; ++i)
        stands[component[i]] =
            open_piece[i] != 0 && after[component[i]].norm() < detail::kClosedFlux * area[component[i]];
      report.closed_by_sheets += static_cast<std::size_t>(std::count(stands.begin(), stands.end(), 1));
      for (std::size_t i = 0; i < n; ++i) {
        if (stands[component[i]] == 0) continue;
        if (trial[i].dot(normals[i]) < 0) ++report.closed_by_sheets_samples;
        normals[i] = trial[i];
      }
    };
    std::vector<std::uint8_t> open_piece(n, 0);
    for (std::size_t i = 0; i < n; ++i)
      open_piece[i] = closed[i] == 0 && now[component[i]].norm() <= kOpenSheetMostFlux * area[component[i]];
    close_by_sheets(open_piece, kOpenSheetFraction);
    // Still open: a sheet of up to half the samples may be inverted as a whole, a face of a solid
    // with few faces, whose jet lines turn by over 90 degrees at its edges, so the tree crossed
    // them with the sign lost (CGAL's reference_tetrahedron, 5,000 bare samples: its slanted face,
    // 1,802 samples, inward; flux 0.72 of the area, past kOpenSheetMostFlux; 40.8 % of the band
    // wrong and 426,826 far-wrong nodes). The trial runs again with such sheets on pieces with few
    // rims, and stands only where it closes a piece.
    now = piece_flux_of(normals);
    std::vector<std::uint8_t> wide(pieces, 0);  // still open by the flux
    bool any_wide = false;
    for (std::size_t i = 0; i < n; ++i) {
      const std::uint32_t c = component[i];
      wide[c] = now[c].norm() >= detail::kClosedFlux * area[c] ? 1 : 0;
      any_wide = any_wide || wide[c] != 0;
    }
    if (any_wide) {
      const SheetNeighbours neighbours = shared.Get();
      // Per piece, the sheet whose turn alone leaves the least flux, and its samples.
      std::vector<double> best_after(pieces, std::numeric_limits<double>::infinity());
      std::vector<std::vector<std::uint32_t>> best_sheet(pieces);
      for (const SheetCut& cut : kSheetCuts) {
        detail::UnionFind joined = JoinSheets(
            positions, normals, neighbours.graph, cut,
            [&](std::uint32_t i, std::uint32_t j) { return wide[component[i]] == 0 || component[j] != component[i]; });
        std::vector<V3> sheet_flux(n, V3::Zero());
        std::vector<std::size_t> sheet_size(n, 0);
        for (std::size_t i = 0; i < n; ++i) {
          if (wide[component[i]] == 0) continue;
          const std::uint32_t r = joined.Find(static_cast<std::uint32_t>(i));
          sheet_flux[r] += areas[i] * normals[i];
          ++sheet_size[r];
        }
        std::vector<std::int64_t> best_root(pieces, -1);
        for (std::size_t r = 0; r < n; ++r) {
          if (sheet_size[r] == 0 || sheet_size[r] > n / kWideOpenSheetFraction) continue;
          const std::uint32_t c = component[r];
          const double after = (now[c] - 2.0 * sheet_flux[r]).norm();
          if (after >= detail::kClosedFlux * area[c]) continue;
          if (after < best_after[c]) {
            best_after[c] = after;
            best_root[c] = static_cast<std::int64_t>(r);
            best_sheet[c].clear();
          }
        }
        for (std::size_t i = 0; i < n; ++i)
          if (wide[component[i]] != 0 && best_root[component[i]] >= 0 &&
              joined.Find(static_cast<std::uint32_t>(i)) == static_cast<std::uint32_t>(best_root[component[i]]))
            best_sheet[component[i]].push_back(static_cast<std::uint32_t>(i));
      }
      // A cost gate: an open scan's rim (samples whose 16 nearest leave a gap wider than kRimGap on
      // their tangent plane) holds several sqrt(n) of its samples, a closed solid's sharp edges and
      // corners fewer (the tetrahedron: 2.1 sqrt(n), 0 with 0.5 voxel of noise; b9_training's
      // largest piece 11.6: the trial there cost its build 28 % for no change).
      std::vector<std::uint8_t> is_rim(n, 0);
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 256), [&](const auto& range) {
        std::array<std::size_t, kPieceRimNeighbours + 1> idx{};
        std::array<double, kPieceRimNeighbours + 1> d2{};
        for (std::size_t i = range.begin(); i != range.end(); ++i) {
          if (wide[component[i]] == 0) continue;
          const std::size_t got =
              neighbours.tree.knnSearch(positions[i].data(), kPieceRimNeighbours + 1, idx.data(), d2.data());
          const detail::TangentGap widest =
              detail::WidestTangentGap<kPieceRimNeighbours + 1>(positions, idx.data(), got, i, normals[i]);
          is_rim[i] = widest.count >= 3 && widest.gap > detail::kRimGap ? 1 : 0;
        }
      });
      std::vector<std::size_t> rims(pieces, 0), size(pieces, 0);
      for (std::size_t i = 0; i < n; ++i) {
        rims[component[i]] += is_rim[i];
        ++size[component[i]];
      }
      std::vector<std::uint8_t> wide_piece(n, 0);
      for (std::size_t i = 0; i < n; ++i) {
        const std::uint32_t c = component[i];
        wide_piece[i] =
            wide[c] != 0 && static_cast<double>(rims[c]) < kWideOpenMostRims * std::sqrt(static_cast<double>(size[c]));
      }
      close_by_sheets(wide_piece, kWideOpenSheetFraction);
      // Where the energy's sheets did not close such a piece (the slanted face of the tetrahedron
      // at one draw of three), the one sheet is turned alone, and stands when the piece's mean
      // winding level (SampleProbes::Levels: 1/2 on a closed surface oriented outward, 0.07-0.45 on
      // an open scan) rises to kWideOpenLevel: a turn that closes an open scan's flux by chance
      // (two equal faces seen from one side) lowers it.
      std::vector<V3> turned = normals;
      std::vector<std::uint8_t> tried(pieces, 0);
      const std::vector<V3> left = piece_flux_of(normals);  // after the sheet pass
      for (std::size_t c = 0; c < pieces; ++c) {
        if (best_sheet[c].empty() || left[c].norm() < detail::kClosedFlux * area[c]) continue;
        bool gated = false;
        for (const std::uint32_t i : best_sheet[c]) gated = gated || wide_piece[i] != 0;
        if (!gated) continue;
        tried[c] = 1;
        for (const std::uint32_t i : best_sheet[c]) turned[i] = -turned[i];
      }
      if (std::find(tried.begin(), tried.end(), 1) != tried.end()) {
        const SampleProbes probes(positions, normals, SampleProbes::Walls::kEitherSign);
        const std::vector<double> before = probes.Levels(normals), after = probes.Levels(turned);
        std::vector<double> weight(pieces, 0.0), level_before(pieces, 0.0), level_after(pieces, 0.0);
        std::vector<std::uint8_t> stood(pieces, 0);
        for (std::size_t i = 0; i < n; ++i) {
          const std::uint32_t c = component[i];
          if (tried[c] == 0) continue;
          weight[c] += areas[i];
          level_before[c] += areas[i] * before[i];
          level_after[c] += areas[i] * after[i];
        }
        for (std::size_t c = 0; c < pieces; ++c) {
          if (tried[c] == 0 || !(weight[c] > 0.0) || !(level_after[c] >= kWideOpenLevel * weight[c]) ||
              !(level_after[c] > level_before[c]))
            continue;
          ++report.closed_by_sheets;
          report.closed_by_sheets_samples += best_sheet[c].size();
          for (const std::uint32_t i : best_sheet[c]) normals[i] = turned[i];
          stood[c] = 1;
        }
        // The sheet's edges, where the jet lines blend two faces, stay inward as strips of their
        // own; on the piece now closed the sheet pass turns them (seed 1: 263 normals inward -> 68).
        std::vector<std::uint8_t> now_closed(n, 0);
        for (std::size_t i = 0; i < n; ++i) now_closed[i] = stood[component[i]];
        if (std::find(stood.begin(), stood.end(), 1) != stood.end()) {
          std::size_t strips = 0;
          report.closed_by_sheets_samples +=
              FlipSheetsOn(shared, normals, now_closed, strips, kSheetCoarseFraction, clean_lines);
        }
      }
    }
  }
  report.flipped = 0;
  for (std::size_t i = 0; i < n; ++i)  // `given` is `normals`: the file's is +-oriented[i] by keep[i]
    if ((normals[i].dot(oriented[i]) < 0.0) == (keep[i] != 0)) ++report.flipped;
}

std::size_t FlipSheetsOnSharpenedLinesOn(SheetGraph& shared, std::vector<V3>& normals, NormalsReport& report) {
  const std::vector<V3>& positions = shared.positions();
  if (report.neighbours != kCleanNormalNeighbours || report.open_components > 0 || positions.empty() ||
      normals.size() != positions.size())
    return 0;
  report.refined_sheet_samples = FlipSheetsOn(shared, normals, std::vector<std::uint8_t>(positions.size(), 1),
                                              report.refined_sheets, kSheetCoarseFraction, true);
  return report.refined_sheet_samples;
}

}  // namespace

void OrientNormals(const std::vector<V3>& positions, std::vector<V3>& normals, bool keep_file_majority,
                   NormalsReport& report, bool given_are_jet_lines) {
  SheetGraph shared(positions);
  OrientOn(shared, normals, keep_file_majority, report, given_are_jet_lines);
}

std::size_t FlipSheetsOnSharpenedLines(const std::vector<V3>& positions, std::vector<V3>& normals,
                                       NormalsReport& report) {
  SheetGraph shared(positions);
  return FlipSheetsOnSharpenedLinesOn(shared, normals, report);
}

bool OrientEstimatedNormals(const std::vector<V3>& positions, std::vector<V3>& normals, NormalsReport& report,
                            double refit_noise_threshold) {
  if (positions.empty() || normals.size() != positions.size()) return false;
  SheetGraph shared(positions);
  OrientOn(shared, normals, false, report, true);
  const bool refit = refit_noise_threshold > 0 &&
                     RefitNoisyNormalLines(positions, normals, report, refit_noise_threshold, kDenoiseNeighbours);
  RefineNormalLines(positions, normals, report.neighbours);
  FlipSheetsOnSharpenedLinesOn(shared, normals, report);
  return refit;
}

bool RefitNoisyNormalLines(const std::vector<V3>& positions, std::vector<V3>& normals, NormalsReport& report,
                           double noise_threshold, std::size_t noise_neighbours) {
  if (report.neighbours != kCleanNormalNeighbours || normals.size() != positions.size()) return false;
  if (!(MeasurePositionNoise(positions, normals, noise_neighbours).noise > noise_threshold)) return false;
  std::vector<V3> lines;
  report.neighbours = EstimateNormalLines(positions, lines, nullptr, true);
  for (std::size_t i = 0; i < lines.size(); ++i) normals[i] = lines[i].dot(normals[i]) < 0 ? V3(-lines[i]) : lines[i];
  return true;
}

}  // namespace palpa::field
