#include "palpa/sampler/trilinear.h"

#include <algorithm>
#include <cstdlib>

namespace palpa::sampler {

TrilinearSampler::TrilinearSampler(const blob::FieldView& field)
    : phi_(field.phi),
      index_(field.brick_index),
      tables_(field.brick_tables),
      octants_(field.octants),
      brick_dims_(field.brick_dims),
      dims_(field.dims),
      last_{static_cast<std::uint32_t>(field.dims[0] - 1) << 16, static_cast<std::uint32_t>(field.dims[1] - 1) << 16,
            static_cast<std::uint32_t>(field.dims[2] - 1) << 16},
      stride_i_(static_cast<std::ptrdiff_t>(field.dims[1]) * field.dims[2]),
      background_((field.phi != nullptr ? field.band_voxels : field.band_outside) << 16) {
  // One pass over every cell through Fetch (the storage's only access path). Skipped: cells whose
  // corners are all equal (free space and deep inside, most of the grid: zero gradient) and cells
  // with every corner ≤ −1 voxel (φ ≤ −1 throughout; the bound is only needed on {φ > −1}, see
  // LipschitzBound), which leaves out the medial-axis kinks deep inside the object.
  std::int32_t mx = 0, my = 0, mz = 0;
  std::int64_t norm2 = 0;
  for (std::int32_t i = 0; i + 1 < dims_[0]; ++i) {
    for (std::int32_t j = 0; j + 1 < dims_[1]; ++j) {
      for (std::int32_t k = 0; k + 1 < dims_[2]; ++k) {
        const Stencil v = Fetch(i, j, k);
        if (std::all_of(v.begin() + 1, v.end(), [&](std::int32_t x) { return x == v[0]; })) continue;
        if (*std::max_element(v.begin(), v.end()) <= -(1 << 16)) continue;
        // v2 free space (docs/blob-format.md § Free-space bound): every corner at or above the
        // outside band. There φ is a lower bound of band_outside + the distance to the cells
        // scanned here, which is all the proxy's certificate needs once Λ ≥ 1 (below).
        if (phi_ == nullptr && *std::min_element(v.begin(), v.end()) >= background_) continue;
        // ∂φ/∂x is bilinear in (y, z) and constant in x, and likewise for y and z, so |∇φ|² is
        // convex along every axis-parallel line and its maximum over the cell is at a corner,
        // where each partial derivative is the edge difference through that corner.
        for (std::size_t n = 0; n < 8; ++n) {
          const std::int64_t gx = v[n | 4] - v[n & 3], gy = v[n | 2] - v[n & 5], gz = v[n | 1] - v[n & 6];
          norm2 = std::max(norm2, gx * gx + gy * gy + gz * gz);
          mx = std::max(mx, static_cast<std::int32_t>(std::llabs(gx)));
          my = std::max(my, static_cast<std::int32_t>(std::llabs(gy)));
          mz = std::max(mz, static_cast<std::int32_t>(std::llabs(gz)));
        }
      }
    }
  }
  if (phi_ == nullptr) {
    bool far_bounds = false;  // any empty slot above the outside band
    const std::size_t slots = static_cast<std::size_t>(brick_dims_[0]) * static_cast<std::size_t>(brick_dims_[1]) *
                              static_cast<std::size_t>(brick_dims_[2]);
    for (std::size_t s = 0; s < slots; ++s) {
      const std::uint32_t e = index_[s];
      far_bounds = far_bounds || ((e & blob::kSlotEmpty) != 0 &&
                                  std::int32_t{static_cast<std::int16_t>(e & 0xFFFFU)} * 256 > background_);
    }
    if (far_bounds) {
      mx = std::max(mx, 1 << 16);
      my = std::max(my, 1 << 16);
      mz = std::max(mz, 1 << 16);
      norm2 = std::max(norm2, std::int64_t{1} << 32);
    }
  }
  lipschitz_.axis = {mx, my, mz};
  const auto root = static_cast<std::int64_t>(fixed::ISqrt(norm2));
  lipschitz_.norm = static_cast<std::int32_t>(root * root == norm2 ? root : root + 1);  // round up: a bound
  lipschitz_.norm_helps = std::int64_t{lipschitz_.norm} * lipschitz_.norm <
                          std::int64_t{mx} * mx + std::int64_t{my} * my + std::int64_t{mz} * mz;
}

std::int32_t TrilinearSampler::Phi(std::int32_t x, std::int32_t y, std::int32_t z) const {
  Cell c;
  if (!Locate(x, y, z, c)) return background_;
  return InterpolatePhi(Fetch(c.i, c.j, c.k), c.fx, c.fy, c.fz);
}

Sample TrilinearSampler::At(std::int32_t x, std::int32_t y, std::int32_t z) const {
  Cell c;
  if (!Locate(x, y, z, c)) return Background();
  if (phi_ == nullptr) return InterpolateSmooth(FetchBricks<4>(c.i, c.j, c.k), c.fx, c.fy, c.fz);
  return InterpolateSmooth(FetchWide(c.i, c.j, c.k), c.fx, c.fy, c.fz);
}

}  // namespace palpa::sampler
