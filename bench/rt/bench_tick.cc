// Google Benchmark of one servo tick (sampler + proxy iterations + force, proxy::ProxyTick) on a
// real field, fixed point against the float64 reference (float64_proxy.h) on the same HIP
// trajectories, in the same run. Scenarios: strokes over the field's own surface in free space
// (1 mm outside), shallow contact (0.2 mm deep) and deep contact (2 mm deep).
//
//   palpa_rt_bench --field=build/kitten.palpa [--benchmark_repetitions=10 ...]
//
// Before the benchmarks it prints the agreement of the two implementations over every tick
// (max |Δ proxy| in voxels, max |Δ force| in N) and how often they took different branches.
// bench/rt/run builds the field and prints the summary table.

#include <benchmark/benchmark.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "float64_proxy.h"
#include "scenarios.h"

namespace {

using palpa::bench::Float64Field;
using palpa::bench::Float64Params;
using palpa::bench::Float64Result;
using palpa::bench::Float64State;
using palpa::bench::Float64Tick;
using palpa::bench::Scenario;
using palpa::bench::Vec3d;

struct Prepared {
  Scenario scenario;
  std::vector<Vec3d> hips_vox;  // the same HIPs in double voxels, for the reference
};

using palpa::bench::ToFloat64;
using palpa::bench::ToVoxels;

struct Agreement {
  double max_proxy_vox = 0, max_force_n = 0;  // one tick from the same state
  double run_proxy_vox = 0, run_force_n = 0;  // free-running trajectories
  int branch_mismatch = 0, ticks = 0, contact_ticks = 0;
  double mean_samples = 0;
};

void Accumulate(const palpa::proxy::TickResult& r, const Float64Result& q, double& max_proxy, double& max_force) {
  const Vec3d fp = ToVoxels(r.proxy);
  for (std::size_t k = 0; k < 3; ++k) {
    max_proxy = std::max(max_proxy, std::abs(fp[k] - q.proxy[k]));
    max_force = std::max(max_force, std::abs(r.force[k].value.ToDouble() - q.force[k]));
  }
}

// Agreement of the two implementations: per tick from the same state (what the tolerance in
// docs/realtime-core.md is about: the arithmetic), and over free-running trajectories (where a
// budget-bound, unconverged iteration lets tiny differences take different but valid paths).
Agreement Compare(const palpa::bench::Field& f, const palpa::proxy::ProxyParams& params, const Prepared& p) {
  const Float64Field ref(f.Stored(), *f.sampler);
  const Float64Params rp = Float64Params::Of(params);
  palpa::proxy::ProxyState s;
  Float64State run;
  Agreement a;
  long samples = 0;
  for (std::size_t i = 0; i < p.scenario.ticks.size(); ++i) {
    const auto& t = p.scenario.ticks[i];
    if (t.reset) {
      s = {};
      run = {};
    }
    Float64State same = ToFloat64(s);
    const Float64Result q = Float64Tick(ref, rp, same, p.hips_vox[i]);
    const Float64Result q_run = Float64Tick(ref, rp, run, p.hips_vox[i]);
    const auto r = palpa::proxy::ProxyTick(*f.sampler, params, s, t.hip);
    Accumulate(r, q, a.max_proxy_vox, a.max_force_n);
    Accumulate(r, q_run, a.run_proxy_vox, a.run_force_n);
    a.branch_mismatch += (r.contact != q.contact || r.iterations != q.iterations) ? 1 : 0;
    a.contact_ticks += r.contact ? 1 : 0;
    samples += r.iterations;
    ++a.ticks;
  }
  a.mean_samples = static_cast<double>(samples) / a.ticks;
  return a;
}

// One servo tick per iteration over the scenario's HIPs, on the blob as stored (as palpad samples
// it).
void FixedTick(benchmark::State& state, const palpa::bench::Field* f, const palpa::proxy::ProxyParams* params,
               const Prepared* p) {
  const auto& ticks = p->scenario.ticks;
  palpa::proxy::ProxyState s;
  std::size_t i = 0;
  for (auto _ : state) {
    if (ticks[i].reset) s = {};
    benchmark::DoNotOptimize(palpa::proxy::ProxyTick(*f->sampler, *params, s, ticks[i].hip));
    if (++i == ticks.size()) i = 0;
  }
  state.SetItemsProcessed(state.iterations());
}

// The float64 reference on the same storage.
void ReferenceTick(benchmark::State& state, const palpa::bench::Field* f, const palpa::proxy::ProxyParams* params,
                   const Prepared* p) {
  const Float64Field ref(f->Stored(), *f->sampler);
  const Float64Params rp = Float64Params::Of(*params);
  const auto& ticks = p->scenario.ticks;
  Float64State s;
  std::size_t i = 0;
  for (auto _ : state) {
    if (ticks[i].reset) s = {};
    benchmark::DoNotOptimize(Float64Tick(ref, rp, s, p->hips_vox[i]));
    if (++i == ticks.size()) i = 0;
  }
  state.SetItemsProcessed(state.iterations());
}

}  // namespace

int main(int argc, char** argv) {
  std::string field_path;
  std::vector<char*> args;
  for (int i = 0; i < argc; ++i) {
    if (std::strncmp(argv[i], "--field=", 8) == 0) {
      field_path = argv[i] + 8;
    } else {
      args.push_back(argv[i]);
    }
  }
  if (field_path.empty()) {
    std::fprintf(stderr, "usage: palpa_rt_bench --field=FIELD.palpa [benchmark flags]\n");
    return 2;
  }
  const auto field = palpa::bench::LoadField(field_path);
  const auto params = palpa::proxy::MakeProxyParams({}, field->view.voxel_m).value();

  static std::vector<Prepared> prepared;
  for (const auto& [name, depth] : {std::pair{"free", -1e-3}, std::pair{"shallow", 0.2e-3}, std::pair{"deep", 2e-3}}) {
    Prepared p{palpa::bench::SurfaceStrokes(*field, name, depth, 0.05, 8, 250, 1), {}};
    for (const auto& t : p.scenario.ticks) p.hips_vox.push_back(ToVoxels(t.hip));
    prepared.push_back(std::move(p));
  }
  const auto& lb = field->sampler->lipschitz();
  std::printf("field %s: %d x %d x %d nodes, voxel %.4f mm, Lipschitz norm %.4f, axis (%.3f, %.3f, %.3f)\n",
              field_path.c_str(), field->view.dims[0], field->view.dims[1], field->view.dims[2],
              field->view.voxel_m * 1e3, lb.norm / 65536.0, lb.axis[0] / 65536.0, lb.axis[1] / 65536.0,
              lb.axis[2] / 65536.0);
  std::printf("fixed point vs float64, one tick from the same state / free-running:\n");
  std::printf("%-8s %6s %8s %13s %16s %12s %13s %16s %12s\n", "scenario", "ticks", "contact", "samples/tick",
              "max|dproxy| vox", "max|df| N", "branch diff", "run |dproxy|", "run |df| N");
  for (const Prepared& p : prepared) {
    const Agreement a = Compare(*field, params, p);
    std::printf("%-8s %6d %7.1f%% %13.2f %16.2e %12.2e %13d %16.2e %12.2e\n", p.scenario.name.c_str(), a.ticks,
                100.0 * a.contact_ticks / a.ticks, a.mean_samples, a.max_proxy_vox, a.max_force_n, a.branch_mismatch,
                a.run_proxy_vox, a.run_force_n);
  }
  std::fflush(stdout);

  for (const Prepared& p : prepared) {
    benchmark::RegisterBenchmark(("fixed/" + p.scenario.name).c_str(), FixedTick, field.get(), &params, &p);
    benchmark::RegisterBenchmark(("float64/" + p.scenario.name).c_str(), ReferenceTick, field.get(), &params, &p);
  }
  int bargc = static_cast<int>(args.size());
  benchmark::Initialize(&bargc, args.data());
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
