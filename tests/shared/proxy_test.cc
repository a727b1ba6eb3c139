#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

#include "analytic_fields.h"
#include "palpa/proxy/proxy.h"

namespace palpa::proxy {
namespace {

constexpr double kVoxel = 0.0002;  // 0.2 mm, the kitten's voxel at 300 cells
constexpr std::uint32_t kN = 100;
constexpr double kRadiusVoxels = 40;  // 8 mm sphere

struct SphereWorld {
  std::vector<std::byte> bytes = testing::SphereBlob(kN, kVoxel, 6, kRadiusVoxels);
  blob::FieldView view = blob::Verify(bytes).value();
  sampler::TrilinearSampler field{view};
  GridFrame frame = GridFrame::Of(view);
  ProxyParams params = MakeProxyParams(ProxyConfig{}, kVoxel).value();
};

std::array<double, 3> Unit(std::mt19937& rng) {
  std::normal_distribution<double> g;
  double d[3] = {g(rng), g(rng), g(rng)};
  const double l = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
  return {d[0] / l, d[1] / l, d[2] / l};
}

double Norm(const std::array<double, 3>& v) { return std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]); }

std::array<double, 3> ForceN(const TickResult& r) {
  return {r.force[0].value.ToDouble(), r.force[1].value.ToDouble(), r.force[2].value.ToDouble()};
}

// The sphere is centred at the device origin; radius R = 8 mm.
TEST(Proxy, PushTwoMillimetresIntoASphere) {
  SphereWorld w;
  const double radius_m = kRadiusVoxels * kVoxel;
  std::mt19937 rng(3);
  for (int trial = 0; trial < 20; ++trial) {
    const auto d = Unit(rng);
    ProxyState state;
    TickResult r;
    // Approach from 3 mm outside to 2 mm inside over 500 ticks (1 m/s at 1 kHz would be 5 ticks;
    // this is a slow press), then hold for 50 ticks.
    for (int t = 0; t <= 550; ++t) {
      const double depth = -0.003 + 0.005 * std::min(t, 500) / 500.0;
      const double rr = radius_m - depth;
      r = ProxyTick(w.field, w.params, state, w.frame.ToGrid({rr * d[0], rr * d[1], rr * d[2]}));
      // Never inside: φ(proxy) ≥ −0.05 voxel.
      ASSERT_GE(w.field.At(r.proxy).phi, -(1 << 16) / 20) << "trial " << trial << " tick " << t;
    }
    ASSERT_TRUE(r.contact);
    const auto f = ForceN(r);
    const double expected = 800 * 0.002;
    EXPECT_NEAR(Norm(f), expected, 0.05 * expected) << "trial " << trial;
    const double cosang = (f[0] * d[0] + f[1] * d[1] + f[2] * d[2]) / Norm(f);
    EXPECT_LE(std::acos(std::min(1.0, cosang)) * 180 / std::numbers::pi, 2.0) << "trial " << trial;
  }
}

TEST(Proxy, FreeSpaceGivesExactlyZeroForceAndProxyAtHip) {
  SphereWorld w;
  std::mt19937 rng(5);
  // Fresh proxy at random free-space points ≥ 1.5 voxels outside.
  for (int t = 0; t < 1000; ++t) {
    ProxyState state;
    const auto d = Unit(rng);
    const double rr = (kRadiusVoxels + 1.5 + 4.0 * (t % 7)) * kVoxel;
    const GridPos hip = w.frame.ToGrid({rr * d[0], rr * d[1], rr * d[2]});
    const TickResult r = ProxyTick(w.field, w.params, state, hip);
    ASSERT_FALSE(r.contact) << t;
    ASSERT_EQ(r.proxy, hip) << t;
    ASSERT_EQ(r.force[0].value.raw() | r.force[1].value.raw() | r.force[2].value.raw(), 0) << t;
  }
  // A continuous orbit 1 voxel outside the surface at 0.3 m/s: the proxy keeps up every tick.
  ProxyState state;
  const double rr = (kRadiusVoxels + 1.0) * kVoxel;
  for (int t = 0; t < 2000; ++t) {
    const double a = 0.3e-3 * t / rr;  // arc length 0.3 mm per tick
    const GridPos hip = w.frame.ToGrid({rr * std::cos(a), rr * std::sin(a), 0.0});
    const TickResult r = ProxyTick(w.field, w.params, state, hip);
    ASSERT_FALSE(r.contact) << t;
    ASSERT_EQ(r.force[0].value.raw() | r.force[1].value.raw() | r.force[2].value.raw(), 0) << t;
  }
}

TEST(Proxy, ForceClampKeepsDirection) {
  SphereWorld w;
  ProxyConfig config;
  config.max_force_n = 2.0;
  const ProxyParams params = MakeProxyParams(config, kVoxel).value();
  ProxyState state;
  TickResult r;
  // Press 4 mm along +x: k·4 mm = 3.2 N > 2 N.
  for (int t = 0; t <= 600; ++t) {
    const double rr = kRadiusVoxels * kVoxel + 0.002 - 0.006 * std::min(t, 500) / 500.0;
    r = ProxyTick(w.field, params, state, w.frame.ToGrid({rr, 0, 0}));
  }
  ASSERT_TRUE(r.clamped);
  const auto f = ForceN(r);
  EXPECT_NEAR(Norm(f), 2.0, 1e-3);
  EXPECT_GT(f[0], 0);
  EXPECT_NEAR(f[1], 0, 1e-3);
  EXPECT_NEAR(f[2], 0, 1e-3);
}

TEST(Proxy, ThinPlateStopsAFastHipOnTheEntrySide) {
  // A plate 2 voxels thick (|z − c| − 1 ≤ 0), crossed at 2 m/s at 1 kHz (10 voxels a tick).
  const std::uint32_t n = 40;
  const double c = 0.5 * (n - 1);
  const auto bytes =
      testing::AnalyticBlob({n, n, n}, kVoxel, 6, [=](double, double, double k) { return std::abs(k - c) - 1.0; });
  const auto view = blob::Verify(bytes).value();
  const sampler::TrilinearSampler field(view);
  const GridFrame frame = GridFrame::Of(view);
  const ProxyParams params = MakeProxyParams(ProxyConfig{}, kVoxel).value();
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> lateral(-0.002, 0.002);
  int tunnelled = 0;
  for (int pass = 0; pass < 200; ++pass) {
    ProxyState state;
    const double x = lateral(rng), y = lateral(rng);
    TickResult r;
    for (int t = 0; t <= 6; ++t) {
      r = ProxyTick(field, params, state, frame.ToGrid({x, y, 0.003 - 0.002 * t}));  // 2 mm per tick
    }
    // Entry side is z > 0: the proxy must still be there.
    if (frame.ToMetres(r.proxy)[2] < 0) ++tunnelled;
  }
  EXPECT_EQ(tunnelled, 0);
}

TEST(ProxyParams, RejectsOutOfRangeValuesAtStartUp) {
  EXPECT_FALSE(MakeProxyParams({.k_n_per_m = -1}, kVoxel).has_value());
  EXPECT_FALSE(MakeProxyParams({.k_n_per_m = 1e9}, kVoxel).has_value());
  EXPECT_FALSE(MakeProxyParams({.max_force_n = 0}, kVoxel).has_value());
  EXPECT_FALSE(MakeProxyParams({.gamma = 1.5}, kVoxel).has_value());
  EXPECT_FALSE(MakeProxyParams({.k_n_per_m = NAN}, kVoxel).has_value());
  EXPECT_TRUE(MakeProxyParams({}, kVoxel).has_value());
}

}  // namespace
}  // namespace palpa::proxy
