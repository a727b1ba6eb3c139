#include <tbb/global_control.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <vector>

#include <fmt/core.h>

#include "atomic_file.h"
#include "commands.h"
#include "palpa/blob/blob.h"
#include "palpa/field/build.h"
#include "palpa/field/point_io.h"

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

}  // namespace

int RunBuild(const BuildArgs& args) {
  const auto t0 = std::chrono::steady_clock::now();
  std::unique_ptr<tbb::global_control> threads;
  if (args.threads > 0)
    threads = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                    static_cast<std::size_t>(args.threads));

  auto points = field::ReadPoints(args.points);
  if (!points) {
    fmt::print(stderr, "palpa build: {}\n", points.error().message);
    return kExitBadInput;
  }
  const field::Transform transform =
      args.scale ? field::Transform{*args.scale, Eigen::Vector3d(args.offset_m[0], args.offset_m[1], args.offset_m[2])}
                 : field::FitTransform(*points, args.fit_m);
  const field::PointSet device = field::ApplyTransform(transform, *points);

  field::BuildOptions options;
  options.grid.cells = args.cells;
  options.grid.voxel_m = args.voxel_m;
  options.grid.band_voxels = args.band_voxels;
  field::BuildResult built;
  {
    ProgressBar bar;
    auto result = field::BuildErosionField(device.positions, device.normals, options, [&](double f) { bar.Update(f); });
    if (!result) {
      fmt::print(stderr, "palpa build: {}: {}\n", args.points, result.error().message);
      return kExitBadInput;
    }
    built = std::move(*result);
  }

  const field::GridSpec& g = built.field.grid;
  std::vector<std::int32_t> phi(built.field.phi_voxels.size());
  for (std::size_t n = 0; n < phi.size(); ++n)
    phi[n] = static_cast<std::int32_t>(std::lround(static_cast<double>(built.field.phi_voxels[n]) * 65536.0));

  blob::BlobMeta meta;
  for (std::size_t a = 0; a < 3; ++a) {
    meta.dims[a] = static_cast<std::uint32_t>(g.dims[a]);
    meta.origin_m[a] = g.origin_m[static_cast<Eigen::Index>(a)];
    meta.fit_offset_m[a] = transform.offset_m[static_cast<Eigen::Index>(a)];
  }
  meta.voxel_m = g.voxel_m;
  meta.band_voxels = static_cast<std::uint32_t>(g.band_voxels);
  meta.method = blob::Method::kErosion;
  meta.point_count = static_cast<std::uint32_t>(points->positions.size());
  meta.fit_scale = transform.scale;
  const auto build_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now() - t0);
  meta.build_time_ns = static_cast<std::uint64_t>(build_ns.count());
  const std::vector<std::byte> bytes = blob::Encode(meta, phi);
  if (auto check = blob::Verify(bytes); !check) {
    fmt::print(stderr, "palpa build: internal error, the encoded blob does not verify: {}\n", check.error().what());
    return kExitIo;
  }
  if (auto w = WriteFileAtomically(args.output, bytes); !w) {
    fmt::print(stderr, "palpa build: {}\n", w.error());
    return kExitIo;
  }
  const double total_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (!args.quiet) {
    fmt::print("{}: {} oriented points → {}\n", args.points, points->positions.size(), args.output);
    fmt::print("  grid        {} x {} x {} nodes, voxel {:.4f} mm, band {} voxels\n", g.dims[0], g.dims[1], g.dims[2],
               g.voxel_m * 1e3, g.band_voxels);
    fmt::print("  method      erosion (paper eq. 4), {} nodes inside\n", built.field.inside_nodes);
    fmt::print("  time        {:.3f} s (packing {:.3f} s, indicator {:.3f} s, distance {:.3f} s)\n", total_s,
               built.seconds_packing, built.seconds_indicator, built.seconds_distance);
    fmt::print("  blob        {} bytes\n", bytes.size());
  }
  return kExitOk;
}

}  // namespace palpa::cli
