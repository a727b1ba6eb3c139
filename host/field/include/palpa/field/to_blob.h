// The build → blob edge (issue 21): the one mapping from a built field to the blob's metadata, and
// the one writer of a field's blob bytes, straight from the sparse field (v2: brick by brick, no
// dense array; v1: the dense payload written once into the output). Host only.
#pragma once

#include <cstdint>
#include <vector>

#include "palpa/blob/blob.h"
#include "palpa/field/grid.h"
#include "palpa/field/sparse_field.h"
#include "palpa/field/transform.h"

namespace palpa::field {

/// Where a field came from, for its blob's header (docs/blob-format.md).
struct BlobProvenance {
  Transform transform;              ///< the fit: device metres = scale · model + offset_m
  std::uint32_t point_count = 0;    ///< samples read from the input
  std::uint64_t build_time_ns = 0;  ///< whole build, wall
};

/// The blob metadata of a field on `grid` built by `method`: dims, origin (m), voxel (m), band
/// (voxels), method, fit, sample count and build time.
blob::BlobMeta BlobMetaOf(const GridSpec& grid, blob::Method method, const BlobProvenance& from);

/// The blob's layout: version 2 (sparse bricks, an asymmetric band; the default) or 1 (dense).
struct BlobLayout {
  int version = 2;
  std::uint32_t band_inside = 6;   ///< v2: voxels kept inside, 1..64
  std::uint32_t band_outside = 2;  ///< v2: voxels kept outside, 1..64
};

/// The verified-to-be blob of `field` (moved in: v2 frees it once every brick is encoded, before
/// the blob is assembled, so that the two never coexist whole), with `meta` (BlobMetaOf). v2:
/// blob::EncodeV2 fed by SparseField::BrickQ16; v1: header and SparseField::WriteQ16's payload,
/// CRC-32C by blob::Crc32c. The same bytes as blob::EncodeV2 / blob::Encode of the field's
/// WriteQ16 values (FieldMethods.BrickWiseBlobEqualsTheDensePayloadsBlob). Allocation failure
/// throws std::bad_alloc.
std::vector<std::byte> ToBlob(SparseField field, const blob::BlobMeta& meta, const BlobLayout& layout);

}  // namespace palpa::field
