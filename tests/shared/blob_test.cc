#include <gtest/gtest.h>

#include <cstring>
#include <string>
#include <vector>

#include "analytic_fields.h"
#include "palpa/blob/blob.h"

namespace palpa::blob {
namespace {

TEST(Crc32c, StandardCheckValue) {
  const char* s = "123456789";  // RFC 3720 / iSCSI check value
  EXPECT_EQ(Crc32c(std::as_bytes(std::span(s, 9))), 0xE3069283U);
  // Continuing a CRC over two halves equals one pass.
  const auto all = std::as_bytes(std::span(s, 9));
  EXPECT_EQ(Crc32c(all.subspan(4), Crc32c(all.first(4))), 0xE3069283U);
}

// The hardware path (SSE4.2 crc32 on x86-64; the table elsewhere, as on the boards) against the
// bitwise definition (reflected 0x82F63B78, RFC 3720 §B.4) on every length 0..200 at every
// alignment 0..7 and a few chunked continuations: the word loop and the byte tail both checked.
TEST(Crc32c, AgreesWithTheBitwiseDefinitionAtEveryLengthAndAlignment) {
  const auto bitwise = [](std::span<const std::byte> data, std::uint32_t crc) {
    crc = ~crc;
    for (const std::byte b : data) {
      crc ^= static_cast<std::uint32_t>(b);
      for (int k = 0; k < 8; ++k) crc = (crc & 1U) != 0 ? 0x82F63B78U ^ (crc >> 1) : crc >> 1;
    }
    return ~crc;
  };
  std::vector<std::byte> buffer(216);
  std::uint32_t x = 12345;
  for (std::byte& b : buffer) {
    x = x * 1664525U + 1013904223U;
    b = static_cast<std::byte>(x >> 24);
  }
  for (std::size_t offset = 0; offset < 8; ++offset)
    for (std::size_t length = 0; length <= 200; ++length) {
      const auto data = std::span<const std::byte>(buffer).subspan(offset, length);
      ASSERT_EQ(Crc32c(data), bitwise(data, 0)) << offset << " " << length;
      const std::size_t half = length / 3;
      ASSERT_EQ(Crc32c(data.subspan(half), Crc32c(data.first(half))), bitwise(data, 0)) << offset << " " << length;
    }
}

std::vector<std::byte> SmallBlob() { return testing::SphereBlob(5, 0.001, 3, 1.5); }

TEST(Blob, RoundTripVerifiesAndReadsInPlace) {
  const auto bytes = SmallBlob();
  ASSERT_EQ(bytes.size(), kHeaderSize + 4u * 125);
  auto v = Verify(bytes);
  ASSERT_TRUE(v.has_value()) << v.error().what();
  EXPECT_EQ(v->dims[0], 5);
  EXPECT_EQ(v->band_voxels, 3);
  EXPECT_DOUBLE_EQ(v->voxel_m, 0.001);
  ASSERT_NE(v->dense(), nullptr);
  EXPECT_EQ(v->bricks(), nullptr);
  EXPECT_EQ(reinterpret_cast<const std::byte*>(v->dense()->data()), bytes.data() + kHeaderSize);  // in place
  // Centre node: φ = −1.5 voxels.
  EXPECT_EQ(v->dense()->data()[(2 * 5 + 2) * 5 + 2], -3 * 32768);
  EXPECT_EQ(v->NodeQ16(2, 2, 2), -3 * 32768);
}

TEST(Blob, HeaderFieldOffsetsMatchTheSpec) {
  // docs/blob-format.md table, byte by byte.
  const auto bytes = SmallBlob();
  auto at32 = [&](std::size_t off) {
    std::uint32_t v;
    std::memcpy(&v, bytes.data() + off, 4);
    return v;
  };
  auto at16 = [&](std::size_t off) {
    std::uint16_t v;
    std::memcpy(&v, bytes.data() + off, 2);
    return v;
  };
  auto atf = [&](std::size_t off) {
    double v;
    std::memcpy(&v, bytes.data() + off, 8);
    return v;
  };
  EXPECT_EQ(std::memcmp(bytes.data(), "PALPASDF", 8), 0);
  EXPECT_EQ(at16(8), 1);
  EXPECT_EQ(at16(10), 144);
  EXPECT_EQ(at32(12), 0u);
  EXPECT_EQ(at32(16), 5u);
  EXPECT_EQ(at32(20), 5u);
  EXPECT_EQ(at32(24), 5u);
  EXPECT_EQ(at32(28), 1u);
  EXPECT_DOUBLE_EQ(atf(32), -0.002);
  EXPECT_DOUBLE_EQ(atf(56), 0.001);
  EXPECT_EQ(at32(64), 3u);
  EXPECT_EQ(at32(68), 1u);
  EXPECT_DOUBLE_EQ(atf(88), 1.0);
  std::uint64_t payload;
  std::memcpy(&payload, bytes.data() + 120, 8);
  EXPECT_EQ(payload, 500u);
  const std::span<const std::byte> all(bytes);
  EXPECT_EQ(at32(140), Crc32c(all.subspan(144), Crc32c(all.first(140))));
}

TEST(Blob, EveryOneByteFlipIsRejected) {
  const auto good = SmallBlob();
  for (std::size_t i = 0; i < good.size(); ++i) {
    auto bad = good;
    bad[i] ^= std::byte{0x5A};
    auto v = Verify(bad);
    ASSERT_FALSE(v.has_value()) << "flip at byte " << i << " was accepted";
    EXPECT_NE(std::string(v.error().what()).find("byte"), std::string::npos) << v.error().what();
  }
}

TEST(Blob, TruncationAtEveryLengthIsRejected) {
  const auto good = SmallBlob();
  for (std::size_t n = 0; n < good.size(); ++n) {
    std::vector<std::byte> cut(good.begin(), good.begin() + static_cast<std::ptrdiff_t>(n));
    EXPECT_FALSE(Verify(cut).has_value()) << "length " << n;
  }
  auto longer = good;
  longer.push_back(std::byte{0});
  auto v = Verify(longer);
  ASSERT_FALSE(v.has_value());
  EXPECT_STREQ(v.error().field, "payload");
}

TEST(Blob, WrongMagicAndVersionNameTheirField) {
  auto bad = SmallBlob();
  bad[0] = std::byte{'X'};
  auto v = Verify(bad);
  ASSERT_FALSE(v.has_value());
  EXPECT_STREQ(v.error().field, "magic");
  EXPECT_EQ(v.error().offset, 0u);

  bad = SmallBlob();
  bad[8] = std::byte{3};  // v2 is known (blob_v2_test.cc); v3 is not
  v = Verify(bad);
  ASSERT_FALSE(v.has_value());
  EXPECT_STREQ(v.error().field, "version");
  EXPECT_EQ(v.error().offset, 8u);
  EXPECT_NE(std::string(v.error().what()).find("rebuild"), std::string::npos);
}

TEST(Blob, ValuesOutsideTheBandAreRejectedWithTheirOffset) {
  // Re-encode (valid CRC) with a value beyond the band: only the range check can catch it.
  std::vector<std::int32_t> phi(8, 0);
  phi[5] = 4 << 16;
  BlobMeta meta;
  meta.dims = {2, 2, 2};
  meta.voxel_m = 0.001;
  meta.band_voxels = 3;
  auto v = Verify(Encode(meta, phi));
  ASSERT_FALSE(v.has_value());
  EXPECT_STREQ(v.error().field, "payload");
  EXPECT_EQ(v.error().offset, kHeaderSize + 4 * 5);
}

TEST(Blob, BadDimsAreRejectedBeforeAnySizeArithmetic) {
  BlobMeta meta;
  meta.dims = {5000, 2, 2};
  meta.voxel_m = 0.001;
  meta.band_voxels = 3;
  std::vector<std::int32_t> phi(5000 * 4, 0);
  auto v = Verify(Encode(meta, phi));
  ASSERT_FALSE(v.has_value());
  EXPECT_STREQ(v.error().field, "dims");
  EXPECT_EQ(v.error().offset, 16u);
}

}  // namespace
}  // namespace palpa::blob
