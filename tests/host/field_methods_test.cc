// The three field methods of issue 5 against truths nobody here computed: the analytic sphere
// (sphere926 is radius 10 at the origin) and CGAL's exact distance to closed meshes that
// palpa_mesh samples (knot1.off, fandisk.off). The default method must meet the targets.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <expected>
#include <functional>
#include <limits>
#include <numbers>
#include <random>
#include <span>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include "palpa/blob/blob.h"
#include "palpa/field/build.h"
#include "palpa/field/edt_field.h"
#include "palpa/field/hermite_field.h"
#include "palpa/field/normals.h"
#include "palpa/field/point_io.h"
#include "palpa/field/samples.h"
#include "palpa/field/to_blob.h"
#include "palpa/field/transform.h"
#include "palpa/mesh/eval.h"
#include "palpa/mesh/mesh_distance.h"
#include "palpa/mesh/sample.h"
#include "palpa/mesh/triangle_mesh.h"
#include "test_util.h"

namespace palpa::field {
namespace {

using testing::DataFile;
using testing::SampledMesh;

// A v1 blob of a built field, as palpa build writes it (the payload straight from WriteQ16).
blob::VerifiedField Encode(const BuildResult& built, const Transform& fit) {
  const GridSpec& g = built.field.grid();
  const blob::BlobMeta meta = BlobMetaOf(g, FieldMethod::kHermite, {.transform = fit});
  std::vector<std::int32_t> phi(g.NodeCount());
  built.field.WriteQ16(phi);
  return blob::VerifyOwned(blob::Encode(meta, phi)).value();
}

struct Case {
  BuildResult built;
  Transform fit;
};

Case Build(const PointSet& model, int cells, FieldMethod method, bool leak_guard = true) {
  const Transform fit = FitTransform(model, 0.06);
  const PointSet device = ApplyTransform(fit, model);
  BuildOptions options;
  options.grid.cells = cells;
  options.method = method;
  options.leak_guard = leak_guard;
  auto built = BuildField(device.positions, device.normals, options);
  EXPECT_TRUE(built.has_value()) << built.error().message;
  return Case{std::move(*built), fit};
}

// The same device samples built with one of `options`' passes off, then on: what the pass changes.
struct OffOn {
  std::expected<BuildResult, Error> off, on;
};
OffOn BuildOffOn(const PointSet& device, BuildOptions options, bool BuildOptions::*pass) {
  options.*pass = false;
  auto off = BuildField(device.positions, device.normals, options);
  options.*pass = true;
  return {std::move(off), BuildField(device.positions, device.normals, options)};
}

// The samples an open scan from above keeps (bench/field/robustness.py's open-scan row): those
// whose normal points away from +z by less than 100 degrees.
PointSet OpenScan(const PointSet& all) {
  PointSet open;
  for (std::size_t i = 0; i < all.positions.size(); ++i)
    if (all.normals[i].z() > -std::cos(80.0 * std::numbers::pi / 180.0)) {
      open.positions.push_back(all.positions[i]);
      open.normals.push_back(all.normals[i]);
    }
  return open;
}

mesh::EvalResult Score(const Case& c, const mesh::Truth& truth, const char* what) {
  const blob::VerifiedField b = Encode(c.built, c.fit);
  auto result = mesh::Evaluate(b.view(), truth);
  EXPECT_TRUE(result.has_value()) << result.error().message;
  const mesh::EvalResult& r = *result;
  std::printf(
      "[ %s ] %s: mean %.4f p99 %.4f max %.4f voxels, signed %+.4f, wrong sign %.3f %% of %zu band nodes, "
      "gross %zu (%.5f %% of all)\n",
      what, std::string(MethodName(FieldMethod::kHermite)).c_str(), r.mean_abs_error, r.p99_abs_error, r.max_abs_error,
      r.mean_signed_error, r.wrong_sign_in_band_percent, r.band_nodes, r.gross_wrong_sign, r.gross_wrong_sign_percent);
  return r;
}

// The bundled closed mesh `file`, 5,000 samples (seed 1) scanned from above (OpenScan), built at
// 150 cells and scored against the mesh.
mesh::EvalResult ScoreOpenScan(const char* file) {
  auto m = mesh::ReadClosedMesh(DataFile(file));
  if (!m.has_value()) {
    ADD_FAILURE() << file << ": " << m.error().message;
    return {};
  }
  const Case c = Build(OpenScan(SampledMesh(file, 5000)), 150, FieldMethod::kHermite);
  const std::string what = std::string(file) + " 5000 pts, open scan (no -z side), 150 cells";
  return Score(c, mesh::Truth::Mesh(*m), what.c_str());
}

// Replaces the normals as `palpa build --normals estimate` does: jet lines, oriented, fitted again
// as noisy when the position noise is over kDenoiseVoxels x `voxel` (> 0; --denoise auto's measure
// over kDenoiseNeighbours), refined, sheets turned again on the refined lines.
NormalsReport EstimateAsBuildDoes(PointSet& points, double voxel = 0) {
  NormalsReport report;
  report.neighbours = EstimateNormalLines(points.positions, points.normals, &report.noise_figure);
  OrientEstimatedNormals(points.positions, points.normals, report, kDenoiseVoxels * voxel);
  return report;
}

// A mesh's 5,000 samples (`seed`, 150 cells) built with their exact normals and with normals
// estimated as `palpa build --normals estimate` does, scored against the mesh.
struct EstimatedAgainstExact {
  mesh::EvalResult with_exact, with_estimated;
  double ratio = 0;           // wrong sign in the band, estimated / exact
  std::size_t inward = 0;     // estimated normals facing against the exact ones
  std::size_t off_30deg = 0;  // estimated normal lines more than 30 degrees off the exact ones
  NormalsReport report;
};
EstimatedAgainstExact EstimateAndCompare(const char* file, std::uint64_t seed = 1) {
  EstimatedAgainstExact r;
  auto m = mesh::ReadClosedMesh(DataFile(file));
  EXPECT_TRUE(m.has_value());
  if (!m) return r;
  const PointSet exact = SampledMesh(file, 5000, seed);
  const std::string name = std::string(file) + " 5000 pts seed " + std::to_string(seed);
  r.with_exact = Score(Build(exact, 150, FieldMethod::kHermite), mesh::Truth::Mesh(*m), (name + ", exact").c_str());
  PointSet estimated = exact;
  r.report = EstimateAsBuildDoes(estimated);
  for (std::size_t i = 0; i < exact.normals.size(); ++i) {
    const double cos = estimated.normals[i].dot(exact.normals[i]);
    r.inward += cos < 0;
    r.off_30deg += std::abs(cos) < std::cos(30.0 * std::numbers::pi / 180.0);
  }
  r.with_estimated =
      Score(Build(estimated, 150, FieldMethod::kHermite), mesh::Truth::Mesh(*m), (name + ", estimated").c_str());
  r.ratio = r.with_estimated.wrong_sign_in_band_percent / r.with_exact.wrong_sign_in_band_percent;
  std::printf(
      "[ %s ] %zu normals inward; wrong sign %.3f %% estimated, %.3f %% exact: %.2fx; %zu far-wrong nodes; %s\n",
      name.c_str(), r.inward, r.with_estimated.wrong_sign_in_band_percent, r.with_exact.wrong_sign_in_band_percent,
      r.ratio, r.with_estimated.far_wrong(), r.report.Describe().c_str());
  return r;
}

// --- Targets of the default method (issue 5) --------------------------------------------------

void CheckSphere926(int cells) {
  const auto points = ReadPoints(DataFile("sphere926.pwn"));
  ASSERT_TRUE(points.has_value());
  const Case c = Build(*points, cells, FieldMethod::kHermite);
  const std::string what = "sphere926 " + std::to_string(cells) + " cells";
  const mesh::EvalResult r = Score(c, mesh::Truth::Sphere(10.0), what.c_str());
  EXPECT_GT(r.band_nodes, 100000u);
  EXPECT_LE(r.mean_abs_error, 0.05);
  EXPECT_LE(r.max_abs_error, 0.25);
  EXPECT_LE(r.wrong_sign_in_band_percent, 0.5);
  EXPECT_LE(r.gross_wrong_sign_percent, 0.002);
}

TEST(HermiteTargets, Sphere926At150Cells) { CheckSphere926(150); }
TEST(HermiteTargets, Sphere926At300Cells) { CheckSphere926(300); }

TEST(HermiteTargets, Knot1Sampled5000) {
  auto m = mesh::ReadClosedMesh(DataFile("knot1.off"));
  ASSERT_TRUE(m.has_value());
  const Case c = Build(SampledMesh("knot1.off", 5000), 150, FieldMethod::kHermite);
  const mesh::EvalResult r = Score(c, mesh::Truth::Mesh(*m), "knot1 5000 pts 150 cells");
  EXPECT_LE(r.mean_abs_error, 0.06);
  EXPECT_LE(r.wrong_sign_in_band_percent, 1.0);
  EXPECT_LE(r.gross_wrong_sign_percent, 0.002);
}

TEST(HermiteTargets, FandiskSampled5000) {
  auto m = mesh::ReadClosedMesh(DataFile("fandisk.off"));
  ASSERT_TRUE(m.has_value());
  const Case c = Build(SampledMesh("fandisk.off", 5000), 150, FieldMethod::kHermite);
  const mesh::EvalResult r = Score(c, mesh::Truth::Mesh(*m), "fandisk 5000 pts 150 cells");
  EXPECT_LE(r.mean_abs_error, 0.15);
  EXPECT_LE(r.wrong_sign_in_band_percent, 2.0);
  EXPECT_LE(r.gross_wrong_sign_percent, 0.002);
}

// Issue 20, noise: Gaussian position noise of sigma = 0.5 voxel per axis. A patch through its own
// noisy sample would put ~0.4 voxel of mean error (E|N(0, 0.5)|) into the band; moved to the
// mean height of its neighbours it costs less (measured 0.235 voxels; 0.280 before).
TEST(HermiteTargets, Knot1WithPositionNoiseAveragesIt) {
  auto m = mesh::ReadClosedMesh(DataFile("knot1.off"));
  ASSERT_TRUE(m.has_value());
  PointSet points = SampledMesh("knot1.off", 5000);
  const Transform fit = FitTransform(points, 0.06);
  BuildOptions probe;
  probe.grid.cells = 150;
  auto grid = MakeGrid(ApplyTransform(fit, points).positions, probe.grid);
  ASSERT_TRUE(grid.has_value());
  const double sigma = 0.5 * grid->voxel_m / fit.scale;  // model units
  std::mt19937_64 rng(2);
  const auto gauss = [&] {  // Box-Muller on the standard's fixed engine: the same on every platform
    const double u1 = (static_cast<double>(rng() >> 11) + 0.5) * 0x1p-53;
    const double u2 = static_cast<double>(rng() >> 11) * 0x1p-53;
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * std::numbers::pi * u2);
  };
  for (Eigen::Vector3d& p : points.positions) p += sigma * Eigen::Vector3d(gauss(), gauss(), gauss());
  const Case c = Build(points, 150, FieldMethod::kHermite);
  const mesh::EvalResult r = Score(c, mesh::Truth::Mesh(*m), "knot1 5000 pts, noise 0.5 voxel, 150 cells");
  EXPECT_LE(r.mean_abs_error, 0.26);
  EXPECT_LE(r.wrong_sign_in_band_percent, 4.8);
  EXPECT_EQ(r.far_wrong(), 0u);
}

// Issue 20, a closed mesh the field methods were not tuned on (CGAL's cow): with 5,000 samples its
// legs, horns and tail are a few samples across, and the local estimate alone extrapolated phantom
// solid and holes up to 24 voxels from the surface (356 far-wrong nodes at 150 cells). Farther
// than a sample spacing from every sample the winding number of the samples decides the side.
TEST(HermiteTargets, CowHasNoWrongSignFarFromTheSurface) {
  auto m = mesh::ReadClosedMesh(DataFile("cow.off"));
  ASSERT_TRUE(m.has_value());
  const Case c = Build(SampledMesh("cow.off", 5000), 150, FieldMethod::kHermite);
  const mesh::EvalResult r = Score(c, mesh::Truth::Mesh(*m), "cow 5000 pts 150 cells");
  EXPECT_LE(r.mean_abs_error, 0.1);
  EXPECT_LE(r.wrong_sign_in_band_percent, 1.8);
  EXPECT_EQ(r.far_wrong(), 0u) << r.phantom_solid.nodes << " phantom, " << r.holes.nodes << " holes";
  EXPECT_GT(c.built.hermite.winding_far_nodes, 0u);
  EXPECT_FALSE(c.built.orientation.Inconsistent()) << c.built.orientation.Describe();  // exact mesh normals
  // Closed: not reported open (its phantoms once reached the grid faces, w a few hundredths there).
  EXPECT_EQ(c.built.hermite.face_nodes_closed, 0u);
}

// Issue 20, a sparse closed set: CGAL's cow with 500 samples (seed 6), about 9 voxels apart at 150
// cells. No sample lies on two of its hooves' soles, and the local estimate carried those legs on
// past them, w unclear there: 131 phantom nodes up to 5.6 voxels below the soles. A closed surface
// lies within a sagitta of its samples' convex hull, so a node held inside more than max(3 voxels,
// 0.3 spacings) outside that hull is set outside (CutBeyondSampleHull in hermite_field.cc).
TEST(HermiteTargets, SparseCowsLegsEndNearTheirUnsampledSoles) {
  auto m = mesh::ReadClosedMesh(DataFile("cow.off"));
  ASSERT_TRUE(m.has_value());
  const Case c = Build(SampledMesh("cow.off", 500, 6), 150, FieldMethod::kHermite);
  const mesh::EvalResult r = Score(c, mesh::Truth::Mesh(*m), "cow 500 pts (seed 6) 150 cells");
  EXPECT_LE(r.phantom_solid.nodes, 5u) << "deepest " << r.phantom_solid.deepest_voxels << " voxels";
  EXPECT_LE(r.holes.nodes, 5u) << r.holes.nodes << " holes";
  EXPECT_GT(c.built.hermite.hull_cut_nodes, 0u);
}

// Issue 20, normals estimated: CGAL's pinion (1,300 flat faces) counts as rough for the edge
// refinement (its samples' offsets from their jet planes are the facets' creases), and every sample
// kept a jet normal bent towards the next facet: wrong sign in the band 2.3x that with the exact
// normals. A sample whose best plane holds 40 % of its neighbourhood at the selection width is on
// a facet and takes its plane (RefineNormalLines, kFacetShare): 2.0x (1.98). First rows then take
// a flat neighbour's plane (TakeFacePlanes): 1.7x; and a sample on a facet, its exact plane
// (TakeExactFacets): 1.48x, within the 1.5x, with 1 far-wrong node (a hole; target 100).
// With the selection at the narrow width and the supporters' quadric (kSupportQuadric): 1.43x.
TEST(HermiteTargets, EstimatedNormalsOfALowPolygonPartFollowItsFacets) {
  const EstimatedAgainstExact r = EstimateAndCompare("pinion.off");
  EXPECT_LT(r.ratio, 1.5);
  EXPECT_LE(r.with_estimated.far_wrong(), 10u);
}

// Issue 20, found on a mesh never used before (CGAL's reference_tetrahedron, robustness seed 55):
// 5,000 bare samples of the tetrahedron (0, 0, 0), e_x, e_y, e_z. Its edges turn the normals by
// 90 and 125 degrees, so the tree carried the sign across the slanted face's edges lost: that
// face (36 % of the samples) came out inward as a whole, the piece open by its flux (0.72 of the
// area) past the sheet pass's reach (a quarter of the samples, flux 0.6), 40.8 % of the band wrong
// and 426,826 far-wrong nodes. A piece that one sheet's turn would close, and with few rims, is
// tried with sheets of up to half the samples, and where their energy does not close it (seed
// 1), that sheet is turned alone when the piece's winding level rises: at three draws, under 2 %
// of the normals inward (the edges' blends), under 1 % of the band wrong and at most 2 far-wrong
// nodes (issue 20's limit: 100).
TEST(HermiteTargets, EstimatedNormalsOfATetrahedronTurnItsInvertedFace) {
  mesh::TriangleMesh tetrahedron;
  tetrahedron.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  tetrahedron.faces = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};  // outward
  for (const std::uint64_t seed : {std::uint64_t{1}, std::uint64_t{2}, std::uint64_t{55}}) {
    auto exact = mesh::SampleSurface(tetrahedron, 5000, seed, "tetrahedron");
    ASSERT_TRUE(exact.has_value()) << exact.error().message;
    PointSet estimated = *exact;
    const NormalsReport report = EstimateAsBuildDoes(estimated);
    std::size_t inward = 0;
    for (std::size_t i = 0; i < estimated.normals.size(); ++i)
      inward += estimated.normals[i].dot(exact->normals[i]) < 0;
    const mesh::EvalResult r = Score(Build(estimated, 150, FieldMethod::kHermite), mesh::Truth::Mesh(tetrahedron),
                                     ("tetrahedron 5000 pts seed " + std::to_string(seed) + ", estimated").c_str());
    std::printf("[ tetrahedron seed %llu ] %zu normals inward; %s\n", static_cast<unsigned long long>(seed), inward,
                report.Describe().c_str());
    EXPECT_LT(inward, 100u) << seed;
    EXPECT_LE(r.far_wrong(), 10u) << seed;
    EXPECT_LT(r.wrong_sign_in_band_percent, 1.0) << seed;
  }
}

// Issue 20, position noise on bare samples of a part whose teeth and creases are as fine as the
// normals' fit: CGAL's pinion, 5,000 samples (seed 3) with 0.3 voxel of noise per axis (150 cells),
// normals estimated as palpa build does. The bisector moves follow lines fitted across the teeth:
// their RMS is over 1.4 x the noise they measure, and they leave the samples farther from the true
// surface than the noise put them. With `fitted_normals` every move is undone (withheld), the
// positions bit for bit as given; without it (given normals) the same lines' moves stand.
TEST(SmoothNoisyPositionsOnAPart, FittedLinesMovesLargerThanTheNoiseAreUndone) {
  auto m = mesh::ReadClosedMesh(DataFile("pinion.off"));
  ASSERT_TRUE(m.has_value());
  PointSet points = SampledMesh("pinion.off", 5000, 3);
  Eigen::Vector3d lo = points.positions[0], hi = lo;
  for (const Eigen::Vector3d& p : points.positions) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  const double voxel = (hi - lo).maxCoeff() / (150 - 1 - 16);  // as at 150 cells
  std::mt19937_64 rng(3);
  std::normal_distribution<double> gauss(0.0, 0.3 * voxel);
  for (Eigen::Vector3d& p : points.positions) p += Eigen::Vector3d(gauss(rng), gauss(rng), gauss(rng));
  EstimateAsBuildDoes(points, voxel);

  const mesh::ExactMeshDistance truth(*m);
  const auto rms_off = [&](const std::vector<Eigen::Vector3d>& positions) {
    double s = 0.0;
    for (const Eigen::Vector3d& p : positions) s += std::pow(truth.UnsignedDistance(p), 2);
    return std::sqrt(s / static_cast<double>(positions.size())) / voxel;
  };
  const std::vector<Eigen::Vector3d> noisy = points.positions;
  std::vector<Eigen::Vector3d> moved = noisy;
  const NoiseSmoothing given =
      SmoothNoisyPositions(moved, points.normals, kDenoiseNeighbours, kDenoiseVoxels * voxel, kMovePasses, false);
  ASSERT_TRUE(given.Applied());
  EXPECT_GT(given.rms_move, kMoveDiscrepancy * given.noise);
  EXPECT_GT(rms_off(moved), rms_off(noisy));  // the moves the rule undoes were doing harm
  std::printf("[ pinion ] noise %.3f voxel, moves %.3f voxel RMS (%.2fx); off the surface %.3f -> %.3f voxel RMS\n",
              given.noise / voxel, given.rms_move / voxel, given.rms_move / given.noise, rms_off(noisy),
              rms_off(moved));

  std::vector<Eigen::Vector3d> kept = noisy;
  const NoiseSmoothing fitted = SmoothNoisyPositions(kept, points.normals, kDenoiseNeighbours, kDenoiseVoxels * voxel,
                                                     kMovePasses, kNormalNeighbours);
  EXPECT_TRUE(fitted.withheld);
  EXPECT_FALSE(fitted.Applied());
  EXPECT_EQ(fitted.rms_move, given.rms_move);  // the bound is asked of the full move, the given normals' one
  EXPECT_EQ(kept, noisy);
}

// Issue 20, normals estimated on a part with thin flanges: CGAL's spool at 5,000 samples (flanges
// 2.5 spacings thick). The tree crossed a flange's rim and oriented the flange's face inward as a
// whole (929 samples, above the sheet pass's n / 8); the piece then read open by its flux, and the
// sheet pass ran on closed pieces only: 980 normals inward, wrong sign in the band 24.8 % against
// 0.93 % with the exact normals (26.8x). The pass now runs again on pieces open by their flux,
// with sheets up to n / 4, and stands where it closes the piece: 127 inward, 2.35 % (2.54x).
// Since the eighteenth session a second spanning tree that prefers the pairs facing each other
// across the flange closes the piece first (83 inward, 1.98x; the sheet pass had reached 83, 2.00x).
// Since the twenty-seventh session the sheet pass runs again on the sharpened lines: 49, 1.62x.
TEST(HermiteTargets, EstimatedNormalsOfAFlangedPartTurnAnInvertedFace) {
  const EstimatedAgainstExact r = EstimateAndCompare("spool.off");
  EXPECT_EQ(r.report.closed_by_tree + r.report.closed_by_sheets, 1u) << r.report.Describe();
  EXPECT_LT(r.inward, 150u);
  EXPECT_LT(r.ratio, 4.0);
}

// Issue 20, normals estimated on clean samples of a part with creases and thin walls: CGAL's
// couplingdown counts as rough for the edge refinement (its creases are the offsets), and where no
// plane holds a facet a sample kept its jet normal, which weighs the next face over a crease and a
// wall's other side like its own surface: 640 normal lines off the exact ones by over 30 degrees,
// wrong sign in the band 2.22x that with the exact normals. On a clean set such a sample now
// takes a robust quadric through itself, from the frame most of its neighbours support
// (RefineNormalLines, kQuadricScale): 566 lines, 2.06x. Most of the rest have at most 4 of their
// 16 nearest on their own face at this spacing, which no local fit recovers.
TEST(HermiteTargets, EstimatedNormalsOfACleanCreasedPartFollowTheirOwnSurface) {
  const EstimatedAgainstExact r = EstimateAndCompare("couplingdown.off");
  ASSERT_EQ(r.report.neighbours, kCleanNormalNeighbours);
  std::printf("[ couplingdown ] %zu estimated normal lines off the exact ones by over 30 degrees\n", r.off_30deg);
  EXPECT_LT(r.off_30deg, 600u);
  EXPECT_LT(r.ratio, 2.15);
  EXPECT_LE(r.with_estimated.far_wrong(), 100u);
}

// Issue 20, normals estimated on a part with a thin shell: CGAL's rotor at 5,000 samples, whose
// ring is 1.7 spacings thick. The spanning tree gave the ring's inner side the outer side's sign
// (1,214 of its 1,334 samples), across cheap chords between the two sides where the jet lines lean
// 47 degrees; the sheet pass on those lines turned most of it back but joined an arc of 52 samples
// to the outer side. As built here (no sample dropped): 195 normals inward, 954 far-wrong nodes,
// 2.60x the exact normals' wrong sign. Run again on the sharpened lines, where the two sides part
// into sheets of their own: 41 inward, no far-wrong node, 1.68x (docs/field-methods.md § Thin
// shells: the sheet pass on sharpened lines).
TEST(HermiteTargets, EstimatedNormalsOfAThinShellTurnItsInnerSide) {
  const EstimatedAgainstExact r = EstimateAndCompare("rotor.off");
  ASSERT_EQ(r.report.neighbours, kCleanNormalNeighbours);
  EXPECT_GT(r.report.refined_sheets, 0u) << r.report.Describe();
  EXPECT_LT(r.inward, 60u);
  EXPECT_LE(r.with_estimated.far_wrong(), 100u);
  EXPECT_LT(r.ratio, 2.0);
}

// Issue 20, the rotor's other draws: on seeds 3, 4 and 5 an arc of the ring's inner wall (0.4-1.5
// spacings thick, 50-75 samples) kept the outer side's sign through both sheet passes, as a sheet
// of its own: its probes straddle the wall, and the winding energy scored its flip about even
// (+0.11 per unit of area on seed 5). Its phantom filled the ring's hole. As built here: 63, 93 and
// 114 normals inward, 294, 554 and 1,740 far-wrong nodes (`palpa build`, which ignores a few
// samples first: 1,772, 545 and 1,650). The facing term (a wall's two sides face apart or
// together, never the same way; FlipSheetsByWinding's `clean_lines`) turns it: 40, 48 and 45
// inward, no far-wrong node, checked.
TEST(HermiteTargets, EstimatedNormalsOfAThinShellTurnItsInnerSideOnOtherDraws) {
  for (const std::uint64_t seed : {3u, 4u, 5u}) {
    const EstimatedAgainstExact r = EstimateAndCompare("rotor.off", seed);
    EXPECT_LE(r.with_estimated.far_wrong(), 100u) << "seed " << seed;
    EXPECT_LT(r.inward, 60u) << "seed " << seed;
  }
}

// Issue 20, sparse sets: with 500 samples on knot1 the local estimate carried the tube's patches
// and balls into the gaps between its strands, 9-13 voxels from every sample, where the samples'
// winding number is 0.30-0.33: unclear against 1/2, but below the level w takes at these samples
// (0.42 median: sparse sets read low); and it left holes inside the tube where w is above 1/2.
// Where w's surface at that level (1/2 for the holes) lies farther from a node than the
// estimate's own and than a voxel, w's side stands (LabelByWinding). Six draws: 18 phantom nodes
// beyond 3 voxels (0, 5, 0, 7, 6, 0; 69 without the level test: 0, 28, 0, 9, 7, 25) and 70 holes
// (36, 2, 6, 0, 0, 26; 144 without the test at 1/2: 95, 2, 15, 0, 0, 32), checked; band means
// 0.286-0.302 voxel (0.297-0.309 without either).
TEST(HermiteTargets, SparseKnot1HasFewPhantomsAndHolesWhereTheWindingNumberIsUnclear) {
  auto m = mesh::ReadClosedMesh(DataFile("knot1.off"));
  ASSERT_TRUE(m.has_value());
  std::size_t phantom = 0, holes = 0;
  for (std::uint64_t seed = 1; seed <= 6; ++seed) {
    auto points = mesh::SampleSurface(*m, 500, seed, "knot1.off");
    ASSERT_TRUE(points.has_value());
    const Case c = Build(*points, 150, FieldMethod::kHermite);
    const std::string what = "knot1 500 pts seed " + std::to_string(seed);
    const mesh::EvalResult r = Score(c, mesh::Truth::Mesh(*m), what.c_str());
    std::printf("[ %s ] phantom %zu (%.2f voxels deep), holes %zu (%.2f voxels deep)\n", what.c_str(),
                r.phantom_solid.nodes, r.phantom_solid.deepest_voxels, r.holes.nodes, r.holes.deepest_voxels);
    EXPECT_LE(r.mean_abs_error, 0.31) << what;
    phantom += r.phantom_solid.nodes;
    holes += r.holes.nodes;
  }
  EXPECT_LE(phantom, 20u);
  EXPECT_LE(holes, 80u);
}

// Far-wrong nodes (phantom solid, holes) summed over fandisk sampled with `count` points from each
// `seed` (mesh::SampleSurface, as `palpa sample`), built with the defaults at 150 cells.
struct FarWrong {
  std::size_t phantom = 0;
  std::size_t holes = 0;
};
FarWrong SparseFandiskFarWrong(std::initializer_list<std::pair<std::size_t, std::uint64_t>> draws) {
  FarWrong sum;
  auto m = mesh::ReadClosedMesh(DataFile("fandisk.off"));
  EXPECT_TRUE(m.has_value());
  if (!m) return {SIZE_MAX, SIZE_MAX};
  for (const auto& [count, seed] : draws) {
    auto points = mesh::SampleSurface(*m, count, seed, "fandisk.off");
    EXPECT_TRUE(points.has_value());
    if (!points) return {SIZE_MAX, SIZE_MAX};
    const Case c = Build(*points, 150, FieldMethod::kHermite);
    const std::string what = "fandisk " + std::to_string(count) + " pts seed " + std::to_string(seed);
    const mesh::EvalResult r = Score(c, mesh::Truth::Mesh(*m), what.c_str());
    std::printf("[ %s ] phantom %zu (%.2f voxels deep), holes %zu (%.2f voxels deep)\n", what.c_str(),
                r.phantom_solid.nodes, r.phantom_solid.deepest_voxels, r.holes.nodes, r.holes.deepest_voxels);
    sum.phantom += r.phantom_solid.nodes;
    sum.holes += r.holes.nodes;
  }
  return sum;
}

// Sparse fandisk: the estimate cuts holes beside its unsampled faces where w is above 1/2 (0.64-0.71)
// and its 1/2 surface lies farther than the estimate's. Rim samples (a sparse sharp part has a
// few) nearest such a node stop only the level rule's cut side. The draws where they did (of 20 at
// 1,000 samples and 20 at 500): holes 10 / 70 / 12 / 309 -> 3 / 10 / 5 / 58, phantoms 170 either way.
TEST(HermiteTargets, SparseFandiskHolesBesideRimSamplesTakeWsSide) {
  const FarWrong far = SparseFandiskFarWrong({{1000, 2}, {1000, 16}, {1000, 18}, {500, 8}});
  EXPECT_LE(far.holes, 100u);
  EXPECT_LE(far.phantom, 180u);
}

// A lone rim sample among a node's nearest is a sparse set's sampling gap, not a part's unsampled
// end, whose rim is a ring (kPartEndRims): with one, w below the surface's level still cuts the
// estimate's patches short where they carry on past the samples (issue 20, docs/field-methods.md
// § Sparse closed sets: one rim sample is no part's end).
TEST(HermiteTargets, SparseFandiskPhantomsBesideALoneRimSampleTakeWsSide) {
  const FarWrong far = SparseFandiskFarWrong({{500, 5}, {500, 6}});
  // 238 phantom nodes where one rim stopped the rule (measured), 198 now; holes 62 either way.
  EXPECT_LE(far.phantom, 210u);
  EXPECT_LE(far.holes, 62u);
}

// --- Determinism ---------------------------------------------------------------------------

TEST(FieldMethods, OneAndTwoThreadsGiveBitIdenticalPayloads) {
  const auto points = ReadPoints(DataFile("kitten.xyz"));
  ASSERT_TRUE(points.has_value());
  for (FieldMethod method : {FieldMethod::kHermite, FieldMethod::kEdt, FieldMethod::kErosion}) {
    const auto payload = [&](std::size_t threads) {
      const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
      const Case c = Build(*points, 120, method);
      std::vector<std::int32_t> phi(c.built.field.grid().NodeCount());
      c.built.field.WriteQ16(phi);
      return phi;
    };
    const std::vector<std::int32_t> one = payload(1);
    const std::vector<std::int32_t> two = payload(2);
    EXPECT_EQ(one, two) << MethodName(method);
    EXPECT_TRUE(std::any_of(one.begin(), one.end(), [](std::int32_t v) { return v < 0; })) << MethodName(method);
  }
}

// palpa build encodes v2 from the sparse field a brick at a time (SparseField::BrickQ16): the same
// blob as the dense payload (WriteQ16) gives, and the same values node by node (ValueQ16).
TEST(FieldMethods, BrickWiseBlobEqualsTheDensePayloadsBlob) {
  const auto points = ReadPoints(DataFile("kitten.xyz"));
  ASSERT_TRUE(points.has_value());
  const Case c = Build(*points, 90, FieldMethod::kHermite);
  const SparseField& field = c.built.field;
  const GridSpec& g = field.grid();
  std::vector<std::int32_t> dense(g.NodeCount());
  field.WriteQ16(dense);
  // field::ToBlob (palpa build's writer, issue 21) against the dense encoders, v2 and v1.
  const blob::BlobMeta meta = BlobMetaOf(g, FieldMethod::kHermite, {.transform = c.fit, .point_count = 5210});
  EXPECT_EQ(meta.method, blob::Method::kHermite);
  EXPECT_EQ(meta.fit_scale, c.fit.scale);
  EXPECT_EQ(meta.dims[2], static_cast<std::uint32_t>(g.dims[2]));
  blob::BlobMetaV2 m;
  m.meta = meta;
  m.band_inside = 6;
  m.band_outside = 2;
  EXPECT_EQ(ToBlob(field, meta, {.version = 2, .band_inside = 6, .band_outside = 2}), blob::EncodeV2(m, dense));
  EXPECT_EQ(ToBlob(field, meta, {.version = 1}), blob::Encode(meta, dense));
  std::size_t differ = 0;
  for (int i = 0; i < g.dims[0]; ++i)
    for (int j = 0; j < g.dims[1]; ++j)
      for (int k = 0; k < g.dims[2]; ++k) {
        // The rounding rule itself: std::lround of phi · 2^16, clamped to the band.
        const std::int32_t band_q = g.band_voxels * 65536;
        const auto want =
            std::clamp(static_cast<std::int32_t>(std::lround(double{field.Value(i, j, k)} * 65536.0)), -band_q, band_q);
        differ += field.ValueQ16(i, j, k) != want || dense[g.Index(i, j, k)] != want ? 1u : 0u;
      }
  EXPECT_EQ(differ, 0u);
}

// --- Field shape: clamped, and neighbour differences within the proxy's 1 voxel ---------------

// The proxy's sphere tracing steps phi/sqrt(3) and needs |grad phi| <= sqrt(3) in every trilinear
// cell, i.e. axis neighbour differences <= 1 voxel (docs/realtime-core.md). Checked on the float
// field and on the Q16.16 payload the controller reads (there exactly: <= 65536), for every
// method on every bundled data set.
struct Shape {
  float worst_float = 0.0f;
  std::int64_t worst_q16 = 0;
  std::size_t over = 0;  // float pairs above 1 + 1e-6
  bool clamped = true;
};

Shape FieldShape(const SparseField& field) {
  const GridSpec& g = field.grid();
  const std::vector<float> phi = field.ToDense();
  std::vector<std::int32_t> q(g.NodeCount());
  field.WriteQ16(q);
  const auto band = static_cast<float>(g.band_voxels);
  Shape shape;
  for (int i = 0; i < g.dims[0]; ++i)
    for (int j = 0; j < g.dims[1]; ++j)
      for (int k = 0; k < g.dims[2]; ++k) {
        const std::size_t x = g.Index(i, j, k);
        shape.clamped = shape.clamped && std::abs(phi[x]) <= band;
        const auto visit = [&](std::size_t y) {
          const float d = std::abs(phi[y] - phi[x]);
          shape.worst_float = std::max(shape.worst_float, d);
          shape.over += d > 1.0f + 1e-6f ? 1u : 0u;
          shape.worst_q16 = std::max(shape.worst_q16, std::abs(std::int64_t{q[y]} - q[x]));
        };
        if (i + 1 < g.dims[0]) visit(g.Index(i + 1, j, k));
        if (j + 1 < g.dims[1]) visit(g.Index(i, j + 1, k));
        if (k + 1 < g.dims[2]) visit(g.Index(i, j, k + 1));
      }
  return shape;
}

TEST(FieldMethods, EveryMethodIsClampedAndNeighbourDifferencesAtMostOneVoxel) {
  struct Data {
    const char* name;
    PointSet points;
  };
  std::vector<Data> data;
  for (const char* file : {"kitten.xyz", "oni.pwn", "sphere926.pwn", "cube.pwn"}) {
    auto points = ReadPoints(DataFile(file));
    ASSERT_TRUE(points.has_value()) << file;
    data.push_back({file, std::move(*points)});
  }
  data.push_back({"knot1.off 5000", SampledMesh("knot1.off", 5000)});
  data.push_back({"fandisk.off 5000", SampledMesh("fandisk.off", 5000)});
  for (const Data& d : data) {
    for (FieldMethod method : {FieldMethod::kHermite, FieldMethod::kEdt, FieldMethod::kErosion}) {
      const Case c = Build(d.points, 150, method);
      const Shape shape = FieldShape(c.built.field);
      std::printf("[ %s 150 cells %s ] max neighbour difference %.6f voxels (Q16.16 %lld), %zu pairs above 1\n", d.name,
                  std::string(MethodName(method)).c_str(), static_cast<double>(shape.worst_float),
                  static_cast<long long>(shape.worst_q16), shape.over);
      EXPECT_TRUE(shape.clamped) << d.name << " " << MethodName(method);
      EXPECT_LE(shape.worst_float, 1.0f + 1e-6f) << d.name << " " << MethodName(method);
      EXPECT_LE(shape.worst_q16, 65536) << d.name << " " << MethodName(method);
      EXPECT_EQ(shape.over, 0u) << d.name << " " << MethodName(method);
    }
  }
}

// --- EDT against a literal brute force ---------------------------------------------------------

TEST(SignedEdt, EqualsBruteForce) {
  GridSpec grid;
  grid.dims = {19, 23, 17};
  grid.voxel_m = 1.0;
  grid.band_voxels = 5;
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<std::uint8_t> indicator(grid.NodeCount());
  for (int i = 0; i < grid.dims[0]; ++i)
    for (int j = 0; j < grid.dims[1]; ++j)
      for (int k = 0; k < grid.dims[2]; ++k) {
        const double r = std::hypot(i - 9.3, j - 11.1, k - 8.2);
        indicator[grid.Index(i, j, k)] = (r < 6.5 || u(rng) < 0.03) ? 1 : 0;
      }
  const std::vector<float> fast = SignedEdtField(grid, indicator);
  ASSERT_EQ(fast.size(), grid.NodeCount());
  const auto in_s = [&](int i, int j, int k) {
    return indicator[grid.Index(i, j, k)] != 0 && i > 0 && j > 0 && k > 0 && i < grid.dims[0] - 1 &&
           j < grid.dims[1] - 1 && k < grid.dims[2] - 1;
  };
  std::size_t mismatches = 0;
  for (int i = 0; i < grid.dims[0]; ++i)
    for (int j = 0; j < grid.dims[1]; ++j)
      for (int k = 0; k < grid.dims[2]; ++k) {
        const bool s = in_s(i, j, k);
        double best = 1e9;
        for (int a = 0; a < grid.dims[0]; ++a)
          for (int b = 0; b < grid.dims[1]; ++b)
            for (int c = 0; c < grid.dims[2]; ++c)
              if (in_s(a, b, c) != s) best = std::min(best, std::hypot(a - i, b - j, c - k));
        const double phi = std::clamp(s ? -(best - 0.5) : best - 0.5, -5.0, 5.0);
        mismatches += std::abs(fast[grid.Index(i, j, k)] - phi) > 1e-5 ? 1u : 0u;
      }
  EXPECT_EQ(mismatches, 0u);
}

// --- Leak guard (paper Fig. 4) -----------------------------------------------------------------

// False inside: nodes with phi <= 0 that are more than 1 voxel outside the true surface, where a
// packed ball leaked through a gap of a sparse sampling. `region` sorts them for the cube: 1 = off
// a face, 2 = off an edge, 3 = off a corner (how many coordinates lie beyond the box).
struct Leak {
  std::size_t false_inside = 0;
  std::array<std::size_t, 4> by_region{};
};

Leak FalseInside(const Case& c, const mesh::Truth& truth, double box_half_model = 0.0) {
  const blob::VerifiedField b = Encode(c.built, c.fit);
  const auto t = mesh::TrueDistances(b.view(), truth);
  EXPECT_TRUE(t.has_value()) << t.error().message;
  Leak leak;
  const GridSpec& g = c.built.field.grid();
  for (int i = 0; i < g.dims[0]; ++i)
    for (int j = 0; j < g.dims[1]; ++j)
      for (int k = 0; k < g.dims[2]; ++k) {
        if (!(t->voxels[g.Index(i, j, k)] > 1.0f) || c.built.field.Value(i, j, k) > 0.0f) continue;
        ++leak.false_inside;
        if (box_half_model > 0.0) {
          const Eigen::Vector3d model = (g.Node(i, j, k) - c.fit.offset_m) / c.fit.scale;
          const int beyond = (std::abs(model.x()) > box_half_model ? 1 : 0) +
                             (std::abs(model.y()) > box_half_model ? 1 : 0) +
                             (std::abs(model.z()) > box_half_model ? 1 : 0);
          ++leak.by_region[static_cast<std::size_t>(beyond)];
        }
      }
  return leak;
}

// The unit cube [-1/2, 1/2]^3 as a closed mesh, outward winding (truth for the corner test).
mesh::TriangleMesh UnitCube() {
  mesh::TriangleMesh cube;
  for (int v = 0; v < 8; ++v) cube.vertices.emplace_back((v & 1) - 0.5, ((v >> 1) & 1) - 0.5, ((v >> 2) & 1) - 0.5);
  // Two triangles per face, counter-clockwise seen from outside.
  cube.faces = {{0, 2, 3}, {0, 3, 1}, {4, 5, 7}, {4, 7, 6}, {0, 1, 5}, {0, 5, 4},
                {2, 6, 7}, {2, 7, 3}, {0, 4, 6}, {0, 6, 2}, {1, 3, 7}, {1, 7, 5}};
  return cube;
}

void ReportLeak(const char* what, const Leak& guarded, const Leak& unguarded, const Leak& erosion) {
  std::printf(
      "[ %s ] false-inside nodes (> 1 voxel outside): hermite guarded %zu (face/edge/corner %zu/%zu/%zu), "
      "unguarded %zu (%zu/%zu/%zu), erosion (paper packing) %zu\n",
      what, guarded.false_inside, guarded.by_region[1], guarded.by_region[2], guarded.by_region[3],
      unguarded.false_inside, unguarded.by_region[1], unguarded.by_region[2], unguarded.by_region[3],
      erosion.false_inside);
}

TEST(LeakGuard, SparseCubeCornersFalseInsideBelowUnguarded) {
  const mesh::TriangleMesh cube = UnitCube();
  for (const std::size_t count : {300u, 1000u}) {
    auto points = mesh::SampleSurface(cube, count, 1, "cube");
    ASSERT_TRUE(points.has_value()) << points.error().message;
    const mesh::Truth truth = mesh::Truth::Mesh(cube);
    const Leak guarded = FalseInside(Build(*points, 150, FieldMethod::kHermite), truth, 0.5);
    const Leak unguarded = FalseInside(Build(*points, 150, FieldMethod::kHermite, false), truth, 0.5);
    const Leak erosion = FalseInside(Build(*points, 150, FieldMethod::kErosion), truth, 0.5);
    const std::string what = "cube " + std::to_string(count) + " pts 150 cells";
    ReportLeak(what.c_str(), guarded, unguarded, erosion);
    EXPECT_GT(unguarded.false_inside, 0u) << count;
    EXPECT_LE(2 * guarded.false_inside, unguarded.false_inside) << count;
  }
}

TEST(LeakGuard, SparseFandiskFalseInsideBelowUnguarded) {
  auto m = mesh::ReadClosedMesh(DataFile("fandisk.off"));
  ASSERT_TRUE(m.has_value());
  const PointSet sparse = SampledMesh("fandisk.off", 500);
  const mesh::Truth truth = mesh::Truth::Mesh(*m);
  const Case guarded_case = Build(sparse, 150, FieldMethod::kHermite);
  const Leak guarded = FalseInside(guarded_case, truth);
  const Leak unguarded = FalseInside(Build(sparse, 150, FieldMethod::kHermite, false), truth);
  const Leak erosion = FalseInside(Build(sparse, 150, FieldMethod::kErosion), truth);
  ReportLeak("fandisk 500 pts 150 cells", guarded, unguarded, erosion);
  Score(guarded_case, truth, "fandisk 500 pts, hermite");
  EXPECT_GT(unguarded.false_inside, 0u);
  EXPECT_LE(2 * guarded.false_inside, unguarded.false_inside);
}

// A box 1 x 1 x 4 (a leg), its sole at z = -2, sampled on its surface.
PointSet SampledLeg(std::size_t count) {
  mesh::TriangleMesh leg = UnitCube();
  for (Eigen::Vector3d& v : leg.vertices) v.z() *= 4.0;
  auto points = mesh::SampleSurface(leg, count, 3, "leg");
  EXPECT_TRUE(points.has_value()) << points.error().message;
  return points ? *points : PointSet{};
}

// SampledLeg's samples but those on its sole (an unsampled end).
PointSet SampledLegWalls(std::size_t count) {
  const PointSet points = SampledLeg(count);
  PointSet walls;
  for (std::size_t i = 0; i < points.positions.size(); ++i) {
    if (points.normals[i].z() < -0.9) continue;
    walls.positions.push_back(points.positions[i]);
    walls.normals.push_back(points.normals[i]);
  }
  return walls;
}

// Builds `samples` (model units) fitted by `fit` at 100 cells, with `guards` (model units; none if
// empty) as HermiteOptions::guard_positions and BuildOptions::hull_cut = `hull_cut`, and counts the
// nodes for which `pred(model point, value <= 0, depth in voxels per model unit)` holds.
template <class Pred>
std::size_t CountLegNodes(const PointSet& samples, const PointSet& guards, const Transform& fit, Pred pred,
                          bool hull_cut = true) {
  const PointSet device = ApplyTransform(fit, samples);
  BuildOptions options;
  options.grid.cells = 100;
  options.hull_cut = hull_cut;
  if (!guards.positions.empty()) {
    const PointSet g = ApplyTransform(fit, guards);
    options.guard_positions = g.positions;
    options.guard_normals = g.normals;
  }
  auto built = BuildField(device.positions, device.normals, options);
  EXPECT_TRUE(built.has_value()) << built.error().message;
  if (!built) return 0;
  const GridSpec& g = built->field.grid();
  const double voxels_per_unit = fit.scale / g.voxel_m;
  std::size_t count = 0;
  for (int i = 0; i < g.dims[0]; ++i)
    for (int j = 0; j < g.dims[1]; ++j)
      for (int k = 0; k < g.dims[2]; ++k)
        if (pred(Eigen::Vector3d((g.Node(i, j, k) - fit.offset_m) / fit.scale), built->field.Value(i, j, k) <= 0.0f,
                 voxels_per_unit))
          ++count;
  return count;
}

// Issue 20: the samples dropped as outliers keep ending the part they stood on. A leg with a
// single sample on its sole (a sparse set's hoof: the bull with 1,000 samples
// has one), which the winding test drops. The walls' patches carry the leg on below the sole
// where the winding number of so few samples is unclear (0.3-0.5); a guard among a node's 8
// nearest samples, which the node lies in front of, decides it outside (LabelByWinding's far
// pass, GuardEndsPart). Inside nodes more than 3 voxels below the sole plane, under the leg's
// footprint: none with the sole sample kept, 250-300 without it. With it as a guard, the sole
// sample at the centre: 3 (a tenth at most; 91 and 60 when only a guard nearer than every sample
// decided), a quarter of the width off it: 95 and 69 (two fifths at most; 176 and 121 then).
// These three are measured without the cut at the samples' hull (BuildOptions::hull_cut), which
// now also ends the leg without the guard: those nodes lie more than 3 voxels outside the hull of
// the walls' samples, whose lowest ring is the sole's rim. With it, none is left either way.
TEST(LeakGuard, ALoneDroppedSoleSampleStillEndsTheLeg) {
  for (const double sx : {0.05, 0.25})
    for (const std::size_t count : {200u, 300u}) {
      const PointSet walls = SampledLegWalls(count);
      PointSet sole, all;
      sole.positions.emplace_back(sx, -sx, -2.0);
      sole.normals.emplace_back(0.0, 0.0, -1.0);
      all = walls;
      all.positions.push_back(sole.positions[0]);
      all.normals.push_back(sole.normals[0]);
      const Transform fit = FitTransform(all, 0.06);
      // Inside nodes more than 3 voxels below the sole, under the leg's footprint.
      const auto below = [](const Eigen::Vector3d& m, bool inside, double per_unit) {
        return inside && std::abs(m.x()) <= 0.5 && std::abs(m.y()) <= 0.5 && (-2.0 - m.z()) * per_unit > 3.0;
      };
      // 0: the sole sample kept; 1: dropped; 2: dropped, as a guard.
      const std::array<std::size_t, 3> far{CountLegNodes(all, PointSet{}, fit, below, false),
                                           CountLegNodes(walls, PointSet{}, fit, below, false),
                                           CountLegNodes(walls, sole, fit, below, false)};
      std::printf(
          "[ leg %zu pts, one sole sample at %g ] inside > 3 voxels below the sole: kept %zu, dropped %zu, guard %zu\n",
          count, sx, far[0], far[1], far[2]);
      EXPECT_EQ(far[0], 0u) << count << " " << sx;
      EXPECT_GT(far[1], 100u) << count << " " << sx;
      if (sx < 0.1)
        EXPECT_LE(10 * far[2], far[1]) << count;
      else
        EXPECT_LE(5 * far[2], 2 * far[1]) << count;
      EXPECT_EQ(CountLegNodes(walls, PointSet{}, fit, below), 0u) << count << " " << sx;  // the hull's cut
      EXPECT_EQ(CountLegNodes(walls, sole, fit, below), 0u) << count << " " << sx;
    }
}

// Issue 20: the cut at the samples' convex hull takes exactly the inside nodes more than its
// threshold beyond the hull, whatever the grid's size (its boxes are clipped at the grid's edge).
// A leg's walls without its sole, and the 8 corners of its box as samples too, so that the hull is
// the box: g, the distance beyond it, is the largest of the 6 face planes' signed distances. Below
// the open sole the estimate carries the leg on (hundreds of inside nodes past the threshold).
// Built with the cut and without, every node keeps its side except those with g > threshold, all
// of which turn outside, and the build counts them.
TEST(HullCut, TakesExactlyTheInsideNodesBeyondTheThreshold) {
  // Turned off the grid's axes, so that no node lies at the threshold's exact distance.
  const Eigen::Matrix3d turn = (Eigen::AngleAxisd(0.5, Eigen::Vector3d::UnitZ()) *
                                Eigen::AngleAxisd(0.3, Eigen::Vector3d(1.0, 1.0, 0.0).normalized()))
                                   .toRotationMatrix();
  PointSet walls = SampledLegWalls(200);
  for (Eigen::Vector3d& p : walls.positions) p = turn * p;
  for (Eigen::Vector3d& n : walls.normals) n = turn * n;
  for (int q = 0; q < 8; ++q) {
    const Eigen::Vector3d s((q & 4) != 0 ? 1.0 : -1.0, (q & 2) != 0 ? 1.0 : -1.0, (q & 1) != 0 ? 1.0 : -1.0);
    walls.positions.push_back(turn * Eigen::Vector3d(0.5 * s.x(), 0.5 * s.y(), 2.0 * s.z()));
    walls.normals.push_back(turn * s.normalized());
  }
  const Transform fit = FitTransform(walls, 0.06);
  const PointSet device = ApplyTransform(fit, walls);
  // g in metres: the box's faces in the leg's own frame.
  const auto g_box = [&](const Eigen::Vector3d& p) {
    const Eigen::Vector3d q = turn.transpose() * ((p - fit.offset_m) / fit.scale);
    return fit.scale * std::max((Eigen::Vector3d(-0.5, -0.5, -2.0) - q).maxCoeff(),
                                (q - Eigen::Vector3d(0.5, 0.5, 2.0)).maxCoeff());
  };
  for (const int cells : {100, 150, 230}) {
    BuildOptions options;
    options.grid.cells = cells;
    const auto [without, with] = BuildOffOn(device, options, &BuildOptions::hull_cut);
    ASSERT_TRUE(without.has_value() && with.has_value());
    const GridSpec& g = with->field.grid();
    const double beyond = with->hermite.hull_cut_beyond_m;
    ASSERT_GE(beyond, 3.0 * g.voxel_m) << cells;
    std::size_t beyond_inside = 0, kept = 0, near = 0;
    for (int i = 0; i < g.dims[0]; ++i)
      for (int j = 0; j < g.dims[1]; ++j)
        for (int k = 0; k < g.dims[2]; ++k) {
          const double out = g_box(g.Node(i, j, k));
          const bool inside_before = without->field.Value(i, j, k) <= 0.0f;
          const bool inside_after = with->field.Value(i, j, k) <= 0.0f;
          if (std::abs(out - beyond) < 1e-9 * g.voxel_m) {
            ++near;  // at the threshold: rounding decides
            continue;
          }
          if (out > beyond && inside_before) {
            ++beyond_inside;
            EXPECT_FALSE(inside_after) << cells << ": node " << i << " " << j << " " << k << " not cut";
          } else {
            EXPECT_EQ(inside_after, inside_before) << cells << ": node " << i << " " << j << " " << k;
            if (inside_after) ++kept;
          }
        }
    std::printf(
        "[ turned leg, walls and corners, %d cells ] %zu inside nodes beyond %.2f voxels, %zu cut; %zu inside kept\n",
        cells, beyond_inside, beyond / g.voxel_m, with->hermite.hull_cut_nodes, kept);
    EXPECT_EQ(near, 0u) << cells;
    EXPECT_GT(beyond_inside, 50u) << cells;
    EXPECT_EQ(with->hermite.hull_cut_nodes, beyond_inside) << cells;
  }
}

// A guard speaks only for its own side of the surfaces around it. Two legs side by side, 0.3
// apart; A's samples on its wall facing B (|z| < 0.6) are dropped and given as guards, B is
// sampled so sparsely (25-50 samples) that w inside it is unclear. Nodes more than 3 voxels deep
// inside B lie in front of those guards, but B's own samples facing them separate the two: the
// guards add no hole in B (they added 19, 122 and 7 holes when a guard nearer than every sample
// decided, and 2,942, 2,726 and 1,178 among the 8 nearest with no such test).
TEST(LeakGuard, GuardsDoNotCutAcrossAGap) {
  for (const std::size_t count : {100u, 150u, 200u}) {
    const PointSet a = SampledLeg(count);
    PointSet b = SampledLeg(count / 4);
    for (Eigen::Vector3d& q : b.positions) q.x() += 1.3;
    PointSet kept, guard;
    for (std::size_t i = 0; i < a.positions.size(); ++i) {
      PointSet& to = (a.normals[i].x() > 0.9 && std::abs(a.positions[i].z()) < 0.6) ? guard : kept;
      to.positions.push_back(a.positions[i]);
      to.normals.push_back(a.normals[i]);
    }
    ASSERT_GE(guard.positions.size(), 2u) << count;
    kept.positions.insert(kept.positions.end(), b.positions.begin(), b.positions.end());
    kept.normals.insert(kept.normals.end(), b.normals.begin(), b.normals.end());
    const Transform fit = FitTransform(kept, 0.06);
    // Holes in B: nodes more than 3 voxels inside it that the field puts outside.
    const auto hole = [](const Eigen::Vector3d& m, bool inside, double per_unit) {
      const double depth = std::min({0.5 - std::abs(m.x() - 1.3), 0.5 - std::abs(m.y()), 2.0 - std::abs(m.z())});
      return !inside && depth * per_unit > 3.0;
    };
    const std::array<std::size_t, 2> holes{CountLegNodes(kept, PointSet{}, fit, hole),
                                           CountLegNodes(kept, guard, fit, hole)};
    std::printf("[ two legs, %zu + %zu pts, %zu guards on A facing B ] holes in B: without guards %zu, with %zu\n",
                count, count / 4, guard.positions.size(), holes[0], holes[1]);
    EXPECT_LE(holes[1], holes[0] + 5) << count;
  }
}

// The samples dropped as outliers keep guarding the packing (HermiteOptions::guard_positions).
// The leg with 400 samples; its sole's samples are taken out, as a sparse set's lone sole samples
// are by the winding test. Built without them, the side walls' inner balls reach below the sole
// plane; with them as guards, no ball reaches more than the guard's tolerance (a quarter voxel)
// below it, and the guards are no balls themselves.
TEST(LeakGuard, DroppedSamplesStillBoundTheBalls) {
  const PointSet points = SampledLeg(400);
  PointSet kept, sole;
  for (std::size_t i = 0; i < points.positions.size(); ++i) {
    PointSet& to = points.normals[i].z() < -0.9 ? sole : kept;
    to.positions.push_back(points.positions[i]);
    to.normals.push_back(points.normals[i]);
  }
  ASSERT_GE(sole.positions.size(), 10u);  // ~1/18 of the area
  const Transform fit = FitTransform(points, 0.06);
  const PointSet device = ApplyTransform(fit, kept);
  const PointSet guards = ApplyTransform(fit, sole);
  const double sole_z = fit.scale * -2.0 + fit.offset_m.z();
  // Inner balls whose lowest point lies more than `depth` below the sole plane, within the
  // leg's footprint (beside it a ball may pass the discs).
  const auto below = [&](bool guarded, double depth) {
    BuildOptions options;
    options.grid.cells = 100;
    if (guarded) {
      options.guard_positions = guards.positions;
      options.guard_normals = guards.normals;
    }
    auto built = BuildField(device.positions, device.normals, options);
    EXPECT_TRUE(built.has_value()) << built.error().message;
    if (!built) return std::size_t{0};
    EXPECT_EQ(built->packing.radii.size(), device.positions.size());
    std::size_t count = 0;
    for (std::size_t i = 0; i < built->packing.radii.size(); ++i) {
      const Eigen::Vector3d c = (built->packing.centres[i] - fit.offset_m) / fit.scale;
      if (std::abs(c.x()) > 0.4 || std::abs(c.y()) > 0.4) continue;
      if (built->packing.centres[i].z() - built->packing.radii[i] < sole_z - depth * built->field.grid().voxel_m)
        ++count;
    }
    return count;
  };
  const std::size_t unguarded = below(false, 0.3), guarded = below(true, 0.3);
  std::printf("[ leg 400 pts, sole dropped ] inner balls > 0.3 voxel below the sole: sole as guards %zu, without %zu\n",
              guarded, unguarded);
  EXPECT_GT(unguarded, 5u);
  EXPECT_EQ(guarded, 0u);
}

}  // namespace
}  // namespace palpa::field

namespace palpa::field {
namespace {

// Appends sphere926's samples (`sphere926`, radius 10) scaled to a closed ball of radius 6 mm
// centred at (0, 0, z_m): it stands below an open scan so that the fitted grid holds the space
// between them.
void AddSmallBall(const PointSet& sphere926, double z_m, std::vector<Eigen::Vector3d>& p,
                  std::vector<Eigen::Vector3d>& n) {
  for (std::size_t i = 0; i < sphere926.positions.size(); ++i) {
    p.push_back(6e-4 * sphere926.positions[i] + Eigen::Vector3d(0, 0, z_m));
    n.push_back(sphere926.normals[i]);
  }
}

// Calls visit(node position, inside (value <= 0), on a grid face) for every node of `f`.
void ForEachNode(const SparseField& f, const std::function<void(const Eigen::Vector3d&, bool, bool)>& visit) {
  const GridSpec& g = f.grid();
  for (int i = 0; i < g.dims[0]; ++i)
    for (int j = 0; j < g.dims[1]; ++j)
      for (int k = 0; k < g.dims[2]; ++k)
        visit(g.Node(i, j, k), f.Value(i, j, k) <= 0,
              i == 0 || j == 0 || k == 0 || i == g.dims[0] - 1 || j == g.dims[1] - 1 || k == g.dims[2] - 1);
}

std::expected<BuildResult, Error> BuildAt96Cells(const std::vector<Eigen::Vector3d>& p,
                                                 const std::vector<Eigen::Vector3d>& n) {
  BuildOptions options;
  options.grid.cells = 96;
  return BuildField(p, n, options);
}

// The nodes of `f` more than 3 voxels from the sphere of radius r (metres) about the origin, and
// those among them on the wrong side; and the inside nodes on the grid's faces.
struct SphereSides {
  std::size_t checked = 0, holes = 0, phantom = 0, face_inside = 0;
};
SphereSides AgainstSphere(const SparseField& f, double r) {
  SphereSides s;
  const double voxel = f.grid().voxel_m;
  ForEachNode(f, [&](const Eigen::Vector3d& x, bool inside, bool face) {
    if (face && inside) ++s.face_inside;
    if (std::abs(x.norm() - r) / voxel <= 3.0) return;
    ++s.checked;
    s.holes += !inside && x.norm() < r ? 1u : 0u;
    s.phantom += inside && x.norm() > r ? 1u : 0u;
  });
  return s;
}

// Issue 20: a one-sided scan (the cap z > 0 of sphere926, radius 10 scaled to r = 30 mm; its
// lower half never scanned) is closed, not left a hollow shell open to the grid faces, and closed
// round. A small closed sphere (6 mm, centre 48 mm below) stands on the table, so the grid holds
// the missing half. There the winding number is unclear (0.3-0.5 down to ~0.4 r below the rim)
// and the rim's inner balls continue the sphere, as the scanned part curves; the winding number
// alone spans the rim with a flat disc (2,316 nodes of the slab checked here, down to 0.2 r below
// the equator, were outside before).
// Every node more than a band (6 voxels) from the sphere has the ball's sign above the rim and
// in that slab, and no node on a grid face is inside. (The former majority vote: 1,696 inside
// nodes on the faces at 64 cells.)
TEST(Winding, OneSidedScanIsClosedRoundBelowItsRim) {
  const auto pts = ReadPoints(DataFile("sphere926.pwn"));
  ASSERT_TRUE(pts) << pts.error().message;
  const double r = 0.03;
  std::vector<Eigen::Vector3d> p, n;
  double rim = r;  // the lowest sample of the cap
  for (std::size_t i = 0; i < pts->positions.size(); ++i) {
    if (pts->positions[i].z() > 0) {
      p.push_back(3e-3 * pts->positions[i]);
      n.push_back(pts->normals[i]);
      rim = std::min(rim, p.back().z());
    }
  }
  AddSmallBall(*pts, -1.6 * r, p, n);
  const auto built = BuildAt96Cells(p, n);
  ASSERT_TRUE(built) << built.error().message;
  const SparseField& f = built->field;
  const GridSpec& g = f.grid();
  std::size_t face_inside = 0, wrong = 0, checked_below = 0, checked = 0;
  ForEachNode(f, [&](const Eigen::Vector3d& x, bool inside, bool face) {
    if (face && inside) ++face_inside;
    if (std::abs(x.norm() - r) / g.voxel_m <= g.band_voxels) return;
    const bool below = x.z() < rim - g.voxel_m;
    if (below && (x.z() < -0.2 * r || x.norm() > r)) return;  // the slab below the rim, in the ball
    ++checked;
    checked_below += below ? 1u : 0u;
    wrong += inside != (x.norm() < r) ? 1u : 0u;
  });
  EXPECT_EQ(face_inside, 0u);
  EXPECT_GT(checked_below, 5000u);
  EXPECT_EQ(wrong, 0u) << "of " << checked;
}

// Issue 20: a scan leaves a few samples in the hole it does not cover (a sphere scanned above
// z = c r, and 1 in 64 of its samples below (c - 0.3) r kept, each several spacings from any
// other). Past the rim w falls below kBallClosingWinding, where only a rim's balls close; the
// strays lie nearer many of those nodes than the rim does, and must not hide it (CGAL's
// radar.xyz, a sphere with a sparse lower cap). Hole nodes more than 3 voxels inside the sphere,
// c = 0 / 0.3: 254 / 6,044 with the nearest sample alone deciding whether a node lies beyond a
// rim, 0 / 333 passing over lone samples (kLoneSampleSpacings; each stray here 3.8-9.2 x the
// median spacing).
TEST(Winding, StraySamplesInAnOpenSideDoNotHideItsRim) {
  const auto pts = ReadPoints(DataFile("sphere926.pwn"));
  ASSERT_TRUE(pts) << pts.error().message;
  const double r = 0.03;
  for (const double cut : {0.0, 0.3}) {
    std::vector<Eigen::Vector3d> p, n;
    std::size_t strays = 0, below = 0;
    for (std::size_t i = 0; i < pts->positions.size(); ++i) {
      const Eigen::Vector3d& x = pts->positions[i];
      const bool scanned = x.z() > cut * x.norm();
      const bool stray = !scanned && x.z() < (cut - 0.3) * x.norm() && below++ % 64 == 0;
      if (!scanned && !stray) continue;
      strays += stray ? 1u : 0u;
      p.push_back(3e-3 * x);
      n.push_back(pts->normals[i]);
    }
    EXPECT_GE(strays, 6u);
    const auto built = BuildAt96Cells(p, n);
    ASSERT_TRUE(built) << built.error().message;
    const SphereSides s = AgainstSphere(built->field, r);
    EXPECT_EQ(s.face_inside, 0u) << "cut " << cut;
    EXPECT_GT(s.checked, 600000u);
    EXPECT_LE(s.holes + s.phantom, cut == 0.0 ? 0u : 400u) << "cut " << cut << ", of " << s.checked;
  }
}

// Issue 20: a scan whose open side is crossed by strips of samples (a sphere of 20,000 samples
// scanned above z = 0.7 r, and three meridian strips 20 degrees wide below that, down to the
// bottom: what a scanner's passes leave on a part it never covered; CGAL's radar.xyz). Inside the
// sphere below the rim w falls under kBallClosingWinding, and the nearest samples are the strips':
// neither rims nor lone. A node behind every one of its nearest samples sees the scanned surface
// from inside it, and the balls close it as they do behind a rim; with a rim alone deciding, 1,852
// nodes more than 3 voxels inside the sphere were holes.
TEST(Winding, StripsAcrossAnOpenSideCloseBehindThem) {
  const double r = 0.03;
  constexpr std::size_t kSamples = 20000;
  std::vector<Eigen::Vector3d> p, n;
  std::size_t in_strips = 0;
  for (std::size_t i = 0; i < kSamples; ++i) {
    const Eigen::Vector3d u = testing::FibonacciPoint(i, kSamples);
    const double azimuth = std::atan2(u.y(), u.x()) * 180.0 / std::numbers::pi;
    const bool strip =
        std::abs(azimuth + 170.0) < 10.0 || std::abs(azimuth + 50.0) < 10.0 || std::abs(azimuth - 70.0) < 10.0;
    if (u.z() <= 0.7 && !strip) continue;
    in_strips += u.z() <= 0.7 ? 1u : 0u;
    p.push_back(r * u);
    n.push_back(u);
  }
  EXPECT_GT(in_strips, 800u);
  const auto built = BuildAt96Cells(p, n);
  ASSERT_TRUE(built) << built.error().message;
  const SphereSides s = AgainstSphere(built->field, r);
  EXPECT_EQ(s.face_inside, 0u);
  EXPECT_GT(s.checked, 600000u);
  EXPECT_EQ(s.holes, 0u) << "of " << s.checked;
  EXPECT_EQ(s.phantom, 0u) << "of " << s.checked;
}

// Issue 20: a cube (40 mm) seen by a virtual range scanner from 6 views above it (mesh::RangeScan,
// 5,000 rays' hits), its bottom never scanned. The winding number's areas come from each sample's
// 16th neighbour distance, which on the rim reaches across the scanned side only: the rim samples'
// areas are about twice their share, and w reads over 1/2 on the missing face's plane. Scaled by
// the share of their disc their neighbours surround (RimAreas), the closure lies within a few
// voxels of the missing face. Every node more than 3 voxels from the cube has the cube's sign
// but for a few below the missing face, none of them over 5 voxels below it. With the plain
// areas the three draws left 72,360 phantom nodes, 1,409-6,162 a draw over 5 voxels below (CGAL's
// cube-meshed, unseen, seed 48: 21,960 far-wrong, 6 voxels deep); scaled, 1,452.
TEST(Winding, RangeScanRimSamplesAreasDoNotLiftTheOpenSidesClosure) {
  constexpr double a = 0.02;
  mesh::TriangleMesh cube = UnitCube();
  for (Eigen::Vector3d& v : cube.vertices) v *= 2.0 * a;  // [-a, a]^3, exactly
  std::size_t phantom_total = 0;
  for (const std::uint64_t draw : {1u, 2u, 3u}) {
    const auto scan = mesh::RangeScan(cube, 5000, 6, 0.0, draw);
    ASSERT_TRUE(scan) << scan.error().message;
    double lowest = a;
    for (const Eigen::Vector3d& x : scan->positions) lowest = std::min(lowest, x.z());
    EXPECT_GT(lowest, -a + 1e-9) << "the bottom is never scanned";
    BuildOptions options;
    options.grid.cells = 150;
    const auto built = BuildField(scan->positions, scan->normals, options);
    ASSERT_TRUE(built) << built.error().message;
    const GridSpec& g = built->field.grid();
    ASSERT_LT(g.origin_m.z(), -a - 5.5 * g.voxel_m);  // the grid holds the space below the cube
    std::size_t wrong = 0, phantom_below = 0, deep = 0;
    ForEachNode(built->field, [&](const Eigen::Vector3d& x, bool inside, bool) {
      const double box = x.cwiseAbs().maxCoeff();
      if (std::abs(box - a) <= 3.0 * g.voxel_m || inside == (box < a)) return;
      ++wrong;
      if (!inside || x.z() >= -a) return;
      ++phantom_below;
      deep += x.z() < -a - 5.0 * g.voxel_m ? 1u : 0u;
    });
    EXPECT_EQ(wrong, phantom_below) << "draw " << draw;
    EXPECT_EQ(deep, 0u) << "draw " << draw;
    phantom_total += phantom_below;
  }
  EXPECT_LT(phantom_total, 3000u);
}

// Issue 20: a sphere scanned only above z = -0.17 r (nothing below it in the grid fitted to the
// samples, which ends ~0.4 r above the sphere's bottom). The closure leaves the grid's bottom face,
// so BuildField grows the grid, voxel kept, to hold it; past the rim, where w falls to ~0.2, the
// rim's inner balls close the sphere round. Every node more than a band from the sphere has the
// ball's sign, and no face node is inside. Without the growth the grid cuts the sphere flat: its
// bottom face layer, inside the true sphere, is outside. The grown grid is built with the search's
// packing and side rules (HermiteStats::side_rules), into the same field as made afresh.
TEST(Winding, OpenScanGrowsTheGridToHoldItsRoundClosure) {
  const auto pts = ReadPoints(DataFile("sphere926.pwn"));
  ASSERT_TRUE(pts) << pts.error().message;
  const double r = 0.03;
  std::vector<Eigen::Vector3d> p, n;
  for (std::size_t i = 0; i < pts->positions.size(); ++i)
    if (pts->positions[i].z() > -0.17 * pts->positions[i].norm()) {
      p.push_back(3e-3 * pts->positions[i]);
      n.push_back(pts->normals[i]);
    }
  const auto wrong_and_faces = [&](const BuildResult& built) {
    const GridSpec& g = built.field.grid();
    std::size_t face_inside = 0, wrong = 0;
    ForEachNode(built.field, [&](const Eigen::Vector3d& x, bool inside, bool face) {
      if (face && inside) ++face_inside;
      if (std::abs(x.norm() - r) / g.voxel_m <= g.band_voxels) return;
      wrong += inside != (x.norm() < r) ? 1u : 0u;
    });
    return std::pair{wrong, face_inside};
  };
  BuildOptions options;
  options.grid.cells = 96;
  const auto built = BuildField(p, n, options);
  ASSERT_TRUE(built) << built.error().message;
  const GridSpec& g = built->field.grid();
  EXPECT_GT(built->grid_grown_from[2], 0);
  EXPECT_TRUE(built->hermite.side_rules_reused);  // from the search's unbuilt call
  EXPECT_GT(g.dims[2], built->grid_grown_from[2]);
  EXPECT_LT(g.origin_m.z(), -r);  // the whole sphere is in the grid
  const auto [wrong, face_inside] = wrong_and_faces(*built);
  EXPECT_EQ(face_inside, 0u);
  EXPECT_EQ(wrong, 0u);
  // Every node more than a band and 2 voxels inside the sphere, the closure's included, is a whole
  // band deep (the values clamp there): the closure is solid, not a shell.
  std::size_t deep = 0, deep_closure = 0, shallow = 0;
  for (int i = 0; i < g.dims[0]; ++i)
    for (int j = 0; j < g.dims[1]; ++j)
      for (int k = 0; k < g.dims[2]; ++k) {
        const Eigen::Vector3d x = g.Node(i, j, k);
        if ((x.norm() - r) / g.voxel_m > -(g.band_voxels + 2.0)) continue;
        ++deep;
        deep_closure += x.z() < -0.17 * r ? 1u : 0u;
        shallow += built->field.Value(i, j, k) > -static_cast<float>(g.band_voxels) ? 1u : 0u;
      }
  EXPECT_GT(deep_closure, 10000u);
  EXPECT_EQ(shallow, 0u) << "of " << deep;

  // The reported area counts the closing surface in the bricks no sample reaches (here sparse
  // samples reach most of the cap): a lower bound of the cap's 2 pi r (0.83 r).
  const double cap = 2.0 * std::numbers::pi * r * 0.83 * r;
  EXPECT_GT(built->hermite.closed_area_m2, 0.1 * cap);
  EXPECT_LT(built->hermite.closed_area_m2, cap);

  options.grow_for_closure = false;
  const auto cut = BuildField(p, n, options);
  ASSERT_TRUE(cut) << cut.error().message;
  EXPECT_EQ(cut->grid_grown_from[0], 0);
  const auto [cut_wrong, cut_faces] = wrong_and_faces(*cut);
  EXPECT_EQ(cut_faces, 0u);
  EXPECT_GT(cut_wrong, 1000u);

  // The closure is found before any node is evaluated: on the fitted grid HermiteField returns at
  // once, unbuilt, and the grown build is one evaluation on the final grid, node for node.
  auto fitted = MakeGrid(p, options.grid);
  ASSERT_TRUE(fitted) << fitted.error().message;
  EXPECT_EQ(fitted->dims, built->grid_grown_from);
  Eigen::Vector3d lo = p.front(), hi = lo;
  for (const Eigen::Vector3d& q : p) {
    lo = lo.cwiseMin(q);
    hi = hi.cwiseMax(q);
  }
  const double r_max = (hi - lo).maxCoeff();
  std::vector<Eigen::Vector3d> unit(n.size());
  for (std::size_t i = 0; i < n.size(); ++i) unit[i] = n[i].normalized();
  HermiteOptions searched;
  searched.closure_reach_m = 0.5 * r_max;
  HermiteStats first;
  const SparseField unbuilt = HermiteField(*fitted, p, unit, r_max, searched, &first);
  ASSERT_TRUE(first.closure_beyond_grid.has_value());
  EXPECT_LT(first.closure_beyond_grid->min().z(), fitted->origin_m.z());
  EXPECT_EQ(first.bricks_evaluated, 0u);
  EXPECT_EQ(unbuilt.AllocatedBricks(), 0u);
  ASSERT_NE(first.side_rules, nullptr);  // for the next call, which builds
  HermiteStats once;
  const SparseField direct = HermiteField(g, p, unit, r_max, {}, &once);
  EXPECT_EQ(once.bricks_evaluated, built->hermite.bricks_evaluated);
  EXPECT_EQ(once.side_rules, nullptr);
  // The unbuilt call's packing and side rules, reused on the grown grid: the same field as made
  // afresh (they do not depend on the grid).
  HermiteOptions again;
  again.packed = &first;
  HermiteStats second;
  const SparseField reused = HermiteField(g, p, unit, r_max, again, &second);
  EXPECT_TRUE(second.side_rules_reused);
  EXPECT_FALSE(once.side_rules_reused);
  std::size_t differ = 0, differ_reused = 0;
  for (int i = 0; i < g.dims[0]; ++i)
    for (int j = 0; j < g.dims[1]; ++j)
      for (int k = 0; k < g.dims[2]; ++k) {
        differ += direct.Value(i, j, k) != built->field.Value(i, j, k) ? 1u : 0u;
        differ_reused += reused.Value(i, j, k) != direct.Value(i, j, k) ? 1u : 0u;
      }
  EXPECT_EQ(differ, 0u);
  EXPECT_EQ(differ_reused, 0u);

  // The rules are matched by the samples' values, not by the vectors' addresses: equal copies
  // reuse them; the same vectors with one sample moved (or a new set at a freed vector's address)
  // do not, and build what the same call without the rules builds (the packing, which the caller
  // vouches for, reused in both).
  const std::vector<Eigen::Vector3d> p_copy = p, unit_copy = unit;
  HermiteStats copied;
  const SparseField from_copies = HermiteField(g, p_copy, unit_copy, r_max, again, &copied);
  EXPECT_TRUE(copied.side_rules_reused);
  p.front().z() += 2.0 * g.voxel_m;
  HermiteStats packing_only = first;
  packing_only.side_rules = nullptr;
  HermiteOptions without_rules;
  without_rules.packed = &packing_only;
  HermiteStats moved, moved_fresh;
  const SparseField from_moved = HermiteField(g, p, unit, r_max, again, &moved);
  const SparseField moved_direct = HermiteField(g, p, unit, r_max, without_rules, &moved_fresh);
  EXPECT_FALSE(moved.side_rules_reused);
  std::size_t differ_copies = 0, differ_moved = 0;
  for (int i = 0; i < g.dims[0]; ++i)
    for (int j = 0; j < g.dims[1]; ++j)
      for (int k = 0; k < g.dims[2]; ++k) {
        differ_copies += from_copies.Value(i, j, k) != direct.Value(i, j, k) ? 1u : 0u;
        differ_moved += from_moved.Value(i, j, k) != moved_direct.Value(i, j, k) ? 1u : 0u;
      }
  EXPECT_EQ(differ_copies, 0u);
  EXPECT_EQ(differ_moved, 0u);
}

// Issue 20: a post cut flat and scanned without its bottom (a wrist, a hub, a part's foot: a
// cylinder of radius a = 15 mm and height 4a whose end disc at z = -2a was never scanned, 4,000
// area-uniform samples with exact normals; a small closed ball 2.5 a below the end makes the grid
// hold the space there). Each side sample's inner ball reaches across the post (radius ~a), and
// continued past the rim it closed the post with a dome; but the side is straight along z, so
// the ball is not the scanned curvature there: 30 and 60 degrees up the ball from a rim sample
// the side lies 0.13 a and 0.5 a off it (ClosingRule::Continues). The closure now spans the rim
// (the winding number's level 1/2, bulging less than a / 2). Inside nodes more than a / 2 below
// the end: 0 (with every ball closing, 894; measured through a temporary switch). The post above
// the end keeps its sign, and no inside node is on a grid face.
TEST(Winding, FlatCutPostIsNotClosedWithADome) {
  constexpr double a = 0.015;
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::vector<Eigen::Vector3d> p, n;
  const double side = 2.0 * std::numbers::pi * a * 4.0 * a, top = std::numbers::pi * a * a;
  for (int m = 0; m < 4000; ++m) {
    const double around = 2.0 * std::numbers::pi * unit(rng);
    if (unit(rng) * (side + top) < side) {
      const Eigen::Vector3d radial(std::cos(around), std::sin(around), 0.0);
      p.push_back(a * radial + Eigen::Vector3d(0, 0, (4.0 * unit(rng) - 2.0) * a));
      n.push_back(radial);
    } else {
      const double rho = a * std::sqrt(unit(rng));
      p.push_back(Eigen::Vector3d(rho * std::cos(around), rho * std::sin(around), 2.0 * a));
      n.push_back(Eigen::Vector3d::UnitZ());
    }
  }
  // A small closed ball (sphere926, 6 mm) stands 2.5 a below the end, so the grid holds the
  // space below it.
  const auto ball = ReadPoints(DataFile("sphere926.pwn"));
  ASSERT_TRUE(ball) << ball.error().message;
  AddSmallBall(*ball, -4.5 * a, p, n);
  const auto built = BuildAt96Cells(p, n);
  ASSERT_TRUE(built) << built.error().message;
  const SparseField& f = built->field;
  const GridSpec& g = f.grid();
  std::size_t shallow = 0, dome = 0, face_inside = 0, wrong_above = 0, checked_above = 0;
  ForEachNode(f, [&](const Eigen::Vector3d& x, bool inside, bool face) {
    if (face && inside) ++face_inside;
    if (x.z() < -2.0 * a - 3.0 * g.voxel_m && x.z() > -3.5 * a) {
      shallow += inside && x.z() > -2.5 * a ? 1u : 0u;
      dome += inside && x.z() <= -2.5 * a ? 1u : 0u;
      return;
    }
    // Above the end plane, more than a band from the side and the top.
    const double to_side = std::abs(std::hypot(x.x(), x.y()) - a), to_top = std::abs(x.z() - 2.0 * a);
    if (x.z() < -2.0 * a + 3.0 * g.voxel_m || std::min(to_side, to_top) < g.band_voxels * g.voxel_m) return;
    ++checked_above;
    const bool truth = std::hypot(x.x(), x.y()) < a && x.z() < 2.0 * a;
    wrong_above += inside != truth ? 1u : 0u;
  });
  std::printf(
      "[ post cut flat, end unscanned ] inside below the end: 3 voxels to a / 2 %zu, deeper %zu; wrong above it: %zu "
      "of %zu\n",
      shallow, dome, wrong_above, checked_above);
  EXPECT_EQ(dome, 0u);
  EXPECT_EQ(face_inside, 0u);
  EXPECT_GT(checked_above, 20000u);
  EXPECT_EQ(wrong_above, 0u);
}

// Issue 20: a part scanned from above (the joint, 5,000 samples, those whose normal points more
// than 100 degrees from +z dropped, as bench/field/robustness.py's open scan). Its walls' inner
// balls span the part, and on such samples a wall's ball passed ClosingRule::Continues on the
// wall itself 30 degrees up (a sample within the tolerance, its normal 30 degrees off the ball's
// radius) and on another face 60 degrees up, so it closed domes under the walls' unscanned edges.
// The surface found on the ball must now have turned past halfway towards the ball's radius.
// Phantom solid more than 3 voxels out at 150 cells: 101,005 before, 58,726 after (58,742 with the
// thirty-fifth session's medial balls; without their antipode test the joint's outer round's
// balls fill its bore: 72,084 on the benchmark's open scan). Beyond the samples' convex hull, where
// w is unclear and no ball holds a node, w decides (thirty-seventh session): 50,673 -> 29,160.
TEST(Winding, OpenScanWallsBallsCloseOnlyASurfaceThatTurnsWithThem) {
  const mesh::EvalResult r = ScoreOpenScan("joint.off");
  EXPECT_LE(r.phantom_solid.nodes, 40000u) << "deepest " << r.phantom_solid.deepest_voxels << " voxels";
}

// Issue 20: a part's unscanned side whose nearest samples belong to other parts is closed by its
// own balls. The spool scanned from above: the lower half of its hub, between the flanges, lies
// nearer the flanges' inner faces than the hub's samples, and the flanges' balls stop at the
// flanges; the balls of the hub's sides span the hub (they touch its far side, scanned too), hold
// the lower half and continue the hub round. 14,127 hole nodes before, 7,837 with the medial balls;
// the phantom solid stays (2,421 -> 2,434). The far pass asks the balls also where the estimate
// holds a node outside and w is unclear but at least 1/2 (thirty-sixth session): 6,590.
TEST(Winding, OpenScanHubIsClosedByItsOwnBallsBetweenFlanges) {
  const mesh::EvalResult r = ScoreOpenScan("spool.off");
  EXPECT_LE(r.holes.nodes, 7500u) << "deepest " << r.holes.deepest_voxels << " voxels";
  EXPECT_LE(r.phantom_solid.nodes, 3000u) << "deepest " << r.phantom_solid.deepest_voxels << " voxels";
}

// Issue 20: beyond an open scan's edge the local estimate carries the scanned patches on (a
// part's unscanned underside, a wrist cut flat), where w is unclear and no ball holds a node. The
// bundled fandisk scanned from above: its side faces' patches went on past their lower edges.
// A node there, w unclear, whose nearest sample is a rim sample 1.5 of its spacings away or more
// is now decided by w (thirty-sixth session): phantom solid 32,047 nodes (23.4 voxels deep) before,
// 11,521 (13.9) after; the holes stay (395).
TEST(Winding, OpenScanPatchesAreNotCarriedPastTheScansEdge) {
  const mesh::EvalResult r = ScoreOpenScan("fandisk.off");
  EXPECT_LE(r.phantom_solid.nodes, 15000u) << "deepest " << r.phantom_solid.deepest_voxels << " voxels";
  EXPECT_LE(r.holes.nodes, 500u) << "deepest " << r.holes.deepest_voxels << " voxels";
}

// Issue 20: a real scan's open side is closed inside the grid. The bundled oni (a head scanned
// down to its open neck, 1,435 samples, 300 cells): the chin's inner ball, which does not continue
// the scanned surface, held a shell under the neck 7-9 mm from every sample, down to the grid's
// lower face (227, 404 and 575 inside nodes on the three layers above it), w unclear (0.30-0.36),
// its nearest samples no rim samples. Beyond the samples' convex hull such a node is now decided
// by w (thirty-seventh session): the neck closes round about 3 mm below its last samples. And the
// build no longer reports it cut at the grid faces: the face nodes the far pass sets outside
// beyond the samples' hull were the estimate's (1,302 counted before).
TEST(Winding, RealOpenScanIsClosedInsideTheGrid) {
  const auto pts = ReadPoints(DataFile("oni.pwn"));
  ASSERT_TRUE(pts) << pts.error().message;
  const Case c = Build(*pts, 300, FieldMethod::kHermite);
  const SparseField& f = c.built.field;
  const GridSpec& g = f.grid();
  std::size_t near_face = 0, inside = 0;  // inside nodes within 3 layers of a face; all
  for (int i = 0; i < g.dims[0]; ++i)
    for (int j = 0; j < g.dims[1]; ++j)
      for (int k = 0; k < g.dims[2]; ++k) {
        if (f.Value(i, j, k) > 0.0f) continue;
        ++inside;
        const int layer = std::min({i, j, k, g.dims[0] - 1 - i, g.dims[1] - 1 - j, g.dims[2] - 1 - k});
        near_face += layer <= 3 ? 1u : 0u;
      }
  EXPECT_EQ(near_face, 0u) << "grid " << g.dims[0] << " x " << g.dims[1] << " x " << g.dims[2];
  EXPECT_GT(inside, 3000000u);  // the head is there (4.2 million nodes)
  EXPECT_EQ(c.built.hermite.face_nodes_closed, 0u);
}

// The 6-connected components of a field's inside nodes (value <= 0) and of its outside nodes.
struct Components {
  std::size_t inside = 0, outside = 0;
  std::size_t pocket_nodes = 0;  // outside nodes not in the largest outside component
};
Components CountComponents(const SparseField& f) {
  const GridSpec& g = f.grid();
  std::vector<std::uint8_t> inside(g.NodeCount()), seen(g.NodeCount(), 0);
  for (int i = 0; i < g.dims[0]; ++i)
    for (int j = 0; j < g.dims[1]; ++j)
      for (int k = 0; k < g.dims[2]; ++k) inside[g.Index(i, j, k)] = f.Value(i, j, k) <= 0.0f ? 1 : 0;
  Components out;
  std::size_t outside_nodes = 0, largest_outside = 0;
  std::vector<std::array<int, 3>> stack;
  for (int i = 0; i < g.dims[0]; ++i)
    for (int j = 0; j < g.dims[1]; ++j)
      for (int k = 0; k < g.dims[2]; ++k) {
        if (seen[g.Index(i, j, k)] != 0) continue;
        const std::uint8_t side = inside[g.Index(i, j, k)];
        std::size_t size = 0;
        seen[g.Index(i, j, k)] = 1;
        stack.push_back({i, j, k});
        while (!stack.empty()) {
          const auto [a, b, c] = stack.back();
          stack.pop_back();
          ++size;
          const std::array<std::array<int, 3>, 6> next{
              {{a - 1, b, c}, {a + 1, b, c}, {a, b - 1, c}, {a, b + 1, c}, {a, b, c - 1}, {a, b, c + 1}}};
          for (const auto& [x, y, z] : next) {
            if (x < 0 || y < 0 || z < 0 || x >= g.dims[0] || y >= g.dims[1] || z >= g.dims[2]) continue;
            if (seen[g.Index(x, y, z)] != 0 || inside[g.Index(x, y, z)] != side) continue;
            seen[g.Index(x, y, z)] = 1;
            stack.push_back({x, y, z});
          }
        }
        if (side != 0) {
          ++out.inside;
        } else {
          ++out.outside;
          outside_nodes += size;
          largest_outside = std::max(largest_outside, size);
        }
      }
  out.pocket_nodes = outside_nodes - largest_outside;
  return out;
}

// Issue 20: beyond every sample's trust distance the far pass decides an open side's closure node
// by node, by rules (w, the closing balls, rims, the samples' hull) that change from node to node
// where they meet, and left the closure ragged: spikes, notches, specks of solid floating in the
// air and pockets of outside enclosed in the solid (CGAL's eight scanned from above: 12 pockets
// under its bottom, none of them in the object). Five rounds of a 3 x 3 x 3 majority vote over those
// nodes (SmoothClosure) leave a knot, one solid round one connected outside, as one: the
// bundled knot1 scanned from above, its exact truth 1 inside and 1 outside component. And the far
// wrong-sign nodes do not grow (111 open and range rows of 37 meshes: 88 fewer, none more by 1 %;
// docs/field-methods.md § Open sides: the closure smoothed).
TEST(Winding, OpenScanClosureIsSmoothedBeyondTheSamples) {
  auto m = mesh::ReadClosedMesh(DataFile("knot1.off"));
  ASSERT_TRUE(m.has_value()) << m.error().message;
  const PointSet model = OpenScan(SampledMesh("knot1.off", 5000));
  const Transform fit = FitTransform(model, 0.06);
  const PointSet device = ApplyTransform(fit, model);
  BuildOptions options;
  options.grid.cells = 150;
  options.sampleless_components = false;  // the vote alone (they would remove the rough pieces too)
  auto [without, with] = BuildOffOn(device, options, &BuildOptions::smooth_closure);
  ASSERT_TRUE(without.has_value() && with.has_value());
  const Components before = CountComponents(without->field), after = CountComponents(with->field);
  const mesh::EvalResult r_before = Score(Case{std::move(*without), fit}, mesh::Truth::Mesh(*m), "knot1 open, rough");
  const mesh::EvalResult r_after = Score(Case{*with, fit}, mesh::Truth::Mesh(*m), "knot1 open, smoothed");
  std::printf(
      "[ knot1 5000 pts, open scan, 150 cells ] components inside / outside (pocket nodes): %zu / %zu (%zu) rough, "
      "%zu / %zu (%zu) smoothed; %zu side changes; far wrong %zu -> %zu\n",
      before.inside, before.outside, before.pocket_nodes, after.inside, after.outside, after.pocket_nodes,
      with->hermite.closure_side_changes, r_before.far_wrong(), r_after.far_wrong());
  EXPECT_GT(before.inside + before.outside, 2u);  // the rough closure the vote is for
  EXPECT_EQ(after.inside, 1u);
  EXPECT_EQ(after.outside, 1u);
  EXPECT_LE(r_after.far_wrong(), r_before.far_wrong());
  EXPECT_LE(r_after.wrong_sign_in_band_percent, r_before.wrong_sign_in_band_percent);
  // The rough closure's pieces that no sample bounds are also filled and cut without the vote
  // (FillSamplelessPockets, CutSamplelessIslands): one inside, one outside.
  options.smooth_closure = false;
  options.sampleless_components = true;
  auto unvoted = BuildField(device.positions, device.normals, options);
  ASSERT_TRUE(unvoted.has_value());
  const Components pieces = CountComponents(unvoted->field);
  EXPECT_EQ(pieces.inside, 1u);
  EXPECT_EQ(pieces.outside, 1u);
  EXPECT_GT(unvoted->hermite.pockets_filled + unvoted->hermite.islands_cut, 0u);
}

// Issue 20: the bundled oni's open neck (1,435 samples, 300 cells) kept outside pockets enclosed in
// its closure (3 of them, 13-30 voxels from every sample: 1,494 nodes as `palpa build` makes it,
// 1,508 here without its outlier drop) that
// HIL's recorded hands push through: every sample within a spacing of them has them behind, so
// FillSamplelessPockets fills them, and the field has one outside component. (A sampled cavity
// stays: FillSamplelessPockets' own tests.)
TEST(Winding, RealScansHollowsInItsClosureAreFilled) {
  const auto pts = ReadPoints(DataFile("oni.pwn"));
  ASSERT_TRUE(pts) << pts.error().message;
  const PointSet device = ApplyTransform(FitTransform(*pts, 0.06), *pts);
  BuildOptions options;
  options.grid.cells = 300;
  const auto [kept, filled] = BuildOffOn(device, options, &BuildOptions::sampleless_components);
  ASSERT_TRUE(kept.has_value() && filled.has_value());
  const Components before = CountComponents(kept->field), after = CountComponents(filled->field);
  std::printf("[ oni, 300 cells ] outside components %zu (pocket nodes %zu) -> %zu (%zu); filled %zu pockets\n",
              before.outside, before.pocket_nodes, after.outside, after.pocket_nodes, filled->hermite.pockets_filled);
  EXPECT_GT(before.pocket_nodes, 1000u);  // the hollows are there to fill
  EXPECT_EQ(after.outside, 1u);
  EXPECT_EQ(after.pocket_nodes, 0u);
  EXPECT_EQ(filled->hermite.pocket_nodes_filled, before.pocket_nodes);
  EXPECT_EQ(after.inside, before.inside);  // no island of the head cut
}

// Issue 20: an upright torus (ring 30 mm, tube 10 mm) scanned from above keeps 65 % of 5,000
// samples; its tube's underside is closed beyond them. At its lowest tube's core the nearest
// samples are the scan's rim samples on the tube's two sides, the core nearly straight behind each,
// and their balls touch the surface on the scanned side only: no ball held the core, and the carry
// rule left a pocket of 487 nodes up to 15.6 voxels deep. A medial ball (its antipode on the
// surface) holds a point straight behind its sample within the samples' hull. Against the torus's
// exact distance: one inside and one outside piece, no node of the wrong sign more than 3 voxels
// from the surface, and the band as right as before (0.19 % wrong sign; 0.20 % with the pocket).
TEST(Winding, OpenTubesCoreIsHeldByMedialBalls) {
  constexpr double kRing = 0.03, kTube = 0.01;
  const PointSet torus = testing::TorusSamples(kRing, kTube, 5000, 3);
  std::vector<Eigen::Vector3d> p, n;
  for (std::size_t i = 0; i < torus.positions.size(); ++i) {
    // Stood upright (y and z swapped): the ring in the x-z plane, its axis along y.
    const auto upright = [](const Eigen::Vector3d& x) { return Eigen::Vector3d(x.x(), x.z(), x.y()); };
    const Eigen::Vector3d normal = upright(torus.normals[i]);
    if (normal.z() <= -std::cos(80.0 * std::numbers::pi / 180.0)) continue;  // OpenScan's rule
    p.push_back(upright(torus.positions[i]));
    n.push_back(normal);
  }
  BuildOptions options;
  options.grid.cells = 150;
  auto built = BuildField(p, n, options);
  ASSERT_TRUE(built.has_value()) << built.error().message;
  const SparseField& f = built->field;
  const GridSpec& g = f.grid();
  std::size_t far_wrong = 0, band = 0, band_wrong = 0;
  for (int i = 0; i < g.dims[0]; ++i)
    for (int j = 0; j < g.dims[1]; ++j)
      for (int k = 0; k < g.dims[2]; ++k) {
        const Eigen::Vector3d x = g.Node(i, j, k);
        const double truth = (std::hypot(std::hypot(x.x(), x.z()) - kRing, x.y()) - kTube) / g.voxel_m;
        const bool wrong = (truth <= 0.0) != (f.Value(i, j, k) <= 0.0f);
        if (std::abs(truth) > 3.0 && wrong) ++far_wrong;
        if (std::abs(truth) <= 2.0) {
          ++band;
          band_wrong += wrong ? 1u : 0u;
        }
      }
  const Components parts = CountComponents(f);
  const double band_wrong_percent = 100.0 * static_cast<double>(band_wrong) / static_cast<double>(band);
  std::printf(
      "[ upright torus, %zu of 5000 samples from above, 150 cells ] inside / outside components %zu / %zu "
      "(%zu pocket nodes), far wrong %zu, wrong sign in the band %.3f %%\n",
      p.size(), parts.inside, parts.outside, parts.pocket_nodes, far_wrong, band_wrong_percent);
  EXPECT_EQ(parts.inside, 1u);
  EXPECT_EQ(parts.outside, 1u);
  EXPECT_EQ(far_wrong, 0u);
  EXPECT_LT(band_wrong_percent, 0.5);
}

// The closing rule's ball search ends at the first ball deep enough for its caller (below the
// band, or below 0 where only the side is read; HermiteOptions::balls_stop_early): a node deep in
// a sphere's balls no longer visits all of them. It must change no node: the same payload, value
// for value, with every ball visited. Two open sets where the balls decide much of the closure:
// sphere926 seen above z = −r/3 (CGAL's radar.xyz, two thirds of a sphere) and an upright torus
// scanned from above (its tube's core held by medial balls). Here 62,591 searches stop early; a
// stop at 2 voxels instead of the band's 6 changes 5,384 nodes.
TEST(Winding, BallsEarlyStopChangesNoNode) {
  const auto pts = ReadPoints(DataFile("sphere926.pwn"));
  ASSERT_TRUE(pts) << pts.error().message;
  PointSet cap;
  for (std::size_t i = 0; i < pts->positions.size(); ++i)
    if (pts->positions[i].z() > -10.0 / 3.0) {
      cap.positions.push_back(3e-3 * pts->positions[i]);
      cap.normals.push_back(pts->normals[i]);
    }
  const PointSet torus = testing::TorusSamples(0.03, 0.01, 5000, 3);
  PointSet upright;
  for (std::size_t i = 0; i < torus.positions.size(); ++i) {
    const auto swap_yz = [](const Eigen::Vector3d& x) { return Eigen::Vector3d(x.x(), x.z(), x.y()); };
    if (swap_yz(torus.normals[i]).z() <= -std::cos(80.0 * std::numbers::pi / 180.0)) continue;
    upright.positions.push_back(swap_yz(torus.positions[i]));
    upright.normals.push_back(swap_yz(torus.normals[i]));
  }
  for (const auto& [what, set] : {std::pair{"sphere926 above z = -r/3", &cap}, {"torus from above", &upright}}) {
    BuildOptions options;
    options.grid.cells = 96;
    const OffOn built = BuildOffOn(*set, options, &BuildOptions::balls_stop_early);
    ASSERT_TRUE(built.off && built.on) << what;
    const SparseField& every = built.off->field;
    const SparseField& early = built.on->field;
    ASSERT_EQ(every.grid().dims, early.grid().dims) << what;
    ASSERT_EQ(every.grid().origin_m, early.grid().origin_m) << what;
    std::size_t differ = 0, inside = 0;
    const GridSpec& g = early.grid();
    for (int i = 0; i < g.dims[0]; ++i)
      for (int j = 0; j < g.dims[1]; ++j)
        for (int k = 0; k < g.dims[2]; ++k) {
          differ += every.Value(i, j, k) != early.Value(i, j, k) ? 1u : 0u;
          inside += early.Value(i, j, k) <= 0.0f ? 1u : 0u;
        }
    EXPECT_EQ(differ, 0u) << what;
    EXPECT_GT(inside, 10000u) << what;  // a closed solid, not an empty field
  }
}

// Issue 20: a face node a hair outside (the closure keeps its side at 1e-6 voxel) was left as it
// was; next to an inside node the Lipschitz projection scales it further down, and the v2 blob,
// which keeps 1/256 voxel, rounded it to 0: inside, on a grid face (CGAL's bear_bis scanned from 6
// views: one such node). Every face node now ends at least half a voxel outside, here where the
// grid cuts a one-sided scan's closure (the sphere above z = -0.17 r, grid not grown).
TEST(Winding, GridFaceNodesEndHalfAVoxelOutside) {
  const auto pts = ReadPoints(DataFile("sphere926.pwn"));
  ASSERT_TRUE(pts) << pts.error().message;
  for (const double below : {0.17, 0.5}) {
    std::vector<Eigen::Vector3d> p, n;
    for (std::size_t i = 0; i < pts->positions.size(); ++i)
      if (pts->positions[i].z() > -below * pts->positions[i].norm()) {
        p.push_back(3e-3 * pts->positions[i]);
        n.push_back(pts->normals[i]);
      }
    BuildOptions options;
    options.grid.cells = 96;
    options.grow_for_closure = false;
    const auto built = BuildField(p, n, options);
    ASSERT_TRUE(built) << built.error().message;
    const SparseField& f = built->field;
    const GridSpec& g = f.grid();
    float lowest = std::numeric_limits<float>::max();
    std::size_t under_blob_step = 0, near_surface = 0;
    for (int i = 0; i < g.dims[0]; ++i)
      for (int j = 0; j < g.dims[1]; ++j)
        for (int k = 0; k < g.dims[2]; ++k) {
          if (i != 0 && j != 0 && k != 0 && i != g.dims[0] - 1 && j != g.dims[1] - 1 && k != g.dims[2] - 1) continue;
          const float v = f.Value(i, j, k);
          lowest = std::min(lowest, v);
          under_blob_step += v < 1.0f / 256.0f ? 1u : 0u;
          near_surface += v < 1.5f ? 1u : 0u;
        }
    EXPECT_GT(near_surface, 100u) << below;  // the closure is cut by a face
    EXPECT_EQ(under_blob_step, 0u) << below;
    EXPECT_GE(lowest, 0.49f) << below;
  }
}

// The leak guard (GuardPacking) against its definition run brute force: every ball, from its
// packed radius r0, is shrunk by the discs of the samples in index order whose plane it pokes
// through by more than the tolerance and whose centre lies within r0 plus the largest disc of
// the ball's centre (the tree's search), each test with the radius shrunk so far. On a sphere of
// scattered samples with noisy normals, inner and outer balls: most outer balls cross a quarter
// of the samples' planes or more (the marks that order them, not a sort), and on a small set (a
// sort). The same radii, bit for bit.
TEST(GuardPacking, ShrinksAsTheBruteForceInIndexOrder) {
  std::mt19937 rng(5);
  std::normal_distribution<double> normal(0.0, 1.0);
  for (const std::size_t n : {3000u, 40u}) {
    std::vector<Eigen::Vector3d> p, outward;
    for (std::size_t i = 0; i < n; ++i) {
      const Eigen::Vector3d u = Eigen::Vector3d(normal(rng), normal(rng), normal(rng)).normalized();
      p.push_back(0.03 * u);
      outward.push_back((u + 0.03 * Eigen::Vector3d(normal(rng), normal(rng), normal(rng))).normalized());
    }
    const std::vector<double> spacing = SampleSpacing(p);
    const double tolerance = 1e-4;
    for (const bool outer : {false, true}) {
      // Outer balls with discs of 20 spacings: each search reaches every sample (a sparse part's
      // wide discs do so on CGAL's radar.xyz).
      const double discs = outer ? 20.0 : 1.5;
      const double max_disc = discs * *std::max_element(spacing.begin(), spacing.end());
      std::vector<Eigen::Vector3d> nrm = outward;
      if (outer)
        for (Eigen::Vector3d& v : nrm) v = -v;
      const Packing packed = PackSpheres(p, nrm, 0.06);
      Packing guarded = packed;
      const std::size_t shrunk = GuardPacking(guarded, p, nrm, spacing, discs, tolerance);
      std::size_t brute_shrunk = 0, many = 0;
      for (std::size_t i = 0; i < n; ++i) {
        const double r0 = packed.radii[i];
        const Eigen::Vector3d c0 = p[i] - r0 * nrm[i];
        double r = r0;
        std::size_t crossed = 0;
        for (std::size_t j = 0; j < n; ++j) {
          if (j == i || !((c0 - p[j]).squaredNorm() < (r0 + max_disc) * (r0 + max_disc)) ||
              !(nrm[j].dot(c0 - p[j]) + r0 > tolerance))
            continue;
          ++crossed;
          const double height = nrm[j].dot(p[i] - p[j]);
          if (height > 0.0) continue;
          const double cos_ij = nrm[j].dot(nrm[i]);
          if (cos_ij > 1.0 - 1e-9) continue;
          const Eigen::Vector3d c = p[i] - r * nrm[i];
          if (nrm[j].dot(c - p[j]) + r <= tolerance) continue;
          const Eigen::Vector3d tip = c + r * nrm[j];
          const Eigen::Vector3d lateral = (tip - p[j]) - nrm[j].dot(tip - p[j]) * nrm[j];
          if (lateral.norm() > discs * spacing[j]) continue;
          r = std::min(r, std::max((tolerance - height) / (1.0 - cos_ij), 0.0));
        }
        many += crossed > n / 4 ? 1u : 0u;
        brute_shrunk += r < r0 ? 1u : 0u;
        ASSERT_EQ(guarded.radii[i], r) << n << " samples, outer " << outer << ", ball " << i;
      }
      EXPECT_EQ(shrunk, brute_shrunk);
      if (!outer) {
        EXPECT_GT(brute_shrunk, n / 50);  // the guard does shrink: noisy normals' inner balls
      } else if (n > 1000) {
        EXPECT_GT(many, n / 2);  // most outer balls cross a quarter of the planes or more
      }
    }
  }
}

}  // namespace
}  // namespace palpa::field
