// Blobs with analytic φ for the tools tests: φ sampled exactly from closed-form signed distances
// (an independent truth), with an arbitrary fit transform recorded in the header.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <vector>

#include <Eigen/Core>

#include "palpa/blob/blob.h"

namespace palpa::tools_test {

struct BlobSpec {
  std::array<std::uint32_t, 3> dims{64, 64, 64};
  Eigen::Vector3d origin_m{0, 0, 0};
  double voxel_m = 1e-3;
  std::uint32_t band = 6;
  double fit_scale = 1;
  Eigen::Vector3d fit_offset_m{0, 0, 0};
};

/// Encodes a blob whose node values are `phi_voxels(device position in m)` clamped to ±band.
inline std::vector<std::byte> MakeBlob(const BlobSpec& s,
                                       const std::function<double(const Eigen::Vector3d&)>& phi_voxels) {
  std::vector<std::int32_t> phi(std::size_t{s.dims[0]} * s.dims[1] * s.dims[2]);
  std::size_t n = 0;
  const double b = s.band;
  for (std::uint32_t i = 0; i < s.dims[0]; ++i)
    for (std::uint32_t j = 0; j < s.dims[1]; ++j)
      for (std::uint32_t k = 0; k < s.dims[2]; ++k) {
        const Eigen::Vector3d x = s.origin_m + s.voxel_m * Eigen::Vector3d(i, j, k);
        phi[n++] = static_cast<std::int32_t>(std::lround(std::clamp(phi_voxels(x), -b, b) * 65536.0));
      }
  blob::BlobMeta meta;
  meta.dims = s.dims;
  meta.origin_m = {s.origin_m.x(), s.origin_m.y(), s.origin_m.z()};
  meta.voxel_m = s.voxel_m;
  meta.band_voxels = s.band;
  meta.fit_scale = s.fit_scale;
  meta.fit_offset_m = {s.fit_offset_m.x(), s.fit_offset_m.y(), s.fit_offset_m.z()};
  return blob::Encode(meta, phi);
}

/// The sphere used across the tools tests: radius 10 model units at the model origin, mapped by
/// fit_scale 2 mm/unit and an off-centre offset, on a 64³ grid of 1 mm voxels. In device space it
/// is a sphere of radius 20 mm (20 voxels) centred at `kSphereCentre`.
inline BlobSpec SphereSpec() {
  BlobSpec s;
  s.dims = {64, 60, 66};
  s.voxel_m = 1e-3;
  s.origin_m = Eigen::Vector3d(-0.031, -0.0285, -0.033);
  s.fit_scale = 2e-3;
  s.fit_offset_m = Eigen::Vector3d(0.0004, -0.0003, 0.0002);
  return s;
}
inline constexpr double kSphereRadiusModel = 10;
inline double SphereSdfVoxels(const BlobSpec& s, const Eigen::Vector3d& x_m) {
  return ((x_m - s.fit_offset_m).norm() - s.fit_scale * kSphereRadiusModel) / s.voxel_m;
}

/// Verifies a blob built by MakeBlob (the tests' own encoder must produce valid blobs).
inline blob::FieldView View(const std::vector<std::byte>& bytes) {
  auto v = blob::Verify(bytes);
  if (!v) std::abort();
  return *v;
}

}  // namespace palpa::tools_test
