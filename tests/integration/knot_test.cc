// The proxy on a thin real shape: the knot mesh (data/knot1.off, a closed genus-1 tube), sampled
// into oriented points (palpa_mesh), built into a field with palpa_field's default method, and
// crossed by a HIP at 0.5 and 2 m/s at 1 kHz. The truth for "tunnelling" is the mesh itself:
// the exact signed distance to it (palpa::mesh::TrueDistances, CGAL), not the field the proxy
// runs on.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>
#include <vector>

#include "palpa/blob/blob.h"
#include "palpa/field/build.h"
#include "palpa/field/to_blob.h"
#include "palpa/field/transform.h"
#include "palpa/mesh/eval.h"
#include "palpa/mesh/sample.h"
#include "palpa/mesh/triangle_mesh.h"
#include "palpa/proxy/proxy.h"

namespace palpa {
namespace {

constexpr double kVoxel = 0.0002;    // 0.2 mm
constexpr double kKnotSize = 0.012;  // longest side 12 mm: the tube is 1.7-2.2 mm (8-11 voxels) thick

struct Knot {
  explicit Knot(blob::VerifiedField f) : blob(std::move(f)), view(blob.view()) {}
  blob::VerifiedField blob;
  const blob::FieldView& view;
  std::unique_ptr<sampler::TrilinearSampler> field;
  std::unique_ptr<mesh::TrueDistanceGrid> truth;  // exact signed distance to the mesh, voxels
  field::PointSet device;                         // the sampled oriented points, device metres
};

// Built once for all tests in this file (about a second).
const Knot& GetKnot() {
  static const Knot* knot = [] {
    auto m = mesh::ReadClosedMesh(PALPA_DATA_DIR "/knot1.off");
    EXPECT_TRUE(m.has_value()) << m.error().message;
    // 40,000 area-uniform points: about 1 per 0.01 mm² at this size, a dense scan.
    auto points = mesh::SampleSurface(*m, 40000, 1, "knot1.off");
    EXPECT_TRUE(points.has_value());
    const field::Transform transform = field::FitTransform(*points, kKnotSize);
    field::PointSet device = field::ApplyTransform(transform, *points);
    field::BuildOptions options;  // the default method, as `palpa build`
    options.grid.voxel_m = kVoxel;
    auto built = field::BuildField(device.positions, device.normals, options);
    EXPECT_TRUE(built.has_value());
    const field::GridSpec& g = built->field.grid();
    const blob::BlobMeta meta =
        field::BlobMetaOf(g, field::FieldMethod::kHermite,
                          {.transform = transform, .point_count = static_cast<std::uint32_t>(device.positions.size())});
    std::vector<std::int32_t> phi(g.NodeCount());
    built->field.WriteQ16(phi);
    auto* k = new Knot(blob::VerifyOwned(blob::Encode(meta, phi)).value());
    k->device = std::move(device);
    k->field = std::make_unique<sampler::TrilinearSampler>(k->view);
    auto truth = mesh::TrueDistances(k->view, mesh::Truth::Mesh(std::move(*m)), 4);
    EXPECT_TRUE(truth.has_value());
    k->truth = std::make_unique<mesh::TrueDistanceGrid>(std::move(*truth));
    return k;
  }();
  return *knot;
}

// The mesh's signed distance at a grid position (voxels), trilinear between the exact node
// values, which are clamped to ±4 voxels (beyond that they may be ±infinity; only the sign and
// "deep inside" matter here).
double TrueDistance(const Knot& k, const std::array<double, 3>& x) {
  const auto& d = k.truth->dims;
  double out = 0;
  int i0[3];
  double f[3];
  for (int a = 0; a < 3; ++a) {
    const double v = std::clamp(x[static_cast<std::size_t>(a)], 0.0, d[static_cast<std::size_t>(a)] - 1.000001);
    i0[a] = static_cast<int>(v);
    f[a] = v - i0[a];
  }
  for (int n = 0; n < 8; ++n) {
    const int i = i0[0] + ((n >> 2) & 1), j = i0[1] + ((n >> 1) & 1), kk = i0[2] + (n & 1);
    const double w = ((n & 4) ? f[0] : 1 - f[0]) * ((n & 2) ? f[1] : 1 - f[1]) * ((n & 1) ? f[2] : 1 - f[2]);
    const std::size_t idx =
        (static_cast<std::size_t>(i) * static_cast<std::size_t>(d[1]) + static_cast<std::size_t>(j)) *
            static_cast<std::size_t>(d[2]) +
        static_cast<std::size_t>(kk);
    out += w * std::clamp(static_cast<double>(k.truth->voxels[idx]), -4.0, 4.0);
  }
  return out;
}

std::array<double, 3> Voxels(sampler::GridPos p) { return {p.x / 65536.0, p.y / 65536.0, p.z / 65536.0}; }

// A pass tunnels if the proxy's path goes 3 voxels into the true solid: most of the way to the
// tube's core (its radius is 4-5.5 voxels), and beyond the field's own error against the mesh
// (up to ~1.8 voxels here, where the proxy, resting on the field's surface, is that deep in the
// mesh without going through anything).
constexpr double kThroughVoxels = 3.0;

struct PassStats {
  int passes = 0;
  int tunnelled = 0;           // the proxy's path went kThroughVoxels into the true solid
  double min_true_phi = 1e9;   // deepest point of any proxy path, voxels (mesh truth)
  double min_field_phi = 1e9;  // deepest proxy position in the field itself, voxels
  int contact_ticks = 0;
  int max_iterations = 0;
  int hip_through = 0;  // passes in which the HIP itself reached kThroughVoxels: the detector's control
};

// Straight passes at `speed` m/s, 1 kHz: from 2 mm outside a random surface point to 2 mm past it,
// in a random direction within 60° of the inward normal, then 20 ticks held there. Each proxy
// move (consecutive tick positions) is checked against the mesh at ¼-voxel steps.
PassStats Drive(const Knot& k, double speed, int passes, std::uint32_t seed) {
  const proxy::ProxyParams params = proxy::MakeProxyParams({}, kVoxel).value();
  const proxy::GridFrame frame = proxy::GridFrame::Of(k.view);
  std::mt19937 rng(seed);
  std::uniform_int_distribution<std::size_t> pick(0, k.device.positions.size() - 1);
  std::uniform_real_distribution<double> u(-1, 1);
  PassStats out;
  while (out.passes < passes) {
    const std::size_t s = pick(rng);
    const Eigen::Vector3d n = k.device.normals[s].normalized();
    Eigen::Vector3d d(u(rng), u(rng), u(rng));
    if (d.norm() > 1 || d.norm() < 0.1) continue;
    d.normalize();
    if (d.dot(n) > 0) d = -d;
    if (d.dot(n) > -0.5) continue;  // within 60° of −n
    const Eigen::Vector3d start = k.device.positions[s] - 2e-3 * d;
    const Eigen::Vector3d end = k.device.positions[s] + 2e-3 * d;
    const auto at = [&](const Eigen::Vector3d& x) { return frame.ToGrid({x.x(), x.y(), x.z()}); };
    // Start in free space (other loops of the knot may be there): well outside by the truth.
    if (TrueDistance(k, Voxels(at(start))) < 1.0) continue;
    const int ticks = static_cast<int>(std::ceil((end - start).norm() / (speed * 1e-3)));
    proxy::ProxyState state;
    std::array<double, 3> last{};
    double hip_deepest = 1e9;
    for (int q = 0; q <= 64; ++q)
      hip_deepest = std::min(hip_deepest, TrueDistance(k, Voxels(at(start + (end - start) * (q / 64.0)))));
    out.hip_through += hip_deepest <= -kThroughVoxels ? 1 : 0;
    for (int t = 0; t <= ticks + 20; ++t) {
      const double along = std::min(1.0, t / static_cast<double>(ticks));
      const proxy::TickResult r = proxy::ProxyTick(*k.field, params, state, at(start + (end - start) * along));
      out.max_iterations = std::max(out.max_iterations, r.iterations);
      out.contact_ticks += r.contact ? 1 : 0;
      const auto p = Voxels(r.proxy);
      double deepest = TrueDistance(k, p);
      if (t > 0) {
        const double len = std::sqrt((p[0] - last[0]) * (p[0] - last[0]) + (p[1] - last[1]) * (p[1] - last[1]) +
                                     (p[2] - last[2]) * (p[2] - last[2]));
        const int steps = static_cast<int>(len * 4) + 1;
        for (int q = 1; q < steps; ++q) {
          const double w = q / static_cast<double>(steps);
          deepest = std::min(deepest, TrueDistance(k, {last[0] + (p[0] - last[0]) * w, last[1] + (p[1] - last[1]) * w,
                                                       last[2] + (p[2] - last[2]) * w}));
        }
      }
      out.min_true_phi = std::min(out.min_true_phi, deepest);
      out.min_field_phi = std::min(out.min_field_phi, k.field->Phi(r.proxy) / 65536.0);
      if (deepest <= -kThroughVoxels) {
        ++out.tunnelled;
        break;
      }
      last = p;
    }
    ++out.passes;
  }
  return out;
}

TEST(Knot, FieldIsThinAndRepresentsTheMesh) {
  const Knot& k = GetKnot();
  // The tube is thin on this grid: at most 11 voxels across, so a 2 m/s HIP (10 voxels a tick)
  // crosses it within one or two ticks.
  std::printf("[ measured ] knot field: %d x %d x %d nodes, voxel %.2f mm, %zu points, Lipschitz norm %.3f\n",
              k.view.dims[0], k.view.dims[1], k.view.dims[2], k.view.voxel_m * 1e3, k.device.positions.size(),
              k.field->lipschitz().norm / 65536.0);
  auto score = mesh::Evaluate(k.view, *k.truth);
  ASSERT_TRUE(score.has_value()) << score.error().message;
  std::printf("[ measured ] knot field vs mesh: mean |error| %.3f voxel, p99 %.3f, wrong sign in band %.2f %%\n",
              score->mean_abs_error, score->p99_abs_error, score->wrong_sign_in_band_percent);
  // Sanity only (the field method's accuracy is tests/host's business): this is the knot.
  EXPECT_LT(score->mean_abs_error, 0.5);
}

TEST(Knot, HipDrivenThroughIsNeverTunnelled) {
  const Knot& k = GetKnot();
  const double params_depth_tolerance = proxy::MakeProxyParams({}, kVoxel).value().depth_tolerance.value.ToDouble();
  for (const double speed : {0.5, 2.0}) {
    const PassStats s = Drive(k, speed, 10000, speed > 1 ? 2 : 1);
    std::printf(
        "[ measured ] knot at %.1f m/s: %d tunnelled of %d passes; deepest proxy path point %.3f voxel (mesh truth), "
        "deepest proxy %.3f voxel (field); %d contact ticks; samples/tick max %d; the HIP itself went through in %d\n",
        speed, s.tunnelled, s.passes, s.min_true_phi, s.min_field_phi, s.contact_ticks, s.max_iterations,
        s.hip_through);
    EXPECT_EQ(s.passes, 10000);
    EXPECT_EQ(s.tunnelled, 0);
    EXPECT_GE(s.min_field_phi, -params_depth_tolerance - 1e-4) << "a proxy rests at φ ≥ −δ in its own field";
    EXPECT_GT(s.contact_ticks, 10000) << "the passes must actually press into the knot";
    EXPECT_GT(s.hip_through, 2500) << "the detector must see the HIP go through the tube (chords near the core)";
  }
}

}  // namespace
}  // namespace palpa
