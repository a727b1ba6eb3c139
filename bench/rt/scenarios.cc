#include "scenarios.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <random>

#include "float64_proxy.h"

namespace palpa::bench {
namespace {

[[noreturn]] void Die(const std::string& message) {
  std::fprintf(stderr, "palpa_rt_bench: %s\n", message.c_str());
  std::exit(2);
}

blob::VerifiedField Verified(std::vector<std::byte> bytes, const std::string& name) {
  auto field = blob::VerifyOwned(std::move(bytes));
  if (!field) Die(name + ": " + field.error().what());
  return std::move(*field);
}

std::unique_ptr<Field> Analytic(std::uint32_t n, double voxel_m,
                                const std::function<double(double, double, double)>& sdf, const std::string& name,
                                Storage storage) {
  constexpr double kBand = 6;
  std::vector<std::int32_t> phi;
  phi.reserve(std::size_t{n} * n * n);
  for (std::uint32_t i = 0; i < n; ++i)
    for (std::uint32_t j = 0; j < n; ++j)
      for (std::uint32_t k = 0; k < n; ++k)
        phi.push_back(static_cast<std::int32_t>(std::lround(std::clamp(sdf(i, j, k), -kBand, kBand) * 65536.0)));
  blob::BlobMeta meta;
  meta.dims = {n, n, n};
  const double half = 0.5 * voxel_m * (n - 1);
  meta.origin_m = {-half, -half, -half};
  meta.voxel_m = voxel_m;
  meta.band_voxels = static_cast<std::uint32_t>(kBand);
  std::optional<blob::VerifiedField> stored;
  if (storage == Storage::kV2) {  // stored as palpa build's default (bands 6 and 2), view dense
    blob::BlobMetaV2 m;
    m.meta = meta;
    stored.emplace(Verified(blob::EncodeV2(m, phi), name + " (v2)"));
  }
  return std::make_unique<Field>(Verified(blob::Encode(meta, phi), name), std::move(stored));
}

sampler::GridPos ToGrid(const Vec3d& x_vox) {
  return {static_cast<std::int32_t>(std::lround(x_vox[0] * 65536)),
          static_cast<std::int32_t>(std::lround(x_vox[1] * 65536)),
          static_cast<std::int32_t>(std::lround(x_vox[2] * 65536))};
}

Vec3d Add(const Vec3d& a, const Vec3d& b, double s = 1) { return {a[0] + s * b[0], a[1] + s * b[1], a[2] + s * b[2]}; }
double Dot(const Vec3d& a, const Vec3d& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
Vec3d Normalized(const Vec3d& a) {
  const double l = std::sqrt(Dot(a, a));
  return {a[0] / l, a[1] / l, a[2] / l};
}

// Newton projection onto φ = 0 along the continuous gradient (float64), in voxels.
bool Project(const Float64Field& f, Vec3d& x, Vec3d& normal) {
  for (int it = 0; it < 20; ++it) {
    const Float64Sample s = f.At(x);
    const double gg = Dot(s.grad, s.grad);
    if (gg < 0.25) return false;
    if (std::abs(s.phi) < 1e-7) {
      normal = Normalized(s.grad);
      return true;
    }
    x = Add(x, s.grad, -s.phi / gg);
  }
  return false;
}

}  // namespace

std::unique_ptr<Field> LoadField(const std::string& path) {
  auto loaded = blob::LoadFile(path.c_str());
  if (!loaded) Die(path + ": " + loaded.error().what());
  blob::VerifiedField field = std::move(*loaded);
  if (field.view().version != blob::kVersion2) return std::make_unique<Field>(std::move(field), std::nullopt);
  // v2: the fixed-point tick samples the bricks in place, as palpad; `view` is the dense form.
  blob::VerifiedField dense = Verified(blob::DenseV1(field.view()), path);
  return std::make_unique<Field>(std::move(dense), std::move(field));
}

std::unique_ptr<Field> SphereField(std::uint32_t n, double voxel_m, double radius_vox, Storage storage) {
  const double c = 0.5 * (n - 1);
  return Analytic(
      n, voxel_m, [=](double i, double j, double k) { return std::hypot(i - c, j - c, k - c) - radius_vox; }, "sphere",
      storage);
}

std::unique_ptr<Field> PlateField(std::uint32_t n, double voxel_m, const std::array<double, 3>& nrm, double offset,
                                  Storage storage) {
  const double centre = 0.5 * (n - 1);
  const double c = centre * (nrm[0] + nrm[1] + nrm[2]) + offset;
  return Analytic(
      n, voxel_m,
      [=](double i, double j, double k) { return std::abs(nrm[0] * i + nrm[1] * j + nrm[2] * k - c) - 1.0; }, "plate",
      storage);
}

Scenario SurfaceStrokes(const Field& f, const std::string& name, double depth_m, double speed_m_s, int strokes,
                        int ticks_per_stroke, std::uint32_t seed) {
  const Float64Field field(f.view, *f.sampler);  // reads view's dense values
  const double voxel = f.view.voxel_m;
  // Surface seeds: the zero crossings along grid x-edges, in node order.
  std::vector<Vec3d> crossings;
  const auto& d = f.view.dims;
  for (std::int32_t i = 0; i + 1 < d[0]; ++i)
    for (std::int32_t j = 0; j < d[1]; ++j)
      for (std::int32_t k = 0; k < d[2]; ++k) {
        const std::size_t a =
            (static_cast<std::size_t>(i) * static_cast<std::size_t>(d[1]) + static_cast<std::size_t>(j)) *
                static_cast<std::size_t>(d[2]) +
            static_cast<std::size_t>(k);
        const std::size_t b = a + static_cast<std::size_t>(d[1]) * static_cast<std::size_t>(d[2]);
        const std::int32_t* phi = f.view.dense()->data();
        const std::int32_t va = phi[a], vb = phi[b];
        if ((va < 0) != (vb < 0)) crossings.push_back({i + static_cast<double>(va) / (va - vb), 1.0 * j, 1.0 * k});
      }
  if (crossings.empty()) Die(name + ": the field has no surface");
  std::mt19937 rng(seed);
  std::normal_distribution<double> gauss;
  Scenario out{name, {}};
  const double step = speed_m_s * 1e-3 / voxel;  // voxels per tick at 1 kHz
  const double depth = depth_m / voxel, outside = 1e-3 / voxel;
  for (int s = 0, attempts = 0; s < strokes && attempts < 100 * strokes; ++attempts) {
    Vec3d sp = crossings[std::uniform_int_distribution<std::size_t>(0, crossings.size() - 1)(rng)], n{};
    if (!Project(field, sp, n)) continue;
    Vec3d t = {gauss(rng), gauss(rng), gauss(rng)};
    t = Normalized(Add(t, n, -Dot(t, n)));
    std::vector<Tick> stroke;
    // Approach along the normal from 1 mm outside to the stroke's depth.
    for (int a = 0; a < 20; ++a) {
      const double u = a / 19.0;
      stroke.push_back({ToGrid(Add(sp, n, outside + (-depth - outside) * u)), a == 0, false});
    }
    bool ok = true;
    for (int i = 0; i < ticks_per_stroke && ok; ++i) {
      Vec3d next = Add(sp, t, step), nn{};
      ok = Project(field, next, nn);
      if (!ok) break;
      sp = next;
      n = nn;
      t = Normalized(Add(t, n, -Dot(t, n)));
      stroke.push_back({ToGrid(Add(sp, n, -depth)), false, true});
    }
    if (!ok) continue;  // the walk left the band: draw another stroke
    out.ticks.insert(out.ticks.end(), stroke.begin(), stroke.end());
    ++s;
  }
  return out;
}

Scenario SphereStroke(const Field& f, double radius_vox, double depth_m, double speed_m_s) {
  const double voxel = f.view.voxel_m;
  const double c = 0.5 * (f.view.dims[0] - 1);
  const double r0 = radius_vox, rh = radius_vox - depth_m / voxel;
  const Vec3d a = Normalized({1, 2, 2}), b = Normalized({2, -1, 0});  // orthonormal
  Scenario out{"sphere_stroke", {}};
  for (int t = 0; t <= 1200; ++t) {
    const double u = std::min(1.0, t / 200.0);
    const double radius = (r0 + 1e-3 / voxel) + (rh - r0 - 1e-3 / voxel) * u;
    const double angle = t > 200 ? speed_m_s * 1e-3 * (t - 200) / (r0 * voxel) : 0.0;
    const Vec3d dir =
        Add(Vec3d{a[0] * std::cos(angle), a[1] * std::cos(angle), a[2] * std::cos(angle)}, b, std::sin(angle));
    out.ticks.push_back({ToGrid(Add({c, c, c}, dir, radius)), t == 0, t > 200});
  }
  return out;
}

Scenario PlatePasses(const Field& f, const std::array<double, 3>& nrm, double offset, double speed_m_s, int passes,
                     std::uint32_t seed) {
  const double voxel = f.view.voxel_m;
  const double centre = 0.5 * (f.view.dims[0] - 1);
  const double c = centre * (nrm[0] + nrm[1] + nrm[2]) + offset;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  Scenario out{"plate_passes", {}};
  for (int made = 0; made < passes;) {
    Vec3d d = {u(rng), u(rng), u(rng)};
    const double dl = std::sqrt(Dot(d, d));
    if (dl > 1 || dl < 0.1) continue;
    d = {d[0] / dl, d[1] / dl, d[2] / dl};
    if (Dot(d, nrm) > 0) d = {-d[0], -d[1], -d[2]};
    if (Dot(d, nrm) > -0.5) continue;
    const Vec3d p = {centre + 3 * u(rng), centre + 3 * u(rng), centre + 3 * u(rng)};
    const Vec3d on = Add(p, nrm, -(Dot(nrm, p) - c));
    const double reach = 2e-3 / voxel / -Dot(d, nrm);
    const Vec3d start = Add(on, d, -reach);
    const double step = speed_m_s * 1e-3 / voxel;
    const int ticks = static_cast<int>(std::ceil(2 * reach / step));
    for (int t = 0; t <= ticks; ++t)
      out.ticks.push_back({ToGrid(Add(start, d, std::min(2 * reach, step * t))), t == 0, true});
    ++made;
  }
  return out;
}

}  // namespace palpa::bench
