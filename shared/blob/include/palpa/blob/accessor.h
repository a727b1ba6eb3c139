// Read access to a verified field's storage, in place: DenseAccessor for blob v1's dense grid,
// BrickAccessor for blob v2's 8³ bricks of 4³ octants (layout.h, docs/blob-format.md). Only
// blob::Verify makes them, over bytes it has checked, so every index below the dims they report
// is inside the blob; a copy reads the same bytes. The sampler is templated on them
// (palpa/sampler/trilinear.h), so the storage is chosen once per field, never per sample, as
// NanoVDB's samplers are on its ReadAccessor. RT-safe: no allocation, bounded work.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>

#include "palpa/blob/layout.h"

namespace palpa::blob {

namespace detail {
struct Verifier;  // blob.cc: the one place that constructs accessors and views
}  // namespace detail

/// Blob v1: φ of node (i, j, k) at data()[(i·ny + j)·nz + k], Q16.16 voxels, |φ| ≤ the band.
class DenseAccessor {
 public:
  static constexpr bool kBricks = false;

  const std::int32_t* data() const { return phi_; }
  /// Nodes per axis (nx, ny, nz), each 2..kMaxDim.
  const std::array<std::int32_t, 3>& dims() const { return dims_; }
  /// The payload's stride along x, ny·nz (along y it is nz, along z 1).
  std::ptrdiff_t stride_i() const { return stride_i_; }
  /// Element offset of node (i, j, k); requires 0 ≤ i < nx etc.
  std::ptrdiff_t Offset(std::int32_t i, std::int32_t j, std::int32_t k) const {
    return static_cast<std::ptrdiff_t>(i) * stride_i_ + static_cast<std::ptrdiff_t>(j) * dims_[2] + k;
  }
  /// φ at node (i, j, k), Q16.16 voxels; same precondition.
  std::int32_t NodeQ16(std::int32_t i, std::int32_t j, std::int32_t k) const { return phi_[Offset(i, j, k)]; }

 private:
  friend struct detail::Verifier;
  DenseAccessor(const std::int32_t* phi, std::array<std::int32_t, 3> dims)
      : phi_(phi), dims_(dims), stride_i_(static_cast<std::ptrdiff_t>(dims[1]) * dims[2]) {}
  const std::int32_t* phi_;
  std::array<std::int32_t, 3> dims_;
  std::ptrdiff_t stride_i_;
};

/// Blob v2: an index entry per 8³ brick slot, (bi·bny + bj)·bnz + bk, holding a brick number or
/// kSlotEmpty | the slot's uniform φ (int16 Q7.8, low half); per stored brick 8 table entries,
/// octant (ox, oy, oz) at 4·ox + 2·oy + oz, holding an octant number or kSlotEmpty | uniform φ;
/// per stored octant 64 int16 Q7.8 values, local (a·4 + b)·4 + c. Stored φ ≥ −band_inside, and
/// ≤ band_outside except in uniform slots that carry the free-space bound.
class BrickAccessor {
 public:
  static constexpr bool kBricks = true;

  const std::uint32_t* index() const { return index_; }
  const std::uint32_t* tables() const { return tables_; }
  const std::int16_t* octants() const { return octants_; }
  /// Nodes per axis (nx, ny, nz), each 2..kMaxDim.
  const std::array<std::int32_t, 3>& dims() const { return dims_; }
  /// Brick slots per axis, ⌈dims/8⌉.
  const std::array<std::int32_t, 3>& brick_dims() const { return brick_dims_; }
  std::uint32_t brick_count() const { return brick_count_; }
  std::uint32_t octant_count() const { return octant_count_; }
  /// The index's stride along x, bny·bnz.
  std::ptrdiff_t slot_stride_i() const { return slot_stride_i_; }

  /// φ at node (i, j, k), Q16.16 voxels (stored Q7.8 · 256); requires 0 ≤ i < nx etc. For tools
  /// and tests: the sampler reads whole stencils (palpa/sampler/fetch.h).
  std::int32_t NodeQ16(std::int32_t i, std::int32_t j, std::int32_t k) const {
    const std::size_t slot = (static_cast<std::size_t>(i >> 3) * static_cast<std::size_t>(brick_dims_[1]) +
                              static_cast<std::size_t>(j >> 3)) *
                                 static_cast<std::size_t>(brick_dims_[2]) +
                             static_cast<std::size_t>(k >> 3);
    std::uint32_t e = index_[slot];
    if ((e & kSlotEmpty) == 0)
      e = tables_[8 * static_cast<std::size_t>(e) +
                  static_cast<std::size_t>(((i >> 2) & 1) * 4 + ((j >> 2) & 1) * 2 + ((k >> 2) & 1))];
    if ((e & kSlotEmpty) != 0) return std::int32_t{static_cast<std::int16_t>(e & 0xFFFFU)} * 256;
    const auto local = static_cast<std::size_t>(((i & 3) << 4) | ((j & 3) << 2) | (k & 3));
    return std::int32_t{octants_[static_cast<std::size_t>(e) * kOctantNodes + local]} * 256;
  }

 private:
  friend struct detail::Verifier;
  BrickAccessor(const std::uint32_t* index, const std::uint32_t* tables, const std::int16_t* octants,
                std::array<std::int32_t, 3> dims, std::array<std::int32_t, 3> brick_dims, std::uint32_t brick_count,
                std::uint32_t octant_count)
      : index_(index),
        tables_(tables),
        octants_(octants),
        dims_(dims),
        brick_dims_(brick_dims),
        slot_stride_i_(static_cast<std::ptrdiff_t>(brick_dims[1]) * brick_dims[2]),
        brick_count_(brick_count),
        octant_count_(octant_count) {}
  const std::uint32_t* index_;
  const std::uint32_t* tables_;
  const std::int16_t* octants_;
  std::array<std::int32_t, 3> dims_;
  std::array<std::int32_t, 3> brick_dims_;
  std::ptrdiff_t slot_stride_i_;
  std::uint32_t brick_count_;
  std::uint32_t octant_count_;
};

}  // namespace palpa::blob
