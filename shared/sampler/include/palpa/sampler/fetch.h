// Stencil fetches, in place, one set per storage: what Sampler<Accessor> reads a cell through.
// Dense (blob v1): the corners at fixed strides. Bricks (blob v2, docs/blob-format.md): a cell
// inside one octant reads one index entry and one table entry; a cell whose corners spill into the
// next octants reads each octant's entry once, branch-free (a uniform brick or octant is read
// through its entry's low half with a zero offset mask), and the continuous gradient's 32 values
// are read as rows of moved octant addresses (RowView). Every form gives the interpolation
// (interpolate.h) the same values; tests/shared/blob_v2_test.cc compares them with the dense grid
// bit for bit. RT-safe: no allocation, bounded work. Preconditions as Sampler's: the cell
// (i, j, k) has 0 ≤ i < nx − 1 etc.
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>

#include "palpa/blob/accessor.h"
#include "palpa/sampler/interpolate.h"

namespace palpa::sampler {

/// The same 32 values read in place from a dense C-order payload (what Wide(DenseAccessor)
/// returns): a base pointer and the strides and outer-layer offsets, so that each value
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

namespace fetch {

// ---- Dense (blob v1) ----

/// The 8 corner values of cell (i, j, k), Q16.16 voxels.
inline Stencil Corners(const blob::DenseAccessor& a, std::int32_t i, std::int32_t j, std::int32_t k) {
  const std::int32_t* b = a.data() + a.Offset(i, j, k);
  const std::ptrdiff_t si = a.stride_i(), sj = a.dims()[2];
  return {b[0], b[1], b[sj], b[sj + 1], b[si], b[si + 1], b[si + sj], b[si + sj + 1]};
}

/// The 32 values of WideStencil for cell (i, j, k), read in place.
inline WideView Wide(const blob::DenseAccessor& a, std::int32_t i, std::int32_t j, std::int32_t k) {
  const std::ptrdiff_t si = a.stride_i(), sj = a.dims()[2];
  const std::array<std::int32_t, 3>& n = a.dims();
  // Outer layers: one node further out, or the face node itself on the grid's faces.
  return {a.data() + a.Offset(i, j, k),
          si,
          sj,
          i > 0 ? -si : 0,
          i + 2 < n[0] ? 2 * si : si,
          j > 0 ? -sj : 0,
          j + 2 < n[1] ? 2 * sj : sj,
          k > 0 ? -1 : 0,
          k + 2 < n[2] ? 2 : 1};
}

// ---- Bricks (blob v2) ----

/// Cell (i, j, k)'s node offset in its octant, 16·(i mod 4) + 4·(j mod 4) + k mod 4.
inline std::uint32_t Local(std::int32_t i, std::int32_t j, std::int32_t k) {
  return static_cast<std::uint32_t>(((i & 3) << 4) | ((j & 3) << 2) | (k & 3));
}
/// The axes along which a cell's corners spill into the next octant (local coordinate 3, both
/// bits of its field in `local` set), as bits 4 (x), 2 (y) and 0 (z).
inline constexpr std::uint32_t kSpillX = 0x10, kSpillY = 0x04, kSpillZ = 0x01;
inline std::uint32_t Spill(std::uint32_t local) { return local & (local >> 1) & (kSpillX | kSpillY | kSpillZ); }
/// The index entry of node (i, j, k)'s brick.
inline const std::uint32_t* Slot(const blob::BrickAccessor& a, std::int32_t i, std::int32_t j, std::int32_t k) {
  return a.index() + static_cast<std::ptrdiff_t>(i >> 3) * a.slot_stride_i() +
         static_cast<std::ptrdiff_t>(j >> 3) * a.brick_dims()[2] + (k >> 3);
}
/// Node (i, j, k)'s octant in its brick, the octant-table entry 4·ox + 2·oy + oz.
inline std::uint32_t OctantBits(std::int32_t i, std::int32_t j, std::int32_t k) {
  return static_cast<std::uint32_t>(((i >> 2) & 1) << 2 | ((j >> 2) & 1) << 1 | ((k >> 2) & 1));
}
/// The entry of node (i, j, k)'s octant: its brick's octant-table entry, or for a uniform brick
/// its index entry; either is an octant number or kSlotEmpty | φ.
inline const std::uint32_t* OwnEntry(const blob::BrickAccessor& a, std::int32_t i, std::int32_t j, std::int32_t k) {
  const std::uint32_t* slot = Slot(a, i, j, k);
  if ((*slot & blob::kSlotEmpty) != 0) return slot;
  return a.tables() + 8 * std::size_t{*slot} + OctantBits(i, j, k);
}
/// Node `local` in stored octant number `octant`.
inline const std::int16_t* OwnCorner(const blob::BrickAccessor& a, std::uint32_t octant, std::uint32_t local) {
  return a.octants() + static_cast<std::size_t>(octant) * blob::kOctantNodes + local;
}

/// A cell whose corners spill into the next octant along the axes in Mask (4: x, 2: y, 1: z; not
/// 0): corner n (4·dx + 2·dy + dz) lies in octant s = n & Mask of the 2, 4 or 8 it touches, the
/// cell's own (s = 0) and its next ones along the axes in s. Each is looked up once, branch-free:
/// its index entry (the cell's own slot, moved one brick along each axis of s where the cell's
/// octant is its brick's second) and its table entry (the octant bits flipped by s). A corner is
/// then one load at a constant offset from it: the cell's local offset, plus the corner's, minus 4
/// nodes along each axis of s. Stored values, Q7.8.
template <int Mask>
[[gnu::always_inline]] inline Stencil SpillStencil(const blob::BrickAccessor& a, std::int32_t i, std::int32_t j,
                                                   std::int32_t k) {
  const std::uint32_t* own = Slot(a, i, j, k);
  const std::ptrdiff_t next[3] = {(i & 4) != 0 ? a.slot_stride_i() : 0, (j & 4) != 0 ? a.brick_dims()[2] : 0,
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
    const std::uint32_t* entry = (e & blob::kSlotEmpty) != 0 ? slot : a.tables() + 8 * std::size_t{e} + (bits ^ s);
    const std::uint32_t t = *entry;
    const bool uniform = (t & blob::kSlotEmpty) != 0;
    octant[s] = uniform ? reinterpret_cast<const std::int16_t*>(entry)
                        : a.octants() + static_cast<std::size_t>(t) * blob::kOctantNodes;
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

/// The corners of cell (i, j, k) as stored, Q7.8 (Q16.16 >> 8). They spill into the next octant
/// along the axes where the cell's local coordinate is 3.
inline Stencil StoredCorners(const blob::BrickAccessor& a, std::int32_t i, std::int32_t j, std::int32_t k) {
  const std::uint32_t local = Local(i, j, k);
  switch (Spill(local)) {
    case 0: {  // one octant: one index entry, one table entry, eight fixed offsets
      const std::uint32_t* entry = OwnEntry(a, i, j, k);
      if ((*entry & blob::kSlotEmpty) != 0) {
        const std::int32_t v = static_cast<std::int16_t>(*entry & 0xFFFFU);
        return {v, v, v, v, v, v, v, v};
      }
      const std::int16_t* b = OwnCorner(a, *entry, local);
      return {b[0], b[1], b[4], b[5], b[16], b[17], b[20], b[21]};
    }
    case kSpillZ:
      return SpillStencil<1>(a, i, j, k);
    case kSpillY:
      return SpillStencil<2>(a, i, j, k);
    case kSpillY | kSpillZ:
      return SpillStencil<3>(a, i, j, k);
    case kSpillX:
      return SpillStencil<4>(a, i, j, k);
    case kSpillX | kSpillZ:
      return SpillStencil<5>(a, i, j, k);
    case kSpillX | kSpillY:
      return SpillStencil<6>(a, i, j, k);
    default:
      return SpillStencil<7>(a, i, j, k);
  }
}

/// The 8 corner values of cell (i, j, k), Q16.16 voxels.
inline Stencil Corners(const blob::BrickAccessor& a, std::int32_t i, std::int32_t j, std::int32_t k) {
  Stencil v = StoredCorners(a, i, j, k);
  for (std::int32_t& x : v) x *= 256;
  return v;
}

/// Whether the wide stencil of cell (i, j, k) repeats a face node (Wide(BrickAccessor) reads
/// those; RowView the interior cells, 1 ≤ cell ≤ n − 3 on every axis, none when n < 4).
inline bool FaceCell(const std::array<std::int32_t, 3>& n, std::int32_t i, std::int32_t j, std::int32_t k) {
  return (static_cast<std::uint32_t>(i - 1) >= static_cast<std::uint32_t>(n[0] - 3)) |
         (static_cast<std::uint32_t>(j - 1) >= static_cast<std::uint32_t>(n[1] - 3)) |
         (static_cast<std::uint32_t>(k - 1) >= static_cast<std::uint32_t>(n[2] - 3));
}

/// The wide stencil's 32 values of cell (i, j, k) in place in the octants (i−1..i+2 per axis,
/// face-clamped like Wide(DenseAccessor)); any cell, the faces included.
inline BrickView Wide(const blob::BrickAccessor& a, std::int32_t i, std::int32_t j, std::int32_t k) {
  BrickView v;
  const std::array<std::int32_t, 3> cell = {i, j, k};
  const std::array<std::int32_t, 3>& dims = a.dims();
  const std::array<std::int32_t, 3>& brick_dims = a.brick_dims();
  std::array<std::int32_t, 3> lo{};
  constexpr std::array<std::int32_t, 3> kLocal = {16, 4, 1};
  for (std::size_t x = 0; x < 3; ++x) {
    const std::int32_t c = cell[x];
    const std::array<std::int32_t, 4> node = {c > 0 ? c - 1 : c, c, c + 1, c + 2 < dims[x] ? c + 2 : c + 1};
    lo[x] = node[0] >> 2;
    for (std::size_t m = 0; m < 4; ++m) {
      v.node[x][m] = (static_cast<std::uint32_t>((node[m] >> 2) - lo[x]) << (18 - x)) |
                     static_cast<std::uint32_t>((node[m] & 3) * kLocal[x]);
    }
  }
  // Per axis, the index offset and octant-table bit of the first and second octant (the second
  // clamped to the last octant: it is then never selected, and the lookup stays in the index).
  const std::array<std::ptrdiff_t, 3> stride = {a.slot_stride_i(), brick_dims[2], 1};
  std::array<std::array<std::ptrdiff_t, 2>, 3> off{};
  std::array<std::array<std::uint32_t, 2>, 3> sub{};
  for (std::size_t x = 0; x < 3; ++x) {
    const std::int32_t o1 = std::min(lo[x] + 1, 2 * brick_dims[x] - 1);
    off[x] = {(lo[x] >> 1) * stride[x], (o1 >> 1) * stride[x]};
    sub[x] = {static_cast<std::uint32_t>(lo[x] & 1) << (2 - x), static_cast<std::uint32_t>(o1 & 1) << (2 - x)};
  }
  for (std::size_t s = 0; s < 8; ++s) {
    const std::size_t sx = s >> 2, sy = (s >> 1) & 1, sz = s & 1;
    const std::uint32_t* slot = a.index() + off[0][sx] + off[1][sy] + off[2][sz];
    const std::uint32_t e = *slot;
    // Select, don't branch: a uniform slot reads itself (the table address is then never used).
    const bool uniform_slot = (e & blob::kSlotEmpty) != 0;
    const std::uint32_t* table =
        a.tables() + 8 * static_cast<std::size_t>(uniform_slot ? 0 : e) + (sub[0][sx] | sub[1][sy] | sub[2][sz]);
    const std::uint32_t* entry = uniform_slot ? slot : table;
    const std::uint32_t t = *entry;
    const bool uniform = (t & blob::kSlotEmpty) != 0;
    v.octant[s] = uniform ? reinterpret_cast<const std::int16_t*>(entry)
                          : a.octants() + static_cast<std::size_t>(t) * blob::kOctantNodes;
    v.mask[s] = uniform ? 0 : blob::kOctantNodes - 1;
  }
  return v;
}

/// Moved octant addresses of an interior cell's RowView, and the uniform octants they point into.
using MovedOctants = std::array<std::uintptr_t, 8>;
using ExpandedOctants = std::array<std::array<std::int16_t, blob::kOctantNodes>, 8>;

/// Cell (i, j, k) with 1 ≤ cell ≤ n − 3 on every axis: the moved addresses of the 8 octants its
/// RowView reads (a uniform one expanded into `expanded` first).
[[gnu::always_inline]] inline void RowOctants(const blob::BrickAccessor& a, std::int32_t i, std::int32_t j,
                                              std::int32_t k, MovedOctants& moved, ExpandedOctants& expanded) {
  // Per axis, the first node n = cell − 1 and the two octants the 4 nodes can touch, those of n and
  // n + 3 (the same one when n mod 4 = 0): the index offset of their brick and their octant-table
  // bit. This is OwnEntry with the per-axis products hoisted out of the 8 look-ups; calling
  // OwnEntry instead costs 49 instructions a tick (callgrind, kitten).
  const std::int32_t n[3] = {i - 1, j - 1, k - 1};
  const std::ptrdiff_t stride[3] = {a.slot_stride_i(), a.brick_dims()[2], 1};
  std::ptrdiff_t slot[3][2];
  std::uint32_t bit[3][2];
  for (std::size_t x = 0; x < 3; ++x) {
    const std::int32_t q0 = n[x] >> 2, q1 = (n[x] + 3) >> 2;
    slot[x][0] = (q0 >> 1) * stride[x];
    slot[x][1] = (q1 >> 1) * stride[x];
    bit[x][0] = static_cast<std::uint32_t>(q0 & 1) << (2 - x);
    bit[x][1] = static_cast<std::uint32_t>(q1 & 1) << (2 - x);
  }
  // Each octant's moved address (RowView): its address + 2·(16·lx + 4·ly + lz) − 2·(64·sx +
  // 16·sy + 4·sz). A uniform octant is expanded on the stack first.
  const auto lx = static_cast<std::uint32_t>(n[0] & 3), ly = static_cast<std::uint32_t>(n[1] & 3);
  const std::uintptr_t shift = 2 * (16 * lx + 4 * ly + static_cast<std::uint32_t>(n[2] & 3));
  const std::uint32_t* const index = a.index();
  const std::uint32_t* const tables = a.tables();
  const std::int16_t* const octants = a.octants();
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

// The wide stencil of RowView<Lz>: per z-row (a, b) and z-octant h, the moved address of octant
// 4·[Lx + a ≥ 4] + 2·[ly + b ≥ 4] + h (only the rows and halves that Lz reads survive inlining).
// Lx is a template parameter too: 16 forms, each reading its rows with one load apiece, which
// saves about 60 instructions a sample over a runtime x start. At() is then 15 KB of code on
// aarch64, 23 KB on x86-64 and 39 KB on armhf; a cell runs one form, about a sixteenth of it.
template <int Lx, int Lz, typename R, typename Use>
[[gnu::always_inline]] inline R WithRows(const MovedOctants& moved, std::uint32_t ly, const Use& use) {
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

/// `use` applied to cell (i, j, k)'s RowView on the addresses RowOctants gave (in one of its 16
/// forms), returning R.
template <typename R, typename Use>
[[gnu::always_inline]] inline R WithRowView(std::int32_t i, std::int32_t j, std::int32_t k, const MovedOctants& moved,
                                            const Use& use) {
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

/// The same on addresses looked up here (RowOctants into locals).
template <typename R, typename Use>
[[gnu::always_inline]] inline R WithRowView(const blob::BrickAccessor& a, std::int32_t i, std::int32_t j,
                                            std::int32_t k, const Use& use) {
  MovedOctants moved;
  alignas(16) ExpandedOctants expanded;
  RowOctants(a, i, j, k, moved, expanded);
  return WithRowView<R>(i, j, k, moved, use);
}

}  // namespace fetch
}  // namespace palpa::sampler
