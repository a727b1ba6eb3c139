#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>

#include "analytic_fields.h"
#include "palpa/proxy/proxy.h"

namespace palpa::proxy {
namespace {

constexpr double kVoxel = 0.0002;  // 0.2 mm, the kitten's voxel at 300 cells
constexpr std::uint32_t kN = 100;
constexpr double kRadiusVoxels = 40;  // 8 mm sphere
constexpr double kK = 800;            // N/m, the ProxyConfig default
constexpr std::int32_t kOne = 1 << 16;

using Vec3 = std::array<double, 3>;

double Norm(const Vec3& v) { return std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]); }
Vec3 Sub(const Vec3& a, const Vec3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
double Dot(const Vec3& a, const Vec3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
double AngleDeg(const Vec3& a, const Vec3& b) {
  return std::acos(std::clamp(Dot(a, b) / (Norm(a) * Norm(b)), -1.0, 1.0)) * 180 / std::numbers::pi;
}

Vec3 Unit(std::mt19937& rng) {
  std::normal_distribution<double> g;
  const Vec3 d = {g(rng), g(rng), g(rng)};
  const double l = Norm(d);
  return {d[0] / l, d[1] / l, d[2] / l};
}

Vec3 ForceN(const TickResult& r) {
  return {r.force[0].value.ToDouble(), r.force[1].value.ToDouble(), r.force[2].value.ToDouble()};
}

// An analytic world: a blob, its sampler and frame, and default parameters.
struct World {
  explicit World(std::vector<std::byte> b, ProxyConfig config = {})
      : bytes(std::move(b)),
        view(blob::Verify(bytes).value()),
        field(view),
        frame(GridFrame::Of(view)),
        params(MakeProxyParams(config, view.voxel_m).value()) {}
  std::vector<std::byte> bytes;
  blob::FieldView view;
  sampler::TrilinearSampler field;
  GridFrame frame;
  ProxyParams params;

  double PhiVoxels(GridPos p) const { return field.Phi(p) / 65536.0; }
};

// The sphere is centred at the device origin (AnalyticBlob centres the grid); radius R = 8 mm.
World Sphere(ProxyConfig config = {}) { return World(testing::SphereBlob(kN, kVoxel, 6, kRadiusVoxels), config); }

TEST(Proxy, PushTwoMillimetresIntoASphere) {
  World w = Sphere();
  const double radius_m = kRadiusVoxels * kVoxel;
  std::mt19937 rng(3);
  for (int trial = 0; trial < 20; ++trial) {
    const auto d = Unit(rng);
    ProxyState state;
    TickResult r;
    // Approach from 3 mm outside to 2 mm inside over 500 ticks (a slow press), then hold 50 ticks.
    for (int t = 0; t <= 550; ++t) {
      const double depth = -0.003 + 0.005 * std::min(t, 500) / 500.0;
      const double rr = radius_m - depth;
      r = ProxyTick(w.field, w.params, state, w.frame.ToGrid({rr * d[0], rr * d[1], rr * d[2]}));
      ASSERT_LE(r.iterations, w.params.max_iterations);
      // Never inside: φ(proxy) ≥ −0.05 voxel.
      ASSERT_GE(w.PhiVoxels(r.proxy), -0.05) << "trial " << trial << " tick " << t;
    }
    ASSERT_TRUE(r.contact);
    EXPECT_TRUE(r.converged);
    const auto f = ForceN(r);
    const double expected = kK * 0.002;
    EXPECT_NEAR(Norm(f), expected, 0.01 * expected) << "trial " << trial;
    EXPECT_LE(AngleDeg(f, d), 0.5) << "trial " << trial;
  }
}

TEST(Proxy, FreeSpaceGivesExactlyZeroForceAndProxyAtHip) {
  World w = Sphere();
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
    ASSERT_EQ(r.proxy, hip) << t;
    ASSERT_EQ(r.force[0].value.raw() | r.force[1].value.raw() | r.force[2].value.raw(), 0) << t;
  }
}

TEST(Proxy, LeavingTheSurfaceReleasesTheProxyAtOnce) {
  // Pressed 1 mm in, then the HIP jumps 1 mm outside: the proxy rejoins it in the same tick.
  World w = Sphere();
  const double r0 = kRadiusVoxels * kVoxel;
  ProxyState state;
  for (int t = 0; t <= 100; ++t) {
    ProxyTick(w.field, w.params, state, w.frame.ToGrid({0, r0 + 1e-3 - 2e-3 * std::min(t, 50) / 50.0, 0}));
  }
  ASSERT_TRUE(ProxyTick(w.field, w.params, state, w.frame.ToGrid({0, r0 - 1e-3, 0})).contact);
  const GridPos out = w.frame.ToGrid({0.0002, r0 + 1e-3, 0.0001});
  const TickResult r = ProxyTick(w.field, w.params, state, out);
  EXPECT_FALSE(r.contact);
  EXPECT_EQ(r.proxy, out);
}

TEST(Proxy, StartedInsideFollowsTheHipWithoutForceUntilItHasBeenOutside) {
  World w = Sphere();
  const double r0 = kRadiusVoxels * kVoxel;
  ProxyState state;
  for (int t = 0; t < 20; ++t) {
    const GridPos hip = w.frame.ToGrid({0, 0, r0 - 2e-3 + 1e-5 * t});
    const TickResult r = ProxyTick(w.field, w.params, state, hip);
    EXPECT_FALSE(r.contact);
    EXPECT_EQ(r.proxy, hip);
  }
  ProxyTick(w.field, w.params, state, w.frame.ToGrid({0, 0, r0 + 1e-3}));  // out once
  TickResult r;
  for (int t = 0; t <= 20; ++t) r = ProxyTick(w.field, w.params, state, w.frame.ToGrid({0, 0, r0 + 1e-3 - 1e-4 * t}));
  EXPECT_TRUE(r.contact);  // 1 mm in
  EXPECT_NEAR(Norm(ForceN(r)), kK * 1e-3, 0.01 * kK * 1e-3);
}

TEST(Proxy, ForceClampKeepsDirection) {
  ProxyConfig config;
  config.max_force_n = 2.0;
  World w = Sphere(config);
  ProxyState state;
  TickResult r;
  // Press 4 mm along +x: k·4 mm = 3.2 N > 2 N.
  for (int t = 0; t <= 600; ++t) {
    const double rr = kRadiusVoxels * kVoxel + 0.002 - 0.006 * std::min(t, 500) / 500.0;
    r = ProxyTick(w.field, w.params, state, w.frame.ToGrid({rr, 0, 0}));
  }
  ASSERT_TRUE(r.clamped);
  const auto f = ForceN(r);
  EXPECT_NEAR(Norm(f), 2.0, 1e-3);
  EXPECT_GT(f[0], 0);
  EXPECT_NEAR(f[1], 0, 1e-3);
  EXPECT_NEAR(f[2], 0, 1e-3);
}

// Sliding: a HIP held `depth` inside the 8 mm sphere moves along a great circle for 1 s. Checked
// against the sphere's closed form every tick: the proxy on the surface, |f| vs k·(R − |X_h|)
// and its direction vs the radial direction at the HIP.
struct SlideFigures {
  double max_abs_phi_voxels = 0;
  double rms_force_error = 0;  // relative
  double max_force_error = 0;  // relative
  double max_angle_deg = 0;
  double min_energy_margin_j = 1e9;  // min over ticks of E_n + B_n (passivity observer)
  double min_energy_j = 1e9;         // min over ticks of E_n
  double max_zoh_bound_j = 0;
  int max_iterations = 0;
  int ticks = 0;
};

SlideFigures SlideOnSphere(World& w, double depth_m, double speed_m_s, const Vec3& axis_a, const Vec3& axis_b) {
  const double r0 = kRadiusVoxels * kVoxel;
  const double rh = r0 - depth_m;
  const auto hip_at = [&](double angle, double radius) {
    return Vec3{radius * (std::cos(angle) * axis_a[0] + std::sin(angle) * axis_b[0]),
                radius * (std::cos(angle) * axis_a[1] + std::sin(angle) * axis_b[1]),
                radius * (std::cos(angle) * axis_a[2] + std::sin(angle) * axis_b[2])};
  };
  ProxyState state;
  PassivityObserver po;
  SlideFigures out;
  // 200 ms press from 1 mm outside to `depth`, 1 s slide at `speed` (angular speed at the surface).
  const int press = 200, slide = 1000;
  double sum_sq = 0;
  for (int t = 0; t <= press + slide; ++t) {
    const double u = std::min(1.0, t / static_cast<double>(press));
    const double radius = (r0 + 1e-3) + (rh - r0 - 1e-3) * u;
    const double angle = t > press ? speed_m_s * 1e-3 * (t - press) / r0 : 0.0;
    const Vec3 hip_m = hip_at(angle, radius);
    const GridPos hip = w.frame.ToGrid(hip_m);
    const TickResult r = ProxyTick(w.field, w.params, state, hip);
    po.Update(hip, r, w.params);
    out.max_iterations = std::max(out.max_iterations, r.iterations);
    out.min_energy_margin_j = std::min(out.min_energy_margin_j, po.EnergyJ(kVoxel) + po.ZohBoundJ(kVoxel));
    out.min_energy_j = std::min(out.min_energy_j, po.EnergyJ(kVoxel));
    out.max_zoh_bound_j = po.ZohBoundJ(kVoxel);
    if (t <= press) continue;
    ++out.ticks;
    EXPECT_TRUE(r.contact) << t;
    out.max_abs_phi_voxels = std::max(out.max_abs_phi_voxels, std::abs(w.PhiVoxels(r.proxy)));
    const Vec3 hip_exact = w.frame.ToMetres(hip);  // the HIP as the loop saw it
    const double penetration = r0 - Norm(hip_exact);
    const auto f = ForceN(r);
    const double err = (Norm(f) - kK * penetration) / (kK * penetration);
    sum_sq += err * err;
    out.max_force_error = std::max(out.max_force_error, std::abs(err));
    out.max_angle_deg = std::max(out.max_angle_deg, AngleDeg(f, hip_exact));
  }
  out.rms_force_error = std::sqrt(sum_sq / out.ticks);
  return out;
}

Vec3 RandomGreatCircleAxis(std::mt19937& rng, const Vec3& a) {
  Vec3 b = Unit(rng);
  const double ab = Dot(a, b);
  b = {b[0] - ab * a[0], b[1] - ab * a[1], b[2] - ab * a[2]};
  const double bl = Norm(b);
  return {b[0] / bl, b[1] / bl, b[2] / bl};
}

TEST(Proxy, SlidingTwoMillimetresDeepTracksTheSphere) {
  // Issue 6: a HIP held 2 mm deep, moved tangentially for 1 s: |φ(proxy)| ≤ 0.05 voxel at the
  // end of every tick, |f| within 2 % of k·penetration (RMS), direction within 1°; and the
  // passivity observer never below the zero-order-hold bound. Asserted at 0.02 m/s (palpa trace
  // synth's default) and 0.05 m/s; 0.1 and 0.25 m/s are measured and bounded more loosely: the
  // proxy's tangential reach per sample is about 1.5δ/Λ (docs/realtime-core.md), so a fast stroke
  // lags a little, it never leaps.
  World w = Sphere();
  std::mt19937 rng(21);
  for (const double speed : {0.02, 0.05, 0.1, 0.25}) {
    for (int trial = 0; trial < 2; ++trial) {
      const Vec3 a = Unit(rng);
      const SlideFigures s = SlideOnSphere(w, 0.002, speed, a, RandomGreatCircleAxis(rng, a));
      std::printf(
          "[ measured ] slide 2 mm deep at %.2f m/s: max |phi(proxy)| %.4f voxel, |f| error RMS %.3f %% (max %.3f %%), "
          "direction max %.3f deg, samples/tick max %d; passivity: min E %.2e J, min E+B %.2e J (B %.2e J)\n",
          speed, s.max_abs_phi_voxels, 100 * s.rms_force_error, 100 * s.max_force_error, s.max_angle_deg,
          s.max_iterations, s.min_energy_j, s.min_energy_margin_j, s.max_zoh_bound_j);
      EXPECT_LE(s.max_iterations, w.params.max_iterations);
      EXPECT_GE(s.min_energy_margin_j, -1e-9) << "passivity observer below the zero-order-hold bound";
      if (speed <= 0.05) {
        EXPECT_LE(s.max_abs_phi_voxels, 0.05);
        EXPECT_LE(s.rms_force_error, 0.02);
        EXPECT_LE(s.max_angle_deg, 1.0);
      } else {
        EXPECT_LE(s.max_abs_phi_voxels, 0.05);
        EXPECT_LE(s.rms_force_error, 0.02);
        EXPECT_LE(s.max_angle_deg, 5.0);
      }
    }
  }
}

TEST(Proxy, FrictionConeSticksBelowAndSlidesAbove) {
  // A plane z = 20 (normal +z). Pressed 1 mm (5 voxels) in, the HIP then moves along x. With
  // μs = 0.5 the proxy must not move while the HIP's tangential offset is below μs·depth
  // (2.5 voxels); beyond it, it slides and trails at the dynamic cone's edge, so |f_t|/|f_n| = μd.
  const std::uint32_t n = 48;
  ProxyConfig config;
  config.mu_static = 0.5;
  config.mu_dynamic = 0.3;
  World w(testing::AnalyticBlob({n, n, n}, kVoxel, 6, [](double, double, double k) { return k - 20.0; }), config);
  const double surface_m = w.view.origin_m[2] + 20 * kVoxel;
  const auto at = [&](double x_m, double z_m) { return w.frame.ToGrid({x_m, 0.0, z_m}); };
  ProxyState state;
  TickResult r;
  for (int t = 0; t <= 100; ++t)
    r = ProxyTick(w.field, w.params, state, at(0, surface_m + 1e-3 - 2e-3 * std::min(t, 50) / 50));
  ASSERT_TRUE(r.contact);
  const GridPos stuck = r.proxy;
  // Below the cone: tangential offset up to 0.9·μs·depth, in 0.02 mm steps.
  const double depth_m = 1e-3;
  for (double x = 0; x <= 0.9 * 0.5 * depth_m; x += 2e-5) {
    r = ProxyTick(w.field, w.params, state, at(x, surface_m - depth_m));
    ASSERT_TRUE(r.contact);
    ASSERT_EQ(r.proxy.x, stuck.x) << "stuck proxy moved at x = " << x;
  }
  // Above it: keep moving to 5 mm. The proxy slips back to the dynamic cone's edge (|f_t|/|f_n| =
  // μd right after each slip), sticks again until the static cone's edge (μs): Coulomb stick-slip.
  double min_ratio = 1e9, max_ratio = 0;
  for (double x = 0.46e-3; x <= 5e-3; x += 2e-5) {
    r = ProxyTick(w.field, w.params, state, at(x, surface_m - depth_m));
    ASSERT_TRUE(r.contact);
    const auto f = ForceN(r);
    ASSERT_LT(f[0], 0) << "friction opposes the motion";
    min_ratio = std::min(min_ratio, -f[0] / f[2]);
    max_ratio = std::max(max_ratio, -f[0] / f[2]);
  }
  EXPECT_GT(w.frame.ToMetres(r.proxy)[0], 2e-3) << "the proxy slides";
  std::printf("[ measured ] friction: sliding |f_t|/|f_n| in [%.4f, %.4f] (mu_d 0.3, mu_s 0.5)\n", min_ratio,
              max_ratio);
  EXPECT_NEAR(min_ratio, 0.3, 0.01);
  EXPECT_LE(max_ratio, 0.5 + 0.01);
  // Friction off (the default): the same path leaves no tangential force once the HIP stops.
  World plain(testing::AnalyticBlob({n, n, n}, kVoxel, 6, [](double, double, double k) { return k - 20.0; }));
  ProxyState s2;
  for (int t = 0; t <= 100; ++t)
    r = ProxyTick(plain.field, plain.params, s2, at(0, surface_m + 1e-3 - 2e-3 * std::min(t, 50) / 50));
  for (int t = 0; t <= 20; ++t) r = ProxyTick(plain.field, plain.params, s2, at(1e-3, surface_m - depth_m));
  EXPECT_NEAR(ForceN(r)[0], 0, 1e-3);
}

// A plate 2 voxels thick, |n·x − c| ≤ 1 (node units), on a 64³ grid with 0.2 mm voxels; n is a
// random unit vector within `tilt_deg` of z, and the mid-plane passes within half a voxel of the
// grid centre at a random sub-voxel offset.
struct Plate {
  Vec3 n;
  double c;
  World world;
};

constexpr std::uint32_t kPlateN = 64;
constexpr double kPlateCentre = 0.5 * (kPlateN - 1);

Plate MakePlate(std::mt19937& rng, double tilt_deg, bool v2 = false) {
  std::uniform_real_distribution<double> u(0, 1);
  const double tilt = tilt_deg * std::numbers::pi / 180 * u(rng), az = 2 * std::numbers::pi * u(rng);
  const Vec3 n = {std::sin(tilt) * std::cos(az), std::sin(tilt) * std::sin(az), std::cos(tilt)};
  const double c = kPlateCentre * (n[0] + n[1] + n[2]) + u(rng) - 0.5;
  const auto sdf = [=](double i, double j, double k) { return std::abs(n[0] * i + n[1] * j + n[2] * k - c) - 1.0; };
  const std::array<std::uint32_t, 3> dims = {kPlateN, kPlateN, kPlateN};
  return {n, c,
          World(v2 ? testing::AnalyticBlobV2(dims, kVoxel, 6, sdf) : testing::AnalyticBlob(dims, kVoxel, 6, sdf))};
}

struct PassResult {
  int passes = 0;
  int tunnelled = 0;
  double min_phi_voxels = 1e9;
  int max_iterations = 0;
};

// Drives the HIP in straight lines from 2 mm on the entry side (n·x > c) to 2 mm past the far
// side, at `speed` m/s sampled at 1 kHz, through random points near the grid centre in random
// directions within 60° of −n. A pass tunnels if the proxy ends on the far side.
PassResult DrivePlatePasses(Plate& plate, double speed, int passes, std::mt19937& rng) {
  World& w = plate.world;
  std::uniform_real_distribution<double> u(-1, 1);
  PassResult out;
  const Vec3& n = plate.n;
  const Vec3 origin = w.view.origin_m;
  const auto plane_m = [&](const Vec3& x_m) {  // signed distance to the plate's mid-plane, m
    return Dot(n, Sub(x_m, origin)) - plate.c * kVoxel;
  };
  while (out.passes < passes) {
    Vec3 d = {u(rng), u(rng), u(rng)};
    const double dl = Norm(d);
    if (dl > 1 || dl < 0.1) continue;
    d = {d[0] / dl, d[1] / dl, d[2] / dl};
    if (Dot(d, n) > 0) d = {-d[0], -d[1], -d[2]};
    if (Dot(d, n) > -0.5) continue;  // within 60° of −n
    const Vec3 centre = {origin[0] + (kPlateCentre + 3 * u(rng)) * kVoxel,
                         origin[1] + (kPlateCentre + 3 * u(rng)) * kVoxel,
                         origin[2] + (kPlateCentre + 3 * u(rng)) * kVoxel};
    const double to_plane = plane_m(centre);
    const Vec3 on = {centre[0] - to_plane * n[0], centre[1] - to_plane * n[1], centre[2] - to_plane * n[2]};
    const double reach = 2e-3 / -Dot(d, n);  // path length from 2 mm above to the mid-plane
    const Vec3 start = {on[0] - reach * d[0], on[1] - reach * d[1], on[2] - reach * d[2]};
    const int ticks = static_cast<int>(std::ceil(2 * reach / (speed * 1e-3)));
    ProxyState state;
    TickResult r;
    for (int t = 0; t <= ticks; ++t) {
      const double s = std::min(2 * reach, speed * 1e-3 * t);
      r = ProxyTick(w.field, w.params, state,
                    w.frame.ToGrid({start[0] + s * d[0], start[1] + s * d[1], start[2] + s * d[2]}));
      out.min_phi_voxels = std::min(out.min_phi_voxels, w.PhiVoxels(r.proxy));
      out.max_iterations = std::max(out.max_iterations, r.iterations);
    }
    ++out.passes;
    if (plane_m(w.frame.ToMetres(r.proxy)) < 0) ++out.tunnelled;
  }
  return out;
}

// 10,000 randomized passes per speed: 20 plates (random tilt up to 45°, random offset) × 500,
// stored dense (v1) or as palpa build's default v2 bricks with free-space bounds, where pieces in
// the band are certified with the band's own Lipschitz bound (TrilinearSampler::lipschitz_band).
void ThinPlatePasses(bool v2) {
  std::mt19937 rng(9);
  for (const double speed : {0.5, 2.0}) {
    PassResult total;
    for (int p = 0; p < 20; ++p) {
      Plate plate = MakePlate(rng, 45.0, v2);
      const PassResult r = DrivePlatePasses(plate, speed, 500, rng);
      total.passes += r.passes;
      total.tunnelled += r.tunnelled;
      total.min_phi_voxels = std::min(total.min_phi_voxels, r.min_phi_voxels);
      total.max_iterations = std::max(total.max_iterations, r.max_iterations);
    }
    std::printf("[ measured ] 2-voxel plate (%s) at %.1f m/s: %d tunnelled of %d passes, min phi(proxy) %.4f voxel\n",
                v2 ? "v2" : "v1", speed, total.tunnelled, total.passes, total.min_phi_voxels);
    EXPECT_EQ(total.passes, 10000);
    EXPECT_EQ(total.tunnelled, 0);
    EXPECT_GE(total.min_phi_voxels, -0.25 - 1e-4);  // rests at φ ≥ −δ (a leaving march's ends; contact −δ/2)
  }
}

TEST(Proxy, ThinPlateIsNeverTunnelledAtHalfAndTwoMetresPerSecond) { ThinPlatePasses(false); }

TEST(Proxy, ThinPlateStoredAsBricksIsNeverTunnelled) { ThinPlatePasses(true); }

TEST(Proxy, HeldHipConvergesWithoutSampling) {
  World w = Sphere();
  ProxyState state;
  TickResult r;
  const double r0 = kRadiusVoxels * kVoxel;
  for (int t = 0; t <= 300; ++t) {
    r = ProxyTick(w.field, w.params, state, w.frame.ToGrid({0.001, 0.002, r0 - 1e-3 * std::min(t, 100) / 100.0}));
  }
  EXPECT_TRUE(r.contact);
  EXPECT_TRUE(r.converged);
  EXPECT_EQ(r.iterations, 0);  // φ and ∇φ at the proxy are carried over (only φ(X_h) is sampled)
}

// A HIP pushed right through a thin tube (radius 3 voxels, along z) and on, 12 voxels beyond
// it, then held. The god-object answer (Zilles & Salisbury 1995): the proxy stays on the entry
// side held by the surface (the spring keeps pulling the HIP back, no matter that φ(HIP) > 0),
// slides round the tube towards the HIP, and is released once, where the straight way to the HIP
// clears the tube; then it joins the HIP. Found by the HIL knot case: the proxy used to stop 8 mm
// behind a free HIP with zero force, and the force to switch on and off.
TEST(Proxy, HipThroughAThinTubeIsHeldThenReleasedOnceAndRejoined) {
  constexpr std::uint32_t n = 64;
  constexpr double kTubeRadius = 3;
  const double c = 0.5 * (n - 1);
  World w(testing::AnalyticBlob({n, n, n}, kVoxel, 6,
                                [=](double i, double j, double) { return std::hypot(i - c, j - c) - kTubeRadius; }));
  // Off the axis (y, voxels): exactly through it the pull is balanced and the proxy stays on the
  // entry side (an unstable equilibrium that any tremor breaks).
  for (const auto& [offset, travel] : {std::pair{0.7, 120}, {-1.9, 120}, {0.7, 12}, {-1.9, 12}}) {
    ProxyState state;
    int on = 0, off = 0, held_beyond = 0;
    bool was_contact = false;
    TickResult r;
    const int hold = 400;  // 120 ticks: 0.25 voxel (50 µm) a tick, 0.05 m/s; 12 ticks: 0.5 m/s
    for (int t = 0; t <= travel + hold; ++t) {
      const double x = -15 + 30.0 * std::min(t, travel) / travel;  // voxels from the axis
      const GridPos hip = w.frame.ToGrid({x * kVoxel, offset * kVoxel, 0.0});
      r = ProxyTick(w.field, w.params, state, hip);
      ASSERT_GE(w.PhiVoxels(r.proxy), -0.25) << "offset " << offset << " tick " << t;
      if (r.contact && !was_contact) ++on;
      if (!r.contact && was_contact) ++off;
      was_contact = r.contact;
      // Beyond the tube with the proxy not yet round it: held (a force towards the entry side).
      if (x > kTubeRadius + 1 && r.contact) {
        ++held_beyond;
        EXPECT_LT(ForceN(r)[0], 0) << "offset " << offset << " tick " << t;
      }
    }
    std::printf(
        "[ measured ] tube pass at %.2f m/s, offset %.1f voxel: contact on %d, off %d, held beyond the tube %d ticks\n",
        30 * kVoxel * 1000 / travel, offset, on, off, held_beyond);
    EXPECT_EQ(on, 1) << "offset " << offset;
    EXPECT_EQ(off, 1) << "offset " << offset;
    if (travel < 20) {
      EXPECT_GT(held_beyond, 0) << "offset " << offset;
    }
    EXPECT_EQ(r.proxy, w.frame.ToGrid({15 * kVoxel, offset * kVoxel, 0.0})) << "offset " << offset;
    EXPECT_FALSE(r.contact);
  }
}

// Passivity with the zero-order-hold bound of docs/realtime-core.md: fast radial taps on the
// sphere (0.5 m/s, 2 mm deep). On release the held force acts over the whole last interval,
// past the surface, so E dips below zero by about k·u·|ΔX_h|; B = (k/2)Σ|ΔX_h|² over intervals
// in contact covers it (the HIL sphere-taps case found the older bound, (k/2)Σ|Δu|², did not).
TEST(Proxy, FastTapsStayWithinTheZeroOrderHoldBound) {
  World w = Sphere();
  const double r0 = kRadiusVoxels * kVoxel;
  std::mt19937 rng(11);
  double min_energy = 0, min_margin = 1e9;
  for (int tap = 0; tap < 20; ++tap) {
    const auto d = Unit(rng);
    ProxyState state;
    PassivityObserver po;
    // From 2.13 mm out to 1.87 mm in and back at 0.5 m/s (0.5 mm a tick), then rest outside: the
    // last tick in contact is 0.37 mm deep, the next 0.13 mm out.
    for (int t = 0; t <= 40; ++t) {
      const double depth = -0.00213 + 0.0005 * (t <= 8 ? t : t <= 16 ? 16 - t : 0);
      const double rr = r0 - depth;
      const GridPos hip = w.frame.ToGrid({rr * d[0], rr * d[1], rr * d[2]});
      po.Update(hip, ProxyTick(w.field, w.params, state, hip), w.params);
      min_energy = std::min(min_energy, po.EnergyJ(kVoxel));
      min_margin = std::min(min_margin, po.EnergyJ(kVoxel) + po.ZohBoundJ(kVoxel));
    }
  }
  std::printf("[ measured ] 20 taps at 0.5 m/s: min E %.3g J, min E + B %.3g J\n", min_energy, min_margin);
  EXPECT_LT(min_energy, -1e-5);  // the ZOH effect is there to bound
  EXPECT_GE(min_margin, -1e-9);
}

// The fixed-point tick is integer-only, so its output bits are a function of its input bits
// alone: this golden (FNV-1a over every output of a scripted press, slide, leave and plate
// crossing, fed with integer grid positions) must match on x86-64, aarch64 and armhf. It changes
// only when the algorithm does, and then deliberately: the test prints the new value (update it
// here, and re-bless the HIL goldens, hil/, with `palpa hil bless`).
std::uint64_t TickHash(std::uint64_t h, const TickResult& r) {
  const std::int64_t words[] = {r.proxy.x,
                                r.proxy.y,
                                r.proxy.z,
                                r.force[0].value.raw(),
                                r.force[1].value.raw(),
                                r.force[2].value.raw(),
                                r.penetration.value.raw(),
                                r.contact,
                                r.clamped,
                                r.converged,
                                r.iterations};
  for (const std::int64_t w : words) {
    for (int b = 0; b < 8; ++b) {
      h ^= static_cast<std::uint8_t>(static_cast<std::uint64_t>(w) >> (8 * b));
      h *= 0x100000001b3ULL;
    }
  }
  return h;
}

// v2: the same sphere stored as palpa build stores it; clear_caches: the sampling caches emptied
// before every tick (its first samples then read the brick index).
std::uint64_t ScriptedRunHash(bool v2 = false, bool clear_caches = false) {
  const double m = 0.5 * (kN - 1);
  World w = v2 ? World(testing::AnalyticBlobV2(
                     {kN, kN, kN}, kVoxel, 6,
                     [m](double i, double j, double k) {
                       return std::sqrt((i - m) * (i - m) + (j - m) * (j - m) + (k - m) * (k - m)) - kRadiusVoxels;
                     }))
               : Sphere();
  const std::int32_t c = (kN - 1) << 15;  // grid centre, Q16.16
  const std::int32_t r0 = static_cast<std::int32_t>(kRadiusVoxels * 65536);
  ProxyState state;
  std::uint64_t h = 0xcbf29ce484222325ULL;
  for (std::int32_t t = 0; t < 3000; ++t) {
    // Integer inputs only (no libm): press along +z from 3 voxels out to 8 in, slide along y on
    // a straight line (the sphere curves away beneath it), then leave.
    const std::int32_t depth = t < 300    ? -3 * 65536 + t * 11 * 65536 / 300
                               : t < 2500 ? 8 * 65536
                                          : 8 * 65536 - (t - 2500) * 2000;
    const std::int32_t y = t < 300 ? 0 : (t - 300) * 900;  // 0.014 voxel a tick, 30 voxels in all
    const GridPos hip{c, c + y, c + r0 - depth};
    if (clear_caches) {
      state.proxy_phi_cache = {};
      state.proxy_gradient_cache = {};
      state.hip_phi_cache = {};
    }
    h = TickHash(h, ProxyTick(w.field, w.params, state, hip));
  }
  return h;
}

TEST(Proxy, OutputBitsAreAFunctionOfInputBitsGolden) {
  const std::uint64_t h = ScriptedRunHash();
  std::printf("[ measured ] scripted run hash 0x%016llx\n", static_cast<unsigned long long>(h));
  EXPECT_EQ(h, ScriptedRunHash()) << "not even deterministic on one machine";
  EXPECT_EQ(h, 0x663b5e2396002067ULL) << "golden changed: the tick's arithmetic or control flow changed";
}

TEST(Proxy, SamplingCachesChangeNoOutputBit) {
  // The scripted run on blob v2, whose samples mostly hit the caches the state keeps, against the
  // same run with the caches emptied before every tick: every output of every tick is the same.
  EXPECT_EQ(ScriptedRunHash(true), ScriptedRunHash(true, true));
  EXPECT_NE(ScriptedRunHash(true), ScriptedRunHash());  // the v2 run is not the v1 one (Q7.8 values)
}

TEST(ProxyParams, RejectsOutOfRangeValuesAtStartUp) {
  EXPECT_FALSE(MakeProxyParams({.k_n_per_m = -1}, kVoxel).has_value());
  EXPECT_FALSE(MakeProxyParams({.k_n_per_m = 1e9}, kVoxel).has_value());
  EXPECT_FALSE(MakeProxyParams({.max_force_n = 0}, kVoxel).has_value());
  EXPECT_FALSE(MakeProxyParams({.max_force_n = 101}, kVoxel).has_value());
  EXPECT_FALSE(MakeProxyParams({.gamma = 1.5}, kVoxel).has_value());
  EXPECT_FALSE(MakeProxyParams({.beta = 0}, kVoxel).has_value());
  EXPECT_FALSE(MakeProxyParams({.max_iterations = 1}, kVoxel).has_value());
  EXPECT_FALSE(MakeProxyParams({.max_iterations = 65}, kVoxel).has_value());
  EXPECT_FALSE(MakeProxyParams({.mu_static = -0.1}, kVoxel).has_value());
  EXPECT_FALSE(MakeProxyParams({.mu_static = 0.3, .mu_dynamic = 0.4}, kVoxel).has_value());
  EXPECT_FALSE(MakeProxyParams({.depth_tolerance_voxels = 0.6}, kVoxel).has_value());
  EXPECT_FALSE(MakeProxyParams({.k_n_per_m = NAN}, kVoxel).has_value());
  EXPECT_FALSE(MakeProxyParams({.k_n_per_m = 1}, 1e-4).has_value());  // k·h = 1e-4 N/voxel: too coarse
  EXPECT_FALSE(MakeProxyParams({}, 0.0).has_value());
  EXPECT_TRUE(MakeProxyParams({}, kVoxel).has_value());
  EXPECT_TRUE(MakeProxyParams({.mu_static = 0.5, .mu_dynamic = 0.3}, kVoxel).has_value());
  EXPECT_FALSE(MakeProxyParams({.max_iterations = 4, .settle_samples = 5}, kVoxel).has_value());
  EXPECT_FALSE(MakeProxyParams({.max_iterations = 4, .gradient_samples = 0}, kVoxel).has_value());
}

}  // namespace
}  // namespace palpa::proxy

// ---------------------------------------------------------------- issue 19: real hands

namespace palpa::proxy {
namespace {

std::int64_t Raw2(const TickResult& r) {
  std::int64_t s = 0;
  for (const auto& f : r.force) s += std::int64_t{f.value.raw()} * f.value.raw();
  return s;
}

// min φ (voxels) along [a, b], sampled every 1/16 voxel in the sampler's own field.
double MinPhiAlong(const World& w, GridPos a, GridPos b) {
  const double dx = b.x - a.x, dy = b.y - a.y, dz = b.z - a.z;
  const int n = 1 + static_cast<int>(std::sqrt(dx * dx + dy * dy + dz * dz) / 4096.0);
  double m = 1e9;
  for (int i = 0; i <= n; ++i) {
    const double s = static_cast<double>(i) / n;
    m = std::min(m, w.PhiVoxels({static_cast<std::int32_t>(a.x + s * dx), static_cast<std::int32_t>(a.y + s * dy),
                                 static_cast<std::int32_t>(a.z + s * dz)}));
  }
  return m;
}

// Item 1: the proxy holds only when the way to the HIP runs into the object. Strokes that press
// into the sphere and leave it tangentially, 5 mm/s to 0.6 m/s (a fast one leaves the proxy behind,
// the HIP outside the sphere but behind the proxy's tangent plane): no force on any tick where the
// HIP is outside and the straight way from the proxy is clear, i.e. never deeper than where the
// proxy rests (or the surface) by more than δ/4.
TEST(ProxyHands, NoForceWhileTheHipIsOutsideAndTheWayIsClear) {
  World w = Sphere();
  const double r0 = kRadiusVoxels * kVoxel;
  std::mt19937 rng(19);
  int checked = 0, forced = 0;
  for (int trial = 0; trial < 60; ++trial) {
    const Vec3 n = Unit(rng);
    Vec3 t = Unit(rng);
    const double dot = Dot(t, n);
    t = {t[0] - dot * n[0], t[1] - dot * n[1], t[2] - dot * n[2]};
    const double lt = Norm(t);
    t = {t[0] / lt, t[1] / lt, t[2] / lt};
    const double depth = 0.2e-3 + 1.8e-3 * (trial % 10) / 9.0;
    ProxyState state;
    for (int k = 0; k < 1400; ++k) {
      // 200 ticks pressing in, then a straight tangential stroke at 5 mm/s–0.6 m/s out of the sphere.
      const double press = std::min(k, 200) / 200.0;
      const double along = k < 200 ? 0 : (k - 200) * (5e-6 + 595e-6 * std::pow((trial % 7) / 6.0, 2));
      const double rr = r0 + 1e-3 - (1e-3 + depth) * press;
      const Vec3 x = {rr * n[0] + along * t[0], rr * n[1] + along * t[1], rr * n[2] + along * t[2]};
      const GridPos hip = w.frame.ToGrid(x);
      const TickResult r = ProxyTick(w.field, w.params, state, hip);
      if (w.PhiVoxels(hip) < 0) continue;
      if (MinPhiAlong(w, r.proxy, hip) < std::min(w.PhiVoxels(r.proxy), 0.0) - 0.0625) continue;
      ++checked;
      if (Raw2(r) != 0) {
        ++forced;
        ADD_FAILURE() << "trial " << trial << " tick " << k << ": " << Norm(ForceN(r)) << " N with the way clear";
        break;
      }
    }
  }
  std::printf("[ measured ] %d ticks with the HIP outside and the way clear, %d with a force\n", checked, forced);
  EXPECT_GT(checked, 5000);
  EXPECT_EQ(forced, 0);
}

// Item 2: a hand that overpowers the device and pushes right through a 16 mm sphere and out of its
// far side, at 0.3 and 1 m/s, then holds there. While the HIP is inside, the force never drops to
// zero; it never steps by more than the spring's ends move (k·(|ΔX_h| + |ΔX_p|)) plus the fade
// rate max_force/1024; the proxy stays on the entry side, never deeper than −δ; beyond the far
// side the held pull fades to zero within 1.1 s (not a sustained 8 N through the object).
TEST(ProxyHands, PassThroughAWholeObjectHasNoStepAndTheHeldPullFades) {
  World w = Sphere();
  const double r0 = kRadiusVoxels * kVoxel;
  const double k_voxel = w.params.k.value.ToDouble();
  const double fade = (w.params.max_force.value.raw() >> 10) / 65536.0;
  for (const double speed : {0.3, 1.0}) {
    for (const double offset : {0.0, 0.3, 2.0}) {  // mm off the centre line
      ProxyState state;
      TickResult prev;
      GridPos prev_hip{}, prev_proxy{};
      const double start = r0 + 2e-3, end = -(r0 + 3e-3);
      const int travel = static_cast<int>((start - end) / (speed * 1e-3));
      int inside_ticks = 0, drops = 0, steps = 0, faded_at = -1;
      bool touched = false;
      for (int k = 0; k < travel + 1500; ++k) {
        const double z = start + (end - start) * std::min(k, travel) / travel;
        const GridPos hip = w.frame.ToGrid({offset * 1e-3, 0.0, z});
        const TickResult r = ProxyTick(w.field, w.params, state, hip);
        const double phi_h = w.PhiVoxels(hip);
        ASSERT_GE(w.PhiVoxels(r.proxy), -0.25) << speed << " " << offset << " tick " << k;
        // On the centre line (an unstable equilibrium) the proxy stays on the entry side; off it, it
        // slides round the surface towards the HIP (never through: φ(proxy) ≥ −δ above).
        if (offset == 0.0) {
          ASSERT_GE(w.frame.ToMetres(r.proxy)[2], -1e-4) << "proxy on the far side, tick " << k;
        }
        touched = touched || r.contact;
        if (touched && phi_h < 0) {
          ++inside_ticks;
          if (!r.contact) ++drops;
        }
        if (k > 0) {
          const auto d = [](GridPos a, GridPos b) {
            return std::sqrt(std::pow(a.x - b.x, 2.0) + std::pow(a.y - b.y, 2.0) + std::pow(a.z - b.z, 2.0)) / 65536.0;
          };
          const double df = Norm(Sub(ForceN(r), ForceN(prev)));
          const bool release = !r.contact && phi_h >= 0;
          if (!release && df > k_voxel * (d(hip, prev_hip) + d(r.proxy, prev_proxy)) + fade + 1e-4) {
            ++steps;
            ADD_FAILURE() << speed << " m/s offset " << offset << " tick " << k << ": step " << df << " N";
          }
        }
        if (k > travel && faded_at < 0 && !r.contact) faded_at = k - travel;
        prev = r, prev_hip = hip, prev_proxy = r.proxy;
      }
      std::printf(
          "[ measured ] through at %.1f m/s, %.1f mm off centre: %d ticks inside, %d drops, %d steps, pull "
          "gone %d ticks after the far side\n",
          speed, offset, inside_ticks, drops, steps, faded_at);
      EXPECT_GT(inside_ticks, 0);
      EXPECT_EQ(drops, 0);
      EXPECT_EQ(steps, 0);
      EXPECT_GE(faded_at, 0) << "a sustained pull through the object";
      EXPECT_LE(faded_at, 1100);
    }
  }
}

// Item 3: a plate 6 voxels thick that reaches the grid's faces (φ < 0 on them). A hand that comes
// from outside the grid, level with the plate, and moves in through the face: the proxy meets the
// plate's extension as a wall (a force) and never enters the plate (φ(proxy) ≥ −δ, sampled inside
// the grid, where the old background made the outside free space).
TEST(ProxyHands, ThePlateIsNotEnteredThroughAGridFace) {
  constexpr std::uint32_t n = 40;
  const double c = 0.5 * (n - 1);
  World w(testing::AnalyticBlob({n, n, n}, kVoxel, 6, [=](double, double, double k) { return std::abs(k - c) - 3; }));
  const double last = (n - 1) * kVoxel, half = 0.5 * last;
  ProxyState state;
  int forced = 0;
  double deepest = 1e9;
  // From 8 voxels beyond the +x face and 6 voxels above the plate, down to 1 voxel inside the
  // plate's top (still outside the grid), then in along −x to the grid's centre.
  const Vec3 a = {last + 8 * kVoxel - half, 0, 6 * kVoxel}, b = {last + 8 * kVoxel - half, 0, 2 * kVoxel},
             e = {0, 0, 2 * kVoxel};
  for (int k = 0; k <= 1000; ++k) {
    const double s = std::min(k, 200) / 200.0, u = std::max(0, k - 200) / 800.0;
    const Vec3 x = {a[0] + (b[0] - a[0]) * s + (e[0] - b[0]) * u, 0, a[2] + (b[2] - a[2]) * s};
    const TickResult r = ProxyTick(w.field, w.params, state, w.frame.ToGrid(x));
    // φ at the proxy's nearest grid point: the field inside the grid, whatever the sampler says outside.
    const GridPos p = r.proxy;
    const auto cl = [&](std::int32_t v) { return std::clamp<std::int32_t>(v, 0, (n - 1) << 16); };
    deepest = std::min(deepest, w.PhiVoxels({cl(p.x), cl(p.y), cl(p.z)}));
    forced += r.contact ? 1 : 0;
  }
  std::printf("[ measured ] entering through a face: deepest proxy %.3f voxel, %d ticks with a force\n", deepest,
              forced);
  EXPECT_GE(deepest, -0.25);
  EXPECT_GT(forced, 500);
}

// Item 4 (issue 18, finding 3): the clamp rounds towards zero, so Σ f_i² ≤ max_force² exactly, in
// integers. k = 1e5 N/m (20 N/voxel: one LSB of |u| is 3e-4 N, where the old rounding overshot to
// 8.0003 N) and 800 N/m, max force 8 N and 0.5 N, HIP pressed deep under a tilted plane.
TEST(ProxyHands, ClampNeverExceedsTheMaximumForceByOneBit) {
  const double c = 31.5;
  const Vec3 nrm = {0.36, 0.48, 0.8};  // unit: 0.36² + 0.48² + 0.8² = 1
  for (const double k : {800.0, 1e5}) {
    for (const double max_f : {8.0, 0.5}) {
      ProxyConfig cfg;
      cfg.k_n_per_m = k;
      cfg.max_force_n = max_f;
      World w(testing::AnalyticBlob({64, 64, 64}, kVoxel, 6,
                                    [&](double i, double j, double kk) {
                                      return nrm[0] * (i - c) + nrm[1] * (j - c) + nrm[2] * (kk - c);
                                    }),
              cfg);
      const std::int64_t max_raw = w.params.max_force.value.raw();
      std::mt19937 rng(4);
      std::uniform_real_distribution<double> off(-3e-3, 3e-3), dep(0.02e-3, 4e-3);
      int clamped = 0;
      std::int64_t worst = 0;
      for (int trial = 0; trial < 200; ++trial) {
        ProxyState state;
        const double ox = off(rng), oy = off(rng), d = dep(rng);
        const Vec3 base = {ox, oy, -(nrm[0] * ox + nrm[1] * oy) / nrm[2]};  // on the plane
        for (int t = 0; t <= 40; ++t) {
          const double s = 1.5e-3 - (1.5e-3 + d) * std::min(t, 30) / 30.0;  // from 1.5 mm out to d in
          const TickResult r =
              ProxyTick(w.field, w.params, state,
                        w.frame.ToGrid({base[0] + s * nrm[0], base[1] + s * nrm[1], base[2] + s * nrm[2]}));
          worst = std::max(worst, Raw2(r) - max_raw * max_raw);
          clamped += r.clamped ? 1 : 0;
        }
      }
      std::printf("[ measured ] k %g N/m, max %g N: %d clamped ticks, worst Σf² − max² = %lld LSB²\n", k, max_f,
                  clamped, static_cast<long long>(worst));
      if (k * 4e-3 > max_f) {
        EXPECT_GT(clamped, 100);  // 4 mm deep at most
      }
      EXPECT_LE(worst, 0) << "k " << k << " max " << max_f;
    }
  }
  // Hand-computed: u = X_p − X_h = (3, 4, 12) voxels, |u| = 13; k·h = 800 N/m · 0.2 mm = 0.16 N/voxel
  // = 10486 raw (Q16.16). Clamped to 0.5 N (32768 raw): ⌊32768·u_i/13⌋ = 7561, 10082, 30247 (to
  // nearest, 7562.) and Σ² = 1,073,696,454 ≤ 32768². Unclamped at 8 N: 10486·u_i = 31458, 41944,
  // 125832 raw (2.08 N).
  ProxyConfig cfg;
  cfg.k_n_per_m = 800;
  cfg.max_force_n = 0.5;
  const ProxyParams p05 = MakeProxyParams(cfg, kVoxel).value();
  cfg.max_force_n = 8;
  const ProxyParams p8 = MakeProxyParams(cfg, kVoxel).value();
  ASSERT_EQ(p05.k.value.raw(), 10486);
  const GridPos hip{5 << 16, 6 << 16, 7 << 16}, proxy{8 << 16, 10 << 16, 19 << 16};
  const auto f05 = SpringForce(p05, proxy, hip);
  EXPECT_EQ(f05[0].value.raw(), 7561);
  EXPECT_EQ(f05[1].value.raw(), 10082);
  EXPECT_EQ(f05[2].value.raw(), 30247);
  const auto f8 = SpringForce(p8, proxy, hip);
  EXPECT_EQ(f8[0].value.raw(), 31458);
  EXPECT_EQ(f8[1].value.raw(), 41944);
  EXPECT_EQ(f8[2].value.raw(), 125832);
  // And pointing the other way (towards zero is not towards −∞): u = (−3, −4, −12).
  const auto fn = SpringForce(p05, hip, proxy);
  EXPECT_EQ(fn[0].value.raw(), -7561);
  EXPECT_EQ(fn[2].value.raw(), -30247);
}

}  // namespace
}  // namespace palpa::proxy
