#include "palpa/sampler/trilinear.h"

#include <algorithm>
#include <atomic>
#include <cstdlib>

#include "palpa/fixed/q.h"

// GCC packs a cell's 8 corners into vectors to store them in a PhiCache: about 20 shuffles on
// every miss, which cost more than the 8 plain stores they replace (palpa_blob_v2_bench). Clang
// (the fuzz and sanitizer builds) does not take the attribute.
#if defined(__GNUC__) && !defined(__clang__)
#define PALPA_NO_SLP __attribute__((optimize("no-tree-slp-vectorize")))
#else
#define PALPA_NO_SLP
#endif

namespace palpa::sampler {
namespace {

// Sampler ids for caches: 1, 2, 3, ...
std::uint64_t NextId() {
  static std::atomic<std::uint64_t> next{0};
  return next.fetch_add(1, std::memory_order_relaxed) + 1;
}

// Copies a cell's corners into a PhiCache element by element, from the registers they were loaded
// into (an aggregate copy goes through a stack temporary and a wide reload, which stalls).
[[gnu::always_inline]] inline void Keep(const Stencil& v, Stencil& cache) {
#pragma GCC unroll 8
  for (std::size_t n = 0; n < 8; ++n) cache[n] = v[n];
}

template <typename Wide>
WideStencil Copy(const Wide& v) {
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

LipschitzBound Bound(std::int32_t bx, std::int32_t by, std::int32_t bz, std::int64_t n2) {
  LipschitzBound lb;
  lb.axis = {bx, by, bz};
  const auto root = static_cast<std::int64_t>(fixed::ISqrt(n2));
  lb.norm = static_cast<std::int32_t>(root * root == n2 ? root : root + 1);  // round up: a bound
  lb.norm_helps =
      std::int64_t{lb.norm} * lb.norm < std::int64_t{bx} * bx + std::int64_t{by} * by + std::int64_t{bz} * bz;
  return lb;
}

}  // namespace

// Cell and fractions of (x, y, z), or false outside [0, n−1]³. On the last node of an axis: the
// last cell at fraction 1 (cell = min(⌊x⌋, n − 2), fraction = x − cell).
template <typename Accessor>
[[gnu::always_inline]] inline bool Sampler<Accessor>::Locate(std::int32_t x, std::int32_t y, std::int32_t z,
                                                             Cell& c) const {
  const auto ux = static_cast<std::uint32_t>(x), uy = static_cast<std::uint32_t>(y), uz = static_cast<std::uint32_t>(z);
  // One unsigned compare per axis rejects both negative positions and those past the last node.
  if ((ux > last_[0]) | (uy > last_[1]) | (uz > last_[2])) return false;
  const std::array<std::int32_t, 3>& n = acc_.dims();
  c.i = std::min(static_cast<std::int32_t>(ux >> 16), n[0] - 2);
  c.j = std::min(static_cast<std::int32_t>(uy >> 16), n[1] - 2);
  c.k = std::min(static_cast<std::int32_t>(uz >> 16), n[2] - 2);
  c.fx = x - (c.i << 16);
  c.fy = y - (c.j << 16);
  c.fz = z - (c.k << 16);
  return true;
}

// ⌊x⌋, ⌊y⌋, ⌊z⌋ as 16-bit fields, one per value an int32 >> 16 can take, so no two positions in
// different cells share it.
template <typename Accessor>
[[gnu::always_inline]] inline std::uint64_t Sampler<Accessor>::CacheCell(std::int32_t x, std::int32_t y,
                                                                         std::int32_t z) {
  return static_cast<std::uint64_t>(static_cast<std::uint16_t>(x >> 16)) << 32 |
         static_cast<std::uint64_t>(static_cast<std::uint16_t>(y >> 16)) << 16 |
         static_cast<std::uint64_t>(static_cast<std::uint16_t>(z >> 16));
}

// Cell c as Locate found it (each index 0 .. 4094). Only these are cached: a position whose
// CacheCell equals one lies inside that cell, below the grid's last node, at the fractions given
// by its low 16 bits, exactly as Locate would place it (not so the last node itself, which Locate
// puts at fraction 1 of the cell below).
template <typename Accessor>
[[gnu::always_inline]] inline std::uint64_t Sampler<Accessor>::CacheCell(const Cell& c) {
  return static_cast<std::uint64_t>(c.i) << 32 | static_cast<std::uint64_t>(c.j) << 16 |
         static_cast<std::uint64_t>(c.k);
}

template <typename Accessor>
template <typename Cache>
[[gnu::always_inline]] inline bool Sampler<Accessor>::Holds(const Cache& cache, std::int32_t x, std::int32_t y,
                                                            std::int32_t z) const {
  return cache.cell == CacheCell(x, y, z) && cache.sampler == id_;
}

template <typename Accessor>
Sample Sampler<Accessor>::Background() const {
  Sample s;
  s.phi = background_;
  return s;
}

template <typename Accessor>
Sampler<Accessor>::Sampler(const Accessor& storage, std::int32_t band_outside)
    : acc_(storage),
      last_{static_cast<std::uint32_t>(storage.dims()[0] - 1) << 16,
            static_cast<std::uint32_t>(storage.dims()[1] - 1) << 16,
            static_cast<std::uint32_t>(storage.dims()[2] - 1) << 16},
      background_(band_outside << 16),
      id_(NextId()) {
  // One pass over every cell through Fetch (the storage's only access path). Skipped: cells whose
  // corners are all equal (free space and deep inside, most of the grid: zero gradient) and cells
  // with every corner ≤ −1 voxel (φ ≤ −1 throughout; the bound is only needed on {φ > −1}, see
  // LipschitzBound), which leaves out the medial-axis kinks deep inside the object.
  const std::array<std::int32_t, 3>& dims = acc_.dims();
  std::int32_t mx = 0, my = 0, mz = 0;
  std::int64_t norm2 = 0;
  for (std::int32_t i = 0; i + 1 < dims[0]; ++i) {
    for (std::int32_t j = 0; j + 1 < dims[1]; ++j) {
      for (std::int32_t k = 0; k + 1 < dims[2]; ++k) {
        const Stencil v = Fetch(i, j, k);
        if (std::all_of(v.begin() + 1, v.end(), [&](std::int32_t x) { return x == v[0]; })) continue;
        if (*std::max_element(v.begin(), v.end()) <= -(1 << 16)) continue;
        // v2 free space (docs/blob-format.md § Free-space bound): every corner at or above the
        // outside band. There φ is a lower bound of band_outside + the distance to the cells
        // scanned here, which is all the proxy's certificate needs once Λ ≥ 1 (below).
        if (Accessor::kBricks && *std::min_element(v.begin(), v.end()) >= background_) continue;
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
  lipschitz_band_ = Bound(mx, my, mz, norm2);
  if constexpr (Accessor::kBricks) {
    bool far_bounds = false;  // any empty slot above the outside band
    const std::array<std::int32_t, 3>& bd = acc_.brick_dims();
    const std::size_t slots =
        static_cast<std::size_t>(bd[0]) * static_cast<std::size_t>(bd[1]) * static_cast<std::size_t>(bd[2]);
    for (std::size_t s = 0; s < slots; ++s) {
      const std::uint32_t e = acc_.index()[s];
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
  lipschitz_ = Bound(mx, my, mz, norm2);
}

// Outside the grid the field is its boundary value extended outward: φ at the nearest grid point
// (each coordinate clamped to [0, n − 1]), so a face where φ < 0 stays a wall, never free space;
// the extension is constant across the face, so its gradient has no component along a clamped
// axis. Clamping is 1-Lipschitz per axis: the Lipschitz bounds hold for the extension too.
template <typename Accessor>
[[gnu::noinline]] std::int32_t Sampler<Accessor>::PhiOutside(std::int32_t x, std::int32_t y, std::int32_t z) const {
  const auto clamp = [&](std::int32_t v, std::size_t a) {
    return static_cast<std::int32_t>(std::clamp<std::int64_t>(v, 0, last_[a]));
  };
  return Phi(clamp(x, 0), clamp(y, 1), clamp(z, 2));
}

template <typename Accessor>
[[gnu::noinline]] Sample Sampler<Accessor>::AtOutside(std::int32_t x, std::int32_t y, std::int32_t z) const {
  const auto clamp = [&](std::int32_t v, std::size_t a) {
    return static_cast<std::int32_t>(std::clamp<std::int64_t>(v, 0, last_[a]));
  };
  const std::int32_t cx = clamp(x, 0), cy = clamp(y, 1), cz = clamp(z, 2);
  Sample s = At(cx, cy, cz);
  if (cx != x) s.grad[0] = 0;
  if (cy != y) s.grad[1] = 0;
  if (cz != z) s.grad[2] = 0;
  s.in_grid = false;
  return s;
}

template <typename Accessor>
Sample Sampler<Accessor>::At(std::int32_t x, std::int32_t y, std::int32_t z) const {
  Cell c;
  if (!Locate(x, y, z, c)) return AtOutside(x, y, z);
  if constexpr (Accessor::kBricks) {
    if (fetch::FaceCell(acc_.dims(), c.i, c.j, c.k))
      return InterpolateSmooth(fetch::Wide(acc_, c.i, c.j, c.k), c.fx, c.fy, c.fz);
    return fetch::WithRowView<Sample>(
        acc_, c.i, c.j,
        c.k, [&](const auto& v) __attribute__((always_inline)) { return InterpolateSmooth(v, c.fx, c.fy, c.fz); });
  } else {
    return InterpolateSmooth(fetch::Wide(acc_, c.i, c.j, c.k), c.fx, c.fy, c.fz);
  }
}

template <typename Accessor>
Sample Sampler<Accessor>::At(std::int32_t x, std::int32_t y, std::int32_t z, GradientCache& cache) const {
  if constexpr (!Accessor::kBricks) {
    return At(x, y, z);
  } else {
    Cell c;
    if (Holds(cache, x, y, z)) {
      c = {x >> 16, y >> 16, z >> 16, x & 0xFFFF, y & 0xFFFF, z & 0xFFFF};
    } else {
      if (!Locate(x, y, z, c)) return AtOutside(x, y, z);
      if (fetch::FaceCell(acc_.dims(), c.i, c.j, c.k))
        return InterpolateSmooth(fetch::Wide(acc_, c.i, c.j, c.k), c.fx, c.fy, c.fz);
      fetch::RowOctants(acc_, c.i, c.j, c.k, cache.moved, cache.expanded);
      cache.sampler = id_;
      cache.cell = CacheCell(c);
    }
    return fetch::WithRowView<Sample>(
        c.i, c.j, c.k, cache.moved, [&](const auto& v) __attribute__((always_inline)) {
          return InterpolateSmooth(v, c.fx, c.fy, c.fz);
        });
  }
}

// Blob v2, a cell that spills along two or three axes (10/64 of cells): out of line, so that Phi's
// common paths do not save its registers.
template <typename Accessor>
template <bool kCache>
[[gnu::noinline]] PALPA_NO_SLP std::int32_t Sampler<Accessor>::PhiSpillMany(std::uint32_t spill, std::int32_t i,
                                                                            std::int32_t j, std::int32_t k,
                                                                            const std::int32_t* f,
                                                                            Stencil* keep) const {
  const auto phi = [&](const Stencil& v) __attribute__((always_inline)) {
    if constexpr (kCache) Keep(v, *keep);
    return InterpolatePhi<8>(v, f[0], f[1], f[2]);
  };
  switch (spill) {
    case fetch::kSpillY | fetch::kSpillZ:
      return phi(fetch::SpillStencil<3>(acc_, i, j, k));
    case fetch::kSpillX | fetch::kSpillZ:
      return phi(fetch::SpillStencil<5>(acc_, i, j, k));
    case fetch::kSpillX | fetch::kSpillY:
      return phi(fetch::SpillStencil<6>(acc_, i, j, k));
    default:
      return phi(fetch::SpillStencil<7>(acc_, i, j, k));
  }
}

// Blob v2. Each path interpolates its own corners (none merged into a stencil in memory first).
// A cell inside one octant (27/64 of cells): one index entry, one table entry, eight fixed offsets;
// a uniform brick or octant is its value (the weights sum to exactly 2^32, so eight equal values
// interpolate to that value). Spilling along one axis (27/64) inline, along more out of line.
// kCache: a cell equal to the cache's is interpolated from its corners; any other is read as
// above and its corners kept (8 stores).
template <typename Accessor>
template <bool kCache>
[[gnu::noinline]] PALPA_NO_SLP std::int32_t Sampler<Accessor>::PhiStored(std::int32_t x, std::int32_t y, std::int32_t z,
                                                                         PhiCache* cache) const {
  Cell c;
  if (!Locate(x, y, z, c)) return PhiOutside(x, y, z);
  const std::int32_t i = c.i, j = c.j, k = c.k;
  if constexpr (kCache) {
    cache->sampler = id_;
    cache->cell = CacheCell(c);
  }
  const auto phi = [&](const Stencil& v) __attribute__((always_inline)) {
    if constexpr (kCache) Keep(v, cache->corners);
    return InterpolatePhi<8>(v, c.fx, c.fy, c.fz);
  };
  const std::uint32_t local = fetch::Local(i, j, k);
  const std::uint32_t spill = fetch::Spill(local);
  switch (spill) {
    case 0: {
      const std::uint32_t* entry = fetch::OwnEntry(acc_, i, j, k);
      if ((*entry & blob::kSlotEmpty) != 0) {
        const std::int32_t v = static_cast<std::int16_t>(*entry & 0xFFFFU);
        if constexpr (kCache) cache->corners.fill(v);
        return v * 256;
      }
      const std::int16_t* b = fetch::OwnCorner(acc_, *entry, local);
      return phi({b[0], b[1], b[4], b[5], b[16], b[17], b[20], b[21]});
    }
    case fetch::kSpillX:
      return phi(fetch::SpillStencil<4>(acc_, i, j, k));
    case fetch::kSpillY:
      return phi(fetch::SpillStencil<2>(acc_, i, j, k));
    case fetch::kSpillZ:
      return phi(fetch::SpillStencil<1>(acc_, i, j, k));
    default: {
      const std::int32_t f[3] = {c.fx, c.fy, c.fz};
      return PhiSpillMany<kCache>(spill, i, j, k, f, kCache ? &cache->corners : nullptr);
    }
  }
}

// Dense (v1): the corners at fixed strides; blob v2 in a function of its own (a tail call), so that
// its paths do not save each other's registers.
template <typename Accessor>
[[gnu::flatten]] std::int32_t Sampler<Accessor>::Phi(std::int32_t x, std::int32_t y, std::int32_t z) const {
  if constexpr (Accessor::kBricks) {
    return PhiStored<false>(x, y, z, nullptr);
  } else {
    Cell c;
    if (!Locate(x, y, z, c)) return PhiOutside(x, y, z);
    return InterpolatePhi(fetch::Corners(acc_, c.i, c.j, c.k), c.fx, c.fy, c.fz);
  }
}

template <typename Accessor>
std::int32_t Sampler<Accessor>::Phi(std::int32_t x, std::int32_t y, std::int32_t z, PhiCache& cache) const {
  if constexpr (!Accessor::kBricks) {
    return Phi(x, y, z);
  } else {
    if (Holds(cache, x, y, z)) return InterpolatePhi<8>(cache.corners, x & 0xFFFF, y & 0xFFFF, z & 0xFFFF);
    return PhiStored<true>(x, y, z, &cache);
  }
}

template <typename Accessor>
Sample Sampler<Accessor>::AtCellGradient(GridPos p) const {
  Cell c;
  if (!Locate(p.x, p.y, p.z, c)) return Background();
  return InterpolateCellGradient(Fetch(c.i, c.j, c.k), c.fx, c.fy, c.fz);
}

template <typename Accessor>
WideStencil Sampler<Accessor>::CopyWide(std::int32_t i, std::int32_t j, std::int32_t k) const {
  if constexpr (Accessor::kBricks) {
    if (fetch::FaceCell(acc_.dims(), i, j, k)) return Copy(fetch::Wide(acc_, i, j, k));
    return fetch::WithRowView<WideStencil>(acc_, i, j, k, [](const auto& v) { return Copy(v); });
  } else {
    return Copy(fetch::Wide(acc_, i, j, k));
  }
}

template class Sampler<blob::DenseAccessor>;
template class Sampler<blob::BrickAccessor>;

TrilinearSampler::TrilinearSampler(const blob::FieldView& field)
    : s_(field.bricks() != nullptr ? std::variant<DenseSampler, BrickSampler>(std::in_place_type<BrickSampler>,
                                                                              *field.bricks(), field.band_outside)
                                   : std::variant<DenseSampler, BrickSampler>(std::in_place_type<DenseSampler>,
                                                                              *field.dense(), field.band_outside)) {}

}  // namespace palpa::sampler
