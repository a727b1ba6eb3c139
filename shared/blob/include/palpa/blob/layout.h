// The signed distance field as the controller reads it, in place. Two versions (both verified and
// sampled): v2, written by palpa build, keeps the narrow band only as sparse 8³ bricks of 4³ int16
// octants behind a dense slot index (layout below, at HeaderV2); v1 is the dense grid:
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
// This header is the layout alone (constants and the two headers as stored); blob.h verifies and
// encodes, accessor.h reads the verified storage.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>

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

/// The method's name as `palpa build --method` spells it ("unknown" for other values).
constexpr const char* MethodName(Method m) {
  switch (m) {
    case Method::kErosion:
      return "erosion";
    case Method::kEdt:
      return "edt";
    case Method::kHermite:
      return "hermite";
  }
  return "unknown";
}

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

// ---- Blob v2: the narrow band as sparse 8³ bricks of 4³ int16 octants (docs/blob-format.md) ----
//
//   0        168          168+4·S           T+32·B    O (64-aligned)     O+128·C
//   | header | index S×u32 | tables B×8×u32 | 0 pad   | octants C×64×int16 |
//
// An index or table entry with bit 31 set is uniform: φ (int16, voxel/256) in its low 16 bits.

inline constexpr std::uint16_t kVersion2 = 2;
inline constexpr std::uint16_t kHeaderSizeV2 = 168;
inline constexpr std::uint32_t kValueFormatQ7_8Voxels = 2;  ///< int16, voxel/256 (Q7.8)
inline constexpr int kBrickLog2 = 3;
inline constexpr int kBrick = 1 << kBrickLog2;                                     ///< nodes per brick edge (8)
inline constexpr int kOctant = kBrick / 2;                                         ///< nodes per octant edge (4)
inline constexpr int kOctantNodes = kOctant * kOctant * kOctant;                   ///< 64
inline constexpr std::size_t kBrickNodes = std::size_t{kBrick} * kBrick * kBrick;  ///< 512
inline constexpr std::size_t kOctantBytes = 2 * kOctantNodes;                      ///< 128
inline constexpr std::size_t kTableBytes = 8 * 4;                                  ///< a brick's octant table
inline constexpr std::size_t kOctantAlign = 64;                                    ///< octants start on a cache line
inline constexpr std::uint32_t kSlotEmpty = 0x80000000U;  ///< entry flag: uniform, φ in the low 16 bits
inline constexpr int kQ7_8ToQ16 = 8;                      ///< stored · 256 = Q16.16

/// The v2 header exactly as stored. Comments: size (offset) meaning, unit, allowed range.
struct HeaderV2 {
  std::array<char, 8> magic;                // 8B (0)    "PALPASDF"
  std::uint16_t version;                    // 2B (8)    2
  std::uint16_t header_size;                // 2B (10)   168
  std::uint32_t flags;                      // 4B (12)   0
  std::array<std::uint32_t, 3> dims;        // 12B (16)  nodes nx, ny, nz, each 2..4096
  std::uint32_t value_format;               // 4B (28)   2 = int16 Q7.8 φ in voxel units
  std::array<double, 3> origin_m;           // 24B (32)  m, finite
  double voxel_m;                           // 8B (56)   m, in (0, 1)
  std::uint32_t band_inside;                // 4B (64)   voxels, 1..64; stored φ ≥ −band_inside
  std::uint32_t band_outside;               // 4B (68)   voxels, 1..64; brick φ ≤ +band_outside
  std::uint32_t method;                     // 4B (72)   Method
  std::uint32_t point_count;                // 4B (76)   points
  std::uint64_t build_time_ns;              // 8B (80)   ns
  double fit_scale;                         // 8B (88)   > 0
  std::array<double, 3> fit_offset_m;       // 24B (96)  m, finite
  std::array<std::uint32_t, 3> brick_dims;  // 12B (120) ⌈dims/8⌉ per axis
  std::uint32_t brick_count;                // 4B (132)  stored bricks (octant tables), ≤ slots
  std::uint32_t octant_count;               // 4B (136)  stored octants, ≤ 8·brick_count
  std::uint32_t reserved0;                  // 4B (140)  0
  std::uint64_t octants_offset;             // 8B (144)  align64(168 + 4·slots + 32·brick_count)
  std::uint64_t payload_size;               // 8B (152)  octants_offset − 168 + 128·octant_count
  std::uint32_t reserved1;                  // 4B (160)  0
  std::uint32_t crc32c;                     // 4B (164)  CRC-32C of bytes [0,164) then [168, end)
};
static_assert(sizeof(HeaderV2) == kHeaderSizeV2);
static_assert(alignof(HeaderV2) == 8);
static_assert(offsetof(HeaderV2, dims) == 16 && offsetof(HeaderV2, value_format) == 28);
static_assert(offsetof(HeaderV2, origin_m) == 32 && offsetof(HeaderV2, voxel_m) == 56);
static_assert(offsetof(HeaderV2, band_inside) == 64 && offsetof(HeaderV2, band_outside) == 68);
static_assert(offsetof(HeaderV2, method) == 72 && offsetof(HeaderV2, point_count) == 76);
static_assert(offsetof(HeaderV2, build_time_ns) == 80 && offsetof(HeaderV2, fit_scale) == 88);
static_assert(offsetof(HeaderV2, fit_offset_m) == 96 && offsetof(HeaderV2, brick_dims) == 120);
static_assert(offsetof(HeaderV2, brick_count) == 132 && offsetof(HeaderV2, octant_count) == 136);
static_assert(offsetof(HeaderV2, reserved0) == 140 && offsetof(HeaderV2, octants_offset) == 144);
static_assert(offsetof(HeaderV2, payload_size) == 152 && offsetof(HeaderV2, reserved1) == 160);
static_assert(offsetof(HeaderV2, crc32c) == 164);
inline constexpr std::size_t kCrcOffsetV2 = offsetof(HeaderV2, crc32c);

}  // namespace palpa::blob
