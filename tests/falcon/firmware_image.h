// A synthetic firmware image in the TI C2000 boot-ROM format Novint's files use (docs/falcon.md
// §1.7): palpa never ships Novint's firmware, so tests upload random payload in the same framing.
#pragma once

#include <cstdint>
#include <random>
#include <vector>

namespace palpa::falcon_test {

inline void PutWord(std::vector<std::uint8_t>& out, std::uint16_t w) {
  out.push_back(static_cast<std::uint8_t>(w & 0xFF));
  out.push_back(static_cast<std::uint8_t>(w >> 8));
}

/// Key 0x08AA, 8 reserved words, entry 0x003F8002, blocks of the given word counts, end block.
inline std::vector<std::uint8_t> SyntheticFirmware(std::vector<std::uint16_t> block_words = {3643, 241, 336, 2},
                                                   unsigned seed = 1) {
  std::mt19937 rng(seed);
  std::vector<std::uint8_t> out;
  PutWord(out, 0x08AA);
  for (int i = 0; i < 8; ++i) PutWord(out, 0);
  PutWord(out, 0x003F);
  PutWord(out, 0x8002);
  std::uint32_t dest = 0x3F8002;
  for (const std::uint16_t n : block_words) {
    PutWord(out, n);
    PutWord(out, static_cast<std::uint16_t>(dest >> 16));
    PutWord(out, static_cast<std::uint16_t>(dest & 0xFFFF));
    for (std::uint16_t i = 0; i < n; ++i) PutWord(out, static_cast<std::uint16_t>(rng()));
    dest += n;
  }
  PutWord(out, 0);
  return out;
}

}  // namespace palpa::falcon_test
