// Trilinear sampling of φ and its continuous gradient on a verified field, in fixed point, in
// place: the public API. Sampler<Accessor> reads one storage (blob v1 through
// blob::DenseAccessor, v2 through blob::BrickAccessor), chosen once per field, so no sample
// branches on the storage; TrilinearSampler holds either, for callers that take any blob.
// interpolate.h has the maths, fetch.h the stencil reads. RT-safe after construction: no
// allocation, no exceptions, bounded work (one 8-value or 32-value stencil fetch per sample).
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <variant>

#include "palpa/blob/blob.h"
#include "palpa/sampler/fetch.h"
#include "palpa/sampler/interpolate.h"

namespace palpa::sampler {

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
/// thread-safe: one per caller. A dense grid's sampler leaves it untouched.
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

/// Samples a verified field's storage. Positions outside [0, n−1] on any axis answer the boundary
/// value extended outward: φ at the nearest grid point (coordinates clamped), its gradient with the
/// clamped axes' components zeroed, `in_grid` false. A face where φ < 0 (an open scan, a part
/// reaching the grid's edge) is then a wall, not free space. Nothing outside the payload is read.
template <typename Accessor>  // blob::DenseAccessor or blob::BrickAccessor
class Sampler {
 public:
  /// `band_outside`: voxels, the field's outside band (FieldView::band_outside), whose value free
  /// space reads as (background()). Non-RT: scans every cell once for the Lipschitz bound, O(nodes).
  Sampler(const Accessor& storage, std::int32_t band_outside);

  const Accessor& storage() const { return acc_; }
  /// φ of free space, Q16.16 voxels: band_outside · 65536.
  std::int32_t background() const { return background_; }
  const std::array<std::int32_t, 3>& dims() const { return acc_.dims(); }
  const LipschitzBound& lipschitz() const { return lipschitz_; }
  /// The bound over the band alone: lipschitz() without blob v2's free-space floor (equal to it
  /// otherwise). It holds along a segment whose two end values are both ≤ background(): the
  /// segment can only leave the band into free space, where φ ≥ background() ≥ both ends, so a
  /// dip below them lies on a stretch inside the band (docs/realtime-core.md § Proxy).
  const LipschitzBound& lipschitz_band() const { return lipschitz_band_; }
  /// (n − 1)·65536 along axis a: the last node's coordinate, Q16.16.
  std::uint32_t last_node(std::size_t a) const { return last_[a]; }

  /// φ alone at (x, y, z), Q16.16 grid coordinates (8 values). RT-safe. Out of line, with the
  /// coordinates in three registers (a packed GridPos costs the caller a store-forwarding stall).
  std::int32_t Phi(std::int32_t x, std::int32_t y, std::int32_t z) const;
  /// φ and the continuous gradient (32 values). RT-safe.
  Sample At(std::int32_t x, std::int32_t y, std::int32_t z) const;
  /// The same through a cache (blob v2; a dense grid ignores it): the same bits, and a sample in
  /// the cell of the previous one skips the brick index. RT-safe.
  std::int32_t Phi(std::int32_t x, std::int32_t y, std::int32_t z, PhiCache& cache) const;
  Sample At(std::int32_t x, std::int32_t y, std::int32_t z, GradientCache& cache) const;
  std::int32_t Phi(GridPos p) const { return Phi(p.x, p.y, p.z); }
  Sample At(GridPos p) const { return At(p.x, p.y, p.z); }
  std::int32_t Phi(GridPos p, PhiCache& cache) const { return Phi(p.x, p.y, p.z, cache); }
  Sample At(GridPos p, GradientCache& cache) const { return At(p.x, p.y, p.z, cache); }

  /// φ and the analytic in-cell gradient. RT-safe; for comparison and tests.
  Sample AtCellGradient(GridPos p) const;
  /// The 8 corners of cell (i, j, k), Q16.16; requires 0 ≤ i < nx − 1 etc.
  Stencil Fetch(std::int32_t i, std::int32_t j, std::int32_t k) const { return fetch::Corners(acc_, i, j, k); }
  /// The wide stencil's 32 values copied out, Q16.16 (for tests); same precondition.
  WideStencil CopyWide(std::int32_t i, std::int32_t j, std::int32_t k) const;

 private:
  struct Cell {
    std::int32_t i, j, k, fx, fy, fz;
  };
  // Cell and fractions of (x, y, z), or false outside [0, n−1]³ (trilinear.cc, as the rest).
  bool Locate(std::int32_t x, std::int32_t y, std::int32_t z, Cell& c) const;
  // A cache's `cell` of position (x, y, z), and of a cell as Locate found it.
  static std::uint64_t CacheCell(std::int32_t x, std::int32_t y, std::int32_t z);
  static std::uint64_t CacheCell(const Cell& c);
  // Whether a cache filled by this sampler holds the cell of (x, y, z).
  template <typename Cache>
  bool Holds(const Cache& cache, std::int32_t x, std::int32_t y, std::int32_t z) const;
  // Blob v2's Phi (kCache: through `cache`, else null), and its cells that spill along two or
  // three axes; kCache: their corners are also written to `keep`.
  template <bool kCache>
  std::int32_t PhiStored(std::int32_t x, std::int32_t y, std::int32_t z, PhiCache* cache) const;
  template <bool kCache>
  std::int32_t PhiSpillMany(std::uint32_t spill, std::int32_t i, std::int32_t j, std::int32_t k, const std::int32_t* f,
                            Stencil* keep) const;
  // Outside the grid: the boundary value extended outward (see the class comment).
  std::int32_t PhiOutside(std::int32_t x, std::int32_t y, std::int32_t z) const;
  Sample AtOutside(std::int32_t x, std::int32_t y, std::int32_t z) const;
  Sample Background() const;

  Accessor acc_;
  std::array<std::uint32_t, 3> last_;  // (n − 1)·65536 per axis
  std::int32_t background_;
  std::uint64_t id_;  // unique per constructed sampler, never 0: what a cache records
  LipschitzBound lipschitz_;
  LipschitzBound lipschitz_band_;
};

using DenseSampler = Sampler<blob::DenseAccessor>;
using BrickSampler = Sampler<blob::BrickAccessor>;
extern template class Sampler<blob::DenseAccessor>;
extern template class Sampler<blob::BrickAccessor>;

/// Either sampler, as a verified view's storage asks: for callers that take any blob (host tools,
/// tests, palpad's field slot). Each call goes to the typed sampler through one branch; the servo
/// tick takes it once per tick (proxy::ProxyTick), not per sample.
class TrilinearSampler {
 public:
  /// Non-RT: constructs the typed sampler (its Lipschitz scan, O(nodes)).
  explicit TrilinearSampler(const blob::FieldView& field);

  const DenseSampler* dense() const { return std::get_if<DenseSampler>(&s_); }
  const BrickSampler* bricks() const { return std::get_if<BrickSampler>(&s_); }
  /// f(typed sampler), for code templated on the storage.
  template <typename F>
  decltype(auto) Visit(F&& f) const {
    if (const BrickSampler* b = bricks()) return f(*b);
    return f(*std::get_if<DenseSampler>(&s_));
  }

  std::int32_t background() const {
    return Visit([](const auto& s) { return s.background(); });
  }
  const std::array<std::int32_t, 3>& dims() const {
    return Visit([](const auto& s) -> const std::array<std::int32_t, 3>& { return s.dims(); });
  }
  const LipschitzBound& lipschitz() const {
    return Visit([](const auto& s) -> const LipschitzBound& { return s.lipschitz(); });
  }
  const LipschitzBound& lipschitz_band() const {
    return Visit([](const auto& s) -> const LipschitzBound& { return s.lipschitz_band(); });
  }
  std::uint32_t last_node(std::size_t a) const {
    return Visit([a](const auto& s) { return s.last_node(a); });
  }
  std::int32_t Phi(GridPos p) const {
    return Visit([p](const auto& s) { return s.Phi(p); });
  }
  std::int32_t Phi(std::int32_t x, std::int32_t y, std::int32_t z) const { return Phi(GridPos{x, y, z}); }
  Sample At(std::int32_t x, std::int32_t y, std::int32_t z) const { return At(GridPos{x, y, z}); }
  Sample At(GridPos p) const {
    return Visit([p](const auto& s) { return s.At(p); });
  }
  std::int32_t Phi(GridPos p, PhiCache& cache) const {
    return Visit([&](const auto& s) { return s.Phi(p, cache); });
  }
  Sample At(GridPos p, GradientCache& cache) const {
    return Visit([&](const auto& s) { return s.At(p, cache); });
  }
  Sample AtCellGradient(GridPos p) const {
    return Visit([p](const auto& s) { return s.AtCellGradient(p); });
  }
  Stencil Fetch(std::int32_t i, std::int32_t j, std::int32_t k) const {
    return Visit([=](const auto& s) { return s.Fetch(i, j, k); });
  }
  WideStencil CopyWide(std::int32_t i, std::int32_t j, std::int32_t k) const {
    return Visit([=](const auto& s) { return s.CopyWide(i, j, k); });
  }

 private:
  std::variant<DenseSampler, BrickSampler> s_;
};

}  // namespace palpa::sampler
