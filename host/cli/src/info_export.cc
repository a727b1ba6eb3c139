#include <cstring>
#include <string>
#include <vector>

#include <fmt/core.h>

#include "atomic_file.h"
#include "commands.h"
#include "palpa/blob/blob.h"

namespace palpa::cli {
namespace {

const char* MethodName(blob::Method m) {
  switch (m) {
    case blob::Method::kErosion:
      return "erosion";
    case blob::Method::kEdt:
      return "edt";
    case blob::Method::kHermite:
      return "hermite";
  }
  return "unknown";
}

// Reads and verifies; prints the refusal naming the file, field and byte.
std::optional<std::pair<std::vector<std::byte>, blob::FieldView>> Load(const std::string& path, const char* cmd) {
  auto bytes = blob::ReadFile(path.c_str());
  if (!bytes) {
    fmt::print(stderr, "palpa {}: {}\n", cmd, bytes.error().what());
    return std::nullopt;
  }
  auto view = blob::Verify(*bytes);
  if (!view) {
    fmt::print(stderr, "palpa {}: {}: {}\n", cmd, path, view.error().what());
    return std::nullopt;
  }
  // The view points into the vector's heap buffer, which moving the vector keeps in place.
  return std::make_pair(std::move(*bytes), *view);
}

}  // namespace

int RunInfo(const std::string& path, bool json) {
  auto loaded = Load(path, "info");
  if (!loaded) return kExitBadInput;
  const blob::FieldView& v = loaded->second;
  const std::size_t size = loaded->first.size();
  if (json) {
    fmt::print(
        "{{\"file\": \"{}\", \"format_version\": 1, \"dims\": [{}, {}, {}], \"origin\": [{:.17g}, {:.17g}, {:.17g}], "
        "\"voxel\": {:.17g}, \"band_voxels\": {}, \"method\": \"{}\", \"point_count\": {}, \"build_time_s\": {:.9g}, "
        "\"fit_scale\": {:.17g}, \"fit_offset\": [{:.17g}, {:.17g}, {:.17g}], \"blob_bytes\": {}, "
        "\"crc32c\": \"0x{:08x}\", \"checksum\": \"ok\"}}\n",
        path, v.dims[0], v.dims[1], v.dims[2], v.origin_m[0], v.origin_m[1], v.origin_m[2], v.voxel_m, v.band_voxels,
        MethodName(v.method), v.point_count, static_cast<double>(v.build_time_ns) * 1e-9, v.fit_scale,
        v.fit_offset_m[0], v.fit_offset_m[1], v.fit_offset_m[2], size, v.crc32c);
    return kExitOk;
  }
  fmt::print("{}: palpa field blob v1, {} bytes\n", path, size);
  fmt::print("  dims        {} x {} x {} nodes\n", v.dims[0], v.dims[1], v.dims[2]);
  fmt::print("  origin      ({:.6f}, {:.6f}, {:.6f}) m\n", v.origin_m[0], v.origin_m[1], v.origin_m[2]);
  fmt::print("  voxel       {:.6f} mm\n", v.voxel_m * 1e3);
  fmt::print("  band        {} voxels ({:.3f} mm)\n", v.band_voxels, v.band_voxels * v.voxel_m * 1e3);
  fmt::print("  method      {}\n", MethodName(v.method));
  fmt::print("  points      {}\n", v.point_count);
  fmt::print("  build time  {:.3f} s\n", static_cast<double>(v.build_time_ns) * 1e-9);
  fmt::print("  fit         device = {:.9g}·model + ({:.6f}, {:.6f}, {:.6f}) m\n", v.fit_scale, v.fit_offset_m[0],
             v.fit_offset_m[1], v.fit_offset_m[2]);
  fmt::print("  checksum    ok (crc32c 0x{:08x})\n", v.crc32c);
  return kExitOk;
}

int RunExport(const std::string& path, const std::string& npy) {
  auto loaded = Load(path, "export");
  if (!loaded) return kExitBadInput;
  const blob::FieldView& v = loaded->second;
  // NPY format 1.0: magic, version, little-endian header length, a Python dict literal padded
  // with spaces to a multiple of 64 bytes and ended by '\n', then the raw C-order data.
  std::string header = fmt::format("{{'descr': '<f4', 'fortran_order': False, 'shape': ({}, {}, {}), }}", v.dims[0],
                                   v.dims[1], v.dims[2]);
  const std::size_t unpadded = 10 + header.size() + 1;
  header.append((64 - unpadded % 64) % 64, ' ');
  header.push_back('\n');
  const std::size_t count =
      static_cast<std::size_t>(v.dims[0]) * static_cast<std::size_t>(v.dims[1]) * static_cast<std::size_t>(v.dims[2]);
  std::vector<std::byte> out(10 + header.size() + 4 * count);
  const unsigned char preamble[8] = {0x93, 'N', 'U', 'M', 'P', 'Y', 1, 0};
  std::memcpy(out.data(), preamble, 8);
  const auto hlen = static_cast<std::uint16_t>(header.size());
  std::memcpy(out.data() + 8, &hlen, 2);
  std::memcpy(out.data() + 10, header.data(), header.size());
  std::byte* data = out.data() + 10 + header.size();
  for (std::size_t n = 0; n < count; ++n) {
    const float metres = static_cast<float>(static_cast<double>(v.phi[n]) / 65536.0 * v.voxel_m);
    std::memcpy(data + 4 * n, &metres, 4);
  }
  if (auto w = WriteFileAtomically(npy, out); !w) {
    fmt::print(stderr, "palpa export: {}\n", w.error());
    return kExitIo;
  }
  return kExitOk;
}

}  // namespace palpa::cli
