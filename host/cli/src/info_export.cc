#include <algorithm>
#include <cstring>
#include <span>
#include <string>
#include <vector>

#include <fmt/core.h>
#include <zstd.h>

#include "commands.h"
#include "palpa/blob/blob.h"
#include "palpa/io/atomic_file.h"
#include "palpa/mesh/field_file.h"

namespace palpa::cli {
namespace {

using blob::MethodName;

// mesh::LoadField; prints the refusal naming the file, field and byte.
std::optional<blob::VerifiedField> Load(const std::string& path, const char* cmd) {
  auto field = mesh::LoadField(path);  // v2 as stored: its own figures
  if (!field) {
    fmt::print(stderr, "palpa {}: {}\n", cmd, field.error().message);
    return std::nullopt;
  }
  return std::move(*field);
}

}  // namespace

int RunInfo(const std::string& path, bool json) {
  auto loaded = Load(path, "info");
  if (!loaded) return kExitBadInput;
  const blob::FieldView& v = loaded->view();
  const std::size_t size = v.blob_size;
  const blob::BrickAccessor* bricks = v.bricks();
  // Size figures (issue 7): stored voxels (v2: octants × 64, padding included), the blob's bytes
  // per stored voxel and against a dense float32 grid, and what zstd (level 3, as an upload would
  // send it) makes of it.
  const double nodes = static_cast<double>(v.dims[0]) * v.dims[1] * v.dims[2];
  const double stored = bricks != nullptr ? static_cast<double>(bricks->octant_count()) * blob::kOctantNodes : nodes;
  const double per_voxel = stored > 0 ? static_cast<double>(size) / stored : 0.0;
  const double pct_dense = 100.0 * static_cast<double>(size) / (4.0 * nodes);
  std::vector<char> packed(ZSTD_compressBound(size));
  const std::size_t zsize = ZSTD_compress(packed.data(), packed.size(), loaded->bytes().data(), size, 3);
  const std::size_t zstd_bytes = ZSTD_isError(zsize) != 0 ? 0 : zsize;
  if (json) {
    fmt::print(
        "{{\"file\": \"{}\", \"format_version\": {}, \"band_outside\": {}, \"brick_count\": {}, \"octant_count\": {}, "
        "\"stored_voxels\": {}, \"bytes_per_stored_voxel\": {:.4f}, \"percent_of_dense_float32\": {:.3f}, "
        "\"zstd_bytes\": {}, ",
        path, v.version, v.band_outside, bricks != nullptr ? bricks->brick_count() : 0,
        bricks != nullptr ? bricks->octant_count() : 0, static_cast<std::uint64_t>(stored), per_voxel, pct_dense,
        zstd_bytes);
    fmt::print(
        "\"dims\": [{}, {}, {}], \"origin\": [{:.17g}, {:.17g}, {:.17g}], "
        "\"voxel\": {:.17g}, \"band_voxels\": {}, \"method\": \"{}\", \"point_count\": {}, \"build_time_s\": {:.9g}, "
        "\"fit_scale\": {:.17g}, \"fit_offset\": [{:.17g}, {:.17g}, {:.17g}], \"blob_bytes\": {}, "
        "\"crc32c\": \"0x{:08x}\", \"checksum\": \"ok\"}}\n",
        v.dims[0], v.dims[1], v.dims[2], v.origin_m[0], v.origin_m[1], v.origin_m[2], v.voxel_m, v.band_voxels,
        MethodName(v.method), v.point_count, static_cast<double>(v.build_time_ns) * 1e-9, v.fit_scale,
        v.fit_offset_m[0], v.fit_offset_m[1], v.fit_offset_m[2], size, v.crc32c);
    return kExitOk;
  }
  fmt::print("{}: palpa field blob v{}, {} bytes\n", path, v.version, size);
  fmt::print(
      "  size        {} stored voxels, {:.3f} bytes per stored voxel, {:.2f} % of dense float32, zstd {} bytes\n",
      static_cast<std::uint64_t>(stored), per_voxel, pct_dense, zstd_bytes);
  if (bricks != nullptr)
    fmt::print("  bricks      {} of {} slots (8³), {} octants (4³, int16 voxel/256)\n", bricks->brick_count(),
               static_cast<std::uint64_t>(bricks->brick_dims()[0]) *
                   static_cast<std::uint64_t>(bricks->brick_dims()[1]) *
                   static_cast<std::uint64_t>(bricks->brick_dims()[2]),
               bricks->octant_count());
  fmt::print("  dims        {} x {} x {} nodes\n", v.dims[0], v.dims[1], v.dims[2]);
  fmt::print("  origin      ({:.6f}, {:.6f}, {:.6f}) m\n", v.origin_m[0], v.origin_m[1], v.origin_m[2]);
  fmt::print("  voxel       {:.6f} mm\n", v.voxel_m * 1e3);
  if (v.version == blob::kVersion2) {
    fmt::print("  band        {} voxels inside, {} outside ({:.3f} / {:.3f} mm)\n", v.band_voxels, v.band_outside,
               v.band_voxels * v.voxel_m * 1e3, v.band_outside * v.voxel_m * 1e3);
  } else {
    fmt::print("  band        {} voxels ({:.3f} mm)\n", v.band_voxels, v.band_voxels * v.voxel_m * 1e3);
  }
  fmt::print("  method      {}\n", MethodName(v.method));
  fmt::print("  points      {}\n", v.point_count);
  fmt::print("  build time  {:.3f} s\n", static_cast<double>(v.build_time_ns) * 1e-9);
  fmt::print("  fit         device = {:.9g}·model + ({:.6f}, {:.6f}, {:.6f}) m\n", v.fit_scale, v.fit_offset_m[0],
             v.fit_offset_m[1], v.fit_offset_m[2]);
  fmt::print("  checksum    ok (crc32c 0x{:08x})\n", v.crc32c);
  return kExitOk;
}

int RunExport(const std::string& path, const std::string& npy) {
  if (const int refused = CheckOutput("export", npy, {path}); refused != kExitOk) return refused;
  auto loaded = Load(path, "export");
  if (!loaded) return kExitBadInput;
  const blob::FieldView& v = loaded->view();
  // NPY format 1.0: magic, version, little-endian header length, a Python dict literal padded
  // with spaces to a multiple of 64 bytes and ended by '\n', then the raw C-order data.
  std::string header = fmt::format("{{'descr': '<f4', 'fortran_order': False, 'shape': ({}, {}, {}), }}", v.dims[0],
                                   v.dims[1], v.dims[2]);
  const std::size_t unpadded = 10 + header.size() + 1;
  header.append((64 - unpadded % 64) % 64, ' ');
  header.push_back('\n');
  const unsigned char preamble[8] = {0x93, 'N', 'U', 'M', 'P', 'Y', 1, 0};
  std::vector<std::byte> head(10 + header.size());
  std::memcpy(head.data(), preamble, 8);
  const auto hlen = static_cast<std::uint16_t>(header.size());
  std::memcpy(head.data() + 8, &hlen, 2);
  std::memcpy(head.data() + 10, header.data(), header.size());
  auto out = io::AtomicFile::Create(npy, {.inputs = {path}});
  if (!out) {
    fmt::print(stderr, "palpa export: {}\n", out.error());
    return kExitIo;
  }
  auto written = out->Append(head);
  // Either version as the dense v1 grid the host tools see (docs/blob-format.md § Tools and v2):
  // v2 values clamped to ±max(band_inside, band_outside), so free-space bounds read as the band.
  // Read in place and written one x-layer at a time: memory is the blob and one layer, whatever
  // the output's size (issue 21).
  std::vector<float> layer(static_cast<std::size_t>(v.dims[1]) * static_cast<std::size_t>(v.dims[2]));
  for (int i = 0; i < v.dims[0] && written; ++i) {
    std::size_t n = 0;
    for (int j = 0; j < v.dims[1]; ++j)
      for (int k = 0; k < v.dims[2]; ++k)
        layer[n++] = static_cast<float>(static_cast<double>(mesh::PhiQ16(v, i, j, k)) / 65536.0 * v.voxel_m);
    written = out->Append(std::as_bytes(std::span(layer)));  // little-endian host (palpa/fixed/q.h)
  }
  if (written) written = out->Commit();
  if (!written) {
    fmt::print(stderr, "palpa export: {}\n", written.error());
    return kExitIo;
  }
  return kExitOk;
}

}  // namespace palpa::cli
