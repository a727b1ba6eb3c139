#include <tbb/global_control.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include <fmt/core.h>

#include "commands.h"
#include "grid_faces.h"
#include "palpa/blob/blob.h"
#include "palpa/field/build.h"
#include "palpa/field/coverage.h"
#include "palpa/field/normals.h"
#include "palpa/field/pockets.h"
#include "palpa/field/point_io.h"
#include "palpa/field/samples.h"
#include "palpa/field/to_blob.h"
#include "palpa/io/atomic_file.h"
#include "palpa/mesh/sample.h"

namespace palpa::cli {
namespace {

// A one-line progress bar on stderr, only when stderr is a terminal (quiet in pipes and CI).
class ProgressBar {
 public:
  ProgressBar() : enabled_(::isatty(STDERR_FILENO) == 1) {}
  void Update(double fraction) {
    if (!enabled_) return;
    const int width = 40;
    const int filled = static_cast<int>(std::lround(fraction * width));
    if (filled == last_) return;
    last_ = filled;
    fmt::print(stderr, "\rpalpa build [{:<{}}] {:3d}%", std::string(static_cast<std::size_t>(filled), '#'), width,
               static_cast<int>(std::lround(fraction * 100)));
    std::fflush(stderr);
  }
  ~ProgressBar() {
    if (enabled_ && last_ >= 0) fmt::print(stderr, "\r{:60}\r", "");
  }

 private:
  bool enabled_;
  int last_ = -1;
};

// The voxel, in model units, that the build will about have: from the bounding box of the middle
// 99.8 % of the samples on each axis (outliers are not removed yet), --fit or --scale, and
// --cells (with the grid's margin) or --voxel. 0 when it cannot be told.
double ProvisionalVoxel(const field::PointSet& points, const BuildArgs& args) {
  const std::size_t n = points.positions.size();
  if (n < 1000) return 0;  // small sets are never denser than a grid
  std::vector<double> coordinate(n);
  double longest = 0;
  for (Eigen::Index a = 0; a < 3; ++a) {
    for (std::size_t i = 0; i < n; ++i) coordinate[i] = points.positions[i][a];
    const std::size_t lo = n / 1000, hi = n - 1 - n / 1000;
    std::nth_element(coordinate.begin(), coordinate.begin() + static_cast<std::ptrdiff_t>(lo), coordinate.end());
    const double low = coordinate[lo];
    std::nth_element(coordinate.begin(), coordinate.begin() + static_cast<std::ptrdiff_t>(hi), coordinate.end());
    longest = std::max(longest, coordinate[hi] - low);
  }
  if (!(longest > 0) || !std::isfinite(longest)) return 0;
  const double scale = args.scale ? *args.scale : args.fit_m / longest;  // metres per model unit
  if (args.voxel_m > 0) return args.voxel_m / scale;
  const int band = args.format == 2 ? std::max(args.band_voxels, args.band_outside) : args.band_voxels;
  const int intervals = args.cells - 1 - 2 * field::GridMarginNodes(band);
  return intervals > 0 ? longest / intervals : 0;
}

// As field::BuildField's minimum.
constexpr std::size_t kMinUsableSamples = 4;

}  // namespace

int RunBuild(const BuildArgs& args) {
  const auto t0 = std::chrono::steady_clock::now();
  std::unique_ptr<tbb::global_control> threads;
  if (args.threads > 0)
    threads = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                    static_cast<std::size_t>(args.threads));

  // Before any work: a build can take minutes, and its target must not be a device or the input.
  if (const int refused = CheckOutput("build", args.output, {args.points}); refused != kExitOk) return refused;
  if (!args.points_out.empty()) {
    // One file under two spellings (./x, a/../x, a link to the directory): neither exists yet, so
    // CheckOutput's inode test cannot see it, and the blob would overwrite the points.
    if (SamePath(args.points_out, args.output)) {
      fmt::print(stderr, "palpa build: --points-out {}: the same path as -o\n", args.points_out);
      return kExitBadInput;
    }
    if (const int refused = CheckOutput("build", args.points_out, {args.points, args.output}); refused != kExitOk)
      return refused;
  }
  // Degenerate samples are dropped here, after reading, and named (issue 20): a real scan with a
  // few zero normals must not be refused whole. --strict refuses them.
  auto points =
      field::ReadPoints(args.points, field::ReadOptions{.keep_bad_normals = true, .allow_missing_normals = true});
  if (!points) {
    fmt::print(stderr, "palpa build: {}\n", points.error().message);
    return kExitBadInput;
  }
  const std::size_t read_count = points->positions.size();
  // A file whose every normal is zero or not finite has none (CGAL and other tools write 0 0 0
  // where they have no normal): estimated, as a file of bare positions, not refused as
  // degenerate. --strict still refuses it below.
  bool all_normals_degenerate = false;
  if (points->has_normals && !args.strict && read_count > 0) {
    all_normals_degenerate = std::none_of(points->normals.begin(), points->normals.end(), [](const Eigen::Vector3d& v) {
      return v.allFinite() && v.squaredNorm() > 0.0;
    });
    if (all_normals_degenerate) points->has_normals = false;
  }
  // Dropping degenerate samples or thinning below moves the middle 99.8 % of a set little: one
  // provisional voxel serves both thinnings.
  const double provisional_voxel = ProvisionalVoxel(*points, args);
  // --normals (issue 20): a file of bare positions is always estimated; estimate replaces the
  // file's normals before the degenerate ones would be dropped, orient keeps their lines.
  const field::NormalsMode normals_mode = !points->has_normals         ? field::NormalsMode::kEstimate
                                          : args.normals == "orient"   ? field::NormalsMode::kOrient
                                          : args.normals == "estimate" ? field::NormalsMode::kEstimate
                                                                       : field::NormalsMode::kKeep;
  field::NormalsReport normals_report;
  if (normals_mode == field::NormalsMode::kEstimate) {
    // A dense scan is thinned by position first (SimplifyBarePositions: half a voxel, or 1.5
    // where a noisy scan's shell is too thick for half-voxel cells to halve it, but not in a cell
    // that holds both sides of a thin wall, and in half-voxel cells where one wraps round a rim).
    if (provisional_voxel > 0) {
      const std::size_t before = points->positions.size();
      const field::Simplification thinned = field::SimplifyBarePositions(*points, provisional_voxel);
      const double voxels = thinned.cell / provisional_voxel;
      if (thinned.Applied() && !args.quiet)
        fmt::print(
            stderr,
            "palpa build: note: {}: {} samples thinned to {} ({} voxel{}, by position{}{}) before their normals "
            "were estimated\n",
            args.points, before, points->positions.size(), voxels == 0.5 ? "half a" : fmt::format("{:g}", voxels),
            voxels == 0.5 ? "" : "s",
            thinned.wall_cells == 0
                ? ""
                : fmt::format("; the {} cells that hold both sides of a wall thinner than that keep every sample",
                              thinned.wall_cells),
            thinned.fold_cells == 0
                ? ""
                : fmt::format("; the {} that wrap round a thin part's rim are thinned to half a voxel",
                              thinned.fold_cells));
    }
    normals_report.neighbours =
        field::EstimateNormalLines(points->positions, points->normals, &normals_report.noise_figure);  // signs below
    normals_report.estimated = points->positions.size();
  }
  const field::DroppedSamples dropped = field::DropDegenerateSamples(*points, args.points);
  if (dropped.Total() > 0) {
    if (args.strict) {
      fmt::print(stderr, "palpa build: {}: --strict: {}\n", args.points, dropped.Describe());
      return kExitBadInput;
    }
    if (dropped.kept < kMinUsableSamples) {
      fmt::print(stderr, "palpa build: {}: {} usable samples after dropping {}; at least {} are needed\n", args.points,
                 dropped.kept, dropped.Describe(), kMinUsableSamples);
      return kExitBadInput;
    }
    fmt::print(stderr, "palpa build: warning: {}: dropped {}; {} samples remain (--strict refuses such files)\n",
               args.points, dropped.Describe(), dropped.kept);
  }
  if (normals_mode != field::NormalsMode::kKeep) {
    // Samples clean for their spacing can be noisy for the grid, and --denoise auto below moves them
    // along their lines: the denoiser's measure and threshold, on the provisional voxel.
    bool refit = false;
    if (normals_mode == field::NormalsMode::kEstimate)
      refit = field::OrientEstimatedNormals(
          points->positions, points->normals, normals_report,
          args.denoise == "auto" && provisional_voxel > 0 ? field::kDenoiseVoxels * provisional_voxel : 0.0);
    else
      field::OrientNormals(points->positions, points->normals, true, normals_report);
    if (refit && !args.quiet)
      fmt::print(stderr,
                 "palpa build: note: {}: the samples are clean for their spacing but their position noise is over "
                 "{} voxel: their normals were fitted again as noisy ones, to the {} nearest (--denoise off keeps "
                 "the clean fit)\n",
                 args.points, field::kDenoiseVoxels, normals_report.neighbours);
    if (!args.quiet || !points->has_normals)
      fmt::print(stderr, "palpa build: note: {}: {}{}\n", args.points, normals_report.Describe(),
                 points->has_normals      ? ""
                 : all_normals_degenerate ? " (every normal in the file is zero or not finite)"
                                          : " (the file has no normals)");
  }
  // A dense scan is thinned before the neighbour searches below (on 2,000,000 samples they cost
  // more than the build): to half the voxel the fit will give, from the bounding box of the
  // middle 99.8 % of the samples per axis (a far outlier must not set the scale). The build
  // thins it again per voxel once the grid is known (below).
  if (const double cell = provisional_voxel / 2; cell > 0) {
    const std::size_t before = points->positions.size();
    if (field::SimplifyDenseSamples(*points, cell).Applied() && !args.quiet)
      fmt::print(stderr, "palpa build: note: {}: {} samples thinned to {} (half a voxel) before the outlier search\n",
                 args.points, before, points->positions.size());
  }
  // Stray samples and outliers are ignored before the fit (one point at 1e30 must not collapse
  // --fit) and before the build (each would make solid of its own: a phantom wall).
  const field::StraySamples stray = field::FindStraySamples(points->positions, points->normals);
  if (!stray.indices.empty()) {
    fmt::print(stderr,
               "palpa build: warning: {}: ignored {} sample{} that {} neighbours do not support (off their "
               "surface or isolated); the farthest: {}, {:.3g} sample spacings off\n",
               args.points, stray.indices.size(), stray.indices.size() == 1 ? "" : "s",
               stray.indices.size() == 1 ? "its" : "their", field::PointPlace(args.points, *points, *stray.farthest),
               stray.farthest_spacings);
    field::RemoveSamples(*points, stray.indices);
  }
  const field::Transform transform =
      args.scale ? field::Transform{*args.scale, Eigen::Vector3d(args.offset_m[0], args.offset_m[1], args.offset_m[2])}
                 : field::FitTransform(*points, args.fit_m);
  field::PointSet device = field::ApplyTransform(transform, *points);

  field::BuildOptions options;
  options.grid.cells = args.cells;
  options.grid.voxel_m = args.voxel_m;
  // v2 clamps each side to its own band: build the field to the wider of the two.
  options.grid.band_voxels = args.format == 2 ? std::max(args.band_voxels, args.band_outside) : args.band_voxels;
  // Issue 20: samples denser than the grid (a phone or tabletop scanner's millions) carry no
  // more information at its resolution, and cost the packing minutes: one sample per voxel cell
  // and normal side. A set at or below the grid's resolution is left as it was.
  if (auto grid = field::MakeGrid(device.positions, options.grid)) {
    const field::Simplification simplified =
        field::SimplifyDenseSamples(device, grid->voxel_m * field::kDenseCellVoxels);
    if (simplified.Applied())
      fmt::print(stderr,
                 "palpa build: note: {}: {} samples are denser than the grid: averaged per cell of {} voxels "
                 "({:.4g} mm) and normal side to {} (denser samples carry no more information at this resolution; "
                 "--cells or --voxel sets it)\n",
                 args.points, simplified.before, field::kDenseCellVoxels, simplified.cell * 1e3, simplified.after);
  }
  options.method = args.method == "erosion" ? field::FieldMethod::kErosion
                   : args.method == "edt"   ? field::FieldMethod::kEdt
                                            : field::FieldMethod::kHermite;
  // Outliers near the surface with a plausible normal pass the stray-sample test above, and each
  // makes phantom solid several voxels deep: the samples' winding number, which should rise by
  // about 1 across every sample along its normal, finds them (issue 20).
  if (const field::WindingOutliers outliers = field::FindWindingOutliers(device.positions, device.normals);
      !outliers.indices.empty()) {
    fmt::print(stderr,
               "palpa build: warning: {}: ignored {} sample{} that the surface's inside and outside disagree with "
               "(the samples' winding number barely changes across {}); the worst: {}\n",
               args.points, outliers.indices.size(), outliers.indices.size() == 1 ? "" : "s",
               outliers.indices.size() == 1 ? "it" : "them", field::PointPlace(args.points, device, *outliers.worst));
    // Not built from, but their tangent discs still bound the packed balls: on a sparse set most
    // are true samples (HermiteOptions::guard_positions).
    for (const std::size_t i : outliers.indices) {
      options.guard_positions.push_back(device.positions[i]);
      options.guard_normals.push_back(device.normals[i]);
    }
    field::RemoveSamples(device, outliers.indices);
  }
  // Position noise reaches the field whole through each sample's patch and balls: averaged out
  // where the samples' own quadric fits say it exceeds a quarter voxel (issue 20; clean samples,
  // sparse or faceted ones included, measure below 0.21 voxel).
  if (args.denoise == "auto") {
    if (auto grid = field::MakeGrid(device.positions, options.grid)) {
      const double h = grid->voxel_m;
      const field::NoiseSmoothing smoothed = field::SmoothNoisyPositions(
          device.positions, device.normals, field::kDenoiseNeighbours, field::kDenoiseVoxels * h, field::kMovePasses,
          normals_mode == field::NormalsMode::kEstimate ? normals_report.neighbours : 0);
      // What the moves leave is noise at the sample spacing: one binomial filter of the field
      // averages it (bull, sigma = 1 voxel, the 16-sample move: band mean 0.289 -> 0.271, wrong
      // sign 4.82 -> 4.23 %).
      // Moves withheld leave the noise in place, and the filter still averages it (pinion, 5,000 bare
      // samples, 0.3 voxel: band mean 0.247 -> 0.232 voxel).
      options.smooth_band = smoothed.Applied() || smoothed.withheld;
      if (smoothed.withheld && !args.quiet)
        fmt::print(
            stderr,
            "palpa build: note: {}: position noise {:.3g} mm RMS ({:.2f} voxels), but the moves towards the "
            "surface the samples' normals agree on were {:.2f} voxels RMS, more than that noise explains: "
            "the estimated normals do not follow the shape at this spacing, so the samples were kept in place and "
            "only the field filtered once over 3x3x3 nodes (--denoise off keeps it unfiltered)\n",
            args.points, smoothed.noise * 1e3, smoothed.noise / h, smoothed.rms_move / h);
      if (smoothed.Applied() && !args.quiet)
        fmt::print(stderr,
                   "palpa build: note: {}: position noise {:.3g} mm RMS ({:.2f} voxels): {} samples moved along "
                   "their normals towards the surface their {} nearest samples' positions and normals agree on "
                   "({} pass{}{}), {:.2f} voxels on average, and the field filtered once over 3x3x3 nodes "
                   "(--denoise off keeps them)\n",
                   args.points, smoothed.noise * 1e3, smoothed.noise / h, smoothed.moved,
                   smoothed.widest > field::kMoveFewestNeighbours
                       ? fmt::format("{}-{}", field::kMoveFewestNeighbours, smoothed.widest)
                       : fmt::format("{}", field::kMoveFewestNeighbours),
                   smoothed.passes, smoothed.passes == 1 ? "" : "es",
                   smoothed.scattered == 0 ? ""
                                           : fmt::format("; {} stayed in the first, their neighbours' offsets "
                                                         "scattered beyond the noise",
                                                         smoothed.scattered),
                   smoothed.mean_move / h);
    }
  }
  field::BuildResult built;
  {
    ProgressBar bar;
    auto result = field::BuildField(device.positions, device.normals, options, [&](double f) { bar.Update(f); });
    if (!result) {
      fmt::print(stderr, "palpa build: {}: {}\n", args.points, result.error().message);
      return kExitBadInput;
    }
    built = std::move(*result);
  }
  // Issue 20: say when the scan is open (the winding number closed a surface where no sample
  // lies) rather than leaving the user to blame the normals (field::ClassifyGaps: CGAL's bull with
  // 1,000 samples, whose sparse legs reached its bottom face, and its spool with 500, whose
  // normals the open-scan test's tighter bound then blamed, were called open).
  const field::ScanGaps scan = field::ClassifyGaps(built);
  const bool open_scan = scan.open;
  const bool grown = built.grid_grown_from[0] > 0;
  // Every method takes the inside from the normals' sign; say so when the file's normals disagree
  // (also with -q: the field is then wrong near those points). An open scan's far side is no
  // evidence (OrientationReport::OpenScanInconsistent).
  const bool normals_blamed = open_scan ? built.orientation.OpenScanInconsistent() : built.orientation.Inconsistent();
  if (normals_blamed) {
    fmt::print(stderr,
               "palpa build: warning: {}: normals are not consistently oriented: {}. Normals must point out of the "
               "object; the field is wrong near these points.{}\n",
               args.points, built.orientation.Describe(),
               normals_mode == field::NormalsMode::kKeep
                   ? " Rerun with --normals orient to re-choose their signs, or --normals estimate to replace them."
                   : "");
  }
  if (open_scan) {
    // The closing surface's area: every crossing of the zero surface farther than 3 sample
    // spacings from every sample (the winding number's own count sees only bricks no sample
    // reaches, a lower bound).
    const field::Coverage coverage = field::MeasureCoverage(built.field, device.positions);
    const double closed_m2 = coverage.uncovered_area_m2;
    const double closed = closed_m2 / (transform.scale * transform.scale);  // model units^2
    fmt::print(
        stderr,
        "palpa build: note: {}: the scan {}: the field closes it (by the "
        "samples' winding number, and where that is unclear by the inner balls that continue the scanned surface, "
        "continuing their curvature{}) over {:.4g} mm^2 ({:.4g} model units^2) more than {:.3g} mm from every "
        "sample (3 sample spacings){}\n",
        args.points,
        // A flipped patch's normals have a flux of their own, which alone makes a closed set look open.
        normals_blamed ? "looks open (the flipped normals above may be why)" : "is open (the normals are not to blame)",
        built.hermite.closure_side_changes > 0
            ? fmt::format("; then smoothed by {} side changes of nodes beyond every sample's reach, each to the "
                          "side of most nodes about it",
                          built.hermite.closure_side_changes)
            : std::string(),
        closed_m2 * 1e6, closed, coverage.min_distance_m * 1e3,
        (grown ? fmt::format("; the grid was grown from {}x{}x{} to {}x{}x{} nodes (same voxel) to hold the "
                             "closed side",
                             built.grid_grown_from[0], built.grid_grown_from[1], built.grid_grown_from[2],
                             built.field.grid().dims[0], built.field.grid().dims[1], built.field.grid().dims[2])
               : std::string()) +
            (built.hermite.face_nodes_closed > 0
                 ? fmt::format(", and it was cut at the grid faces ({} face nodes set outside)",
                               built.hermite.face_nodes_closed)
                 : std::string()));
  }
  if (scan.gaps && !open_scan && !args.quiet) {
    const field::Coverage coverage = field::MeasureCoverage(built.field, device.positions);
    if (coverage.uncovered_area_m2 > scan.min_area_m2)
      fmt::print(stderr,
                 "palpa build: note: {}: the samples make a closed surface, sparsely: {:.4g} mm^2 of the field's "
                 "surface lies more than {:.3g} mm from every sample (3 sample spacings), where it is the samples' "
                 "winding number's and the nearest samples' guess; more samples there would settle it\n",
                 args.points, coverage.uncovered_area_m2 * 1e6, coverage.min_distance_m * 1e3);
  }
  if (built.hermite.hull_cut_nodes > 0 && !args.quiet)
    fmt::print(stderr,
               "palpa build: note: {}: {} nodes that the nearest samples held inside lay more than {:.3g} mm outside "
               "the samples' convex hull (a part carried on past its last samples, such as an unsampled end) and were "
               "set outside\n",
               args.points, built.hermite.hull_cut_nodes, built.hermite.hull_cut_beyond_m * 1e3);
  // Pockets filled and islands cut (FillSamplelessPockets, CutSamplelessIslands): one sentence
  // each, what was changed and why the samples do not show it.
  const auto sampleless_note = [&](std::size_t count, std::size_t nodes, const char* done, const char* what,
                                   const char* where, const char* why) {
    if (count == 0 || args.quiet) return;
    fmt::print(stderr,
               "palpa build: note: {}: {} {} {}{} {} ({} nodes): {} lay more than {} voxels from every sample and {}\n",
               args.points, done, count, what, count == 1 ? "" : "s", where, nodes, count == 1 ? "it" : "each",
               field::kPocketReachVoxels, why);
  };
  sampleless_note(built.hermite.pockets_filled, built.hermite.pocket_nodes_filled, "filled", "hollow",
                  "enclosed in the solid",
                  "behind every sample within a spacing of it, a gap the closure left rather than a cavity (a "
                  "cavity's wall samples face into it)");
  sampleless_note(built.hermite.islands_cut, built.hermite.island_nodes_cut, "cut", "island",
                  "of solid floating apart from the rest",
                  "in front of every sample within a spacing of it, nothing any sample shows");
  if (!open_scan && built.hermite.face_nodes_closed > 0)
    fmt::print(stderr,
               "palpa build: note: {}: the field's inside reached the grid faces at {} nodes, set outside; {}, so this "
               "is a closed part thinner or sparser than the samples resolve, not an open side\n",
               args.points, built.hermite.face_nodes_closed,
               built.hermite.face_nodes_open > 0 ? "the samples show no open side (their normals' flux and rims)"
                                                 : "samples beside them face the grid face");
  const field::GridSpec g = built.field.grid();  // a copy: the field is handed to the encoder below
  const std::size_t field_bricks = built.field.AllocatedBricks();
  const std::array<int, 3> brick_dims = built.field.brick_dims();
  const auto build_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now() - t0);
  const blob::BlobMeta meta = field::BlobMetaOf(g, options.method,
                                                {.transform = transform,
                                                 .point_count = static_cast<std::uint32_t>(points->positions.size()),
                                                 .build_time_ns = static_cast<std::uint64_t>(build_ns.count())});
  const std::size_t nodes = g.NodeCount();
  const std::size_t face_nodes_inside = NegativeFaceNodes(
      [&](std::size_t i, std::size_t j, std::size_t k) {
        return built.field.ValueQ16(static_cast<int>(i), static_cast<int>(j), static_cast<int>(k));
      },
      g.dims);
  if (face_nodes_inside > 0)
    fmt::print(stderr,
               "palpa build: warning: {}: the field touches its grid boundary (φ < 0 on {} face nodes); palpad treats "
               "those faces as walls\n",
               args.points, face_nodes_inside);
  // Straight from the sparse field (issue 21): the writer owns the field from here and, for v2,
  // frees it once every brick is read, before it assembles the blob.
  const std::vector<std::byte> bytes = field::ToBlob(std::move(built.field), meta,
                                                     {.version = args.format,
                                                      .band_inside = static_cast<std::uint32_t>(args.band_voxels),
                                                      .band_outside = static_cast<std::uint32_t>(args.band_outside)});
  // --points-out before the blob: a failure leaves neither new (the blob's own failure can
  // still leave the points written, complete).
  if (!args.points_out.empty()) {
    const std::string text = mesh::ToXyzText(field::ApplyTransform(transform.Inverse(), device));
    if (auto w = io::WriteFileAtomically(args.points_out, std::as_bytes(std::span(text)), {.inputs = {args.points}});
        !w) {
      fmt::print(stderr, "palpa build: {}\n", w.error());
      return kExitIo;
    }
  }
  if (auto w = io::WriteFileAtomically(args.output, bytes, {.inputs = {args.points}}); !w) {
    fmt::print(stderr, "palpa build: {}\n", w.error());
    return kExitIo;
  }
  const double total_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (!args.quiet) {
    fmt::print(
        "{}: {} {}points{} → {}\n", args.points, read_count, points->has_normals ? "oriented " : "",
        read_count == device.positions.size() ? std::string() : fmt::format(" ({} built)", device.positions.size()),
        args.output);
    if (args.format == 2) {
      fmt::print("  grid        {} x {} x {} nodes, voxel {:.4f} mm, band {} voxels inside, {} outside\n", g.dims[0],
                 g.dims[1], g.dims[2], g.voxel_m * 1e3, args.band_voxels, args.band_outside);
    } else {
      fmt::print("  grid        {} x {} x {} nodes, voxel {:.4f} mm, band {} voxels\n", g.dims[0], g.dims[1], g.dims[2],
                 g.voxel_m * 1e3, g.band_voxels);
    }
    fmt::print("  method      {}, {} nodes inside, {} of {} bricks with band values\n",
               field::MethodName(options.method), built.inside_nodes, field_bricks,
               static_cast<std::size_t>(brick_dims[0]) * static_cast<std::size_t>(brick_dims[1]) *
                   static_cast<std::size_t>(brick_dims[2]));
    fmt::print("  time        {:.3f} s (packing {:.3f} s, indicator {:.3f} s, distance {:.3f} s)\n", total_s,
               built.seconds_packing, built.seconds_indicator, built.seconds_distance);
    fmt::print("  blob        v{}, {} bytes ({:.2f} % of dense float32)\n", args.format, bytes.size(),
               100.0 * static_cast<double>(bytes.size()) / (4.0 * static_cast<double>(nodes)));
  }
  return kExitOk;
}

}  // namespace palpa::cli
