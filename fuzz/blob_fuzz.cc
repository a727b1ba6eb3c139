// libFuzzer harness (issue 7): blob::Verify on arbitrary bytes, then, for a blob it accepts, the
// sampler built on it and sampled at points derived from the input. Built with clang,
// -fsanitize=fuzzer,address,undefined, by fuzz/CMakeLists.txt (a separate project; fuzz/run).
// Beyond the sanitizers it checks four invariants of a verified blob and traps on a breach:
// Phi() == At().phi everywhere, φ at a node equals the stored node value, outside the grid the
// background, and sampling through a PhiCache / GradientCache (kept across the input's samples,
// so that most near points hit) gives the same bits as without.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <vector>

#include "palpa/blob/blob.h"
#include "palpa/sampler/trilinear.h"

namespace {

std::uint64_t Mix(std::uint64_t& s) {  // splitmix64
  std::uint64_t z = (s += 0x9E3779B97F4A7C15ULL);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
  return z ^ (z >> 31);
}

// Verify, then sample what it accepts. `words` holds the blob 8-byte aligned, as palpad's vector
// gives it.
void Check(const std::vector<std::uint64_t>& words, std::size_t size, const std::uint8_t* data) {
  const std::span<const std::byte> blob(reinterpret_cast<const std::byte*>(words.data()), size);
  const auto view = palpa::blob::Verify(blob);
  if (!view) {
    if (view.error().what()[0] == '\0') __builtin_trap();  // every refusal says why
    return;
  }
  const palpa::sampler::TrilinearSampler s(*view);
  palpa::sampler::PhiCache phi_cache;
  palpa::sampler::GradientCache gradient_cache;
  std::uint64_t seed = size;
  for (std::size_t i = 0; i < size && i < 64; ++i) seed = seed * 131 + data[i];
  for (int n = 0; n < 64; ++n) {
    std::array<std::int32_t, 3> node{};
    palpa::sampler::GridPos p;
    for (std::size_t a = 0; a < 3; ++a) {
      const std::uint64_t r = Mix(seed);
      node[a] = static_cast<std::int32_t>(r % static_cast<std::uint64_t>(view->dims[a]));
    }
    // A node, then a random point in or near the grid (a quarter of them outside).
    p = {node[0] << 16, node[1] << 16, node[2] << 16};
    if (s.Phi(p) != view->NodeQ16(node[0], node[1], node[2])) __builtin_trap();
    const auto span = [&](std::size_t a) { return static_cast<std::int64_t>(view->dims[a] + 2) << 16; };
    p = {static_cast<std::int32_t>(static_cast<std::int64_t>(Mix(seed) % static_cast<std::uint64_t>(span(0))) - 65536),
         static_cast<std::int32_t>(static_cast<std::int64_t>(Mix(seed) % static_cast<std::uint64_t>(span(1))) - 65536),
         static_cast<std::int32_t>(static_cast<std::int64_t>(Mix(seed) % static_cast<std::uint64_t>(span(2))) - 65536)};
    const std::int32_t phi = s.Phi(p);
    const palpa::sampler::Sample at = s.At(p);
    if (phi != at.phi) __builtin_trap();
    // Outside the grid: the value at the nearest grid point (the boundary extended outward).
    const auto clamp = [&](std::int32_t v, std::size_t a) {
      return static_cast<std::int32_t>(std::clamp<std::int64_t>(v, 0, s.last_node(a)));
    };
    if (!at.in_grid && phi != s.Phi(clamp(p.x, 0), clamp(p.y, 1), clamp(p.z, 2))) __builtin_trap();
    // The point and one within 1/8 voxel of it (mostly the same cell) through the caches.
    const auto near = [&](std::int32_t v) { return v + static_cast<std::int32_t>(Mix(seed) % 16384) - 8192; };
    for (const palpa::sampler::GridPos x : {p, palpa::sampler::GridPos{near(p.x), near(p.y), near(p.z)}}) {
      if (s.Phi(x, phi_cache) != s.Phi(x)) __builtin_trap();
      const palpa::sampler::Sample cached = s.At(x, gradient_cache), plain = s.At(x);
      if (cached.phi != plain.phi || cached.grad != plain.grad || cached.in_grid != plain.in_grid) __builtin_trap();
    }
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  std::vector<std::uint64_t> words((size + 7) / 8);
  if (size > 0) std::memcpy(words.data(), data, size);
  Check(words, size, data);
  // Again with the CRC made right, so that mutations reach the structural checks and the sampler
  // instead of stopping at the checksum.
  auto* bytes = reinterpret_cast<std::byte*>(words.data());
  const std::span<const std::byte> all(bytes, size);
  std::size_t crc_at = 0, header = 0;
  if (size >= palpa::blob::kHeaderSizeV2 && data[8] == palpa::blob::kVersion2 && data[9] == 0) {
    crc_at = palpa::blob::kCrcOffsetV2;
    header = palpa::blob::kHeaderSizeV2;
  } else if (size >= palpa::blob::kHeaderSize && data[8] == palpa::blob::kVersion && data[9] == 0) {
    crc_at = palpa::blob::kCrcOffset;
    header = palpa::blob::kHeaderSize;
  }
  if (header != 0) {
    const std::uint32_t crc = palpa::blob::Crc32c(all.subspan(header), palpa::blob::Crc32c(all.first(crc_at)));
    std::memcpy(bytes + crc_at, &crc, sizeof crc);
    Check(words, size, data);
  }
  return 0;
}
