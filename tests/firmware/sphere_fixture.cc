#include "sphere_fixture.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>

namespace palpa::firmware_test {
namespace {

std::array<double, 3> Normalised(std::array<double, 3> v) {
  const double n = Norm(v);
  return {v[0] / n, v[1] / n, v[2] / n};
}

}  // namespace

double Norm(const std::array<double, 3>& v) { return std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]); }

SphereField::SphereField(int n, double radius_vox, std::uint32_t band, double voxel_m, std::array<double, 3> center_vox)
    : voxel_m_(voxel_m) {
  blob::BlobMeta meta;
  const auto un = static_cast<std::uint32_t>(n);
  meta.dims = {un, un, un};
  meta.origin_m = {-0.016, -0.016, -0.016};
  meta.voxel_m = voxel_m;
  meta.band_voxels = band;
  meta.point_count = 1;
  std::vector<std::int32_t> phi(static_cast<std::size_t>(n) * static_cast<std::size_t>(n) *
                                static_cast<std::size_t>(n));
  const double b = static_cast<double>(band);
  std::size_t idx = 0;
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      for (int k = 0; k < n; ++k) {
        const double dx = i - center_vox[0], dy = j - center_vox[1], dz = k - center_vox[2];
        const double d = std::clamp(std::sqrt(dx * dx + dy * dy + dz * dz) - radius_vox, -b, b);
        phi[idx++] = static_cast<std::int32_t>(std::lround(d * 65536.0));
      }
    }
  }
  auto v = blob::VerifyOwned(blob::Encode(meta, phi));
  if (!v) std::abort();  // fixture bug
  field_.emplace(std::move(*v));
  for (std::size_t a = 0; a < 3; ++a) center_m_[a] = meta.origin_m[a] + center_vox[a] * voxel_m;
  radius_m_ = radius_vox * voxel_m;
}

std::array<double, 3> SphereField::PointAt(double r_m, std::array<double, 3> dir) const {
  const auto d = Normalised(dir);
  return {center_m_[0] + r_m * d[0], center_m_[1] + r_m * d[1], center_m_[2] + r_m * d[2]};
}

std::vector<trace::TraceSample> TraceFromKeys(const SphereField& field, const std::vector<KeyFrame>& keys,
                                              double dt_s) {
  std::vector<trace::TraceSample> out;
  const double t_end = keys.back().t_s;
  const auto steps = static_cast<long>(std::lround(t_end / dt_s));
  std::size_t seg = 0;
  for (long s = 0; s <= steps; ++s) {
    const double t = static_cast<double>(s) * dt_s;
    while (seg + 2 < keys.size() && keys[seg + 1].t_s <= t) ++seg;
    const KeyFrame& a = keys[seg];
    const KeyFrame& b = keys[seg + 1];
    const double u = std::clamp((t - a.t_s) / (b.t_s - a.t_s), 0.0, 1.0);
    const double r = a.r_m + (b.r_m - a.r_m) * u;
    std::array<double, 3> dir{};
    for (std::size_t i = 0; i < 3; ++i) dir[i] = a.dir[i] + (b.dir[i] - a.dir[i]) * u;
    out.push_back({t, field.PointAt(r, dir)});
  }
  return out;
}

std::vector<trace::TraceSample> PressSlideLeaveTrace(const SphereField& field) {
  const double r = field.radius_m();
  const std::array<double, 3> up = {0, 0, 1};
  const std::array<double, 3> tilted = {std::sin(0.5), 0, std::cos(0.5)};
  return TraceFromKeys(field, {{0.0, r + 3e-3, up},
                               {1.0, r + 3e-3, up},
                               {2.0, r - 2e-3, up},
                               {3.0, r - 2e-3, up},
                               {5.0, r - 2e-3, tilted},
                               {6.0, r + 3e-3, tilted},
                               {10.0, r + 3e-3, tilted}});
}

}  // namespace palpa::firmware_test
