// The signed distance field as the controller reads it, in place: verification of an untrusted
// blob (Verify), the verified view it gives (FieldView: metadata and the storage accessor), an
// owning verified field (VerifiedField), and the encoders. Two versions, both verified and
// sampled: v2, written by palpa build, keeps the narrow band only as sparse 8³ bricks of 4³ int16
// octants; v1 is the dense grid. layout.h has the byte layout, accessor.h the storage's read
// access; docs/blob-format.md is the specification.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <expected>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <utility>
#include <variant>
#include <vector>

#include "palpa/blob/accessor.h"
#include "palpa/blob/layout.h"

namespace palpa::blob {

/// A verified field, read in place: its metadata, and its storage through dense() (v1) or
/// bricks() (v2), which point into the blob's bytes; these must outlive the view (VerifiedField
/// owns both). Only Verify makes one, so "verified" is a property of the type: the metadata are
/// read-only (const members) and a view is replaced only whole, by another verified view (copy or
/// assignment); a copy reads the same verified bytes. RT-safe to read.
class FieldView {
 public:
  FieldView(const FieldView&) noexcept = default;
  // Replaces the whole view (the members are const, so it is destroyed and constructed anew: well
  // defined since C++20, [basic.life]/8, as std::optional does).
  FieldView& operator=(const FieldView& other) noexcept {
    if (this != &other) {
      std::destroy_at(this);
      std::construct_at(this, other);
    }
    return *this;
  }
  ~FieldView() = default;

  const std::uint16_t version;               ///< kVersion (1) or kVersion2 (2)
  const std::size_t blob_size;               ///< bytes of the verified blob
  const std::array<std::int32_t, 3> dims;    ///< nodes nx, ny, nz, each 2..kMaxDim
  const std::array<double, 3> origin_m;      ///< device-frame position of node (0,0,0), m
  const double voxel_m;                      ///< node spacing, m
  const std::int32_t band_voxels;            ///< v1: the band, |φ| ≤ it; v2: band_inside, φ ≥ −it
  const std::int32_t band_outside;           ///< v2: brick φ ≤ this; v1: = band_voxels
  const Method method;                       ///< how the field was built
  const std::uint32_t point_count;           ///< oriented points it was built from
  const std::uint64_t build_time_ns;         ///< wall time of palpa build, ns
  const double fit_scale;                    ///< model units → metres (device = scale·model + offset)
  const std::array<double, 3> fit_offset_m;  ///< m
  const std::uint32_t crc32c;                ///< as stored (and checked)

  /// v1's storage, or null for v2.
  const DenseAccessor* dense() const { return std::get_if<DenseAccessor>(&storage_); }
  /// v2's storage, or null for v1.
  const BrickAccessor* bricks() const { return std::get_if<BrickAccessor>(&storage_); }

  /// φ at node (i, j, k), Q16.16 voxels, for either version (non-RT helpers and tests; the
  /// sampler fetches whole stencils through the accessor). Indices must be inside the grid.
  std::int32_t NodeQ16(std::int32_t i, std::int32_t j, std::int32_t k) const {
    if (const DenseAccessor* d = dense()) return d->NodeQ16(i, j, k);
    return std::get_if<BrickAccessor>(&storage_)->NodeQ16(i, j, k);
  }

  /// The metadata as Verify reads them (a plain record; only Verify turns one into a view).
  struct Meta {
    std::uint16_t version;
    std::size_t blob_size;
    std::array<std::int32_t, 3> dims;
    std::array<double, 3> origin_m;
    double voxel_m;
    std::int32_t band_voxels, band_outside;
    Method method;
    std::uint32_t point_count;
    std::uint64_t build_time_ns;
    double fit_scale;
    std::array<double, 3> fit_offset_m;
    std::uint32_t crc32c;
  };

 private:
  friend struct detail::Verifier;
  FieldView(const Meta& m, std::variant<DenseAccessor, BrickAccessor> storage)
      : version(m.version),
        blob_size(m.blob_size),
        dims(m.dims),
        origin_m(m.origin_m),
        voxel_m(m.voxel_m),
        band_voxels(m.band_voxels),
        band_outside(m.band_outside),
        method(m.method),
        point_count(m.point_count),
        build_time_ns(m.build_time_ns),
        fit_scale(m.fit_scale),
        fit_offset_m(m.fit_offset_m),
        crc32c(m.crc32c),
        storage_(storage) {}
  std::variant<DenseAccessor, BrickAccessor> storage_;
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

/// A verified blob that owns its bytes: the bytes and the FieldView over them, moved together (a
/// moved std::vector keeps its buffer, so the view stays valid). Only VerifyOwned and LoadFile make
/// one. What the host tools, palpa hil, the benches and the tests hold; palpad verifies into
/// buffers it preallocated, with Verify. Non-RT to make, RT-safe to read.
class VerifiedField {
 public:
  const FieldView& view() const { return view_; }
  std::span<const std::byte> bytes() const { return bytes_; }

  VerifiedField(VerifiedField&&) noexcept = default;
  VerifiedField(const VerifiedField&) = delete;
  VerifiedField& operator=(const VerifiedField&) = delete;
  VerifiedField& operator=(VerifiedField&&) noexcept = default;  // the buffer moves with its address too
  ~VerifiedField() = default;

 private:
  friend struct detail::Verifier;
  VerifiedField(std::vector<std::byte> bytes, const FieldView& view) : bytes_(std::move(bytes)), view_(view) {}
  std::vector<std::byte> bytes_;
  FieldView view_;
};

/// Verify, keeping the bytes (4-byte aligned, as any std::vector<std::byte> of ours is: the
/// allocator aligns to 16). Same errors as Verify.
[[nodiscard]] std::expected<VerifiedField, BlobError> VerifyOwned(std::vector<std::byte> blob);

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
/// clamped to [−band_inside, +band_outside] and rounded to Q7.8 (nearest, ties up; a value > 0
/// stores at least 1/256 voxel, so that a node outside never reads as the surface). A brick whose
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

/// Runs body(first, last) over ranges that together cover [0, count) once, possibly at once on
/// several threads (a host's thread pool).
using ParallelFor =
    std::function<void(std::size_t count, const std::function<void(std::size_t first, std::size_t last)>& body)>;

/// EncodeV2 from bricks, the planes of bricks (one bi each) and the free-space bounds' passes run
/// through `parallel_for`: the same bytes. `bricks` is then called from several threads at once,
/// for distinct bricks.
[[nodiscard]] std::vector<std::byte> EncodeV2(const BlobMetaV2& meta, BrickSource bricks,
                                              const ParallelFor& parallel_for);

/// Every node of a verified view as Q16.16 voxels, C order (v2: what the sampler reads, padding
/// excluded). Non-RT.
[[nodiscard]] std::vector<std::int32_t> DenseQ16(const FieldView& view);

/// The dense v1 blob equivalent to a verified v2 view: the same node values, clamped to a symmetric
/// band ±max(band_inside, band_outside) (v1's rule), and the same metadata. Non-RT.
[[nodiscard]] std::vector<std::byte> DenseV1(const FieldView& v2);

/// The largest blob file ReadFile reads: 4 GiB (1 GiB where size_t has 32 bits), above the
/// largest field palpa builds (a dense 1000³ v1 blob is 3.7 GiB).
inline constexpr std::uint64_t kMaxFileBytes =
    sizeof(std::size_t) >= 8 ? std::uint64_t{4} << 30 : std::uint64_t{1} << 30;

/// Reads a whole file into a buffer suitable for Verify (non-RT). Only a regular file of at most
/// kMaxFileBytes is read (io::ReadBounded: a FIFO or device is refused at once), as stored: every
/// reader uses a v2 blob in place. Errors name the file.
[[nodiscard]] std::expected<std::vector<std::byte>, BlobError> ReadFile(const char* path);

/// ReadFile as stored, then VerifyOwned: the verified blob file, read once and used in place (no
/// dense copy of a v2 blob). Errors as ReadFile's and Verify's (the caller names the file in the
/// latter). Non-RT.
[[nodiscard]] std::expected<VerifiedField, BlobError> LoadFile(const char* path);

}  // namespace palpa::blob
