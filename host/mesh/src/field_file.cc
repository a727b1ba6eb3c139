#include "palpa/mesh/field_file.h"

#include <limits>

namespace palpa::mesh {

std::expected<blob::VerifiedField, Error> LoadField(const std::string& path) {
  auto bytes = blob::ReadFile(path.c_str());
  if (!bytes) return std::unexpected(Error{bytes.error().what()});
  auto field = blob::VerifyOwned(std::move(*bytes));
  if (!field) return std::unexpected(Error{path + ": " + field.error().what()});
  return std::move(*field);
}

std::pair<std::int32_t, std::int32_t> PhiRangeQ16(const blob::FieldView& f) {
  std::int32_t lo = std::numeric_limits<std::int32_t>::max();
  std::int32_t hi = std::numeric_limits<std::int32_t>::min();
  ForEachBlockQ16(f, [&](std::array<int, 3>, std::array<int, 3> n, std::optional<std::int32_t> one,
                         std::span<const std::int32_t, blob::kBrickNodes> q16) {
    if (one) {
      lo = std::min(lo, *one);
      hi = std::max(hi, *one);
      return;
    }
    for (int a = 0; a < n[0]; ++a)
      for (int b = 0; b < n[1]; ++b)
        for (int c = 0; c < n[2]; ++c) {
          const std::int32_t v = q16[static_cast<std::size_t>((a * blob::kBrick + b) * blob::kBrick + c)];
          lo = std::min(lo, v);
          hi = std::max(hi, v);
        }
  });
  return {lo, hi};
}

}  // namespace palpa::mesh
