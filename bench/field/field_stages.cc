// Stage times and counters of one field build (not a test; bench/field/run.sh calls it):
//   palpa_field_stages POINTS.xyz|.pwn CELLS [hermite|edt|erosion] [--threads N] [--repeat R]
//       [--no-leak-guard]
// Prints one JSON object: the minimum over R builds of each stage's wall time (s), the build's
// CPU time (user + system, s), and the hermite counters. The grid is the one `palpa build`
// makes (--fit 0.06, band 6).
#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <memory>
#include <string>
#include <string_view>

#include <tbb/global_control.h>

#include "palpa/field/build.h"
#include "palpa/field/point_io.h"
#include "palpa/field/transform.h"

namespace {

double CpuSeconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return static_cast<double>(u.ru_utime.tv_sec + u.ru_stime.tv_sec) +
         1e-6 * static_cast<double>(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

}  // namespace

int main(int argc, char** argv) {
  using palpa::field::FieldMethod;
  if (argc < 3) {
    std::fprintf(stderr, "usage: %s POINTS CELLS [hermite|edt|erosion] [--threads N] [--repeat R] [--no-leak-guard]\n",
                 argv[0]);
    return 2;
  }
  palpa::field::BuildOptions options;
  options.grid.cells = std::atoi(argv[2]);
  int threads = 0, repeat = 1;
  for (int a = 3; a < argc; ++a) {
    const std::string_view arg = argv[a];
    if (arg == "edt") options.method = FieldMethod::kEdt;
    if (arg == "erosion") options.method = FieldMethod::kErosion;
    if (arg == "--no-leak-guard") options.leak_guard = false;
    if (arg == "--threads" && a + 1 < argc) threads = std::atoi(argv[++a]);
    if (arg == "--repeat" && a + 1 < argc) repeat = std::max(1, std::atoi(argv[++a]));
  }
  std::unique_ptr<tbb::global_control> limit;
  if (threads > 0) {
    limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                  static_cast<std::size_t>(threads));
  }
  const auto points = palpa::field::ReadPoints(argv[1]);
  if (!points) {
    std::fprintf(stderr, "%s\n", points.error().message.c_str());
    return 2;
  }
  const auto device = palpa::field::ApplyTransform(palpa::field::FitTransform(*points, 0.06), *points);
  constexpr double kInf = std::numeric_limits<double>::infinity();
  double wall = kInf, cpu = kInf, packing = kInf, distance = kInf, patches = kInf, active = kInf, evaluate = kInf,
         project = kInf;
  palpa::field::BuildResult last;
  for (int r = 0; r < repeat; ++r) {
    const double cpu0 = CpuSeconds();
    const auto t0 = std::chrono::steady_clock::now();
    auto built = palpa::field::BuildField(device.positions, device.normals, options);
    const double w = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (!built) {
      std::fprintf(stderr, "%s\n", built.error().message.c_str());
      return 2;
    }
    wall = std::min(wall, w);
    cpu = std::min(cpu, CpuSeconds() - cpu0);
    packing = std::min(packing, built->seconds_packing);
    distance = std::min(distance, built->seconds_distance);
    patches = std::min(patches, built->hermite.seconds_patches);
    active = std::min(active, built->hermite.seconds_active);
    evaluate = std::min(evaluate, built->hermite.seconds_evaluate);
    project = std::min(project, built->hermite.seconds_project);
    last = std::move(*built);
  }
  const auto& g = last.field.grid();
  const auto& hs = last.hermite;
  std::printf(
      "{\"points\": %zu, \"cells\": %d, \"method\": \"%s\", \"dims\": [%d, %d, %d], \"repeat\": %d, "
      "\"wall_s\": %.4f, \"cpu_s\": %.4f, \"packing_s\": %.4f, \"distance_s\": %.4f, \"patches_s\": %.4f, "
      "\"active_s\": %.4f, \"evaluate_s\": %.4f, \"project_s\": %.4f, \"allocated_bricks\": %zu, "
      "\"bricks_evaluated\": %zu, \"bricks_added\": %zu, \"label_minority_votes\": %zu, \"sign_conflict_nodes\": %zu, "
      "\"interface_nodes_scaled\": %zu, \"node_updates\": %zu, \"bricks_allocated_by_projection\": %zu, "
      "\"sweeps\": %d, \"balls_shrunk\": %zu, \"inside_nodes\": %zu}\n",
      device.positions.size(), options.grid.cells, std::string(palpa::field::MethodName(options.method)).c_str(),
      g.dims[0], g.dims[1], g.dims[2], repeat, wall, cpu, packing, distance, patches, active, evaluate, project,
      last.field.AllocatedBricks(), hs.bricks_evaluated, hs.bricks_added, hs.label_minority_votes,
      hs.lipschitz.sign_conflict_nodes, hs.lipschitz.interface_nodes_scaled, hs.lipschitz.node_updates,
      hs.lipschitz.bricks_allocated, hs.lipschitz.sweeps, last.balls_shrunk, last.inside_nodes);
  return 0;
}
