#include "palpa/field/to_blob.h"

#include <array>
#include <cstring>
#include <functional>
#include <span>
#include <utility>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace palpa::field {

blob::BlobMeta BlobMetaOf(const GridSpec& grid, blob::Method method, const BlobProvenance& from) {
  blob::BlobMeta meta;
  for (std::size_t a = 0; a < 3; ++a) {
    const auto e = static_cast<Eigen::Index>(a);
    meta.dims[a] = static_cast<std::uint32_t>(grid.dims[a]);
    meta.origin_m[a] = grid.origin_m[e];
    meta.fit_offset_m[a] = from.transform.offset_m[e];
  }
  meta.voxel_m = grid.voxel_m;
  meta.band_voxels = static_cast<std::uint32_t>(grid.band_voxels);
  meta.method = method;
  meta.point_count = from.point_count;
  meta.build_time_ns = from.build_time_ns;
  meta.fit_scale = from.transform.scale;
  return meta;
}

std::vector<std::byte> ToBlob(SparseField field, const blob::BlobMeta& meta, const BlobLayout& layout) {
  if (layout.version == 2) {
    blob::BlobMetaV2 m2;
    m2.meta = meta;
    m2.band_inside = layout.band_inside;
    m2.band_outside = layout.band_outside;
    // The planes of bricks on TBB's threads: encoding was the build's longest serial stage.
    return blob::EncodeV2(
        m2,
        [field = std::move(field)](std::array<std::uint32_t, 3> b, std::span<std::int32_t, blob::kBrickNodes> q16) {
          return field.BrickQ16(
              field.BrickIndex(static_cast<int>(b[0]), static_cast<int>(b[1]), static_cast<int>(b[2])), q16);
        },
        [](std::size_t count, const std::function<void(std::size_t, std::size_t)>& body) {
          tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count),
                            [&](const tbb::blocked_range<std::size_t>& r) { body(r.begin(), r.end()); });
        });
  }
  // v1: the header as blob::Encode writes it, the payload written once into the output.
  const std::size_t nodes = field.grid().NodeCount();
  std::vector<std::byte> out = blob::Encode(meta, {});
  out.resize(blob::kHeaderSize + nodes * sizeof(std::int32_t));
  // operator new aligns to 16 and the header is 144 bytes: the payload is int32-aligned.
  field.WriteQ16(std::span<std::int32_t>(reinterpret_cast<std::int32_t*>(out.data() + blob::kHeaderSize), nodes));
  blob::HeaderV1 header;
  std::memcpy(&header, out.data(), sizeof header);
  header.payload_size = nodes * sizeof(std::int32_t);
  std::memcpy(out.data(), &header, sizeof header);
  const std::span<const std::byte> bytes(out);
  header.crc32c = blob::Crc32c(bytes.subspan(blob::kHeaderSize), blob::Crc32c(bytes.first(blob::kCrcOffset)));
  std::memcpy(out.data(), &header, sizeof header);
  return out;
}

}  // namespace palpa::field
