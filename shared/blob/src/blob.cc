#include "palpa/blob/blob.h"

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>

namespace palpa::blob {
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

}  // namespace

std::uint32_t Crc32c(std::span<const std::byte> data, std::uint32_t crc) {
  crc = ~crc;
  for (std::byte b : data) crc = kCrcTable[(crc ^ static_cast<std::uint32_t>(b)) & 0xFFU] ^ (crc >> 8);
  return ~crc;
}

std::expected<FieldView, BlobError> Verify(std::span<const std::byte> blob) {
  const std::size_t size = blob.size();
  if (size < 12) return Fail("header", size, "blob is %zu bytes, shorter than the 12-byte preamble", size);
  if (std::memcmp(blob.data(), kMagic.data(), kMagic.size()) != 0)
    return Fail("magic", 0, "not a palpa field blob (expected \"PALPASDF\")");
  std::uint16_t version = 0;
  std::memcpy(&version, blob.data() + offsetof(HeaderV1, version), sizeof version);
  if (version != kVersion)
    return Fail("version", offsetof(HeaderV1, version),
                "%u is not supported (this build reads v1; rebuild the field with a matching palpa)",
                static_cast<unsigned>(version));
  std::uint16_t header_size = 0;
  std::memcpy(&header_size, blob.data() + offsetof(HeaderV1, header_size), sizeof header_size);
  if (header_size != kHeaderSize)
    return Fail("header_size", offsetof(HeaderV1, header_size), "%u, expected %u", static_cast<unsigned>(header_size),
                static_cast<unsigned>(kHeaderSize));
  if (size < kHeaderSize) return Fail("header", size, "truncated: blob is %zu bytes, header needs %u", size, 144U);
  if (reinterpret_cast<std::uintptr_t>(blob.data()) % alignof(std::int32_t) != 0)
    return Fail("payload", kHeaderSize, "buffer is not 4-byte aligned; cannot read in place");

  HeaderV1 h;
  std::memcpy(&h, blob.data(), sizeof h);
  if (h.flags != 0) return Fail("flags", offsetof(HeaderV1, flags), "0x%08x has unknown bits set", h.flags);
  for (std::size_t a = 0; a < 3; ++a) {
    if (h.dims[a] < 2 || h.dims[a] > kMaxDim)
      return Fail("dims", offsetof(HeaderV1, dims) + 4 * a, "axis %zu has %u nodes, allowed 2..%u", a, h.dims[a],
                  kMaxDim);
  }
  if (h.value_format != kValueFormatQ16Voxels)
    return Fail("value_format", offsetof(HeaderV1, value_format), "%u is unknown (1 = int32 Q16.16 voxels)",
                h.value_format);
  if (!Finite3(h.origin_m)) return Fail("origin_m", offsetof(HeaderV1, origin_m), "not finite");
  if (!(std::isfinite(h.voxel_m) && h.voxel_m > 0 && h.voxel_m < 1))
    return Fail("voxel_m", offsetof(HeaderV1, voxel_m), "%g m is outside (0, 1)", h.voxel_m);
  if (h.band_voxels < 1 || h.band_voxels > kMaxBandVoxels)
    return Fail("band_voxels", offsetof(HeaderV1, band_voxels), "%u, allowed 1..%u", h.band_voxels, kMaxBandVoxels);
  if (h.method < static_cast<std::uint32_t>(Method::kErosion) || h.method > static_cast<std::uint32_t>(Method::kHermite))
    return Fail("method", offsetof(HeaderV1, method), "%u is unknown", h.method);
  if (h.reserved0 != 0) return Fail("reserved0", offsetof(HeaderV1, reserved0), "must be zero");
  if (!(std::isfinite(h.fit_scale) && h.fit_scale > 0))
    return Fail("fit_scale", offsetof(HeaderV1, fit_scale), "%g must be finite and > 0", h.fit_scale);
  if (!Finite3(h.fit_offset_m)) return Fail("fit_offset_m", offsetof(HeaderV1, fit_offset_m), "not finite");
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
    return Fail("payload", kHeaderSize + static_cast<std::size_t>(h.payload_size), "%llu trailing bytes after the payload",
                static_cast<unsigned long long>(have - h.payload_size));

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

  FieldView v;
  v.phi = phi;
  for (std::size_t a = 0; a < 3; ++a) v.dims[a] = static_cast<std::int32_t>(h.dims[a]);
  v.origin_m = h.origin_m;
  v.voxel_m = h.voxel_m;
  v.band_voxels = static_cast<std::int32_t>(h.band_voxels);
  v.method = static_cast<Method>(h.method);
  v.point_count = h.point_count;
  v.build_time_ns = h.build_time_ns;
  v.fit_scale = h.fit_scale;
  v.fit_offset_m = h.fit_offset_m;
  v.crc32c = h.crc32c;
  return v;
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

std::expected<std::vector<std::byte>, BlobError> ReadFile(const char* path) {
  std::FILE* f = std::fopen(path, "rb");
  if (f == nullptr) return Fail("file", 0, "cannot open %s: %s", path, std::strerror(errno));
  std::vector<std::byte> data;
  std::array<std::byte, 1 << 16> chunk;
  std::size_t n = 0;
  while ((n = std::fread(chunk.data(), 1, chunk.size(), f)) > 0)
    data.insert(data.end(), chunk.begin(), chunk.begin() + static_cast<std::ptrdiff_t>(n));
  const bool failed = std::ferror(f) != 0;
  std::fclose(f);
  if (failed) return Fail("file", data.size(), "read error in %s", path);
  return data;
}

}  // namespace palpa::blob
