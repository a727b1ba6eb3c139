#include "palpa/blob/blob.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <functional>
#include <limits>

namespace palpa::blob {

// The one maker of verified views, accessors and owned fields (their constructors are private).
struct detail::Verifier {
  static FieldView View(const FieldView::Meta& m, std::variant<DenseAccessor, BrickAccessor> storage) {
    return FieldView(m, storage);
  }
  static DenseAccessor Dense(const std::int32_t* phi, std::array<std::int32_t, 3> dims) {
    return DenseAccessor(phi, dims);
  }
  static BrickAccessor Bricks(const std::uint32_t* index, const std::uint32_t* tables, const std::int16_t* octants,
                              std::array<std::int32_t, 3> dims, std::array<std::int32_t, 3> brick_dims,
                              std::uint32_t brick_count, std::uint32_t octant_count) {
    return BrickAccessor(index, tables, octants, dims, brick_dims, brick_count, octant_count);
  }
  static VerifiedField Owned(std::vector<std::byte> bytes, const FieldView& view) {
    return VerifiedField(std::move(bytes), view);
  }
};

namespace {

constexpr std::array<std::uint32_t, 256> MakeCrcTable() {
  std::array<std::uint32_t, 256> table{};
  for (std::uint32_t i = 0; i < 256; ++i) {
    std::uint32_t c = i;
    for (int b = 0; b < 8; ++b) c = (c & 1U) != 0 ? 0x82F63B78U ^ (c >> 1) : c >> 1;
    table[i] = c;
  }
  return table;
}
constexpr auto kCrcTable = MakeCrcTable();

// All refusals go through here so that every message has the same shape.
template <typename... Args>
std::unexpected<BlobError> Fail(const char* field, std::size_t offset, const char* fmt, Args... args) {
  BlobError e;
  e.field = field;
  e.offset = offset;
  int n = std::snprintf(e.message.data(), e.message.size(), "%s at byte %zu: ", field, offset);
  if (n < 0) n = 0;
  const auto used = static_cast<std::size_t>(n) < e.message.size() ? static_cast<std::size_t>(n) : e.message.size() - 1;
  if constexpr (sizeof...(Args) == 0) {
    std::snprintf(e.message.data() + used, e.message.size() - used, "%s", fmt);
  } else {
    std::snprintf(e.message.data() + used, e.message.size() - used, fmt, args...);
  }
  return std::unexpected(e);
}

bool Finite3(const std::array<double, 3>& v) {
  return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]);
}

// The metadata both versions store alike (the bands are read by each version's verifier).
template <typename Header>
FieldView::Meta CommonMeta(const Header& h, std::size_t size) {
  FieldView::Meta m{};
  m.version = h.version;
  m.blob_size = size;
  for (std::size_t a = 0; a < 3; ++a) m.dims[a] = static_cast<std::int32_t>(h.dims[a]);
  m.origin_m = h.origin_m;
  m.voxel_m = h.voxel_m;
  m.method = static_cast<Method>(h.method);
  m.point_count = h.point_count;
  m.build_time_ns = h.build_time_ns;
  m.fit_scale = h.fit_scale;
  m.fit_offset_m = h.fit_offset_m;
  m.crc32c = h.crc32c;
  return m;
}

std::expected<FieldView, BlobError> VerifyV2(std::span<const std::byte> blob);

// The header fields v1 and v2 share by name, each at its own version's offset: checked first,
// then the version's own fields.
template <class Header>
std::expected<void, BlobError> CheckSharedFields(const Header& h) {
  if (h.flags != 0) return Fail("flags", offsetof(Header, flags), "0x%08x has unknown bits set", h.flags);
  for (std::size_t a = 0; a < 3; ++a) {
    if (h.dims[a] < 2 || h.dims[a] > kMaxDim)
      return Fail("dims", offsetof(Header, dims) + 4 * a, "axis %zu has %u nodes, allowed 2..%u", a, h.dims[a],
                  kMaxDim);
  }
  if (!Finite3(h.origin_m)) return Fail("origin_m", offsetof(Header, origin_m), "not finite");
  if (!(std::isfinite(h.voxel_m) && h.voxel_m > 0 && h.voxel_m < 1))
    return Fail("voxel_m", offsetof(Header, voxel_m), "%g m is outside (0, 1)", h.voxel_m);
  if (h.method < static_cast<std::uint32_t>(Method::kErosion) ||
      h.method > static_cast<std::uint32_t>(Method::kHermite))
    return Fail("method", offsetof(Header, method), "%u is unknown", h.method);
  if (!(std::isfinite(h.fit_scale) && h.fit_scale > 0))
    return Fail("fit_scale", offsetof(Header, fit_scale), "%g must be finite and > 0", h.fit_scale);
  if (!Finite3(h.fit_offset_m)) return Fail("fit_offset_m", offsetof(Header, fit_offset_m), "not finite");
  return {};
}

// What both versions check first, once the version is known: header_size, the length, the buffer's
// alignment (payloads are read in place as 4-byte words); then the header, copied out, and the
// fields both versions share.
template <typename Header>
std::expected<Header, BlobError> ReadHeader(std::span<const std::byte> blob, std::uint16_t expected_size) {
  const std::size_t size = blob.size();
  std::uint16_t header_size = 0;
  std::memcpy(&header_size, blob.data() + offsetof(Header, header_size), sizeof header_size);
  if (header_size != expected_size)
    return Fail("header_size", offsetof(Header, header_size), "%u, expected %u", static_cast<unsigned>(header_size),
                static_cast<unsigned>(expected_size));
  if (size < expected_size)
    return Fail("header", size, "truncated: blob is %zu bytes, header needs %u", size,
                static_cast<unsigned>(expected_size));
  if (reinterpret_cast<std::uintptr_t>(blob.data()) % 4 != 0)
    return Fail("payload", expected_size, "buffer is not 4-byte aligned; cannot read in place");
  Header h;
  std::memcpy(&h, blob.data(), sizeof h);
  if (auto shared = CheckSharedFields(h); !shared) return std::unexpected(shared.error());
  return h;
}

std::uint32_t Crc32cTable(std::span<const std::byte> data, std::uint32_t crc) {
  crc = ~crc;
  for (std::byte b : data) crc = kCrcTable[(crc ^ static_cast<std::uint32_t>(b)) & 0xFFU] ^ (crc >> 8);
  return ~crc;
}

// The SSE4.2 crc32 instruction computes the same CRC-32C (same polynomial; the init and final
// xor are ours): ~4 GB/s where the table runs at ~0.3 GB/s, which a dense v1 payload or the
// verification of a large blob feels.
#if defined(__x86_64__)
__attribute__((target("sse4.2"))) std::uint32_t Crc32cSse42(std::span<const std::byte> data, std::uint32_t crc) {
  std::uint64_t c = ~crc;
  std::size_t i = 0;
  for (; i + 8 <= data.size(); i += 8) {
    std::uint64_t word = 0;
    std::memcpy(&word, data.data() + i, 8);
    c = __builtin_ia32_crc32di(c, word);
  }
  auto c32 = static_cast<std::uint32_t>(c);
  for (; i < data.size(); ++i) c32 = __builtin_ia32_crc32qi(c32, static_cast<unsigned char>(data[i]));
  return ~c32;
}
#endif

}  // namespace

std::uint32_t Crc32c(std::span<const std::byte> data, std::uint32_t crc) {
#if defined(__x86_64__)
  if (__builtin_cpu_supports("sse4.2")) return Crc32cSse42(data, crc);
#endif
  return Crc32cTable(data, crc);
}

std::expected<FieldView, BlobError> Verify(std::span<const std::byte> blob) {
  const std::size_t size = blob.size();
  if (size < 12) return Fail("header", size, "blob is %zu bytes, shorter than the 12-byte preamble", size);
  if (std::memcmp(blob.data(), kMagic.data(), kMagic.size()) != 0)
    return Fail("magic", 0, "not a palpa field blob (expected \"PALPASDF\")");
  std::uint16_t version = 0;
  std::memcpy(&version, blob.data() + offsetof(HeaderV1, version), sizeof version);
  if (version == kVersion2) return VerifyV2(blob);
  if (version != kVersion)
    return Fail("version", offsetof(HeaderV1, version),
                "%u is not supported (this build reads v1 and v2; rebuild the field with a matching palpa)",
                static_cast<unsigned>(version));
  auto header = ReadHeader<HeaderV1>(blob, kHeaderSize);
  if (!header) return std::unexpected(header.error());
  const HeaderV1& h = *header;
  if (h.value_format != kValueFormatQ16Voxels)
    return Fail("value_format", offsetof(HeaderV1, value_format), "%u is unknown (1 = int32 Q16.16 voxels)",
                h.value_format);
  if (h.band_voxels < 1 || h.band_voxels > kMaxBandVoxels)
    return Fail("band_voxels", offsetof(HeaderV1, band_voxels), "%u, allowed 1..%u", h.band_voxels, kMaxBandVoxels);
  if (h.reserved0 != 0) return Fail("reserved0", offsetof(HeaderV1, reserved0), "must be zero");
  // Each dim ≤ 4096 = 2^12, so the product fits 2^36 and ·4 cannot overflow 64 bits.
  const std::uint64_t nodes = std::uint64_t{h.dims[0]} * h.dims[1] * h.dims[2];
  if (h.payload_size != nodes * 4)
    return Fail("payload_size", offsetof(HeaderV1, payload_size), "%llu, expected 4·nx·ny·nz = %llu",
                static_cast<unsigned long long>(h.payload_size), static_cast<unsigned long long>(nodes * 4));
  if (h.reserved1 != 0) return Fail("reserved1", offsetof(HeaderV1, reserved1), "must be zero");
  if (h.reserved2 != 0) return Fail("reserved2", offsetof(HeaderV1, reserved2), "must be zero");
  const std::size_t have = size - kHeaderSize;
  if (have < h.payload_size)
    return Fail("payload", size, "truncated: %zu of %llu payload bytes present", have,
                static_cast<unsigned long long>(h.payload_size));
  if (have > h.payload_size)  // here payload_size < have, so it fits size_t
    return Fail("payload", kHeaderSize + static_cast<std::size_t>(h.payload_size),
                "%llu trailing bytes after the payload", static_cast<unsigned long long>(have - h.payload_size));

  std::uint32_t crc = Crc32c(blob.first(kCrcOffset));
  crc = Crc32c(blob.subspan(kHeaderSize), crc);
  if (crc != h.crc32c)
    return Fail("crc32c", kCrcOffset, "stored 0x%08x, computed 0x%08x: the blob is corrupt", h.crc32c, crc);

  const auto* phi = reinterpret_cast<const std::int32_t*>(blob.data() + kHeaderSize);
  const std::int32_t limit = static_cast<std::int32_t>(h.band_voxels) << 16;
  // payload_size == have (checked above), so nodes fits size_t even on 32-bit boards.
  const auto count = static_cast<std::size_t>(nodes);
  for (std::size_t n = 0; n < count; ++n) {
    if (phi[n] > limit || phi[n] < -limit)
      return Fail("payload", kHeaderSize + 4 * n, "φ = %.4f voxels is outside the band ±%u",
                  static_cast<double>(phi[n]) / 65536.0, h.band_voxels);
  }

  FieldView::Meta m = CommonMeta(h, size);
  m.band_voxels = static_cast<std::int32_t>(h.band_voxels);
  m.band_outside = m.band_voxels;
  return detail::Verifier::View(m, detail::Verifier::Dense(phi, m.dims));
}

std::vector<std::byte> Encode(const BlobMeta& meta, std::span<const std::int32_t> phi) {
  HeaderV1 h{};
  h.magic = kMagic;
  h.version = kVersion;
  h.header_size = kHeaderSize;
  h.dims = meta.dims;
  h.value_format = kValueFormatQ16Voxels;
  h.origin_m = meta.origin_m;
  h.voxel_m = meta.voxel_m;
  h.band_voxels = meta.band_voxels;
  h.method = static_cast<std::uint32_t>(meta.method);
  h.point_count = meta.point_count;
  h.build_time_ns = meta.build_time_ns;
  h.fit_scale = meta.fit_scale;
  h.fit_offset_m = meta.fit_offset_m;
  h.payload_size = phi.size_bytes();
  std::vector<std::byte> out(kHeaderSize + phi.size_bytes());
  std::memcpy(out.data(), &h, sizeof h);
  if (!phi.empty()) std::memcpy(out.data() + kHeaderSize, phi.data(), phi.size_bytes());
  const std::span<const std::byte> bytes(out);
  std::uint32_t crc = Crc32c(bytes.first(kCrcOffset));
  crc = Crc32c(bytes.subspan(kHeaderSize), crc);
  std::memcpy(out.data() + kCrcOffset, &crc, sizeof crc);
  return out;
}

std::expected<VerifiedField, BlobError> VerifyOwned(std::vector<std::byte> blob) {
  auto view = Verify(blob);
  if (!view) return std::unexpected(view.error());
  // The buffer moves into the field with its address: the view's pointers stay valid.
  return detail::Verifier::Owned(std::move(blob), *view);
}

std::vector<std::byte> DenseV1(const FieldView& v2) {
  const std::int32_t band = std::max(v2.band_voxels, v2.band_outside);
  std::vector<std::int32_t> phi = DenseQ16(v2);
  for (std::int32_t& x : phi) x = std::clamp(x, -(band << 16), band << 16);
  BlobMeta meta;
  for (std::size_t a = 0; a < 3; ++a) meta.dims[a] = static_cast<std::uint32_t>(v2.dims[a]);
  meta.origin_m = v2.origin_m;
  meta.voxel_m = v2.voxel_m;
  meta.band_voxels = static_cast<std::uint32_t>(band);
  meta.method = v2.method;
  meta.point_count = v2.point_count;
  meta.build_time_ns = v2.build_time_ns;
  meta.fit_scale = v2.fit_scale;
  meta.fit_offset_m = v2.fit_offset_m;
  return Encode(meta, phi);
}

}  // namespace palpa::blob

// ---- v2 ----

namespace palpa::blob {
namespace {

constexpr std::uint64_t AlignUp(std::uint64_t x, std::uint64_t a) { return (x + a - 1) / a * a; }

std::int32_t EntryPhi(std::uint32_t e) { return static_cast<std::int16_t>(e & 0xFFFFU); }

std::expected<FieldView, BlobError> VerifyV2(std::span<const std::byte> blob) {
  const std::size_t size = blob.size();
  auto header = ReadHeader<HeaderV2>(blob, kHeaderSizeV2);
  if (!header) return std::unexpected(header.error());
  const HeaderV2& h = *header;
  if (h.value_format != kValueFormatQ7_8Voxels)
    return Fail("value_format", offsetof(HeaderV2, value_format), "%u is unknown (2 = int16 Q7.8 voxels)",
                h.value_format);
  if (h.band_inside < 1 || h.band_inside > kMaxBandVoxels)
    return Fail("band_inside", offsetof(HeaderV2, band_inside), "%u, allowed 1..%u", h.band_inside, kMaxBandVoxels);
  if (h.band_outside < 1 || h.band_outside > kMaxBandVoxels)
    return Fail("band_outside", offsetof(HeaderV2, band_outside), "%u, allowed 1..%u", h.band_outside, kMaxBandVoxels);
  // dims ≤ 2^12, so brick_dims ≤ 2^9 and slots ≤ 2^27; the counts are checked against slots
  // before use, so every size below is < 2^40 and no sum can overflow 64 bits.
  std::uint64_t slots = 1;
  for (std::size_t a = 0; a < 3; ++a) {
    const std::uint32_t want = (h.dims[a] + kBrick - 1) / kBrick;
    if (h.brick_dims[a] != want)
      return Fail("brick_dims", offsetof(HeaderV2, brick_dims) + 4 * a, "axis %zu has %u bricks, expected ⌈%u/8⌉ = %u",
                  a, h.brick_dims[a], h.dims[a], want);
    slots *= want;
  }
  if (h.brick_count > slots)
    return Fail("brick_count", offsetof(HeaderV2, brick_count), "%u bricks for %llu slots", h.brick_count,
                static_cast<unsigned long long>(slots));
  if (h.octant_count > 8ULL * h.brick_count)
    return Fail("octant_count", offsetof(HeaderV2, octant_count), "%u octants for %u bricks", h.octant_count,
                h.brick_count);
  if (h.reserved0 != 0) return Fail("reserved0", offsetof(HeaderV2, reserved0), "must be zero");
  const std::uint64_t tables = kHeaderSizeV2 + 4 * slots;
  const std::uint64_t tables_end = tables + kTableBytes * h.brick_count;
  const std::uint64_t octants_offset = AlignUp(tables_end, kOctantAlign);
  if (h.octants_offset != octants_offset)
    return Fail("octants_offset", offsetof(HeaderV2, octants_offset),
                "%llu, expected align64(168 + 4·%llu + 32·%u) = %llu",
                static_cast<unsigned long long>(h.octants_offset), static_cast<unsigned long long>(slots),
                h.brick_count, static_cast<unsigned long long>(octants_offset));
  const std::uint64_t payload = octants_offset - kHeaderSizeV2 + std::uint64_t{h.octant_count} * kOctantBytes;
  if (h.payload_size != payload)
    return Fail("payload_size", offsetof(HeaderV2, payload_size), "%llu, expected %llu",
                static_cast<unsigned long long>(h.payload_size), static_cast<unsigned long long>(payload));
  if (h.reserved1 != 0) return Fail("reserved1", offsetof(HeaderV2, reserved1), "must be zero");
  const std::size_t have = size - kHeaderSizeV2;
  if (have < payload)
    return Fail("payload", size, "truncated: %zu of %llu payload bytes present", have,
                static_cast<unsigned long long>(payload));
  if (have > payload)
    return Fail("payload", kHeaderSizeV2 + static_cast<std::size_t>(payload), "%llu trailing bytes after the payload",
                static_cast<unsigned long long>(have - payload));

  std::uint32_t crc = Crc32c(blob.first(kCrcOffsetV2));
  crc = Crc32c(blob.subspan(kHeaderSizeV2), crc);
  if (crc != h.crc32c)
    return Fail("crc32c", kCrcOffsetV2, "stored 0x%08x, computed 0x%08x: the blob is corrupt", h.crc32c, crc);

  // Every offset is now inside the buffer, hence fits size_t.
  for (auto b = static_cast<std::size_t>(tables_end); b < static_cast<std::size_t>(octants_offset); ++b) {
    if (blob[b] != std::byte{0}) return Fail("padding", b, "must be zero");
  }
  const auto* index = reinterpret_cast<const std::uint32_t*>(blob.data() + kHeaderSizeV2);
  const auto* table = reinterpret_cast<const std::uint32_t*>(blob.data() + static_cast<std::size_t>(tables));
  const auto* octants = reinterpret_cast<const std::int16_t*>(blob.data() + static_cast<std::size_t>(octants_offset));
  const std::int32_t lo = -static_cast<std::int32_t>(h.band_inside) * 256;
  const std::int32_t hi = static_cast<std::int32_t>(h.band_outside) * 256;
  // A uniform entry: flag, zero bits 16..30, φ ≥ −band_inside (above +band_outside only as a
  // free-space bound).
  const auto uniform_ok = [&](std::uint32_t e) { return (e & 0x7FFF0000U) == 0 && EntryPhi(e) >= lo; };
  std::uint32_t next_brick = 0, next_octant = 0;  // both stored in order of first use, once each
  std::size_t slot = 0;
  for (std::uint32_t bi = 0; bi < h.brick_dims[0]; ++bi) {
    for (std::uint32_t bj = 0; bj < h.brick_dims[1]; ++bj) {
      for (std::uint32_t bk = 0; bk < h.brick_dims[2]; ++bk, ++slot) {
        const std::uint32_t e = index[slot];
        const std::size_t at = kHeaderSizeV2 + 4 * slot;
        if ((e & kSlotEmpty) != 0) {
          if (!uniform_ok(e)) return Fail("index", at, "uniform slot 0x%08x: bits 16..30 set or φ < −band_inside", e);
          continue;
        }
        if (e != next_brick)
          return Fail("index", at, "brick %u, expected %u (bricks are stored in slot order, once each)", e, next_brick);
        if (next_brick >= h.brick_count) return Fail("index", at, "brick %u is past brick_count %u", e, h.brick_count);
        for (std::uint32_t o = 0; o < 8; ++o) {
          const std::size_t t_at = static_cast<std::size_t>(tables) + kTableBytes * next_brick + 4 * o;
          const std::uint32_t t = table[8 * static_cast<std::size_t>(next_brick) + o];
          if ((t & kSlotEmpty) != 0) {
            if (!uniform_ok(t))
              return Fail("tables", t_at, "uniform octant 0x%08x: bits 16..30 set or φ < −band_inside", t);
            continue;
          }
          if (t != next_octant)
            return Fail("tables", t_at, "octant %u, expected %u (octants are stored in order, once each)", t,
                        next_octant);
          if (next_octant >= h.octant_count)
            return Fail("tables", t_at, "octant %u is past octant_count %u", t, h.octant_count);
          const std::int16_t* v = octants + static_cast<std::size_t>(next_octant) * kOctantNodes;
          const std::uint32_t i0 = bi * kBrick + (o >> 2) * kOctant, j0 = bj * kBrick + ((o >> 1) & 1) * kOctant,
                              k0 = bk * kBrick + (o & 1) * kOctant;
          for (std::uint32_t n = 0; n < kOctantNodes; ++n) {
            const std::size_t byte = static_cast<std::size_t>(octants_offset) + next_octant * kOctantBytes + 2 * n;
            const bool in_grid =
                i0 + (n >> 4) < h.dims[0] && j0 + ((n >> 2) & 3) < h.dims[1] && k0 + (n & 3) < h.dims[2];
            if (!in_grid) {
              if (v[n] != 0) return Fail("padding", byte, "node outside the grid must be zero");
            } else if (v[n] < lo || v[n] > hi) {
              return Fail("octants", byte, "φ = %.4f voxels is outside [−%u, %u]", static_cast<double>(v[n]) / 256.0,
                          h.band_inside, h.band_outside);
            }
          }
          ++next_octant;
        }
        ++next_brick;
      }
    }
  }
  if (next_brick != h.brick_count)
    return Fail("brick_count", offsetof(HeaderV2, brick_count), "%u, but the index references %u bricks", h.brick_count,
                next_brick);
  if (next_octant != h.octant_count)
    return Fail("octant_count", offsetof(HeaderV2, octant_count), "%u, but the tables reference %u octants",
                h.octant_count, next_octant);

  FieldView::Meta m = CommonMeta(h, size);
  m.band_voxels = static_cast<std::int32_t>(h.band_inside);
  m.band_outside = static_cast<std::int32_t>(h.band_outside);
  std::array<std::int32_t, 3> brick_dims{};
  for (std::size_t a = 0; a < 3; ++a) brick_dims[a] = static_cast<std::int32_t>(h.brick_dims[a]);
  return detail::Verifier::View(
      m, detail::Verifier::Bricks(index, table, octants, m.dims, brick_dims, h.brick_count, h.octant_count));
}

// Squared lower bound, voxels², of the distance between the cells touching two bricks |d| slots
// apart along one axis: their node ranges [8b − 1, 8b + 8] are 8|d| − 9 apart.
constexpr std::int64_t AxisGap2(std::int64_t d) {
  const std::int64_t g = std::max<std::int64_t>(0, kBrick * (d < 0 ? -d : d) - (kBrick + 1));
  return g * g;
}

// Free-space bounds (docs/blob-format.md): for every slot, the squared distance in voxels from the
// cells touching it to the cells touching any "near" slot (not free space), by three separable
// min-plus passes with the per-axis gap above. Window: beyond 17 slots on any axis the gap is
// ≥ 135 voxels, above any Q7.8 value, so the cap stands.
std::vector<std::int64_t> FreeSpaceDistance2(const std::array<std::uint32_t, 3>& bd, const std::vector<bool>& near,
                                             const ParallelFor& parallel_for) {
  constexpr std::int64_t kInf = std::numeric_limits<std::int64_t>::max() / 4;
  constexpr int kWindow = 17;
  const std::size_t n = near.size();
  std::vector<std::int64_t> d(n), tmp;
  for (std::size_t s = 0; s < n; ++s) d[s] = near[s] ? 0 : kInf;
  const std::array<std::size_t, 3> stride = {std::size_t{bd[1]} * bd[2], bd[2], 1};
  for (std::size_t axis = 0; axis < 3; ++axis) {
    tmp = d;
    const auto len = static_cast<std::int64_t>(bd[axis]);
    // Each slot from the previous pass only: any split of the slots gives the same values.
    parallel_for(n, [&](std::size_t first, std::size_t last) {
      for (std::size_t s = first; s < last; ++s) {
        const auto pos = static_cast<std::int64_t>((s / stride[axis]) % bd[axis]);
        std::int64_t best = kInf;
        for (std::int64_t off = -kWindow; off <= kWindow; ++off) {
          const std::int64_t q = pos + off;
          if (q < 0 || q >= len) continue;
          const std::int64_t v = tmp[static_cast<std::size_t>(static_cast<std::int64_t>(s) +
                                                              off * static_cast<std::int64_t>(stride[axis]))];
          if (v < kInf) best = std::min(best, v + AxisGap2(off));
        }
        d[s] = best;
      }
    });
  }
  return d;
}

std::uint32_t Uniform(std::int16_t phi) { return kSlotEmpty | static_cast<std::uint16_t>(phi); }

}  // namespace

std::vector<std::byte> EncodeV2(const BlobMetaV2& m, BrickSource bricks) {
  return EncodeV2(m, std::move(bricks),
                  [](std::size_t count, const std::function<void(std::size_t, std::size_t)>& body) { body(0, count); });
}

std::vector<std::byte> EncodeV2(const BlobMetaV2& m, BrickSource bricks, const ParallelFor& parallel_for) {
  HeaderV2 h{};
  h.magic = kMagic;
  h.version = kVersion2;
  h.header_size = kHeaderSizeV2;
  h.dims = m.meta.dims;
  h.value_format = kValueFormatQ7_8Voxels;
  h.origin_m = m.meta.origin_m;
  h.voxel_m = m.meta.voxel_m;
  h.band_inside = m.band_inside;
  h.band_outside = m.band_outside;
  h.method = static_cast<std::uint32_t>(m.meta.method);
  h.point_count = m.meta.point_count;
  h.build_time_ns = m.meta.build_time_ns;
  h.fit_scale = m.meta.fit_scale;
  h.fit_offset_m = m.meta.fit_offset_m;
  std::uint64_t slots = 1;
  for (std::size_t a = 0; a < 3; ++a) {
    h.brick_dims[a] = (h.dims[a] + kBrick - 1) / kBrick;
    slots *= h.brick_dims[a];
  }
  const auto n_slots = static_cast<std::size_t>(slots);
  const std::int32_t lo = -static_cast<std::int32_t>(m.band_inside) << 16;
  const std::int32_t hi = static_cast<std::int32_t>(m.band_outside) << 16;
  // Q16.16 -> Q7.8 within the band: nearest, ties up; a value outside (> 0) stays outside, at
  // least 1/256 voxel (rounded to 0 it would read as the surface, or inside where 0 counts so).
  const auto quantise = [&](std::int32_t v) {
    const std::int32_t q = (std::clamp(v, lo, hi) + 128) >> 8;
    return static_cast<std::int16_t>(v > 0 ? std::max(q, std::int32_t{1}) : q);
  };
  const std::array<std::size_t, 3> dims = {h.dims[0], h.dims[1], h.dims[2]};
  std::vector<std::uint32_t> index(n_slots);
  // Each plane of bricks (one bi) is encoded on its own, its stored bricks numbered from 0 and
  // their octants from 0; the planes are then numbered on in order, so the bytes do not depend
  // on how parallel_for splits them. A plane's octants are never moved once written: a vector
  // grown by doubling held its old and new buffers at once, a third of the 1,200-cell kitten
  // build's peak; a plane's is a small share of the whole.
  struct Plane {
    std::vector<std::uint32_t> tables;  // 8 a stored brick; octant entries numbered in the plane
    std::vector<std::int16_t> octants;
  };
  std::vector<Plane> planes(h.brick_dims[0]);
  const std::size_t plane_slots = std::size_t{h.brick_dims[1]} * h.brick_dims[2];
  parallel_for(planes.size(), [&](std::size_t first, std::size_t last) {
    std::array<std::int32_t, kBrickNodes> brick{};
    for (std::size_t p = first; p < last; ++p) {
      const auto bi = static_cast<std::uint32_t>(p);
      Plane& plane = planes[p];
      std::size_t slot = p * plane_slots;
      for (std::uint32_t bj = 0; bj < h.brick_dims[1]; ++bj) {
        for (std::uint32_t bk = 0; bk < h.brick_dims[2]; ++bk, ++slot) {
          // A brick its source calls uniform: every octant with grid nodes holds this one value.
          if (const std::optional<std::int32_t> all = bricks({bi, bj, bk}, brick)) {
            index[slot] = Uniform(quantise(*all));
            continue;
          }
          std::array<std::array<std::int16_t, kOctantNodes>, 8> oct{};
          std::array<bool, 8> oct_uniform{}, oct_any{};
          std::array<std::int16_t, 8> oct_phi{};
          // Nodes of this brick inside the grid, per axis (8 but at the grid's far edges).
          const std::array<std::size_t, 3> in = {std::min<std::size_t>(kBrick, dims[0] - bi * std::size_t{kBrick}),
                                                 std::min<std::size_t>(kBrick, dims[1] - bj * std::size_t{kBrick}),
                                                 std::min<std::size_t>(kBrick, dims[2] - bk * std::size_t{kBrick})};
          for (std::size_t o = 0; o < 8; ++o) {
            const std::size_t a0 = (o >> 2) * kOctant, b0 = ((o >> 1) & 1) * kOctant, c0 = (o & 1) * kOctant;
            if (a0 >= in[0] || b0 >= in[1] || c0 >= in[2]) {
              oct_uniform[o] = true;  // no grid node: a uniform 0 entry
              continue;
            }
            const std::int32_t* src = brick.data() + (a0 * kBrick + b0) * kBrick + c0;
            std::int16_t* dst = oct[o].data();
            const std::size_t na = std::min<std::size_t>(kOctant, in[0] - a0);
            const std::size_t nb = std::min<std::size_t>(kOctant, in[1] - b0);
            const std::size_t nc = std::min<std::size_t>(kOctant, in[2] - c0);
            const std::int16_t q0 = quantise(src[0]);
            bool same = true;
            for (std::size_t a = 0; a < na; ++a)
              for (std::size_t b = 0; b < nb; ++b)
                for (std::size_t c = 0; c < nc; ++c) {
                  const std::int16_t q = quantise(src[(a * kBrick + b) * kBrick + c]);
                  dst[(a * kOctant + b) * kOctant + c] = q;
                  same = same && q == q0;
                }
            oct_any[o] = true;
            oct_uniform[o] = same;
            oct_phi[o] = q0;
          }
          // The brick is uniform if every octant with grid nodes is, with one value.
          bool uniform = true;
          std::int16_t brick_phi = 0;
          bool have = false;
          for (std::size_t o = 0; o < 8; ++o) {
            if (!oct_any[o]) continue;
            uniform = uniform && oct_uniform[o] && (!have || oct_phi[o] == brick_phi);
            if (!have) brick_phi = oct_phi[o];
            have = true;
          }
          if (uniform) {
            index[slot] = Uniform(brick_phi);
            continue;
          }
          index[slot] = static_cast<std::uint32_t>(plane.tables.size() / 8);  // numbered on below
          for (std::size_t o = 0; o < 8; ++o) {
            if (oct_uniform[o]) {
              plane.tables.push_back(Uniform(oct_phi[o]));  // an octant without grid nodes: 0
            } else {
              plane.tables.push_back(static_cast<std::uint32_t>(plane.octants.size() / kOctantNodes));
              plane.octants.insert(plane.octants.end(), oct[o].begin(), oct[o].end());
            }
          }
        }
      }
      plane.tables.shrink_to_fit();  // the planes together hold no slack of their doubling
      plane.octants.shrink_to_fit();
    }
  });
  bricks = nullptr;  // every brick is read: free the source (and its field) before the output
  // The planes' bricks and octants numbered on in plane order.
  std::size_t brick_count = 0, octants = 0;
  for (std::size_t p = 0; p < planes.size(); ++p) {
    for (std::size_t slot = p * plane_slots; slot < (p + 1) * plane_slots; ++slot)
      if ((index[slot] & kSlotEmpty) == 0) index[slot] += static_cast<std::uint32_t>(brick_count);
    for (std::uint32_t& t : planes[p].tables)
      if ((t & kSlotEmpty) == 0) t += static_cast<std::uint32_t>(octants);
    brick_count += planes[p].tables.size() / 8;
    octants += planes[p].octants.size() / kOctantNodes;
  }
  if (m.free_space_bounds) {
    const std::uint32_t outside = Uniform(static_cast<std::int16_t>(m.band_outside * 256));
    std::vector<bool> near(n_slots);
    for (std::size_t s = 0; s < n_slots; ++s) near[s] = index[s] != outside;
    const std::vector<std::int64_t> d2 = FreeSpaceDistance2(h.brick_dims, near, parallel_for);
    for (std::size_t s = 0; s < n_slots; ++s) {
      if (near[s]) continue;
      // floor(256·√d2) exactly: the double estimate, corrected by integer squares.
      const std::int64_t t = 65536 * std::min<std::int64_t>(d2[s], std::int64_t{1} << 30);
      auto r = static_cast<std::int64_t>(std::sqrt(static_cast<double>(t)));
      while (r * r > t) --r;
      while ((r + 1) * (r + 1) <= t) ++r;
      index[s] =
          Uniform(static_cast<std::int16_t>(std::min<std::int64_t>(32767, std::int64_t{m.band_outside} * 256 + r)));
    }
  }
  h.brick_count = static_cast<std::uint32_t>(brick_count);
  h.octant_count = static_cast<std::uint32_t>(octants);
  const std::uint64_t tables_at = kHeaderSizeV2 + 4 * slots;
  h.octants_offset = AlignUp(tables_at + kTableBytes * h.brick_count, kOctantAlign);
  h.payload_size = h.octants_offset - kHeaderSizeV2 + std::uint64_t{h.octant_count} * kOctantBytes;
  std::vector<std::byte> out(kHeaderSizeV2 + static_cast<std::size_t>(h.payload_size));  // zeroed padding
  std::memcpy(out.data() + kHeaderSizeV2, index.data(), 4 * index.size());
  std::size_t tables_end = static_cast<std::size_t>(tables_at), at = static_cast<std::size_t>(h.octants_offset);
  for (Plane& plane : planes) {
    if (!plane.tables.empty()) std::memcpy(out.data() + tables_end, plane.tables.data(), 4 * plane.tables.size());
    tables_end += 4 * plane.tables.size();
    if (!plane.octants.empty()) std::memcpy(out.data() + at, plane.octants.data(), 2 * plane.octants.size());
    at += 2 * plane.octants.size();
    plane = {};  // freed as soon as copied
  }
  std::memcpy(out.data(), &h, sizeof h);
  const std::span<const std::byte> bytes(out);
  std::uint32_t crc = Crc32c(bytes.first(kCrcOffsetV2));
  crc = Crc32c(bytes.subspan(kHeaderSizeV2), crc);
  std::memcpy(out.data() + kCrcOffsetV2, &crc, sizeof crc);
  return out;
}

std::vector<std::byte> EncodeV2(const BlobMetaV2& m, std::span<const std::int32_t> phi) {
  const std::array<std::size_t, 3> dims = {m.meta.dims[0], m.meta.dims[1], m.meta.dims[2]};
  return EncodeV2(m, [&](std::array<std::uint32_t, 3> b, std::span<std::int32_t, kBrickNodes> out) {
    for (std::size_t a = 0; a < kBrick; ++a)
      for (std::size_t c = 0; c < kBrick; ++c)
        for (std::size_t e = 0; e < kBrick; ++e) {
          const std::size_t i = b[0] * std::size_t{kBrick} + a, j = b[1] * std::size_t{kBrick} + c,
                            k = b[2] * std::size_t{kBrick} + e;
          if (i < dims[0] && j < dims[1] && k < dims[2])
            out[(a * kBrick + c) * kBrick + e] = phi[(i * dims[1] + j) * dims[2] + k];
        }
    return std::optional<std::int32_t>{};
  });
}

std::vector<std::int32_t> DenseQ16(const FieldView& view) {
  const auto nx = static_cast<std::size_t>(view.dims[0]), ny = static_cast<std::size_t>(view.dims[1]),
             nz = static_cast<std::size_t>(view.dims[2]);
  std::vector<std::int32_t> out(nx * ny * nz);
  std::size_t n = 0;
  for (std::int32_t i = 0; i < view.dims[0]; ++i)
    for (std::int32_t j = 0; j < view.dims[1]; ++j)
      for (std::int32_t k = 0; k < view.dims[2]; ++k) out[n++] = view.NodeQ16(i, j, k);
  return out;
}

}  // namespace palpa::blob
