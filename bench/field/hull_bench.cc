// Google Benchmark of the side rules' geometric helpers against what they replace (issue 20,
// docs/field-methods.md § A scan on a sphere), in one run so that they compare as ratios:
// - the samples' hull: ConvexHull::Beyond and ::Distance against the scan over every face, on
//   the support planes of a sphere (the hull of samples on a curved surface: about twice as many
//   faces as samples; CGAL's radar.xyz has 40,748), at points inside, near and beyond the faces;
// - a crossing list's order: SortDistinctIndices against std::sort, for lists dense in their span
//   (a sphere's outer ball) and sparse (the sort path).
//
//   palpa_hull_bench [--benchmark_repetitions=3 ...]
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cstdint>
#include <limits>
#include <numeric>
#include <random>
#include <vector>

#include <Eigen/Core>

#include "palpa/field/convex_hull.h"
#include "palpa/field/index_order.h"

namespace {

using V3 = Eigen::Vector3d;
using V4 = Eigen::Vector4d;

// `faces` tangent planes of the unit sphere and 4,096 points at radius 0.2-1.05 (some beyond).
struct Hull {
  std::vector<V4> planes;
  std::vector<V3> points;
};

const Hull& Sphere(std::size_t faces) {
  static std::vector<std::pair<std::size_t, Hull>> made;
  for (const auto& [n, h] : made)
    if (n == faces) return h;
  std::mt19937 rng(1);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> radius(0.2, 1.05);
  Hull h;
  for (std::size_t f = 0; f < faces; ++f) {
    const V3 n = V3(normal(rng), normal(rng), normal(rng)).normalized();
    h.planes.emplace_back(n.x(), n.y(), n.z(), -1.0);
  }
  for (int q = 0; q < 4096; ++q)
    h.points.push_back(radius(rng) * V3(normal(rng), normal(rng), normal(rng)).normalized());
  made.emplace_back(faces, std::move(h));
  return made.back().second;
}

constexpr double kLimit = 0.02;  // "beyond": 2 % of the radius past the faces

void BM_HullBeyondScan(benchmark::State& state) {
  const Hull& h = Sphere(static_cast<std::size_t>(state.range(0)));
  std::size_t q = 0;
  for (auto _ : state) {
    const V3& p = h.points[q++ % h.points.size()];
    benchmark::DoNotOptimize(
        std::any_of(h.planes.begin(), h.planes.end(), [&](const V4& f) { return f.head<3>().dot(p) + f[3] > kLimit; }));
  }
}
BENCHMARK(BM_HullBeyondScan)->ArgName("faces")->Arg(400)->Arg(4000)->Arg(40000);

void BM_HullBeyondGrouped(benchmark::State& state) {
  const Hull& h = Sphere(static_cast<std::size_t>(state.range(0)));
  const palpa::field::ConvexHull hull(h.planes, V3::Zero());
  std::size_t q = 0;
  for (auto _ : state) benchmark::DoNotOptimize(hull.Beyond(h.points[q++ % h.points.size()], kLimit));
}
BENCHMARK(BM_HullBeyondGrouped)->ArgName("faces")->Arg(400)->Arg(4000)->Arg(40000);

void BM_HullDistanceScan(benchmark::State& state) {
  const Hull& h = Sphere(static_cast<std::size_t>(state.range(0)));
  std::size_t q = 0;
  for (auto _ : state) {
    const V3& p = h.points[q++ % h.points.size()];
    double best = -std::numeric_limits<double>::infinity();
    for (const V4& f : h.planes) best = std::max(best, f.head<3>().dot(p) + f[3]);
    benchmark::DoNotOptimize(best);
  }
}
BENCHMARK(BM_HullDistanceScan)->ArgName("faces")->Arg(400)->Arg(4000)->Arg(40000);

void BM_HullDistanceGrouped(benchmark::State& state) {
  const Hull& h = Sphere(static_cast<std::size_t>(state.range(0)));
  const palpa::field::ConvexHull hull(h.planes, V3::Zero());
  std::size_t q = 0;
  for (auto _ : state) benchmark::DoNotOptimize(hull.Distance(h.points[q++ % h.points.size()]));
}
BENCHMARK(BM_HullDistanceGrouped)->ArgName("faces")->Arg(400)->Arg(4000)->Arg(40000);

// `count` distinct indices of [0, span), shuffled; each iteration orders a fresh copy.
std::vector<std::size_t> Indices(std::size_t count, std::size_t span) {
  std::vector<std::size_t> all(span);
  std::iota(all.begin(), all.end(), std::size_t{0});
  std::shuffle(all.begin(), all.end(), std::mt19937(2));
  all.resize(count);
  return all;
}

void BM_OrderStdSort(benchmark::State& state) {
  const auto list = Indices(static_cast<std::size_t>(state.range(0)), static_cast<std::size_t>(state.range(1)));
  std::vector<std::size_t> work;
  for (auto _ : state) {
    work = list;
    std::sort(work.begin(), work.end());
    benchmark::DoNotOptimize(work.data());
  }
}
BENCHMARK(BM_OrderStdSort)->ArgNames({"count", "span"})->Args({5000, 20000})->Args({200, 1000000});

void BM_OrderMarks(benchmark::State& state) {
  const auto list = Indices(static_cast<std::size_t>(state.range(0)), static_cast<std::size_t>(state.range(1)));
  std::vector<std::size_t> work;
  std::vector<std::uint64_t> marks;
  for (auto _ : state) {
    work = list;
    palpa::field::SortDistinctIndices(work, marks);
    benchmark::DoNotOptimize(work.data());
  }
}
BENCHMARK(BM_OrderMarks)->ArgNames({"count", "span"})->Args({5000, 20000})->Args({200, 1000000});

}  // namespace

BENCHMARK_MAIN();
