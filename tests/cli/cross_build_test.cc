// The aarch64 preset's palpad is an aarch64 ELF (scripts/test builds it before running ctest).
#include <gtest/gtest.h>

#include <unistd.h>
#include <array>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>

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

namespace {

// The fixed-point loop is integer-only with FP contraction off at the device boundary, so the
// x86-64, aarch64 and armhf palpads must write byte-identical force logs for the same inputs.
int Shell(const std::string& cmd) { return std::system(cmd.c_str()); }

std::string Slurp(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>()};
}

TEST(CrossBuild, PalpadOutputsAreBitIdenticalAcrossArchitectures) {
  const char* skip = std::getenv("PALPA_NO_CROSS");
  if (skip != nullptr && std::strcmp(skip, "1") == 0) GTEST_SKIP() << "PALPA_NO_CROSS=1: cross builds not made";
  const std::string dir = ::testing::TempDir() + "palpa-cross-" + std::to_string(::getpid());
  ASSERT_EQ(Shell("mkdir -p " + dir), 0);
  const std::string field = dir + "/sphere.palpa", trace = dir + "/stroke.csv";
  ASSERT_EQ(
      Shell(std::string(PALPA_BIN) + " build " + PALPA_DATA_DIR + "/sphere926.pwn -o " + field + " --cells 64 -q"), 0);
  ASSERT_EQ(Shell(std::string(PALPA_BIN) + " trace synth --field " + field + " --kind stroke --depth 0.003 -o " +
                  trace + " > /dev/null"),
            0);
  const std::string args = " --device sim --field " + field + " --trace " + trace + " --fast --out ";
  ASSERT_EQ(Shell(std::string(PALPA_NATIVE_PALPAD) + args + dir + "/x86.csv > /dev/null"), 0);
  const struct {
    const char* name;
    const char* emulator;
    const char* binary;
  } targets[] = {{"aarch64", "qemu-aarch64", PALPA_AARCH64_PALPAD}, {"armhf", "qemu-arm", PALPA_ARMHF_PALPAD}};
  const std::string native = Slurp(dir + "/x86.csv");
  ASSERT_GT(native.size(), 1000u);
  for (const auto& t : targets) {
    const std::string out = dir + "/" + t.name + ".csv";
    ASSERT_EQ(Shell(std::string(t.emulator) + " -L / " + t.binary + args + out + " > /dev/null"), 0) << t.name;
    EXPECT_TRUE(Slurp(out) == native) << t.name << " output differs from x86-64";
  }
  Shell("rm -rf " + dir);
}

}  // namespace
