// libFuzzer harness: the PLY point reader (host/field/src/ply.cc) on arbitrary bytes, as
// palpa build meets an untrusted scan. Built with clang, -fsanitize=fuzzer,address,undefined, by
// fuzz/CMakeLists.txt (fuzz/run BUILD_DIR SECONDS ply). Beyond the sanitizers it traps on a breach
// of the reader's contract: a refusal names the file, and an accepted file gives finite positions
// with unit normals, as many of each.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "ply.h"

namespace {

constexpr char kName[] = "fuzz.ply";

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  palpa::field::PointSet points;
  if (const auto error = palpa::field::detail::ReadPly(kName, text, palpa::field::detail::AddOrientedPoint, points)) {
    if (error->rfind(kName, 0) != 0) __builtin_trap();
    return 0;
  }
  if (points.positions.size() != points.normals.size()) __builtin_trap();
  for (std::size_t i = 0; i < points.positions.size(); ++i) {
    if (!points.positions[i].allFinite() || std::abs(points.normals[i].norm() - 1.0) > 1e-9) __builtin_trap();
  }
  return 0;
}
