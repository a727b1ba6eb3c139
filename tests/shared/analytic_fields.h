// Analytic test fields (independent truths): φ sampled exactly from a closed-form signed distance.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <vector>

#include "palpa/blob/blob.h"

namespace palpa::testing {

/// The node values `sdf_voxels(i,j,k)` clamped to ±band, as Q16.16, C order.
inline std::vector<std::int32_t> AnalyticPhi(std::array<std::uint32_t, 3> dims, std::uint32_t band,
                                             const std::function<double(double, double, double)>& sdf_voxels) {
  std::vector<std::int32_t> phi(std::size_t{dims[0]} * dims[1] * dims[2]);
  std::size_t n = 0;
  const double b = band;
  for (std::uint32_t i = 0; i < dims[0]; ++i)
    for (std::uint32_t j = 0; j < dims[1]; ++j)
      for (std::uint32_t k = 0; k < dims[2]; ++k) {
        const double v = std::clamp(sdf_voxels(i, j, k), -b, b);
        phi[n++] = static_cast<std::int32_t>(std::lround(v * 65536.0));
      }
  return phi;
}

inline blob::BlobMeta AnalyticMeta(std::array<std::uint32_t, 3> dims, double voxel_m, std::uint32_t band) {
  blob::BlobMeta meta;
  meta.dims = dims;
  meta.origin_m = {-0.5 * voxel_m * (dims[0] - 1), -0.5 * voxel_m * (dims[1] - 1), -0.5 * voxel_m * (dims[2] - 1)};
  meta.voxel_m = voxel_m;
  meta.band_voxels = band;
  meta.point_count = 0;
  return meta;
}

/// Encodes a dense (v1) blob whose node values are `sdf_voxels(i,j,k)` clamped to ±band, as Q16.16.
inline std::vector<std::byte> AnalyticBlob(std::array<std::uint32_t, 3> dims, double voxel_m, std::uint32_t band,
                                           const std::function<double(double, double, double)>& sdf_voxels) {
  return blob::Encode(AnalyticMeta(dims, voxel_m, band), AnalyticPhi(dims, band, sdf_voxels));
}

/// The same field as a v2 blob as palpa build writes it: bands `band` inside and 2 outside, with
/// free-space bounds.
inline std::vector<std::byte> AnalyticBlobV2(std::array<std::uint32_t, 3> dims, double voxel_m, std::uint32_t band,
                                             const std::function<double(double, double, double)>& sdf_voxels) {
  blob::BlobMetaV2 m;
  m.meta = AnalyticMeta(dims, voxel_m, band);
  m.band_inside = band;
  return blob::EncodeV2(m, AnalyticPhi(dims, band, sdf_voxels));
}

/// Sphere of radius r (voxels) centred at node-space point c: φ = |x − c| − r.
inline std::vector<std::byte> SphereBlob(std::uint32_t n, double voxel_m, std::uint32_t band, double r) {
  const double c = 0.5 * (n - 1);
  return AnalyticBlob({n, n, n}, voxel_m, band, [=](double i, double j, double k) {
    return std::sqrt((i - c) * (i - c) + (j - c) * (j - c) + (k - c) * (k - c)) - r;
  });
}

}  // namespace palpa::testing
