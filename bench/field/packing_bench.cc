// Google Benchmark of the sphere packing (paper eq. 2-3) on cube.pwn, as `palpa build` runs it
// (positions fitted to 0.06 m, r_max = the longest side): the k-d tree (PackingRadii) on all
// 50,000 points with 1 and 2 TBB threads, and the brute force beside it on a 5,000-point subset
// (every 10th point), where the k-d tree runs too for the ratio.
//
//   palpa_field_bench [--benchmark_repetitions=3 --benchmark_format=json ...]
#include <benchmark/benchmark.h>

#include <cstdio>
#include <cstdlib>
#include <vector>

#include <tbb/global_control.h>

#include "palpa/field/packing.h"
#include "palpa/field/point_io.h"
#include "palpa/field/transform.h"

namespace {

using palpa::field::PointSet;

// cube.pwn fitted to 0.06 m: `every` = 1 for all points, 10 for the subset.
const PointSet& Cube(std::size_t every) {
  static const PointSet all = [] {
    auto points = palpa::field::ReadPoints(PALPA_DATA_DIR "/cube.pwn");
    if (!points) {
      std::fprintf(stderr, "%s\n", points.error().message.c_str());
      std::exit(2);
    }
    return palpa::field::ApplyTransform(palpa::field::FitTransform(*points, 0.06), *points);
  }();
  static const PointSet subset = [] {
    PointSet s;
    for (std::size_t i = 0; i < all.positions.size(); i += 10) {
      s.positions.push_back(all.positions[i]);
      s.normals.push_back(all.normals[i]);
    }
    return s;
  }();
  return every == 1 ? all : subset;
}

constexpr double kRMax = 0.06;

void BM_PackingKdTree(benchmark::State& state) {
  const PointSet& points = Cube(static_cast<std::size_t>(state.range(0)));
  const tbb::global_control limit(tbb::global_control::max_allowed_parallelism,
                                  static_cast<std::size_t>(state.range(1)));
  for (auto _ : state) {
    benchmark::DoNotOptimize(palpa::field::PackingRadii(points.positions, points.normals, kRMax));
  }
  state.counters["points"] = static_cast<double>(points.positions.size());
}
BENCHMARK(BM_PackingKdTree)
    ->ArgNames({"every", "threads"})
    ->Args({1, 1})
    ->Args({1, 2})
    ->Args({10, 1})
    ->Args({10, 2})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

void BM_PackingBruteForce(benchmark::State& state) {
  const PointSet& points = Cube(10);
  for (auto _ : state) {
    benchmark::DoNotOptimize(palpa::field::PackingRadiiBruteForce(points.positions, points.normals, kRMax));
  }
  state.counters["points"] = static_cast<double>(points.positions.size());
}
BENCHMARK(BM_PackingBruteForce)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
