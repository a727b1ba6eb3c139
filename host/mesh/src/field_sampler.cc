#include "palpa/mesh/field_sampler.h"

#include "palpa/mesh/field_file.h"

#include <algorithm>
#include <cmath>

namespace palpa::mesh {

double FieldSampler::Phi(const Eigen::Vector3d& x_m) const {
  double g[3];
  std::ptrdiff_t c[3];
  for (int a = 0; a < 3; ++a) {
    g[a] = (x_m[a] - f_.origin_m[static_cast<std::size_t>(a)]) / f_.voxel_m;
    const double last = f_.dims[static_cast<std::size_t>(a)] - 1;
    if (!(g[a] == g[a])) return std::max(f_.band_voxels, f_.band_outside) * f_.voxel_m;  // NaN: free space
    g[a] = std::clamp(g[a], 0.0, last);  // outside: the boundary value extended outward, as the sampler
    c[a] = std::min(static_cast<std::ptrdiff_t>(g[a]), static_cast<std::ptrdiff_t>(last) - 1);
    g[a] -= static_cast<double>(c[a]);
  }
  double out = 0;
  for (int n = 0; n < 8; ++n) {
    const auto i = static_cast<int>(c[0] + ((n >> 2) & 1)), j = static_cast<int>(c[1] + ((n >> 1) & 1)),
               k = static_cast<int>(c[2] + (n & 1));
    const double w = ((n & 4) ? g[0] : 1 - g[0]) * ((n & 2) ? g[1] : 1 - g[1]) * ((n & 1) ? g[2] : 1 - g[2]);
    out += w * mesh::PhiQ16(f_, i, j, k);  // v1 or v2, read in place as the dense equivalent
  }
  return out / 65536.0 * f_.voxel_m;
}

Eigen::Vector3d FieldSampler::Gradient(const Eigen::Vector3d& x_m) const {
  const double h = 0.5 * f_.voxel_m;
  Eigen::Vector3d g;
  for (int a = 0; a < 3; ++a) {
    Eigen::Vector3d e = Eigen::Vector3d::Zero();
    e[a] = h;
    g[a] = (Phi(x_m + e) - Phi(x_m - e)) / (2 * h);
  }
  return g;
}

bool FieldSampler::Project(Eigen::Vector3d& x_m) const {
  for (int it = 0; it < 20; ++it) {
    const double phi = Phi(x_m);
    if (std::abs(phi) < 1e-3 * f_.voxel_m) return true;
    const Eigen::Vector3d g = Gradient(x_m);
    const double g2 = g.squaredNorm();
    if (g2 < 1e-4) return false;
    x_m -= phi * g / g2;
  }
  return std::abs(Phi(x_m)) < 1e-2 * f_.voxel_m;
}

bool FieldSampler::RayHit(const Eigen::Vector3d& from_m, const Eigen::Vector3d& dir, double max_len_m,
                          Eigen::Vector3d& hit) const {
  const double step = 0.25 * f_.voxel_m;
  double prev_t = 0;
  double prev_phi = Phi(from_m);
  for (double t = step; t <= max_len_m; t += step) {
    const double phi = Phi(from_m + t * dir);
    if (prev_phi > 0 && phi <= 0) {
      double lo = prev_t, hi = t;  // bisection to 1e-6 voxel
      for (int i = 0; i < 40; ++i) {
        const double mid = 0.5 * (lo + hi);
        (Phi(from_m + mid * dir) > 0 ? lo : hi) = mid;
      }
      hit = from_m + hi * dir;
      return true;
    }
    prev_t = t;
    prev_phi = phi;
  }
  return false;
}

Eigen::Vector3d FieldSampler::GridMax() const {
  return {f_.origin_m[0] + (f_.dims[0] - 1) * f_.voxel_m, f_.origin_m[1] + (f_.dims[1] - 1) * f_.voxel_m,
          f_.origin_m[2] + (f_.dims[2] - 1) * f_.voxel_m};
}

}  // namespace palpa::mesh
