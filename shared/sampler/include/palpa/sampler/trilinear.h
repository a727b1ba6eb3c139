// Trilinear sampling of φ and its gradient on a verified blob, in fixed point, in place.
// RT-safe: no allocation, no exceptions, bounded work (one 8-value stencil fetch per sample).
//
// Fetching is apart from the math: Stencil() is the only memory access; Interpolate() is a pure
// function of the 8 corner values and the Q0.16 cell fractions, tested against hand-computed
// vectors and the float64 trilinear formula.
#pragma once

#include <array>
#include <cstdint>

#include "palpa/blob/blob.h"
#include "palpa/fixed/q.h"

namespace palpa::sampler {

/// A position in grid coordinates, Q16.16 voxel units: node (i,j,k) is at (i,j,k)·65536.
struct GridPos {
  std::int32_t x = 0, y = 0, z = 0;
  friend constexpr bool operator==(GridPos, GridPos) = default;
};

/// φ and its gradient at a point. φ in Q16.16 voxel units (negative inside); gradient
/// ∂φ/∂(x,y,z) in Q16.16 (voxel per voxel, dimensionless).
struct Sample {
  std::int32_t phi = 0;
  std::array<std::int32_t, 3> grad{};
  bool in_grid = false;  ///< false: outside the grid, φ = background, gradient 0
};

/// Corner values v[dx][dy][dz] of one cell, Q16.16 voxels; v[4·dx + 2·dy + dz].
using Stencil = std::array<std::int32_t, 8>;

/// Q16.16 linear interpolation a + (b−a)·t for t in [0, 65536], rounded to nearest. Exact in
/// int64 for |a|,|b| < 2^30.
constexpr std::int32_t Lerp(std::int32_t a, std::int32_t b, std::int32_t t) {
  return static_cast<std::int32_t>(a + fixed::ShiftRight((std::int64_t{b} - a) * t, 16, fixed::Round::kNearest));
}

/// Trilinear φ and its analytic in-cell gradient (the exact derivative of the trilinear
/// polynomial of this cell) at fractions f = (fx,fy,fz) in [0, 65536]. The order of the lerps
/// (z, then y, then x) is part of the bit-exact contract.
constexpr Sample Interpolate(const Stencil& v, std::int32_t fx, std::int32_t fy, std::int32_t fz) {
  const std::int32_t c00 = Lerp(v[0], v[1], fz), c01 = Lerp(v[2], v[3], fz);
  const std::int32_t c10 = Lerp(v[4], v[5], fz), c11 = Lerp(v[6], v[7], fz);
  const std::int32_t c0 = Lerp(c00, c01, fy), c1 = Lerp(c10, c11, fy);
  Sample s;
  s.phi = Lerp(c0, c1, fx);
  s.grad[0] = c1 - c0;
  s.grad[1] = Lerp(c01 - c00, c11 - c10, fx);
  const std::int32_t e0 = Lerp(v[1] - v[0], v[3] - v[2], fy);
  const std::int32_t e1 = Lerp(v[5] - v[4], v[7] - v[6], fy);
  s.grad[2] = Lerp(e0, e1, fx);
  s.in_grid = true;
  return s;
}

/// Samples a verified FieldView. Positions outside [0, n−1] on any axis answer the background
/// (+band voxels, the value of free space) with a zero gradient; nothing outside the payload is
/// ever read.
class TrilinearSampler {
 public:
  explicit TrilinearSampler(const blob::FieldView& field)
      : phi_(field.phi),
        dims_(field.dims),
        stride_i_(field.dims[1] * field.dims[2]),
        background_(field.band_voxels << 16) {}

  std::int32_t background() const { return background_; }
  const std::array<std::int32_t, 3>& dims() const { return dims_; }

  /// φ and gradient at `p`. RT-safe.
  Sample At(GridPos p) const {
    std::int32_t cell[3];
    std::int32_t frac[3];
    const std::int32_t pos[3] = {p.x, p.y, p.z};
    for (std::size_t a = 0; a < 3; ++a) {
      const std::int32_t last = (dims_[a] - 1) << 16;
      if (pos[a] < 0 || pos[a] > last) {
        Sample out;
        out.phi = background_;
        return out;
      }
      cell[a] = pos[a] >> 16;
      frac[a] = pos[a] & 0xFFFF;
      if (cell[a] == dims_[a] - 1) {  // on the last node: use the last cell at t = 1
        cell[a] -= 1;
        frac[a] = 1 << 16;
      }
    }
    return Interpolate(Fetch(cell[0], cell[1], cell[2]), frac[0], frac[1], frac[2]);
  }

  /// The 8 corner values of cell (i,j,k); requires 0 ≤ i < nx−1 etc. (At() guarantees it).
  Stencil Fetch(std::int32_t i, std::int32_t j, std::int32_t k) const {
    const std::int32_t nz = dims_[2];
    const std::int32_t* base = phi_ + (static_cast<std::ptrdiff_t>(i) * stride_i_ + j * nz + k);
    const std::ptrdiff_t di = stride_i_;
    return {base[0], base[1], base[nz], base[nz + 1], base[di], base[di + 1], base[di + nz], base[di + nz + 1]};
  }

 private:
  const std::int32_t* phi_;
  std::array<std::int32_t, 3> dims_;
  std::int32_t stride_i_;
  std::int32_t background_;
};

}  // namespace palpa::sampler
