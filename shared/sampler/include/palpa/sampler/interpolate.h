// The interpolation maths of the sampler: pure functions of a cell's stencil values and its Q0.16
// fractions, in fixed point. Stencils come from palpa/sampler/fetch.h (in place, either storage)
// or are filled by hand; the results are part of the bit-exact contract (every HIL golden and the
// proxy golden hash depend on them). Tested against hand-computed vectors, the float64 trilinear
// formula and analytic shapes (tests/shared/sampler_test.cc).
//
// Gradient. InterpolateSmooth returns the trilinear interpolation of the central differences at
// the cell's 8 corners, (φ(x+e) − φ(x−e))/2 per axis. It is continuous across cell faces (the
// analytic gradient of the trilinear cell is not), exact for linear fields, and second-order
// accurate: on a sphere of radius 20 voxels its direction error is ≤ 0.1° (the in-cell analytic
// gradient: 2°). docs/realtime-core.md § Sampler gives the comparison and why.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <type_traits>

namespace palpa::sampler {

/// A position in grid coordinates, Q16.16 voxel units: node (i,j,k) is at (i,j,k)·65536.
/// A type of its own (not three loose ints, nor metres): the proxy's API passes positions as it;
/// the components stay raw Q16.16 because every hot function reads them so.
struct GridPos {
  std::int32_t x = 0, y = 0, z = 0;
  friend constexpr bool operator==(GridPos, GridPos) = default;
};
static_assert(sizeof(GridPos) == 12 && std::is_trivially_copyable_v<GridPos>);  // three registers, no cost

/// φ and its gradient at a point. φ in Q16.16 voxel units (negative inside); gradient
/// ∂φ/∂(x,y,z) in Q16.16 (voxel per voxel, dimensionless).
struct Sample {
  std::int32_t phi = 0;
  std::array<std::int32_t, 3> grad{};
  bool in_grid = false;  ///< false: outside the grid, the boundary value extended outward
};

/// Corner values v[dx][dy][dz] of one cell, Q16.16 voxels; v[4·dx + 2·dy + dz].
using Stencil = std::array<std::int32_t, 8>;

/// What a continuous-gradient sample reads: the 8 corners of cell (i,j,k) and, for each corner,
/// its neighbour one node further out along x, y and z. With n = 4·dx + 2·dy + dz:
///   corner[n] = φ(i+dx, j+dy, k+dz)
///   x_out[n]  = φ(dx ? i+2 : i−1, j+dy, k+dz), likewise y_out (j) and z_out (k).
/// On the grid's outer faces a missing outer node repeats the face node (one-sided difference).
struct WideStencil {
  Stencil corner{};
  Stencil x_out{};
  Stencil y_out{};
  Stencil z_out{};
  constexpr std::int32_t Corner(std::size_t n) const { return corner[n]; }
  constexpr std::int32_t XOut(std::size_t n) const { return x_out[n]; }
  constexpr std::int32_t YOut(std::size_t n) const { return y_out[n]; }
  constexpr std::int32_t ZOut(std::size_t n) const { return z_out[n]; }
};

/// Q16.16 linear interpolation a + (b−a)·t for t in [0, 65536], rounded to nearest (ties up).
/// Exact in int64 for |a|, |b| < 2^30. Used by InterpolateCellGradient.
constexpr std::int32_t Lerp(std::int32_t a, std::int32_t b, std::int32_t t) {
  return a + static_cast<std::int32_t>(((std::int64_t{b} - a) * t + 0x8000) >> 16);
}

/// The trilinear weights of fractions (fx, fy, fz) in [0, 65536], Q32, one pair per z-column
/// (dx, dy): xy[c] = wx·wy exactly (c = 2·dx + dy), and z0[c] = (xy[c]·(65536 − fz)) >> 16, with
/// the column's other weight xy[c] − z0[c]. They sum to exactly 2^32 (a constant field
/// interpolates exactly), and cost 5 multiplies: the four xy products follow from one by
/// wx·(65536 − wy) = (wx << 16) − wx·wy.
struct Weights {
  std::int64_t xy[4];
  std::int64_t z0[4];
};

constexpr Weights TrilinearWeights(std::int32_t fx, std::int32_t fy, std::int32_t fz) {
  const std::int64_t x0 = 65536 - fx, x1 = fx, y0 = 65536 - fy, zw = 65536 - fz;
  Weights w{};
  w.xy[0] = x0 * y0;
  w.xy[1] = (x0 << 16) - w.xy[0];  // x0·y1
  w.xy[2] = (y0 << 16) - w.xy[0];  // x1·y0
  w.xy[3] = (x1 << 16) - w.xy[2];  // x1·y1
  for (std::size_t c = 0; c < 4; ++c) w.z0[c] = (w.xy[c] * zw) >> 16;
  return w;
}

/// Trilinear interpolation of the 8 values at fractions (fx, fy, fz) in [0, 65536]: Σ w_n·v_n
/// with the weights above, rounded to nearest once. Within 1 LSB of the exact trilinear value.
/// Part of the bit-exact contract, and the same arithmetic as the φ of InterpolateSmooth (so
/// Phi() and At() agree to the bit).
/// kShift: the values are Q16.16 >> kShift (blob v2's stored Q7.8: 8), with the same result bits:
/// with v = u·2^s, (Σw·v + 2^31) >> 32 = (Σw·u + 2^(31−s)) >> (32 − s).
template <int kShift = 0>
constexpr std::int32_t InterpolatePhi(const Stencil& v, std::int32_t fx, std::int32_t fy, std::int32_t fz) {
  const Weights w = TrilinearWeights(fx, fy, fz);
  std::int64_t phi = std::int64_t{1} << (31 - kShift);
  for (std::size_t c = 0; c < 4; ++c) phi += w.z0[c] * v[2 * c] + (w.xy[c] - w.z0[c]) * v[2 * c + 1];
  return static_cast<std::int32_t>(phi >> (32 - kShift));
}

/// φ and the analytic gradient of this cell's trilinear polynomial (discontinuous across cell
/// faces). Kept to compare against InterpolateSmooth; the servo loop does not use it.
constexpr Sample InterpolateCellGradient(const Stencil& v, std::int32_t fx, std::int32_t fy, std::int32_t fz) {
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

template <typename Wide>
constexpr int ValueShift() {
  if constexpr (requires { Wide::kValueShift; }) return Wide::kValueShift;
  return 0;
}

/// A stencil whose values are Q16.16 >> kValueShift (RowView: 8, its stored Q7.8) gives the same
/// bits: with v = u·2^s, (Σw·v + 2^31) >> 32 = (Σw·u + 2^(31−s)) >> (32 − s), and likewise for the
/// gradient's >> 33.
/// φ (bit-identical to InterpolatePhi of the corners) and the continuous gradient: the central
/// differences at the 8 corners, interpolated with the same trilinear weights. Derivatives are
/// carried doubled and halved, rounded, at the end.
/// How far below Q16.16 a stencil's values are: Wide::kValueShift (RowView: 8), else 0.
template <typename Wide>  // WideStencil, WideView, BrickView or RowView
[[gnu::always_inline]] inline constexpr Sample InterpolateSmooth(const Wide& s, std::int32_t fx, std::int32_t fy,
                                                                 std::int32_t fz) {
  constexpr int kShift = ValueShift<Wide>();
  const Weights w = TrilinearWeights(fx, fy, fz);
  std::int64_t phi = std::int64_t{1} << (31 - kShift), gx = 0, gy = 0, gz = 0;
  // One z-column (dx, dy) at a time: its corners n0, n0 + 1, their weights, and φ and the three
  // doubled central differences at each (the outer neighbour against the corner across the cell).
  const auto column = [&](std::size_t c) __attribute__((always_inline)) {
    const std::size_t n0 = 2 * c, n1 = n0 + 1;
    const std::int64_t w0 = w.z0[c], w1 = w.xy[c] - w0;
    const std::int64_t v0 = s.Corner(n0), v1 = s.Corner(n1);
    phi += w0 * v0 + w1 * v1;
    gz += w0 * (v1 - s.ZOut(n0)) + w1 * (s.ZOut(n1) - v0);
    if (n0 & 4) {
      gx += w0 * (s.XOut(n0) - std::int64_t{s.Corner(n0 - 4)}) + w1 * (s.XOut(n1) - std::int64_t{s.Corner(n1 - 4)});
    } else {
      gx += w0 * (s.Corner(n0 + 4) - std::int64_t{s.XOut(n0)}) + w1 * (s.Corner(n1 + 4) - std::int64_t{s.XOut(n1)});
    }
    if (n0 & 2) {
      gy += w0 * (s.YOut(n0) - std::int64_t{s.Corner(n0 - 2)}) + w1 * (s.YOut(n1) - std::int64_t{s.Corner(n1 - 2)});
    } else {
      gy += w0 * (s.Corner(n0 + 2) - std::int64_t{s.YOut(n0)}) + w1 * (s.Corner(n1 + 2) - std::int64_t{s.YOut(n1)});
    }
  };
  column(0);
  column(1);
  column(2);
  column(3);
  Sample out;
  out.phi = static_cast<std::int32_t>(phi >> (32 - kShift));
  constexpr int kG = 33 - kShift;                              // doubled differences: one more bit
  constexpr std::int64_t kHalf = std::int64_t{1} << (kG - 1);  // rounding
  out.grad = {static_cast<std::int32_t>((gx + kHalf) >> kG), static_cast<std::int32_t>((gy + kHalf) >> kG),
              static_cast<std::int32_t>((gz + kHalf) >> kG)};
  out.in_grid = true;
  return out;
}

}  // namespace palpa::sampler
