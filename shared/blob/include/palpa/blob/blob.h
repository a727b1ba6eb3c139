// Blob v1: the signed distance field as the controller reads it, in place.
//
//   byte 0                                                        144            144 + 4·nx·ny·nz
//   +----------------------------- header (144 B) -----------------+------ payload -------------+
//   | magic | ver | hsize | flags | dims | fmt | origin | voxel |…| crc32c | φ[nx][ny][nz] int32 |
//   +-----------------------------------------------------------------------+--------------------+
//
// All fields little-endian; every byte of the header is a named field or zeroed padding. The
// payload is φ in Q16.16 voxel units (negative inside), C order with k fastest:
// index (i·ny + j)·nz + k, node (i,j,k) at origin + (i,j,k)·voxel. Payload starts 16-byte aligned.
// CRC-32C (Castagnoli) covers header bytes [0, 140) followed by the whole payload.
// docs/blob-format.md is the specification; the static_asserts and tests/shared keep the two in step.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <expected>
#include <span>
#include <vector>

namespace palpa::blob {

inline constexpr std::array<char, 8> kMagic = {'P', 'A', 'L', 'P', 'A', 'S', 'D', 'F'};
inline constexpr std::uint16_t kVersion = 1;
inline constexpr std::uint16_t kHeaderSize = 144;
inline constexpr std::uint32_t kValueFormatQ16Voxels = 1;  ///< int32 Q16.16, voxel units
inline constexpr std::uint32_t kMaxDim = 4096;             ///< nodes per axis
inline constexpr std::uint32_t kMaxBandVoxels = 64;

/// How the field was built (palpa build --method).
enum class Method : std::uint32_t {
  kErosion = 1,  ///< paper §3.2 eq. 4, both sides
  kEdt = 2,      ///< exact signed Euclidean distance transform of the packing indicator
  kHermite = 3,  ///< sub-voxel: osculating quadrics clamped by the packed-ball bracket (default)
};

/// The v1 header exactly as stored (little-endian target asserted in palpa/fixed/q.h).
/// Comments: size (offset) meaning, unit, allowed range.
struct HeaderV1 {
  std::array<char, 8> magic;           // 8B (0)   "PALPASDF"
  std::uint16_t version;               // 2B (8)   1
  std::uint16_t header_size;           // 2B (10)  144
  std::uint32_t flags;                 // 4B (12)  0; no flags defined, any set bit is rejected
  std::array<std::uint32_t, 3> dims;   // 12B (16) nodes nx, ny, nz, each 2..4096
  std::uint32_t value_format;          // 4B (28)  1 = int32 Q16.16 φ in voxel units
  std::array<double, 3> origin_m;      // 24B (32) device-frame position of node (0,0,0), m, finite
  double voxel_m;                      // 8B (56)  node spacing, m, in (0, 1)
  std::uint32_t band_voxels;           // 4B (64)  narrow band half-width, voxels, 1..64; |φ| ≤ band
  std::uint32_t method;                // 4B (68)  Method
  std::uint32_t point_count;           // 4B (72)  oriented points the field was built from
  std::uint32_t reserved0;             // 4B (76)  0
  std::uint64_t build_time_ns;         // 8B (80)  wall time of palpa build, ns
  double fit_scale;                    // 8B (88)  model units → metres: device = scale·model + offset, > 0
  std::array<double, 3> fit_offset_m;  // 24B (96) m, finite
  std::uint64_t payload_size;          // 8B (120) bytes = 4·nx·ny·nz
  std::uint64_t reserved1;             // 8B (128) 0
  std::uint32_t reserved2;             // 4B (136) 0
  std::uint32_t crc32c;                // 4B (140) CRC-32C of bytes [0,140) then the payload
};
static_assert(sizeof(HeaderV1) == kHeaderSize);
static_assert(alignof(HeaderV1) == 8);
static_assert(offsetof(HeaderV1, dims) == 16 && offsetof(HeaderV1, value_format) == 28);
static_assert(offsetof(HeaderV1, origin_m) == 32 && offsetof(HeaderV1, voxel_m) == 56);
static_assert(offsetof(HeaderV1, band_voxels) == 64 && offsetof(HeaderV1, build_time_ns) == 80);
static_assert(offsetof(HeaderV1, fit_scale) == 88 && offsetof(HeaderV1, fit_offset_m) == 96);
static_assert(offsetof(HeaderV1, payload_size) == 120 && offsetof(HeaderV1, crc32c) == 140);
inline constexpr std::size_t kCrcOffset = offsetof(HeaderV1, crc32c);

/// A verified field, read in place: `phi` points into the caller's blob buffer, which must outlive
/// the view. RT-safe to read.
struct FieldView {
  const std::int32_t* phi = nullptr;  ///< Q16.16 voxel units, (nx,ny,nz) C order
  std::array<std::int32_t, 3> dims{};
  std::array<double, 3> origin_m{};
  double voxel_m = 0;
  std::int32_t band_voxels = 0;
  Method method = Method::kErosion;
  std::uint32_t point_count = 0;
  std::uint64_t build_time_ns = 0;
  double fit_scale = 1;
  std::array<double, 3> fit_offset_m{};
  std::uint32_t crc32c = 0;
};

/// Why a blob was refused: the field, its byte offset and a readable sentence (no allocation).
struct BlobError {
  const char* field = "";
  std::size_t offset = 0;
  std::array<char, 192> message{};
  const char* what() const { return message.data(); }
};

/// CRC-32C (Castagnoli, reflected polynomial 0x82F63B78, init and final xor 0xFFFFFFFF), as in
/// RFC 3720 §B.4. `crc` is a previous result to continue from (0 to start). Check value:
/// Crc32c("123456789") == 0xE3069283.
std::uint32_t Crc32c(std::span<const std::byte> data, std::uint32_t crc = 0);

/// Verifies every header field, size and payload value of an untrusted blob before any use
/// (non-RT: O(payload) for the CRC and range scan). On success the view reads `blob` in place;
/// `blob.data()` must be 4-byte aligned. Errors name the field and byte offset, e.g.
/// "version at byte 8: 7 is not supported (this build reads v1)".
[[nodiscard]] std::expected<FieldView, BlobError> Verify(std::span<const std::byte> blob);

/// The non-payload fields of a blob to encode.
struct BlobMeta {
  std::array<std::uint32_t, 3> dims{};
  std::array<double, 3> origin_m{};
  double voxel_m = 0;
  std::uint32_t band_voxels = 0;
  Method method = Method::kErosion;
  std::uint32_t point_count = 0;
  std::uint64_t build_time_ns = 0;
  double fit_scale = 1;
  std::array<double, 3> fit_offset_m{};
};

/// Encodes a v1 blob (header + payload + CRC). `phi` holds nx·ny·nz Q16.16 values. Non-RT.
/// The result verifies if the meta and values are within the ranges above.
[[nodiscard]] std::vector<std::byte> Encode(const BlobMeta& meta, std::span<const std::int32_t> phi);

/// Reads a whole file into a buffer suitable for Verify (non-RT). Errors name the file.
[[nodiscard]] std::expected<std::vector<std::byte>, BlobError> ReadFile(const char* path);

}  // namespace palpa::blob
