#include "palpa/field/build.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <exception>
#include <new>
#include <utility>

#include <fmt/format.h>
#include <Eigen/Geometry>

#include "palpa/field/edt_field.h"
#include "palpa/field/erosion_field.h"
#include "palpa/field/hermite_field.h"
#include "palpa/field/indicator.h"

namespace palpa::field {
namespace {

constexpr std::size_t kMinPoints = 4;
// How far past the samples' grid an open scan's closure may grow it, per side, as a share of
// the samples' longest bounding-box side: a sphere scanned above 0.17 R needs 0.42; an open sheet's
// huge inner balls would otherwise grow it without bound.
constexpr double kClosureReach = 0.5;

// Share of the total progress at the end of each stage (rough typical cost).
constexpr double kProgressPacked = 0.4;
constexpr double kProgressIndicator = 0.6;

double SecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

std::expected<BuildResult, Error> Build(const std::vector<Eigen::Vector3d>& device_positions,
                                        const std::vector<Eigen::Vector3d>& normals, const BuildOptions& options,
                                        const std::function<void(double)>& progress) {
  const auto report = [&](double fraction) {
    if (progress) progress(fraction);
  };
  if (device_positions.size() != normals.size()) {
    return std::unexpected(
        Error{fmt::format("build: {} positions but {} normals", device_positions.size(), normals.size())});
  }
  if (device_positions.size() < kMinPoints) {
    return std::unexpected(
        Error{fmt::format("build: {} points; at least {} are needed", device_positions.size(), kMinPoints)});
  }
  std::vector<Eigen::Vector3d> unit_normals(normals.size());
  for (std::size_t i = 0; i < normals.size(); ++i) {
    if (!device_positions[i].allFinite()) {
      return std::unexpected(Error{fmt::format("build: position {} is not finite", i)});
    }
    const double length = normals[i].norm();
    if (!std::isfinite(length) || !(length > 0.0)) {
      return std::unexpected(Error{fmt::format("build: normal {} is zero or not finite", i)});
    }
    unit_normals[i] = normals[i] / length;
  }
  auto grid = MakeGrid(device_positions, options.grid);
  if (!grid) return std::unexpected(grid.error());
  report(0.0);

  BuildResult result;
  // r_max: no packed ball is larger than the object's bounding box.
  Eigen::Vector3d lo = device_positions.front();
  Eigen::Vector3d hi = lo;
  for (const Eigen::Vector3d& p : device_positions) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  const double r_max = (hi - lo).maxCoeff();
  result.orientation = CheckOrientation(device_positions, unit_normals);

  if (options.method == FieldMethod::kHermite) {
    HermiteStats& stats = result.hermite;
    HermiteOptions hermite_options;
    hermite_options.leak_guard = options.leak_guard;
    hermite_options.hull_cut = options.hull_cut;
    hermite_options.smooth_closure = options.smooth_closure;
    hermite_options.sampleless_components = options.sampleless_components;
    hermite_options.balls_stop_early = options.balls_stop_early;
    hermite_options.guard_positions = options.guard_positions;
    hermite_options.guard_normals = options.guard_normals;
    const Eigen::Vector3d reach = Eigen::Vector3d::Constant(kClosureReach * r_max);
    const bool grow = options.grow_for_closure && !result.orientation.OpenScanInconsistent();
    hermite_options.closure_reach_m = grow ? reach.x() : 0.0;
    // An open scan closed past the grid's faces: grow the grid, voxel kept, to hold the closure
    // (issue 20: no inside node on a grid face, and no flat cut where the closure goes on). Not
    // when the normals disagree: the closure then follows flipped samples (data/cube.pwn: a
    // grid 4.2 times larger, 26 s instead of 9, and still cut at its faces). HermiteField finds
    // the closure before it evaluates a node and then returns unbuilt; the grown grid is built
    // without a second search. That search, on a lattice aligned with the first, could only find
    // what the first found or what lies past the reach; on its own lattice it had found nothing
    // in any of 22 grown builds (the 111 open and range rows and CGAL's hippo1), at 0.04 s each.
    Eigen::AlignedBox3d hold(lo, hi);  // what the grid must hold: the samples and their closure
    double seconds = 0.0;              // of the unbuilt call, counted as distance time
    result.field = HermiteField(*grid, device_positions, unit_normals, r_max, hermite_options, &stats);
    HermiteStats searched;  // the unbuilt call's packing, reused: same voxel, same balls
    if (stats.closure_beyond_grid) {
      hold.extend(*stats.closure_beyond_grid);
      hold = hold.intersection(Eigen::AlignedBox3d(lo - reach, hi + reach));
      GridOptions grown = options.grid;
      grown.voxel_m = grid->voxel_m;
      auto bigger = MakeGrid({hold.min(), hold.max()}, grown);
      if (bigger && bigger->NodeCount() > grid->NodeCount()) {
        result.grid_grown_from = grid->dims;
        grid = std::move(bigger);
      }
      hermite_options.closure_reach_m = 0.0;
      seconds = stats.seconds_packing + stats.seconds_distance;
      searched = std::exchange(stats, {});
      hermite_options.packed = &searched;
      result.field = HermiteField(*grid, device_positions, unit_normals, r_max, hermite_options, &stats);
    }
    stats.seconds_distance += seconds;
    result.packing = std::move(stats.inner);
    stats.inner = {};
    stats.outer = {};
    result.balls_shrunk = stats.inner_balls_shrunk + stats.outer_balls_shrunk;
    result.seconds_packing = stats.seconds_packing;
    result.seconds_distance = stats.seconds_distance;
  } else {
    auto start = std::chrono::steady_clock::now();
    result.packing = PackSpheres(device_positions, unit_normals, r_max);
    result.seconds_packing = SecondsSince(start);
    report(kProgressPacked);

    start = std::chrono::steady_clock::now();
    const std::vector<std::uint8_t> indicator = Indicator(*grid, result.packing);
    result.seconds_indicator = SecondsSince(start);
    report(kProgressIndicator);

    start = std::chrono::steady_clock::now();
    if (options.method == FieldMethod::kEdt) {
      result.field = SparseField::FromDense(*grid, SignedEdtField(*grid, indicator));
    } else {
      result.field = SparseField::FromDense(*grid, ErosionField(*grid, indicator).phi_voxels);
    }
    result.seconds_distance = SecondsSince(start);
  }
  if (options.smooth_band) {
    result.field.SmoothBand();
    result.field.ProjectLipschitz();
  }
  result.inside_nodes = result.field.CountInside();
  report(1.0);
  return result;
}

}  // namespace

ScanGaps ClassifyGaps(const BuildResult& built) {
  const HermiteStats& st = built.hermite;
  const double voxel_area = built.field.grid().voxel_m * built.field.grid().voxel_m;
  ScanGaps out{.min_area_m2 = 4.0 * voxel_area};
  out.gaps = st.closed_area_m2 > out.min_area_m2 || st.face_nodes_open > 0 || built.grid_grown_from[0] > 0;
  const double face_share =
      static_cast<double>(st.face_nodes_open) * voxel_area / std::max(st.sample_area_m2, voxel_area);
  out.open = out.gaps && (st.samples_open || face_share > kOpenFaceShare);
  return out;
}

std::expected<BuildResult, Error> BuildField(const std::vector<Eigen::Vector3d>& device_positions,
                                             const std::vector<Eigen::Vector3d>& normals, const BuildOptions& options,
                                             std::function<void(double fraction)> progress) {
  // Keep the API exception-free: allocation of a large grid, or a throwing callback, ends here.
  try {
    return Build(device_positions, normals, options, progress);
  } catch (const std::bad_alloc&) {
    return std::unexpected(Error{"build: out of memory (grid too large?)"});
  } catch (const std::exception& e) {
    return std::unexpected(Error{fmt::format("build: {}", e.what())});
  }
}

}  // namespace palpa::field
