// The fixed-point tick against the float64 reference of the same equations (bench/rt/
// float64_proxy.*), one tick at a time from the same state, on the benchmark's scenarios: the
// tolerance in docs/realtime-core.md § Float64 reference. (Free-running trajectories are not
// compared: where the iteration is budget-bound, tiny differences take different valid paths.)
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdio>

#include "float64_proxy.h"
#include "palpa/field/build.h"
#include "palpa/field/point_io.h"
#include "palpa/field/transform.h"
#include "scenarios.h"

namespace palpa::bench {
namespace {

struct Agreement {
  double max_proxy_vox = 0;  // max over ticks and axes of |Δ proxy|
  double max_force_n = 0;    // max over ticks and axes of |Δ f|
  int contact_mismatch = 0;
  int ticks = 0;
};

Agreement Compare(const Field& f, const Scenario& s) {
  const proxy::ProxyParams params = proxy::MakeProxyParams({}, f.view.voxel_m).value();
  const Float64Field ref(f.Stored(), *f.sampler);  // the storage the fixed tick reads
  const Float64Params rp = Float64Params::Of(params);
  proxy::ProxyState state;
  Agreement a;
  for (const Tick& t : s.ticks) {
    if (t.reset) state = {};
    Float64State same = ToFloat64(state);
    const Float64Result q = Float64Tick(ref, rp, same, ToVoxels(t.hip));
    const proxy::TickResult r = proxy::ProxyTick(*f.sampler, params, state, t.hip);
    const Vec3d p = ToVoxels(r.proxy);
    for (std::size_t k = 0; k < 3; ++k) {
      a.max_proxy_vox = std::max(a.max_proxy_vox, std::abs(p[k] - q.proxy[k]));
      a.max_force_n = std::max(a.max_force_n, std::abs(r.force[k].value.ToDouble() - q.force[k]));
    }
    a.contact_mismatch += r.contact != q.contact ? 1 : 0;
    ++a.ticks;
  }
  return a;
}

void Check(const char* name, const Agreement& a) {
  std::printf(
      "[ measured ] %s: %d ticks, fixed vs float64 one tick from the same state: max |dproxy| %.2e voxel, "
      "max |df| %.2e N, contact differs %d\n",
      name, a.ticks, a.max_proxy_vox, a.max_force_n, a.contact_mismatch);
  // docs/realtime-core.md § Float64 reference: 0.01 voxel and 2 mN (k·h·0.01 voxel at 800 N/m,
  // 0.2 mm), and the contact decision may differ only where the two sit on a threshold (a few in
  // a thousand ticks).
  EXPECT_LE(a.max_proxy_vox, 0.01) << name;
  EXPECT_LE(a.max_force_n, 0.002) << name;
  EXPECT_LE(a.contact_mismatch, a.ticks / 200 + 1) << name;
}

TEST(Float64Agreement, SphereStrokeAndPlatePasses) {
  const auto sphere = SphereField(100, 0.0002, 40);
  for (const double speed : {0.02, 0.1})
    Check("sphere stroke", Compare(*sphere, SphereStroke(*sphere, 40, 2e-3, speed)));
  const std::array<double, 3> n = {0.3, 0.4, std::sqrt(0.75)};
  const auto plate = PlateField(64, 0.0002, n, 0.25);
  for (const double speed : {0.5, 2.0})
    Check("plate passes", Compare(*plate, PlatePasses(*plate, n, 0.25, speed, 50, 3)));
}

TEST(Float64Agreement, KittenStrokes) {
  // The kitten as `palpa build data/kitten.xyz` makes it (default method, --fit 0.06, 300 cells).
  auto points = field::ReadPoints(PALPA_DATA_DIR "/kitten.xyz");
  ASSERT_TRUE(points.has_value());
  const field::PointSet device = field::ApplyTransform(field::FitTransform(*points, 0.06), *points);
  auto built = field::BuildField(device.positions, device.normals, {});
  ASSERT_TRUE(built.has_value());
  const field::GridSpec& g = built->field.grid();
  blob::BlobMeta meta;
  for (std::size_t a = 0; a < 3; ++a) {
    meta.dims[a] = static_cast<std::uint32_t>(g.dims[a]);
    meta.origin_m[a] = g.origin_m[static_cast<Eigen::Index>(a)];
  }
  meta.voxel_m = g.voxel_m;
  meta.band_voxels = static_cast<std::uint32_t>(g.band_voxels);
  meta.method = blob::Method::kHermite;
  std::vector<std::int32_t> phi(g.NodeCount());
  built->field.WriteQ16(phi);
  Field f(blob::VerifyOwned(blob::Encode(meta, phi)).value(), std::nullopt);
  for (const auto& [name, depth] :
       {std::pair{"kitten free", -1e-3}, std::pair{"kitten shallow", 0.2e-3}, std::pair{"kitten deep", 2e-3}}) {
    Check(name, Compare(f, SurfaceStrokes(f, name, depth, 0.05, 8, 250, 1)));
  }
}

}  // namespace
}  // namespace palpa::bench
