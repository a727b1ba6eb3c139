// One-call pipeline: oriented points in device metres -> narrow-band signed distance field, by
// one of three methods (issue 5; docs/field-methods.md compares them):
//   kHermite (default): osculating quadrics of the oriented points, clamped by the guarded
//     packed-ball bracket (hermite_field.h); sparse, sub-voxel.
//   kEdt: packing (paper §3.1) -> indicator -> exact signed Euclidean distance transform.
//   kErosion: packing -> indicator -> erosion (paper §3.2 eq. 4), the reference.
#pragma once

#include <array>
#include <expected>
#include <functional>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "palpa/blob/blob.h"
#include "palpa/field/error.h"
#include "palpa/field/grid.h"
#include "palpa/field/hermite_field.h"
#include "palpa/field/orientation.h"
#include "palpa/field/packing.h"
#include "palpa/field/sparse_field.h"
#include "palpa/field/transform.h"

namespace palpa::field {

// One method enum from build to blob (issue 21): the blob's header stores it as built.
using FieldMethod = blob::Method;
// "erosion", "edt", "hermite" (blob::MethodName).
using blob::MethodName;

struct BuildOptions {
  GridOptions grid;
  FieldMethod method = FieldMethod::kHermite;
  // kHermite: the leak guard (hermite_field.h). erosion and edt always use the paper's raw packing.
  bool leak_guard = true;
  // kHermite: HermiteOptions::hull_cut. Off only to measure what it prevents (tests).
  bool hull_cut = true;
  // kHermite: HermiteOptions::smooth_closure. Off only to measure what it prevents (tests).
  bool smooth_closure = true;
  // kHermite: HermiteOptions::sampleless_components. Off only to measure what it prevents (tests).
  bool sampleless_components = true;
  // kHermite: HermiteOptions::balls_stop_early. Off only to show the early stop changes nothing (tests).
  bool balls_stop_early = true;
  // kHermite: when an open scan's closure goes on past the grid's faces, grow the grid (same
  // voxel, up to half the samples' longest side per side) to hold it before the field is
  // evaluated (HermiteStats::closure_beyond_grid). false keeps the grid fitted to the samples.
  bool grow_for_closure = true;
  // Filter the finished field once (SparseField::SmoothBand, then ProjectLipschitz): what palpa
  // build does after it denoised noisy samples (issue 20), to average the noise the samples'
  // fits leave. Any method.
  bool smooth_band = false;
  // kHermite: samples dropped as outliers whose tangent discs still guard the packing
  // (HermiteOptions::guard_positions), device coordinates; same sizes.
  std::vector<Eigen::Vector3d> guard_positions;
  std::vector<Eigen::Vector3d> guard_normals;
};

struct BuildResult {
  SparseField field;                     // voxels, negative inside, clamped to +-band
  Transform transform;                   // identity: the caller passed device (already fitted) positions
  Packing packing;                       // metres; for kHermite the guarded inner balls
  std::size_t inside_nodes = 0;          // nodes with phi <= 0
  std::size_t balls_shrunk = 0;          // kHermite: inner + outer balls shrunk by the leak guard
  HermiteStats hermite;                  // kHermite: the method's counters (its packings moved to `packing`)
  std::array<int, 3> grid_grown_from{};  // kHermite: the samples' grid, when grown for a closure; else 0s
  OrientationReport orientation;         // every method: are the normals consistently outward?
  double seconds_packing = 0.0;
  double seconds_indicator = 0.0;  // kErosion, kEdt only
  double seconds_distance = 0.0;
};

// What a kHermite build's field says of how its samples cover the object (issue 20), from
// BuildResult::hermite and grid_grown_from; all false for the other methods.
struct ScanGaps {
  // The field spans gaps: surface farther than the winding number's reach from every sample over
  // more than `min_area_m2` (HermiteStats::closed_area_m2), inside nodes cut at a grid face that no
  // sample near them faces (face_nodes_open), or a grid grown to hold a closure.
  bool gaps = false;
  // ... and they make an open scan: the samples show an open side themselves
  // (HermiteStats::samples_open), or the inside leaves the grid over more than kOpenFaceShare of
  // the samples' area. A closed set's sparse parts span gaps too and are not an open scan.
  bool open = false;
  double min_area_m2 = 0.0;  // 4 voxel faces: a smaller area of surface is noise
};
// Open through the grid faces over more than this share of the samples' area (face nodes x voxel
// area): an open object whose samples look closed (the HIL's open plate, two sheets without a rim,
// flux 0: 9 %) rather than a sparse part's leak (0-1.2 % over 10 sparse draws of CGAL's bull,
// spool, rotor, cow and couplingdown).
inline constexpr double kOpenFaceShare = 0.03;
ScanGaps ClassifyGaps(const BuildResult& built);

// Builds the field of oriented points already in device coordinates (metres; see FitTransform).
// Packing uses r_max = longest bounding-box side of `device_positions`. Normals are normalised
// here. `progress`, if set, is called on the calling thread only with non-decreasing values in
// [0, 1], ending with 1. Deterministic: any thread count gives bit-identical fields. kHermite:
// the grid is MakeGrid's around the positions, grown (same voxel) to hold an open scan's closure
// when options.grow_for_closure (BuildResult::grid_grown_from).
// Errors: size mismatch; fewer than 4 points; non-finite position; zero or non-finite normal;
// any MakeGrid error; out of memory.
std::expected<BuildResult, Error> BuildField(const std::vector<Eigen::Vector3d>& device_positions,
                                             const std::vector<Eigen::Vector3d>& normals, const BuildOptions& options,
                                             std::function<void(double fraction)> progress = {});

}  // namespace palpa::field
