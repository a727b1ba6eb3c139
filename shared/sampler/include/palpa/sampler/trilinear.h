// Trilinear sampling of φ and its gradient on a verified blob, in fixed point, in place.
// RT-safe after construction: no allocation, no exceptions, bounded work (one 8-value or 32-value
// stencil fetch per sample).
//
// Fetching is apart from the math: on a dense grid Fetch() and FetchWide() are the only memory
// accesses; blob v2 reads its octants through the forms below (BrickView, RowView, the spill
// stencils), each giving the interpolation the same values. InterpolatePhi(),
// InterpolateSmooth() and InterpolateCellGradient() are pure functions of the stencil and the
// Q0.16 cell fractions, tested against hand-computed vectors, the float64 trilinear formula and
// analytic shapes (tests/shared/sampler_test.cc).
//
// Gradient. At() returns the trilinear interpolation of the central differences at the cell's 8
// corners, (φ(x+e) − φ(x−e))/2 per axis. It is continuous across cell faces (the analytic
// gradient of the trilinear cell is not), exact for linear fields, and second-order accurate: on a
// sphere of radius 20 voxels its direction error is ≤ 0.1° (the in-cell analytic gradient: 2°).
// docs/realtime-core.md § Sampler gives the comparison and why.
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
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

/// The same 32 values read in place from a dense C-order payload (what TrilinearSampler::
/// FetchWide returns): a base pointer and the strides and outer-layer offsets, so that each value
/// is loaded where the math uses it instead of being copied first.
struct WideView {
  const std::int32_t* base;               // node (i, j, k)
  std::ptrdiff_t si, sj;                  // strides of i and j (k is contiguous)
  std::ptrdiff_t xm, xp, ym, yp, zm, zp;  // offsets of the outer layers, face-clamped
  constexpr std::ptrdiff_t Off(std::size_t n) const {
    return ((n & 4) ? si : 0) + ((n & 2) ? sj : 0) + static_cast<std::ptrdiff_t>(n & 1);
  }
  constexpr std::int32_t Corner(std::size_t n) const { return base[Off(n)]; }
  constexpr std::int32_t XOut(std::size_t n) const {
    return base[((n & 4) ? xp : xm) + ((n & 2) ? sj : 0) + static_cast<std::ptrdiff_t>(n & 1)];
  }
  constexpr std::int32_t YOut(std::size_t n) const {
    return base[((n & 4) ? si : 0) + ((n & 2) ? yp : ym) + static_cast<std::ptrdiff_t>(n & 1)];
  }
  constexpr std::int32_t ZOut(std::size_t n) const {
    return base[((n & 4) ? si : 0) + ((n & 2) ? sj : 0) + ((n & 1) ? zp : zm)];
  }
};

/// The wide stencil's 32 values read in place from blob v2's 4³ int16 octants
/// (docs/blob-format.md), for any cell, the grid's faces included: its 4 nodes per axis (−1..2,
/// face-clamped) span at most two octants per axis, so at most 8. Each node picks its octant by one bit per axis and
/// adds its octant-local offset; a uniform brick or octant points at its own index or table entry's low half (its φ,
/// little-endian) with mask 0, so every value is one branch-free load. Stored Q7.8, returned
/// Q16.16 (·256).
struct BrickView {
  std::array<const std::int16_t*, 8> octant;  // 4·sx + 2·sy + sz
  std::array<std::uint32_t, 8> mask;          // 63 stored, 0 uniform
  // Per axis and node: octant bit (4, 2, 1 or 0) << 16 | local offset (·16, ·4, ·1). The bits and
  // offsets of the three axes are disjoint, so one sum gives both.
  std::array<std::array<std::uint32_t, 4>, 3> node;
  constexpr std::int32_t Get(std::size_t a, std::size_t b, std::size_t c) const {
    const std::uint32_t t = node[0][a] + node[1][b] + node[2][c];
    const std::uint32_t s = t >> 16;
    return std::int32_t{octant[s][t & mask[s]]} * 256;
  }
  // The WideStencil interface (corner nodes are 1 and 2 on each axis).
  constexpr std::int32_t Corner(std::size_t n) const {
    return Get(1 + ((n >> 2) & 1), 1 + ((n >> 1) & 1), 1 + (n & 1));
  }
  constexpr std::int32_t XOut(std::size_t n) const { return Get((n & 4) ? 3 : 0, 1 + ((n >> 1) & 1), 1 + (n & 1)); }
  constexpr std::int32_t YOut(std::size_t n) const { return Get(1 + ((n >> 2) & 1), (n & 2) ? 3 : 0, 1 + (n & 1)); }
  constexpr std::int32_t ZOut(std::size_t n) const {
    return Get(1 + ((n >> 2) & 1), 1 + ((n >> 1) & 1), (n & 1) ? 3 : 0);
  }
};

/// Blob v2's wide stencil for an interior cell (no face-clamped node), read in place. Along each
/// axis the nodes i−1..i+2 start at local coordinate l = (i−1) mod 4 of an octant and spill into
/// the next octant after 4 − l nodes, so node (a, b, c) of the stencil (each 0..3) lies in octant
/// s = 4·[lx + a ≥ 4] + 2·[ly + b ≥ 4] + [lz + c ≥ 4] at local offset
/// 16·lx + 4·ly + lz + 16a + 4b + c − (64·sx + 16·sy + 4·sz). With the octant's address moved by
/// everything but 16a + 4b + c (`row`, one per z-row (a, b) and z-octant h), every value is one
/// load at a constant offset; lz = Lz is a template parameter so that h is known too. Addresses are
/// integers because a moved address may lie outside its octant (only the sums are dereferenced).
/// Values stay Q7.8 (kValueShift = 8): InterpolateSmooth folds the ·256 into its final shifts.
template <int Lz>
struct RowView {
  static constexpr int kValueShift = 8;
  using Rows = std::array<std::array<std::array<std::uintptr_t, 2>, 4>, 4>;
  const Rows& row;
  std::int32_t Get(std::size_t a, std::size_t b, std::size_t c) const {
    const std::size_t h = (static_cast<std::size_t>(Lz) + c) >> 2;
    return *reinterpret_cast<const std::int16_t*>(row[a][b][h] + 2 * (16 * a + 4 * b + c));
  }
  std::int32_t Corner(std::size_t n) const { return Get(1 + ((n >> 2) & 1), 1 + ((n >> 1) & 1), 1 + (n & 1)); }
  std::int32_t XOut(std::size_t n) const { return Get((n & 4) ? 3 : 0, 1 + ((n >> 1) & 1), 1 + (n & 1)); }
  std::int32_t YOut(std::size_t n) const { return Get(1 + ((n >> 2) & 1), (n & 2) ? 3 : 0, 1 + (n & 1)); }
  std::int32_t ZOut(std::size_t n) const { return Get(1 + ((n >> 2) & 1), 1 + ((n >> 1) & 1), (n & 1) ? 3 : 0); }
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

/// φ (bit-identical to InterpolatePhi of the corners) and the continuous gradient: the central
/// differences at the 8 corners, interpolated with the same trilinear weights. Derivatives are
/// carried doubled and halved, rounded, at the end.
/// How far below Q16.16 a stencil's values are: Wide::kValueShift (RowView: 8), else 0.
template <typename Wide>
constexpr int ValueShift() {
  if constexpr (requires { Wide::kValueShift; }) return Wide::kValueShift;
  return 0;
}

/// A stencil whose values are Q16.16 >> kValueShift (RowView: 8, its stored Q7.8) gives the same
/// bits: with v = u·2^s, (Σw·v + 2^31) >> 32 = (Σw·u + 2^(31−s)) >> (32 − s), and likewise for the
/// gradient's >> 33.
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

/// Lipschitz bounds of the trilinear φ over the whole grid, Q16.16 (voxel per voxel).
/// In a trilinear cell ∂φ/∂x is a convex combination of the cell's four x-edge differences, so
/// |∂φ/∂x| ≤ the largest of them (`axis`). |∇φ|² is convex along axis-parallel lines, so its
/// maximum over a cell is at one of the 8 corners (`norm`, exact per cell). φ is continuous across
/// faces, so the largest cell bound holds between any two points of the grid joined by a segment
/// inside the region {φ > −1 voxel}: cells whose corners are all ≤ −1 voxel are left out. That is
/// all the proxy needs: a segment whose end values satisfy φ(a) + φ(b) + 2δ ≥ Λ|b − a| with δ < 1
/// cannot leave the region (leaving and re-entering it would cost ≥ 2 + φ(a) + φ(b) > Λ|b − a|),
/// see docs/realtime-core.md § Proxy.
struct LipschitzBound {
  std::array<std::int32_t, 3> axis{};  ///< max |node difference| along x, y, z over the grid
  std::int32_t norm = 0;               ///< max |∇φ| over the grid (at cell corners), rounded up
  /// norm < |axis| (Euclidean-like fields): only then can `norm`·|d| undercut Σ|d_i|·axis_i
  /// (Cauchy–Schwarz), so users skip the root otherwise (city-block fields: norm = |axis| = √3).
  bool norm_helps = false;
};

/// Blob v2 sampling that is coherent (each sample near the last, as a proxy's are) keeps one of
/// these per sampling point, from one sample to the next: a sample in the cell of the previous one
/// then reads the cell's 8 corners (PhiCache) or its 8 octant addresses (GradientCache) from it
/// instead of through the brick index, as OpenVDB's ValueAccessor keeps the last node it visited.
/// Results are the same bits with or without a cache: it holds exactly what the index gave. A miss
/// costs the look-up plus the stores that fill the cache (about 30 instructions); a hit skips the
/// look-up (docs/blob-format.md § Sampling in place). A cache records the id of the sampler that
/// filled it (unique per constructed sampler, 64 bits), so it never answers for another field, not
/// even one constructed at the same address; the field's bytes must not change while a sampler
/// reads them (they never do: palpad swaps whole blobs and samplers). Value-initialised: empty. Not
/// thread-safe: one per caller. A dense grid leaves it untouched.
struct PhiCache {
  std::uint64_t sampler = 0;  ///< id of the sampler that filled it; 0: empty
  std::uint64_t cell = 0;     ///< its cell (i, j, k), 16 bits an axis: i << 32 | j << 16 | k
  Stencil corners{};          ///< the cell's corners as stored, Q7.8
};

/// At's counterpart of PhiCache (1.1 kB): the RowView addresses of an interior cell's 8 octants.
/// A copy starts empty, since the addresses of uniform octants point into the original.
struct GradientCache {
  std::uint64_t sampler = 0;              ///< as PhiCache
  std::uint64_t cell = 0;                 ///< as PhiCache
  std::array<std::uintptr_t, 8> moved{};  ///< octant addresses, moved as RowView reads them
  /// A uniform octant expanded to 64 values, for `moved` to point into.
  alignas(16) std::array<std::array<std::int16_t, blob::kOctantNodes>, 8> expanded{};

  GradientCache() = default;
  GradientCache(const GradientCache& /*other*/) noexcept {}
  GradientCache& operator=(const GradientCache& /*other*/) noexcept {
    sampler = 0;
    return *this;
  }
};

/// Samples a verified FieldView. Positions outside [0, n−1] on any axis answer the boundary value
/// extended outward: φ at the nearest grid point (coordinates clamped), its gradient with the
/// clamped axes' components zeroed, `in_grid` false. A face where φ < 0 (an open scan, a part
/// reaching the grid's edge) is then a wall, not free space. Nothing outside the payload is ever
/// read.
class TrilinearSampler {
 public:
  /// Non-RT: scans every cell once (through Fetch) for the Lipschitz bound, O(nodes).
  explicit TrilinearSampler(const blob::FieldView& field);

  std::int32_t background() const { return background_; }
  const std::array<std::int32_t, 3>& dims() const { return dims_; }
  const LipschitzBound& lipschitz() const { return lipschitz_; }
  /// The bound over the band alone: lipschitz() without blob v2's free-space floor (equal to it
  /// otherwise). It holds along a segment whose two end values are both ≤ background(): the
  /// segment can only leave the band into free space, where φ ≥ background() ≥ both ends, so a
  /// dip below them lies on a stretch inside the band (docs/realtime-core.md § Proxy).
  const LipschitzBound& lipschitz_band() const { return lipschitz_band_; }
  /// (n − 1)·65536 along axis a: the last node's coordinate, Q16.16.
  std::uint32_t last_node(std::size_t a) const { return last_[a]; }

  /// φ alone at `p` (8 values). RT-safe.
  std::int32_t Phi(GridPos p) const { return Phi(p.x, p.y, p.z); }
  /// φ and the continuous gradient at `p` (32 values). RT-safe.
  Sample At(GridPos p) const { return At(p.x, p.y, p.z); }
  /// The same with the coordinates apart: out of line, and three registers rather than a packed
  /// struct (packing two int32 into one register costs the caller a store-forwarding stall).
  std::int32_t Phi(std::int32_t x, std::int32_t y, std::int32_t z) const;
  Sample At(std::int32_t x, std::int32_t y, std::int32_t z) const;

  /// Phi and At through a cache (blob v2; a dense grid ignores it): the same bits, and a sample in
  /// the cell of the previous one skips the brick index. RT-safe.
  std::int32_t Phi(std::int32_t x, std::int32_t y, std::int32_t z, PhiCache& cache) const;
  Sample At(std::int32_t x, std::int32_t y, std::int32_t z, GradientCache& cache) const;
  std::int32_t Phi(GridPos p, PhiCache& cache) const { return Phi(p.x, p.y, p.z, cache); }
  Sample At(GridPos p, GradientCache& cache) const { return At(p.x, p.y, p.z, cache); }

  /// φ and the analytic in-cell gradient at `p`. RT-safe; for comparison and tests.
  Sample AtCellGradient(GridPos p) const {
    Cell c;
    if (!Locate(p, c)) return Background();
    return InterpolateCellGradient(Fetch(c.i, c.j, c.k), c.fx, c.fy, c.fz);
  }

  /// The 8 corner values of cell (i,j,k); requires 0 ≤ i < nx−1 etc. (Locate guarantees it).
  Stencil Fetch(std::int32_t i, std::int32_t j, std::int32_t k) const {
    if (phi_ == nullptr) {
      Stencil v = FetchStored(i, j, k);
      for (std::int32_t& x : v) x *= 256;
      return v;
    }
    const std::int32_t* b = phi_ + Offset(i, j, k);
    const std::ptrdiff_t si = stride_i_, sj = dims_[2];
    return {b[0], b[1], b[sj], b[sj + 1], b[si], b[si + 1], b[si + sj], b[si + sj + 1]};
  }

  /// Blob v2: Fetch's corners as stored, Q7.8 (Q16.16 >> 8); same precondition. The corners
  /// spill into the next octant along the axes where the cell's local coordinate is 3.
  Stencil FetchStored(std::int32_t i, std::int32_t j, std::int32_t k) const {
    const std::uint32_t local = Local(i, j, k);
    switch (Spill(local)) {
      case 0: {  // one octant: one index entry, one table entry, eight fixed offsets
        const std::uint32_t* entry = OwnEntry(i, j, k);
        if ((*entry & blob::kSlotEmpty) != 0) {
          const std::int32_t v = static_cast<std::int16_t>(*entry & 0xFFFFU);
          return {v, v, v, v, v, v, v, v};
        }
        const std::int16_t* b = OwnCorner(*entry, local);
        return {b[0], b[1], b[4], b[5], b[16], b[17], b[20], b[21]};
      }
      case kSpillZ:
        return SpillStencil<1>(i, j, k);
      case kSpillY:
        return SpillStencil<2>(i, j, k);
      case kSpillY | kSpillZ:
        return SpillStencil<3>(i, j, k);
      case kSpillX:
        return SpillStencil<4>(i, j, k);
      case kSpillX | kSpillZ:
        return SpillStencil<5>(i, j, k);
      case kSpillX | kSpillY:
        return SpillStencil<6>(i, j, k);
      default:
        return SpillStencil<7>(i, j, k);
    }
  }

  /// The 32 values of WideStencil for cell (i,j,k), read in place; same precondition as Fetch.
  WideView FetchWide(std::int32_t i, std::int32_t j, std::int32_t k) const {
    const std::ptrdiff_t si = stride_i_, sj = dims_[2];
    // Outer layers: one node further out, or the face node itself on the grid's faces.
    return {phi_ + Offset(i, j, k),
            si,
            sj,
            i > 0 ? -si : 0,
            i + 2 < dims_[0] ? 2 * si : si,
            j > 0 ? -sj : 0,
            j + 2 < dims_[1] ? 2 * sj : sj,
            k > 0 ? -1 : 0,
            k + 2 < dims_[2] ? 2 : 1};
  }

  /// Blob v2: FetchWide's 32 values of cell (i,j,k) in place in the octants (i−1..i+2 per axis,
  /// face-clamped like FetchWide). Same precondition as Fetch.
  BrickView FetchBricks(std::int32_t i, std::int32_t j, std::int32_t k) const {
    BrickView v;
    const std::array<std::int32_t, 3> cell = {i, j, k};
    std::array<std::int32_t, 3> lo{};
    constexpr std::array<std::int32_t, 3> kLocal = {16, 4, 1};
    for (std::size_t a = 0; a < 3; ++a) {
      const std::int32_t c = cell[a];
      const std::array<std::int32_t, 4> node = {c > 0 ? c - 1 : c, c, c + 1, c + 2 < dims_[a] ? c + 2 : c + 1};
      lo[a] = node[0] >> 2;
      for (std::size_t m = 0; m < 4; ++m) {
        v.node[a][m] = (static_cast<std::uint32_t>((node[m] >> 2) - lo[a]) << (18 - a)) |
                       static_cast<std::uint32_t>((node[m] & 3) * kLocal[a]);
      }
    }
    // Per axis, the index offset and octant-table bit of the first and second octant (the second
    // clamped to the last octant: it is then never selected, and the lookup stays in the index).
    const std::array<std::ptrdiff_t, 3> stride = {slot_stride_i_, brick_dims_[2], 1};
    std::array<std::array<std::ptrdiff_t, 2>, 3> off{};
    std::array<std::array<std::uint32_t, 2>, 3> sub{};
    for (std::size_t a = 0; a < 3; ++a) {
      const std::int32_t o1 = std::min(lo[a] + 1, 2 * brick_dims_[a] - 1);
      off[a] = {(lo[a] >> 1) * stride[a], (o1 >> 1) * stride[a]};
      sub[a] = {static_cast<std::uint32_t>(lo[a] & 1) << (2 - a), static_cast<std::uint32_t>(o1 & 1) << (2 - a)};
    }
    for (std::size_t s = 0; s < 8; ++s) {
      const std::size_t sx = s >> 2, sy = (s >> 1) & 1, sz = s & 1;
      const std::uint32_t* slot = index_ + off[0][sx] + off[1][sy] + off[2][sz];
      const std::uint32_t e = *slot;
      // Select, don't branch: a uniform slot reads itself (the table address is then never used).
      const bool uniform_slot = (e & blob::kSlotEmpty) != 0;
      const std::uint32_t* table =
          tables_ + 8 * static_cast<std::size_t>(uniform_slot ? 0 : e) + (sub[0][sx] | sub[1][sy] | sub[2][sz]);
      const std::uint32_t* entry = uniform_slot ? slot : table;
      const std::uint32_t t = *entry;
      const bool uniform = (t & blob::kSlotEmpty) != 0;
      v.octant[s] = uniform ? reinterpret_cast<const std::int16_t*>(entry)
                            : octants_ + static_cast<std::size_t>(t) * blob::kOctantNodes;
      v.mask[s] = uniform ? 0 : blob::kOctantNodes - 1;
    }
    return v;
  }

  /// FetchWide's values copied out (for tests); either storage.
  WideStencil CopyWide(std::int32_t i, std::int32_t j, std::int32_t k) const;

 private:
  template <typename Wide>
  static WideStencil Copy(const Wide& v) {
    constexpr int kShift = ValueShift<Wide>();
    WideStencil w;
    for (std::size_t n = 0; n < 8; ++n) {
      w.corner[n] = v.Corner(n) * (1 << kShift);
      w.x_out[n] = v.XOut(n) * (1 << kShift);
      w.y_out[n] = v.YOut(n) * (1 << kShift);
      w.z_out[n] = v.ZOut(n) * (1 << kShift);
    }
    return w;
  }

  struct Cell {
    std::int32_t i, j, k, fx, fy, fz;
  };

  // Blob v2: cell (i, j, k)'s node offset in its octant, 16·(i mod 4) + 4·(j mod 4) + k mod 4.
  static std::uint32_t Local(std::int32_t i, std::int32_t j, std::int32_t k) {
    return static_cast<std::uint32_t>(((i & 3) << 4) | ((j & 3) << 2) | (k & 3));
  }
  // Blob v2: the axes along which a cell's corners spill into the next octant (local coordinate
  // 3, both bits of its field in `local` set), as bits 4 (x), 2 (y) and 0 (z): kSpillX etc.
  static constexpr std::uint32_t kSpillX = 0x10, kSpillY = 0x04, kSpillZ = 0x01;
  static std::uint32_t Spill(std::uint32_t local) { return local & (local >> 1) & (kSpillX | kSpillY | kSpillZ); }
  // Blob v2: the entry of node (i, j, k)'s octant: its brick's octant-table entry, or for a uniform
  // brick its index entry; either is an octant number or kSlotEmpty | φ.
  const std::uint32_t* OwnEntry(std::int32_t i, std::int32_t j, std::int32_t k) const {
    const std::uint32_t* slot = Slot(i, j, k);
    if ((*slot & blob::kSlotEmpty) != 0) return slot;
    return tables_ + 8 * std::size_t{*slot} + OctantBits(i, j, k);
  }
  // Blob v2: the index entry of node (i, j, k)'s brick.
  const std::uint32_t* Slot(std::int32_t i, std::int32_t j, std::int32_t k) const {
    return index_ + static_cast<std::ptrdiff_t>(i >> 3) * slot_stride_i_ +
           static_cast<std::ptrdiff_t>(j >> 3) * brick_dims_[2] + (k >> 3);
  }
  // Blob v2: node (i, j, k)'s octant in its brick, the octant-table entry 4·ox + 2·oy + oz.
  static std::uint32_t OctantBits(std::int32_t i, std::int32_t j, std::int32_t k) {
    return static_cast<std::uint32_t>(((i >> 2) & 1) << 2 | ((j >> 2) & 1) << 1 | ((k >> 2) & 1));
  }
  // Blob v2: node (i, j, k) in stored octant number `octant`.
  const std::int16_t* OwnCorner(std::uint32_t octant, std::uint32_t local) const {
    return octants_ + static_cast<std::size_t>(octant) * blob::kOctantNodes + local;
  }
  // Blob v2, a cell whose corners spill into the next octant along the axes in Mask (4: x, 2: y,
  // 1: z; not 0): corner n (4·dx + 2·dy + dz) lies in octant s = n & Mask of the 2, 4 or 8 it
  // touches, the cell's own (s = 0) and its next ones along the axes in s. Each is looked up once,
  // branch-free: its index entry (the cell's own slot, moved one brick along each axis of s where
  // the cell's octant is its brick's second) and its table entry (the octant bits flipped by s).
  // A corner is then one load at a constant offset from it: the cell's local offset, plus the
  // corner's, minus 4 nodes along each axis of s. A uniform brick or octant is read through its
  // entry's low half (its φ, little-endian) with a zero offset mask. Stored values, Q7.8.
  template <int Mask>
  [[gnu::always_inline]] Stencil SpillStencil(std::int32_t i, std::int32_t j, std::int32_t k) const {
    const std::uint32_t* own = Slot(i, j, k);
    const std::ptrdiff_t next[3] = {(i & 4) != 0 ? slot_stride_i_ : 0, (j & 4) != 0 ? brick_dims_[2] : 0,
                                    (k & 4) != 0 ? 1 : 0};
    const std::uint32_t bits = OctantBits(i, j, k);
    const std::uint32_t local = Local(i, j, k);
    std::array<const std::int16_t*, 8> octant{};
    std::array<std::uint32_t, 8> mask{};
#pragma GCC unroll 8
    for (std::uint32_t s = 0; s < 8; ++s) {
      if ((s & ~static_cast<std::uint32_t>(Mask)) != 0) continue;
      const std::uint32_t* slot =
          own + ((s & 4) != 0 ? next[0] : 0) + ((s & 2) != 0 ? next[1] : 0) + ((s & 1) != 0 ? next[2] : 0);
      const std::uint32_t e = *slot;
      const std::uint32_t* entry = (e & blob::kSlotEmpty) != 0 ? slot : tables_ + 8 * std::size_t{e} + (bits ^ s);
      const std::uint32_t t = *entry;
      const bool uniform = (t & blob::kSlotEmpty) != 0;
      octant[s] = uniform ? reinterpret_cast<const std::int16_t*>(entry)
                          : octants_ + static_cast<std::size_t>(t) * blob::kOctantNodes;
      mask[s] = uniform ? 0 : 63;
    }
    const auto at = [&](std::uint32_t n) -> std::int32_t {
      const std::uint32_t s = n & static_cast<std::uint32_t>(Mask);
      const std::uint32_t offset = local + (((n >> 2) & 1) << 4) + (((n >> 1) & 1) << 2) + (n & 1) -
                                   (((s >> 2) & 1) << 6) - (((s >> 1) & 1) << 4) - ((s & 1) << 2);
      return octant[s][offset & mask[s]];
    };
    return {at(0), at(1), at(2), at(3), at(4), at(5), at(6), at(7)};
  }

  // Phi() on blob v2; kCache: through `cache` (else null).
  template <bool kCache>
  std::int32_t PhiStored(std::int32_t x, std::int32_t y, std::int32_t z, PhiCache* cache) const;
  // The cache's `cell` of the cell holding Q16.16 position (x, y, z): ⌊x⌋, ⌊y⌋, ⌊z⌋ as 16-bit
  // fields, one per value an int32 >> 16 can take, so no two positions in different cells share it.
  static std::uint64_t CacheCell(std::int32_t x, std::int32_t y, std::int32_t z) {
    return static_cast<std::uint64_t>(static_cast<std::uint16_t>(x >> 16)) << 32 |
           static_cast<std::uint64_t>(static_cast<std::uint16_t>(y >> 16)) << 16 |
           static_cast<std::uint64_t>(static_cast<std::uint16_t>(z >> 16));
  }
  // Whether a cache filled by this sampler holds the cell of position (x, y, z) (its `cell` and
  // `sampler` fields, as PhiCache and GradientCache both have them).
  template <typename Cache>
  [[gnu::always_inline]] bool Holds(const Cache& cache, std::int32_t x, std::int32_t y, std::int32_t z) const {
    return cache.cell == CacheCell(x, y, z) && cache.sampler == id_;
  }
  // The cache's `cell` of cell c as Locate found it (each index 0 .. 4094). Only these are cached: a position
  // whose CacheCell equals one lies inside that cell, below the grid's last node, at the fractions
  // given by its low 16 bits, exactly as Locate would place it (not so the last node itself, which
  // Locate puts at fraction 1 of the cell below).
  static std::uint64_t CacheCell(const Cell& c) {
    return static_cast<std::uint64_t>(c.i) << 32 | static_cast<std::uint64_t>(c.j) << 16 |
           static_cast<std::uint64_t>(c.k);
  }
  // Phi() on blob v2 for cell (i, j, k) at fractions f, whose corners spill into the next octant
  // along the axes in `spill` (two or three); kCache: the corners are also written to `keep`.
  template <bool kCache>
  std::int32_t PhiSpillMany(std::uint32_t spill, std::int32_t i, std::int32_t j, std::int32_t k, const std::int32_t* f,
                            Stencil* keep) const;
  // Blob v2, cell (i, j, k) with 1 ≤ cell ≤ n − 3 on every axis: the moved addresses of the 8
  // octants its RowView reads (a uniform one expanded into `expanded` first).
  void RowOctants(std::int32_t i, std::int32_t j, std::int32_t k, std::array<std::uintptr_t, 8>& moved,
                  std::array<std::array<std::int16_t, blob::kOctantNodes>, 8>& expanded) const;
  // `use` applied to cell (i, j, k)'s RowView on the addresses RowOctants gave (in one of its 16
  // forms), returning R. At() and CopyWide() read bricks through it.
  template <typename R, typename Use>
  R WithRowView(std::int32_t i, std::int32_t j, std::int32_t k, const std::array<std::uintptr_t, 8>& moved,
                const Use& use) const;
  // The same on addresses looked up here (RowOctants into locals): At() and CopyWide() without a cache.
  template <typename R, typename Use>
  R WithRowView(std::int32_t i, std::int32_t j, std::int32_t k, const Use& use) const;
  // Whether the wide stencil of cell (i, j, k) repeats a face node (FetchBricks reads those).
  bool FaceCell(std::int32_t i, std::int32_t j, std::int32_t k) const {
    // One unsigned compare per axis: interior is 1 ≤ cell ≤ n − 3 (none when n < 4).
    return (static_cast<std::uint32_t>(i - 1) >= static_cast<std::uint32_t>(dims_[0] - 3)) |
           (static_cast<std::uint32_t>(j - 1) >= static_cast<std::uint32_t>(dims_[1] - 3)) |
           (static_cast<std::uint32_t>(k - 1) >= static_cast<std::uint32_t>(dims_[2] - 3));
  }

  // Cell and fractions of `p`, or false outside [0, n−1]³. On the last node of an axis: the last
  // cell at fraction 1 (cell = min(⌊x⌋, n − 2), fraction = x − cell).
  bool Locate(GridPos p, Cell& c) const { return Locate(p.x, p.y, p.z, c); }
  bool Locate(std::int32_t x, std::int32_t y, std::int32_t z, Cell& c) const {
    const auto ux = static_cast<std::uint32_t>(x), uy = static_cast<std::uint32_t>(y),
               uz = static_cast<std::uint32_t>(z);
    // One unsigned compare per axis rejects both negative positions and those past the last node.
    if ((ux > last_[0]) | (uy > last_[1]) | (uz > last_[2])) return false;
    c.i = std::min(static_cast<std::int32_t>(ux >> 16), dims_[0] - 2);
    c.j = std::min(static_cast<std::int32_t>(uy >> 16), dims_[1] - 2);
    c.k = std::min(static_cast<std::int32_t>(uz >> 16), dims_[2] - 2);
    c.fx = x - (c.i << 16);
    c.fy = y - (c.j << 16);
    c.fz = z - (c.k << 16);
    return true;
  }

  std::ptrdiff_t Offset(std::int32_t i, std::int32_t j, std::int32_t k) const {
    return static_cast<std::ptrdiff_t>(i) * stride_i_ + static_cast<std::ptrdiff_t>(j) * dims_[2] + k;
  }

  // Outside the grid: the boundary value extended outward (see the class comment).
  std::int32_t PhiOutside(std::int32_t x, std::int32_t y, std::int32_t z) const;
  Sample AtOutside(std::int32_t x, std::int32_t y, std::int32_t z) const;

  Sample Background() const {
    Sample s;
    s.phi = background_;
    return s;
  }

  const std::int32_t* phi_;      // v1 dense payload, or null for v2
  const std::uint32_t* index_;   // v2 brick index
  const std::uint32_t* tables_;  // v2 octant tables
  const std::int16_t* octants_;  // v2 octants
  std::array<std::int32_t, 3> brick_dims_;
  std::array<std::int32_t, 3> dims_;
  std::array<std::uint32_t, 3> last_;  // (n − 1)·65536 per axis
  std::ptrdiff_t stride_i_;
  std::ptrdiff_t slot_stride_i_;  // v2: bny·bnz, the brick index's stride along x
  std::int32_t background_;
  std::uint64_t id_;  // unique per constructed sampler, never 0: what a cache records
  LipschitzBound lipschitz_;
  LipschitzBound lipschitz_band_;
};

}  // namespace palpa::sampler
