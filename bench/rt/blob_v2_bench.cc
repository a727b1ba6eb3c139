// Sampling through blob v2's brick index against dense sampling of the same values, in one run
// (issue 7: within 1.3×), and the brick lookup itself: the dense slot index blob v2 uses against
// an open-addressing hash of the stored bricks (docs/blob-format.md § Index).
//
//   palpa_blob_v2_bench [--field=FIELD.palpa]   # a v2 blob from palpa build; default: a sphere
//
// Points: 4096 fixed random positions with |φ| below the band (where the proxy samples), the same
// for both storages; strokes: 64 walks of 64 steps of 0.1 voxel (coherent, as a proxy samples).
// Dense: a FieldView over blob::DenseQ16 of the v2 blob (identical values). bricks: the sampler's
// plain Phi/At on the blob; bricks_cached: the same through a PhiCache/GradientCache kept from one
// sample to the next, as the proxy keeps them (a dense grid has no use for one).
#include <benchmark/benchmark.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "palpa/blob/blob.h"
#include "palpa/sampler/trilinear.h"

namespace {

using palpa::sampler::GridPos;
using palpa::sampler::TrilinearSampler;

struct Fixture {
  std::optional<palpa::blob::VerifiedField> v2;
  std::optional<palpa::blob::VerifiedField> v1;   // blob::DenseV1 of v2: the same values, dense
  std::vector<GridPos> points;                    // random, in band
  std::vector<GridPos> strokes;                   // coherent walks
  std::vector<std::array<std::int32_t, 3>> octs;  // octants of the points' cells, for the lookups
};

Fixture& Get() {
  static Fixture f;
  return f;
}

std::vector<std::byte> SphereBlob() {
  constexpr std::uint32_t n = 160;
  std::vector<std::int32_t> phi(std::size_t{n} * n * n);
  std::size_t idx = 0;
  for (std::uint32_t i = 0; i < n; ++i)
    for (std::uint32_t j = 0; j < n; ++j)
      for (std::uint32_t k = 0; k < n; ++k) {
        const double d = std::sqrt((i - 79.5) * (i - 79.5) + (j - 80.2) * (j - 80.2) + (k - 78.9) * (k - 78.9)) - 60.0;
        phi[idx++] = static_cast<std::int32_t>(std::lround(std::clamp(d, -60.0, 60.0) * 65536.0));
      }
  palpa::blob::BlobMetaV2 m;
  m.meta.dims = {n, n, n};
  m.meta.voxel_m = 0.0002;
  return palpa::blob::EncodeV2(m, phi);
}

bool Prepare(const std::string& path) {
  Fixture& f = Get();
  std::vector<std::byte> bytes;
  if (path.empty()) {
    bytes = SphereBlob();
  } else {
    auto b = palpa::blob::ReadFile(path.c_str());
    if (!b) {
      std::fprintf(stderr, "%s: %s\n", path.c_str(), b.error().what());
      return false;
    }
    bytes = std::move(*b);
  }
  auto v = palpa::blob::VerifyOwned(std::move(bytes));
  if (!v || v->view().version != palpa::blob::kVersion2) {
    std::fprintf(stderr, "need a valid v2 blob: %s\n", v ? "this is v1" : v.error().what());
    return false;
  }
  f.v2.emplace(std::move(*v));
  f.v1.emplace(palpa::blob::VerifyOwned(palpa::blob::DenseV1(f.v2->view())).value());
  const TrilinearSampler s(f.v2->view());
  std::mt19937 rng(5);
  std::array<std::uniform_int_distribution<std::int32_t>, 3> u = {
      std::uniform_int_distribution<std::int32_t>(0, (f.v2->view().dims[0] - 1) << 16),
      std::uniform_int_distribution<std::int32_t>(0, (f.v2->view().dims[1] - 1) << 16),
      std::uniform_int_distribution<std::int32_t>(0, (f.v2->view().dims[2] - 1) << 16)};
  while (f.points.size() < 4096) {
    const GridPos p{u[0](rng), u[1](rng), u[2](rng)};
    const std::int32_t phi = s.Phi(p);
    if (phi > -(f.v2->view().band_voxels << 16) && phi < (f.v2->view().band_outside << 16)) {
      f.points.push_back(p);
      f.octs.push_back({p.x >> 18, p.y >> 18, p.z >> 18});
    }
  }
  // Strokes: 64 walks of 64 steps of 0.1 voxel from in-band points, in random directions (the
  // coherent pattern of a servo loop, where a proxy moves ≤ a voxel per tick).
  std::normal_distribution<double> nd;
  for (std::size_t w = 0; w < 64; ++w) {
    double d[3] = {nd(rng), nd(rng), nd(rng)};
    const double l = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    GridPos p = f.points[w * 61];
    for (std::size_t n = 0; n < 64; ++n) {
      f.strokes.push_back(p);
      const GridPos q{p.x + static_cast<std::int32_t>(6554 * d[0] / l),
                      p.y + static_cast<std::int32_t>(6554 * d[1] / l),
                      p.z + static_cast<std::int32_t>(6554 * d[2] / l)};
      if (q.x >= 0 && q.y >= 0 && q.z >= 0 && q.x <= (f.v2->view().dims[0] - 1) << 16 &&
          q.y <= (f.v2->view().dims[1] - 1) << 16 && q.z <= (f.v2->view().dims[2] - 1) << 16)
        p = q;
    }
  }
  std::printf("field: %d x %d x %d nodes, %u bricks, %u octants, %zu bytes; %zu in-band points\n", f.v2->view().dims[0],
              f.v2->view().dims[1], f.v2->view().dims[2], f.v2->view().bricks()->brick_count(),
              f.v2->view().bricks()->octant_count(), f.v2->view().blob_size, f.points.size());
  return true;
}

// One sample per iteration: φ alone (kGradient false, Phi) or φ and ∇φ (At), on the bricks or the
// dense copy, at the random points or along the strokes.
template <bool kGradient, bool kBricks, bool kStrokes, bool kCached = false>
void BM_Sample(benchmark::State& state) {
  const Fixture& f = Get();
  const TrilinearSampler s(kBricks ? f.v2->view() : f.v1->view());
  const std::vector<GridPos>& points = kStrokes ? f.strokes : f.points;
  palpa::sampler::PhiCache phi_cache;
  palpa::sampler::GradientCache gradient_cache;
  std::size_t n = 0;
  for (auto _ : state) {
    if constexpr (kGradient && kCached) {
      benchmark::DoNotOptimize(s.At(points[n], gradient_cache));
    } else if constexpr (kGradient) {
      benchmark::DoNotOptimize(s.At(points[n]));
    } else if constexpr (kCached) {
      benchmark::DoNotOptimize(s.Phi(points[n], phi_cache));
    } else {
      benchmark::DoNotOptimize(s.Phi(points[n]));
    }
    n = (n + 1) & 4095;
  }
}

// Octant lookup alone: octant → data pointer through the dense slot index and the brick's octant
// table (two dependent loads), or through a linear-probing hash of the stored octants (what a
// hash index would cost instead; uniform regions would then also need their φ somewhere).
const std::int16_t* DenseLookup(const palpa::blob::BrickAccessor& v, const std::array<std::int32_t, 3>& o) {
  const std::size_t slot = (static_cast<std::size_t>(o[0] >> 1) * static_cast<std::size_t>(v.brick_dims()[1]) +
                            static_cast<std::size_t>(o[1] >> 1)) *
                               static_cast<std::size_t>(v.brick_dims()[2]) +
                           static_cast<std::size_t>(o[2] >> 1);
  std::uint32_t e = v.index()[slot];
  if ((e & palpa::blob::kSlotEmpty) != 0) return nullptr;
  e = v.tables()[8 * std::size_t{e} + static_cast<std::size_t>(((o[0] & 1) << 2) | ((o[1] & 1) << 1) | (o[2] & 1))];
  if ((e & palpa::blob::kSlotEmpty) != 0) return nullptr;
  return v.octants() + std::size_t{e} * 64;
}

void BM_LookupDenseIndex(benchmark::State& state) {
  const Fixture& f = Get();
  std::size_t n = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(DenseLookup(*f.v2->view().bricks(), f.octs[n]));
    n = (n + 1) & 4095;
  }
  state.counters["index_bytes"] =
      static_cast<double>(4 * static_cast<std::size_t>(f.v2->view().bricks()->brick_dims()[0]) *
                              static_cast<std::size_t>(f.v2->view().bricks()->brick_dims()[1]) *
                              static_cast<std::size_t>(f.v2->view().bricks()->brick_dims()[2]) +
                          32 * std::size_t{f.v2->view().bricks()->brick_count()});
}

void BM_LookupHash(benchmark::State& state) {
  const Fixture& f = Get();
  const std::array<std::uint32_t, 3> od = {2 * static_cast<std::uint32_t>(f.v2->view().bricks()->brick_dims()[0]),
                                           2 * static_cast<std::uint32_t>(f.v2->view().bricks()->brick_dims()[1]),
                                           2 * static_cast<std::uint32_t>(f.v2->view().bricks()->brick_dims()[2])};
  const auto key = [&](const std::array<std::int32_t, 3>& o) {
    return (static_cast<std::uint32_t>(o[0]) * od[1] + static_cast<std::uint32_t>(o[1])) * od[2] +
           static_cast<std::uint32_t>(o[2]);
  };
  std::size_t cap = 1;
  while (cap < 2 * std::size_t{f.v2->view().bricks()->octant_count()} + 2) cap <<= 1;  // load ≤ 0.5
  std::vector<std::uint64_t> table(cap, ~std::uint64_t{0});                            // (key << 32) | octant
  const auto hash = [&](std::uint32_t k) { return (k * 0x9E3779B1U) & (cap - 1); };
  for (std::int32_t x = 0; x < static_cast<std::int32_t>(od[0]); ++x)
    for (std::int32_t y = 0; y < static_cast<std::int32_t>(od[1]); ++y)
      for (std::int32_t z = 0; z < static_cast<std::int32_t>(od[2]); ++z) {
        const std::int16_t* p = DenseLookup(*f.v2->view().bricks(), {x, y, z});
        if (p == nullptr) continue;
        std::size_t h = hash(key({x, y, z}));
        while (table[h] != ~std::uint64_t{0}) h = (h + 1) & (cap - 1);
        table[h] = (std::uint64_t{key({x, y, z})} << 32) |
                   static_cast<std::uint64_t>((p - f.v2->view().bricks()->octants()) / 64);
      }
  std::size_t n = 0;
  for (auto _ : state) {
    const std::uint32_t k = key(f.octs[n]);
    std::size_t h = hash(k);
    const std::int16_t* p = nullptr;
    while (table[h] != ~std::uint64_t{0}) {
      if ((table[h] >> 32) == k) {
        p = f.v2->view().bricks()->octants() + (table[h] & 0xFFFFFFFFU) * 64;
        break;
      }
      h = (h + 1) & (cap - 1);
    }
    benchmark::DoNotOptimize(p);
    n = (n + 1) & 4095;
  }
  state.counters["index_bytes"] = static_cast<double>(cap * 8);
}

BENCHMARK(BM_Sample<false, false, false>)->Name("Phi/dense");
BENCHMARK(BM_Sample<false, true, false>)->Name("Phi/bricks");
BENCHMARK(BM_Sample<true, false, false>)->Name("At/dense");
BENCHMARK(BM_Sample<true, true, false>)->Name("At/bricks");
BENCHMARK(BM_Sample<false, false, true>)->Name("Phi_strokes/dense");
BENCHMARK(BM_Sample<false, true, true>)->Name("Phi_strokes/bricks");
BENCHMARK(BM_Sample<true, false, true>)->Name("At_strokes/dense");
BENCHMARK(BM_Sample<true, true, true>)->Name("At_strokes/bricks");
BENCHMARK(BM_Sample<false, true, false, true>)->Name("Phi/bricks_cached");
BENCHMARK(BM_Sample<true, true, false, true>)->Name("At/bricks_cached");
BENCHMARK(BM_Sample<false, true, true, true>)->Name("Phi_strokes/bricks_cached");
BENCHMARK(BM_Sample<true, true, true, true>)->Name("At_strokes/bricks_cached");
BENCHMARK(BM_LookupDenseIndex)->Name("Lookup/dense_index");
BENCHMARK(BM_LookupHash)->Name("Lookup/hash");

}  // namespace

int main(int argc, char** argv) {
  std::string field;
  std::vector<char*> rest;
  for (int i = 0; i < argc; ++i) {
    if (std::strncmp(argv[i], "--field=", 8) == 0) {
      field = argv[i] + 8;
    } else {
      rest.push_back(argv[i]);
    }
  }
  if (!Prepare(field)) return 2;
  int n = static_cast<int>(rest.size());
  benchmark::Initialize(&n, rest.data());
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
