#include "palpa/sampler/trilinear.h"

#include <algorithm>
#include <atomic>
#include <cstdlib>

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

}  // namespace

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
      slot_stride_i_(static_cast<std::ptrdiff_t>(field.brick_dims[1]) * field.brick_dims[2]),
      background_((field.phi != nullptr ? field.band_voxels : field.band_outside) << 16),
      id_(NextId()) {
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
  const auto bound = [](std::int32_t bx, std::int32_t by, std::int32_t bz, std::int64_t n2) {
    LipschitzBound lb;
    lb.axis = {bx, by, bz};
    const auto root = static_cast<std::int64_t>(fixed::ISqrt(n2));
    lb.norm = static_cast<std::int32_t>(root * root == n2 ? root : root + 1);  // round up: a bound
    lb.norm_helps =
        std::int64_t{lb.norm} * lb.norm < std::int64_t{bx} * bx + std::int64_t{by} * by + std::int64_t{bz} * bz;
    return lb;
  };
  lipschitz_band_ = bound(mx, my, mz, norm2);
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
  lipschitz_ = bound(mx, my, mz, norm2);
}

namespace {

// The wide stencil of RowView<Lz>: per z-row (a, b) and z-octant h, the moved address of octant
// 4·[Lx + a ≥ 4] + 2·[ly + b ≥ 4] + h (only the rows and halves that Lz reads survive inlining).
// Lx is a template parameter too: 16 forms, each reading its rows with one load apiece, which
// saves about 60 instructions a sample over a runtime x start. At() is then 15 KB of code on
// aarch64, 23 KB on x86-64 and 39 KB on armhf; a cell runs one form, about a sixteenth of it.
template <int Lx, int Lz, typename R, typename Use>
[[gnu::always_inline]] inline R WithRows(const std::array<std::uintptr_t, 8>& moved, std::uint32_t ly, const Use& use) {
  typename RowView<Lz>::Rows rows;
  const auto set = [&](std::uint32_t a, std::uint32_t b) __attribute__((always_inline)) {
    const std::uint32_t s = (((Lx + a) >> 2) << 2) | (((ly + b) >> 2) << 1);
    rows[a][b] = {moved[s], moved[s + 1]};
  };
  set(1, 1), set(1, 2), set(2, 1), set(2, 2);  // corners and z outer layers
  set(0, 1), set(0, 2), set(3, 1), set(3, 2);  // x outer layers
  set(1, 0), set(2, 0), set(1, 3), set(2, 3);  // y outer layers
  return use(RowView<Lz>{rows});
}

}  // namespace

[[gnu::always_inline]] inline void TrilinearSampler::RowOctants(
    std::int32_t i, std::int32_t j, std::int32_t k, std::array<std::uintptr_t, 8>& moved,
    std::array<std::array<std::int16_t, blob::kOctantNodes>, 8>& expanded) const {
  // Per axis, the first node n = cell − 1 and the two octants the 4 nodes can touch, those of n and
  // n + 3 (the same one when n mod 4 = 0): the index offset of their brick and their octant-table
  // bit. This is OctantEntry with the per-axis products hoisted out of the 8 look-ups; calling
  // OctantEntry instead costs 49 instructions a tick (callgrind, kitten).
  const std::int32_t n[3] = {i - 1, j - 1, k - 1};
  const std::ptrdiff_t stride[3] = {slot_stride_i_, brick_dims_[2], 1};
  std::ptrdiff_t slot[3][2];
  std::uint32_t bit[3][2];
  for (std::size_t a = 0; a < 3; ++a) {
    const std::int32_t q0 = n[a] >> 2, q1 = (n[a] + 3) >> 2;
    slot[a][0] = (q0 >> 1) * stride[a];
    slot[a][1] = (q1 >> 1) * stride[a];
    bit[a][0] = static_cast<std::uint32_t>(q0 & 1) << (2 - a);
    bit[a][1] = static_cast<std::uint32_t>(q1 & 1) << (2 - a);
  }
  // Each octant's moved address (RowView): its address + 2·(16·lx + 4·ly + lz) − 2·(64·sx +
  // 16·sy + 4·sz). A uniform octant is expanded on the stack first.
  const auto lx = static_cast<std::uint32_t>(n[0] & 3), ly = static_cast<std::uint32_t>(n[1] & 3);
  const std::uintptr_t shift = 2 * (16 * lx + 4 * ly + static_cast<std::uint32_t>(n[2] & 3));
  const std::uint32_t* const index = index_;
  const std::uint32_t* const tables = tables_;
  const std::int16_t* const octants = octants_;
#pragma GCC unroll 4
  for (std::size_t xy = 0; xy < 4; ++xy) {
    const std::ptrdiff_t row = slot[0][xy >> 1] + slot[1][xy & 1];
    const std::uint32_t bits = bit[0][xy >> 1] | bit[1][xy & 1];
#pragma GCC unroll 2
    for (std::size_t z = 0; z < 2; ++z) {
      const std::size_t s = 2 * xy + z;
      const std::uint32_t e = index[row + slot[2][z]];
      std::uint32_t t = e;
      if ((e & blob::kSlotEmpty) == 0) t = tables[8 * static_cast<std::size_t>(e) + (bits | bit[2][z])];
      const std::int16_t* o;
      if ((t & blob::kSlotEmpty) == 0) {
        o = octants + static_cast<std::size_t>(t) * blob::kOctantNodes;
      } else {
        expanded[s].fill(static_cast<std::int16_t>(t & 0xFFFFU));
        o = expanded[s].data();
      }
      moved[s] = reinterpret_cast<std::uintptr_t>(o) + shift - 2 * (64 * (s >> 2) + 16 * ((s >> 1) & 1) + 4 * (s & 1));
    }
  }
}

template <typename R, typename Use>
[[gnu::always_inline]] inline R TrilinearSampler::WithRowView(std::int32_t i, std::int32_t j, std::int32_t k,
                                                              const std::array<std::uintptr_t, 8>& moved,
                                                              const Use& use) const {
  const auto lx = static_cast<std::uint32_t>((i - 1) & 3), ly = static_cast<std::uint32_t>((j - 1) & 3);
  switch ((lx << 2) | static_cast<std::uint32_t>((k - 1) & 3)) {
    case 0:
      return WithRows<0, 0, R>(moved, ly, use);
    case 1:
      return WithRows<0, 1, R>(moved, ly, use);
    case 2:
      return WithRows<0, 2, R>(moved, ly, use);
    case 3:
      return WithRows<0, 3, R>(moved, ly, use);
    case 4:
      return WithRows<1, 0, R>(moved, ly, use);
    case 5:
      return WithRows<1, 1, R>(moved, ly, use);
    case 6:
      return WithRows<1, 2, R>(moved, ly, use);
    case 7:
      return WithRows<1, 3, R>(moved, ly, use);
    case 8:
      return WithRows<2, 0, R>(moved, ly, use);
    case 9:
      return WithRows<2, 1, R>(moved, ly, use);
    case 10:
      return WithRows<2, 2, R>(moved, ly, use);
    case 11:
      return WithRows<2, 3, R>(moved, ly, use);
    case 12:
      return WithRows<3, 0, R>(moved, ly, use);
    case 13:
      return WithRows<3, 1, R>(moved, ly, use);
    case 14:
      return WithRows<3, 2, R>(moved, ly, use);
    default:
      return WithRows<3, 3, R>(moved, ly, use);
  }
}

template <typename R, typename Use>
[[gnu::always_inline]] inline R TrilinearSampler::WithRowView(std::int32_t i, std::int32_t j, std::int32_t k,
                                                              const Use& use) const {
  std::array<std::uintptr_t, 8> moved;
  alignas(16) std::array<std::array<std::int16_t, blob::kOctantNodes>, 8> expanded;
  RowOctants(i, j, k, moved, expanded);
  return WithRowView<R>(i, j, k, moved, use);
}

// Outside the grid the field is its boundary value extended outward: φ at the nearest grid point
// (each coordinate clamped to [0, n − 1]), so a face where φ < 0 stays a wall, never free space;
// the extension is constant across the face, so its gradient has no component along a clamped
// axis. Clamping is 1-Lipschitz per axis: the Lipschitz bounds hold for the extension too.
[[gnu::noinline]] std::int32_t TrilinearSampler::PhiOutside(std::int32_t x, std::int32_t y, std::int32_t z) const {
  const auto clamp = [&](std::int32_t v, std::size_t a) {
    return static_cast<std::int32_t>(std::clamp<std::int64_t>(v, 0, last_[a]));
  };
  return Phi(clamp(x, 0), clamp(y, 1), clamp(z, 2));
}

[[gnu::noinline]] Sample TrilinearSampler::AtOutside(std::int32_t x, std::int32_t y, std::int32_t z) const {
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

Sample TrilinearSampler::At(std::int32_t x, std::int32_t y, std::int32_t z) const {
  Cell c;
  if (!Locate(x, y, z, c)) return AtOutside(x, y, z);
  if (phi_ == nullptr) {
    if (FaceCell(c.i, c.j, c.k)) return InterpolateSmooth(FetchBricks(c.i, c.j, c.k), c.fx, c.fy, c.fz);
    return WithRowView<Sample>(
        c.i, c.j,
        c.k, [&](const auto& v) __attribute__((always_inline)) { return InterpolateSmooth(v, c.fx, c.fy, c.fz); });
  }
  return InterpolateSmooth(FetchWide(c.i, c.j, c.k), c.fx, c.fy, c.fz);
}

Sample TrilinearSampler::At(std::int32_t x, std::int32_t y, std::int32_t z, GradientCache& cache) const {
  if (phi_ != nullptr) return At(x, y, z);
  Cell c;
  if (Holds(cache, x, y, z)) {
    c = {x >> 16, y >> 16, z >> 16, x & 0xFFFF, y & 0xFFFF, z & 0xFFFF};
  } else {
    if (!Locate(x, y, z, c)) return AtOutside(x, y, z);
    if (FaceCell(c.i, c.j, c.k)) return InterpolateSmooth(FetchBricks(c.i, c.j, c.k), c.fx, c.fy, c.fz);
    RowOctants(c.i, c.j, c.k, cache.moved, cache.expanded);
    cache.sampler = id_;
    cache.cell = CacheCell(c);
  }
  return WithRowView<Sample>(
      c.i, c.j, c.k, cache.moved, [&](const auto& v) __attribute__((always_inline)) {
        return InterpolateSmooth(v, c.fx, c.fy, c.fz);
      });
}

// Blob v2, a cell that spills along two or three axes (10/64 of cells): out of line, so that Phi's
// common paths do not save its registers.
template <bool kCache>
[[gnu::noinline]] PALPA_NO_SLP std::int32_t TrilinearSampler::PhiSpillMany(std::uint32_t spill, std::int32_t i,
                                                                           std::int32_t j, std::int32_t k,
                                                                           const std::int32_t* f, Stencil* keep) const {
  const auto phi = [&](const Stencil& v) __attribute__((always_inline)) {
    if constexpr (kCache) Keep(v, *keep);
    return InterpolatePhi<8>(v, f[0], f[1], f[2]);
  };
  switch (spill) {
    case kSpillY | kSpillZ:
      return phi(SpillStencil<3>(i, j, k));
    case kSpillX | kSpillZ:
      return phi(SpillStencil<5>(i, j, k));
    case kSpillX | kSpillY:
      return phi(SpillStencil<6>(i, j, k));
    default:
      return phi(SpillStencil<7>(i, j, k));
  }
}

// Blob v2. Each path interpolates its own corners (none merged into a stencil in memory first).
// A cell inside one octant (27/64 of cells): one index entry, one table entry, eight fixed offsets;
// a uniform brick or octant is its value (the weights sum to exactly 2^32, so eight equal values
// interpolate to that value). Spilling along one axis (27/64) inline, along more out of line.
// kCache: a cell equal to the cache's is interpolated from its corners; any other is read as
// above and its corners kept (8 stores).
template <bool kCache>
[[gnu::noinline]] PALPA_NO_SLP std::int32_t TrilinearSampler::PhiStored(std::int32_t x, std::int32_t y, std::int32_t z,
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
  const std::uint32_t local = Local(i, j, k);
  const std::uint32_t spill = Spill(local);
  switch (spill) {
    case 0: {
      const std::uint32_t* entry = OwnEntry(i, j, k);
      if ((*entry & blob::kSlotEmpty) != 0) {
        const std::int32_t v = static_cast<std::int16_t>(*entry & 0xFFFFU);
        if constexpr (kCache) cache->corners.fill(v);
        return v * 256;
      }
      const std::int16_t* b = OwnCorner(*entry, local);
      return phi({b[0], b[1], b[4], b[5], b[16], b[17], b[20], b[21]});
    }
    case kSpillX:
      return phi(SpillStencil<4>(i, j, k));
    case kSpillY:
      return phi(SpillStencil<2>(i, j, k));
    case kSpillZ:
      return phi(SpillStencil<1>(i, j, k));
    default: {
      const std::int32_t f[3] = {c.fx, c.fy, c.fz};
      return PhiSpillMany<kCache>(spill, i, j, k, f, kCache ? &cache->corners : nullptr);
    }
  }
}

// Dense (v1): the corners at fixed strides; blob v2 in a function of its own (a tail call), so that
// neither saves the other's registers.
[[gnu::flatten]] std::int32_t TrilinearSampler::Phi(std::int32_t x, std::int32_t y, std::int32_t z) const {
  if (phi_ == nullptr) return PhiStored<false>(x, y, z, nullptr);
  Cell c;
  if (!Locate(x, y, z, c)) return PhiOutside(x, y, z);
  return InterpolatePhi(Fetch(c.i, c.j, c.k), c.fx, c.fy, c.fz);
}

std::int32_t TrilinearSampler::Phi(std::int32_t x, std::int32_t y, std::int32_t z, PhiCache& cache) const {
  if (phi_ != nullptr) return Phi(x, y, z);
  if (Holds(cache, x, y, z)) return InterpolatePhi<8>(cache.corners, x & 0xFFFF, y & 0xFFFF, z & 0xFFFF);
  return PhiStored<true>(x, y, z, &cache);
}

WideStencil TrilinearSampler::CopyWide(std::int32_t i, std::int32_t j, std::int32_t k) const {
  if (phi_ != nullptr) return Copy(FetchWide(i, j, k));
  if (FaceCell(i, j, k)) return Copy(FetchBricks(i, j, k));
  return WithRowView<WideStencil>(i, j, k, [](const auto& v) { return Copy(v); });
}

}  // namespace palpa::sampler
