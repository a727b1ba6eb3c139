#include "palpa/mesh/field_file.h"

#include <limits>

namespace palpa::mesh {

std::expected<LoadedField, Error> LoadField(const std::string& path, blob::Load load) {
  auto bytes = blob::ReadFile(path.c_str(), blob::Load::kAsStored);
  if (!bytes) return std::unexpected(Error{bytes.error().what()});
  LoadedField out;
  out.bytes = std::move(*bytes);
  auto view = blob::Verify(out.bytes);
  if (!view) return std::unexpected(Error{path + ": " + view.error().what()});
  out.file_crc32c = view->crc32c;
  out.file_bytes = out.bytes.size();
  if (load == blob::Load::kDense && view->version == blob::kVersion2) {
    out.bytes = blob::DenseV1(*view);
    view = blob::Verify(out.bytes);
    if (!view) return std::unexpected(Error{path + ": " + view.error().what()});  // not reached: DenseV1 is valid
  }
  out.view = *view;
  return out;
}

std::pair<std::int32_t, std::int32_t> PhiRangeQ16(const blob::FieldView& f) {
  constexpr int kB = blob::kBrick;
  std::int32_t lo = std::numeric_limits<std::int32_t>::max();
  std::int32_t hi = std::numeric_limits<std::int32_t>::min();
  std::array<std::int32_t, blob::kBrickNodes> q16{};
  for (int bi = 0; kB * bi < f.dims[0]; ++bi)
    for (int bj = 0; kB * bj < f.dims[1]; ++bj)
      for (int bk = 0; kB * bk < f.dims[2]; ++bk) {
        if (const auto one = BlockQ16(f, {bi, bj, bk}, q16)) {
          lo = std::min(lo, *one);
          hi = std::max(hi, *one);
          continue;
        }
        const int ni = std::min(kB, f.dims[0] - kB * bi), nj = std::min(kB, f.dims[1] - kB * bj),
                  nk = std::min(kB, f.dims[2] - kB * bk);
        for (int a = 0; a < ni; ++a)
          for (int b = 0; b < nj; ++b)
            for (int c = 0; c < nk; ++c) {
              const std::int32_t v = q16[static_cast<std::size_t>((a * kB + b) * kB + c)];
              lo = std::min(lo, v);
              hi = std::max(hi, v);
            }
      }
  return {lo, hi};
}

}  // namespace palpa::mesh
