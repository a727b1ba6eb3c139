// The aarch64 preset's palpad is an aarch64 ELF (scripts/test builds it before running ctest).
#include <gtest/gtest.h>

#include <array>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <fstream>

namespace {

TEST(CrossBuild, Aarch64PalpadIsAnAarch64Elf) {
  std::ifstream f(PALPA_AARCH64_PALPAD, std::ios::binary);
  if (!f) {
    const char* skip = std::getenv("PALPA_NO_CROSS");
    if (skip != nullptr && std::strcmp(skip, "1") == 0) GTEST_SKIP() << "PALPA_NO_CROSS=1: cross build not made";
    FAIL() << PALPA_AARCH64_PALPAD << " is missing: run `cmake --preset aarch64 && cmake --build --preset aarch64`";
  }
  std::array<unsigned char, 20> h{};
  f.read(reinterpret_cast<char*>(h.data()), h.size());
  ASSERT_EQ(f.gcount(), 20);
  EXPECT_EQ(std::memcmp(h.data(),
                        "\x7f"
                        "ELF",
                        4),
            0);
  EXPECT_EQ(h[4], 2);  // ELFCLASS64
  EXPECT_EQ(h[5], 1);  // little-endian
  std::uint16_t machine = 0;
  std::memcpy(&machine, h.data() + 18, 2);
  EXPECT_EQ(machine, 183);  // EM_AARCH64
}

}  // namespace
