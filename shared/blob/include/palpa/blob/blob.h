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
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <expected>
#include <functional>
#include <optional>
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

/// A verified field, read in place: `phi` (v1) or `brick_index`, `brick_tables` and `octants`
/// (v2) point into the caller's blob buffer, which must outlive the view. RT-safe to read.
struct FieldView {
  const std::int32_t* phi = nullptr;  ///< v1: Q16.16 voxel units, (nx,ny,nz) C order; v2: null
  /// v2: one entry per 8³ brick slot (bi·bny + bj)·bnz + bk: a brick number, or kSlotEmpty | the
  /// slot's uniform φ as int16 Q7.8 in the low 16 bits. Null for v1.
  const std::uint32_t* brick_index = nullptr;
  /// v2: 8 entries per stored brick, octant (ox, oy, oz) at 4·ox + 2·oy + oz: an octant number or
  /// kSlotEmpty | uniform φ.
  const std::uint32_t* brick_tables = nullptr;
  const std::int16_t* octants = nullptr;  ///< v2: octant_count × 64 int16 Q7.8, local (a·4 + b)·4 + c
  std::array<std::int32_t, 3> brick_dims{};
  std::uint32_t brick_count = 0;
  std::uint32_t octant_count = 0;
  std::int32_t band_outside = 0;  ///< v2: brick φ ≤ this; v1: = band_voxels
  std::uint16_t version = kVersion;
  std::size_t blob_size = 0;  ///< bytes of the verified blob
  std::array<std::int32_t, 3> dims{};
  std::array<double, 3> origin_m{};
  double voxel_m = 0;
  std::int32_t band_voxels = 0;  ///< v1: the band; v2: band_inside (stored φ ≥ −band_voxels)
  Method method = Method::kErosion;
  std::uint32_t point_count = 0;
  std::uint64_t build_time_ns = 0;
  double fit_scale = 1;
  std::array<double, 3> fit_offset_m{};
  std::uint32_t crc32c = 0;

  /// φ at node (i, j, k), Q16.16 voxels, for either version (non-RT helpers and tests; the
  /// sampler has its own stencil fetch). Indices must be inside the grid.
  std::int32_t NodeQ16(std::int32_t i, std::int32_t j, std::int32_t k) const {
    if (phi != nullptr)
      return phi[(static_cast<std::size_t>(i) * static_cast<std::size_t>(dims[1]) + static_cast<std::size_t>(j)) *
                     static_cast<std::size_t>(dims[2]) +
                 static_cast<std::size_t>(k)];
    const std::size_t slot = (static_cast<std::size_t>(i >> 3) * static_cast<std::size_t>(brick_dims[1]) +
                              static_cast<std::size_t>(j >> 3)) *
                                 static_cast<std::size_t>(brick_dims[2]) +
                             static_cast<std::size_t>(k >> 3);
    std::uint32_t e = brick_index[slot];
    if ((e & kSlotEmpty) == 0)
      e = brick_tables[8 * static_cast<std::size_t>(e) +
                       static_cast<std::size_t>(((i >> 2) & 1) * 4 + ((j >> 2) & 1) * 2 + ((k >> 2) & 1))];
    if ((e & kSlotEmpty) != 0) return std::int32_t{static_cast<std::int16_t>(e & 0xFFFFU)} * 256;
    const auto local = static_cast<std::size_t>(((i & 3) << 4) | ((j & 3) << 2) | (k & 3));
    return std::int32_t{octants[static_cast<std::size_t>(e) * kOctantNodes + local]} * 256;
  }
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

/// The non-payload fields of a v2 blob: BlobMeta plus the asymmetric band. `meta.band_voxels` is
/// ignored.
struct BlobMetaV2 {
  BlobMeta meta;
  std::uint32_t band_inside = 6;   ///< voxels, 1..64
  std::uint32_t band_outside = 2;  ///< voxels, 1..64
  /// Empty slots outside the band carry a lower bound of band_outside + their distance to the
  /// band (docs/blob-format.md § Free-space bound); false: they carry band_outside.
  bool free_space_bounds = true;
};

/// Encodes a v2 blob from a dense field (nx·ny·nz Q16.16 voxels, C order, k fastest): values are
/// clamped to [−band_inside, +band_outside] and rounded to Q7.8 (nearest, ties up). A brick whose
/// nodes all agree becomes a uniform slot; in the others, each octant whose nodes all agree
/// becomes a uniform table entry and the rest are stored. Uniform slots at +band_outside then get
/// the free-space bound (docs/blob-format.md). Non-RT; the result verifies if `meta` is in range.
[[nodiscard]] std::vector<std::byte> EncodeV2(const BlobMetaV2& meta, std::span<const std::int32_t> phi);

/// Brick-wise input of EncodeV2 (a sparse field never made dense): called once per brick slot
/// (bi, bj, bk), x slowest, k fastest. Either returns the one Q16.16 value (voxels) of every node
/// of the brick, or writes the brick's 8³ Q16.16 values to `q16` (local index (a·8 + b)·8 + c for
/// node (8·bi + a, 8·bj + b, 8·bk + c); nodes past the grid's edge are ignored) and returns
/// nullopt.
using BrickSource = std::function<std::optional<std::int32_t>(std::array<std::uint32_t, 3> brick,
                                                              std::span<std::int32_t, kBrickNodes> q16)>;

/// EncodeV2 from bricks: the same bytes as the dense overload for the same node values, with
/// memory for one brick at a time besides the output. `bricks`, and whatever it owns, is released
/// once every brick is read and before the blob is assembled, so that a source that owns its
/// field (palpa build's) never coexists with the whole output. Non-RT.
[[nodiscard]] std::vector<std::byte> EncodeV2(const BlobMetaV2& meta, BrickSource bricks);

/// Every node of a verified view as Q16.16 voxels, C order (v2: what the sampler reads, padding
/// excluded). Non-RT.
[[nodiscard]] std::vector<std::int32_t> DenseQ16(const FieldView& view);

/// The dense v1 blob equivalent to a verified v2 view: the same node values, clamped to a symmetric
/// band ±max(band_inside, band_outside) (v1's rule), and the same metadata. Non-RT.
[[nodiscard]] std::vector<std::byte> DenseV1(const FieldView& v2);

/// How ReadFile hands a v2 blob back.
enum class Load {
  kAsStored,  ///< the file's bytes (palpad, palpa info: the blob is used in place)
  kDense,     ///< a v2 blob is verified, then re-encoded by DenseV1 for the host tools that index φ
};

/// The largest blob file ReadFile reads: 4 GiB (1 GiB where size_t has 32 bits), above the
/// largest field palpa builds (a dense 1000³ v1 blob is 3.7 GiB).
inline constexpr std::uint64_t kMaxFileBytes =
    sizeof(std::size_t) >= 8 ? std::uint64_t{4} << 30 : std::uint64_t{1} << 30;

/// Reads a whole file into a buffer suitable for Verify (non-RT). Only a regular file of at most
/// kMaxFileBytes is read (io::ReadBounded: a FIFO or device is refused at once). Errors name the
/// file; with Load::kDense also the v2 blob's field and byte.
[[nodiscard]] std::expected<std::vector<std::byte>, BlobError> ReadFile(const char* path, Load load = Load::kDense);

}  // namespace palpa::blob
