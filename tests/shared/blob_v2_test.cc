// Blob v2 (docs/blob-format.md): layout against the spec, the verifier on corrupt input, the
// sampler in place against the dense sampler on the same values, and the free-space bound
// through the real proxy.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <functional>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "analytic_fields.h"
#include "palpa/blob/blob.h"
#include "palpa/proxy/proxy.h"
#include "palpa/sampler/trilinear.h"

namespace palpa::blob {
namespace {

constexpr double kVoxel = 0.0002;

// φ of a sphere (voxels) of radius r around node-space point c, and its dense Q16.16 grid.
struct SphereGrid {
  std::array<std::uint32_t, 3> dims;
  std::array<double, 3> c;
  double r;
  std::vector<std::int32_t> q16;
  double Sdf(double i, double j, double k) const {
    return std::sqrt((i - c[0]) * (i - c[0]) + (j - c[1]) * (j - c[1]) + (k - c[2]) * (k - c[2])) - r;
  }
};

SphereGrid MakeSphere(std::array<std::uint32_t, 3> dims, std::array<double, 3> c, double r) {
  SphereGrid g{dims, c, r, {}};
  g.q16.resize(std::size_t{dims[0]} * dims[1] * dims[2]);
  std::size_t n = 0;
  for (std::uint32_t i = 0; i < dims[0]; ++i)
    for (std::uint32_t j = 0; j < dims[1]; ++j)
      for (std::uint32_t k = 0; k < dims[2]; ++k)
        g.q16[n++] = static_cast<std::int32_t>(std::lround(std::clamp(g.Sdf(i, j, k), -60.0, 60.0) * 65536.0));
  return g;
}

BlobMetaV2 Meta(const SphereGrid& g, std::uint32_t inside = 6, std::uint32_t outside = 2, bool bounds = true) {
  BlobMetaV2 m;
  m.meta.dims = g.dims;
  m.meta.origin_m = {-0.01, -0.02, 0.03};
  m.meta.voxel_m = kVoxel;
  m.meta.method = Method::kHermite;
  m.meta.point_count = 77;
  m.meta.fit_scale = 0.5;
  m.band_inside = inside;
  m.band_outside = outside;
  m.free_space_bounds = bounds;
  return m;
}

// Small enough for the every-byte tests: 13 × 11 × 20 nodes, 2 × 2 × 3 slots (the last z layer
// uniform), index at 168..216, then the octant tables and zero padding to a multiple of 64.
const SphereGrid& Small() {
  static const SphereGrid g = MakeSphere({13, 11, 20}, {6.3, 5.1, 4.7}, 3.2);
  return g;
}

void FixCrc(std::vector<std::byte>& b) {
  std::uint32_t crc = Crc32c(std::span<const std::byte>(b).first(kCrcOffsetV2));
  crc = Crc32c(std::span<const std::byte>(b).subspan(kHeaderSizeV2), crc);
  std::memcpy(b.data() + kCrcOffsetV2, &crc, 4);
}

template <typename T>
T At(const std::vector<std::byte>& b, std::size_t off) {
  T v;
  std::memcpy(&v, b.data() + off, sizeof v);
  return v;
}

TEST(BlobV2, RoundTripStoresTheQuantisedClampedField) {
  const SphereGrid& g = Small();
  const auto bytes = EncodeV2(Meta(g, 2, 1, false), g.q16);
  const auto v = Verify(bytes);
  ASSERT_TRUE(v.has_value()) << v.error().what();
  EXPECT_EQ(v->version, 2);
  EXPECT_EQ(v->dense(), nullptr);
  ASSERT_NE(v->bricks(), nullptr);
  EXPECT_EQ(reinterpret_cast<const std::byte*>(v->bricks()->index()), bytes.data() + kHeaderSizeV2);  // in place
  EXPECT_EQ(v->band_voxels, 2);
  EXPECT_EQ(v->band_outside, 1);
  // Every node: round(clamp(sdf, −2, 1)·256)·256, computed here from the closed form.
  for (std::int32_t i = 0; i < 13; ++i)
    for (std::int32_t j = 0; j < 11; ++j)
      for (std::int32_t k = 0; k < 20; ++k) {
        const double want = std::floor(std::clamp(g.Sdf(i, j, k), -2.0, 1.0) * 256.0 + 0.5);
        ASSERT_NEAR(v->NodeQ16(i, j, k) / 256.0, want, 1.0) << i << ' ' << j << ' ' << k;  // input rounded to Q16
        ASSERT_EQ(v->NodeQ16(i, j, k) % 256, 0);
      }
}

// Q16.16 -> Q7.8 rounds to nearest, ties up, except that a value outside (> 0) stays outside at
// 1/256 voxel at least: rounded to 0 a reader takes it for the surface and `palpa eval` for
// inside. Expected values worked by hand in 1/256 voxel.
TEST(BlobV2, ValuesOutsideStayOutside) {
  const std::int32_t in[] = {1, 127, 128, 383, 384, 0, -1, -128, -129, -384, -385, 2 * 65536};
  const std::int32_t want[] = {1, 1, 1, 1, 2, 0, 0, 0, -1, -1, -2, 512};
  // 12 x 2 x 2 nodes (each axis needs 2), the same value along j and k.
  SphereGrid g{{12, 2, 2}, {0, 0, 0}, 0, {}};
  for (const std::int32_t x : in) g.q16.insert(g.q16.end(), 4, x);
  const auto bytes = EncodeV2(Meta(g, 6, 2, false), g.q16);
  const auto v = Verify(bytes);
  ASSERT_TRUE(v.has_value()) << v.error().what();
  for (std::int32_t i = 0; i < 12; ++i) EXPECT_EQ(v->NodeQ16(i, 1, 1), want[i] * 256) << in[i];
}

// The brick-wise encoder (palpa build's, from a sparse field) against the dense one on a field with
// uniform bricks inside, outside and at the grid's edge: the same bytes, whether a uniform brick
// is handed over as one value or as 512.
TEST(BlobV2, BrickSourceEncodesTheSameBytesAsTheDenseField) {
  SphereGrid g = MakeSphere({37, 29, 41}, {17.2, 13.9, 20.4}, 11.3);
  for (std::int32_t& v : g.q16) v = std::clamp(v, -6 * 65536, 2 * 65536);  // uniform bricks inside and out
  for (const bool say_uniform : {false, true}) {
    std::size_t uniform_bricks = 0;
    const auto bricks = EncodeV2(
        Meta(g),
        [&](std::array<std::uint32_t, 3> b, std::span<std::int32_t, kBrickNodes> q16) -> std::optional<std::int32_t> {
          std::optional<std::int32_t> first;
          bool uniform = true;
          for (std::uint32_t a = 0; a < kBrick; ++a)
            for (std::uint32_t c = 0; c < kBrick; ++c)
              for (std::uint32_t e = 0; e < kBrick; ++e) {
                const std::uint32_t i = b[0] * kBrick + a, j = b[1] * kBrick + c, k = b[2] * kBrick + e;
                // Past the grid's edge: garbage the encoder must ignore.
                const std::int32_t v = i < g.dims[0] && j < g.dims[1] && k < g.dims[2]
                                           ? g.q16[(std::size_t{i} * g.dims[1] + j) * g.dims[2] + k]
                                           : -123456789;
                q16[(a * kBrick + c) * kBrick + e] = v;
                if (v == -123456789) continue;
                uniform = uniform && (!first || *first == v);
                if (!first) first = v;
              }
          if (!say_uniform || !uniform) return std::nullopt;
          ++uniform_bricks;
          return first;
        });
    EXPECT_EQ(bricks, EncodeV2(Meta(g), g.q16)) << "uniform bricks handed as one value: " << say_uniform;
    if (say_uniform) {
      EXPECT_GT(uniform_bricks, 10u);  // the test exercises that path
    }
  }
}

// The planes of bricks (and the free-space passes' slots) run through a ParallelFor one at a time
// in reverse order, as threads may finish them: numbered on in plane order, the same bytes.
TEST(BlobV2, PlanesEncodedInAnyOrderGiveTheSameBytes) {
  SphereGrid g = MakeSphere({37, 29, 41}, {17.2, 13.9, 20.4}, 11.3);
  const auto source = [&](std::array<std::uint32_t, 3> b,
                          std::span<std::int32_t, kBrickNodes> q16) -> std::optional<std::int32_t> {
    for (std::uint32_t a = 0; a < kBrick; ++a)
      for (std::uint32_t c = 0; c < kBrick; ++c)
        for (std::uint32_t e = 0; e < kBrick; ++e) {
          const std::uint32_t i = b[0] * kBrick + a, j = b[1] * kBrick + c, k = b[2] * kBrick + e;
          q16[(a * kBrick + c) * kBrick + e] = i < g.dims[0] && j < g.dims[1] && k < g.dims[2]
                                                   ? g.q16[(std::size_t{i} * g.dims[1] + j) * g.dims[2] + k]
                                                   : 0;
        }
    return std::nullopt;
  };
  std::vector<std::size_t> counts;  // the planes, then the slots of each free-space pass
  const auto reversed =
      EncodeV2(Meta(g), source, [&](std::size_t count, const std::function<void(std::size_t, std::size_t)>& body) {
        counts.push_back(count);
        for (std::size_t p = count; p-- > 0;) body(p, p + 1);
      });
  ASSERT_FALSE(counts.empty());
  EXPECT_EQ(counts.front(), (g.dims[0] + kBrick - 1) / kBrick);
  EXPECT_EQ(reversed, EncodeV2(Meta(g), g.q16));
}

TEST(BlobV2, HeaderFieldOffsetsMatchTheSpec) {
  // docs/blob-format.md v2 header table, byte by byte.
  const SphereGrid& g = Small();
  const auto b = EncodeV2(Meta(g), g.q16);
  EXPECT_EQ(std::memcmp(b.data(), "PALPASDF", 8), 0);
  EXPECT_EQ(At<std::uint16_t>(b, 8), 2);
  EXPECT_EQ(At<std::uint16_t>(b, 10), 168);
  EXPECT_EQ(At<std::uint32_t>(b, 12), 0u);
  EXPECT_EQ(At<std::uint32_t>(b, 16), 13u);
  EXPECT_EQ(At<std::uint32_t>(b, 20), 11u);
  EXPECT_EQ(At<std::uint32_t>(b, 24), 20u);
  EXPECT_EQ(At<std::uint32_t>(b, 28), 2u);
  EXPECT_EQ(At<double>(b, 32), -0.01);
  EXPECT_EQ(At<double>(b, 40), -0.02);
  EXPECT_EQ(At<double>(b, 48), 0.03);
  EXPECT_EQ(At<double>(b, 56), kVoxel);
  EXPECT_EQ(At<std::uint32_t>(b, 64), 6u);
  EXPECT_EQ(At<std::uint32_t>(b, 68), 2u);
  EXPECT_EQ(At<std::uint32_t>(b, 72), 3u);
  EXPECT_EQ(At<std::uint32_t>(b, 76), 77u);
  EXPECT_EQ(At<double>(b, 88), 0.5);
  EXPECT_EQ(At<std::uint32_t>(b, 120), 2u);
  EXPECT_EQ(At<std::uint32_t>(b, 124), 2u);
  EXPECT_EQ(At<std::uint32_t>(b, 128), 3u);
  const auto bricks = At<std::uint32_t>(b, 132);
  const auto octants = At<std::uint32_t>(b, 136);
  EXPECT_GT(bricks, 0u);
  EXPECT_GT(octants, 0u);
  EXPECT_LE(octants, 8 * bricks);
  EXPECT_EQ(At<std::uint32_t>(b, 140), 0u);
  const std::size_t tables_end = 168 + 4 * 12 + 32 * bricks;
  const std::size_t octants_at = (tables_end + 63) / 64 * 64;
  EXPECT_EQ(At<std::uint64_t>(b, 144), octants_at);
  EXPECT_EQ(At<std::uint64_t>(b, 152), octants_at - 168 + 128 * octants);
  EXPECT_EQ(At<std::uint32_t>(b, 160), 0u);
  EXPECT_EQ(b.size(), octants_at + 128 * octants);
  for (std::size_t p = tables_end; p < octants_at; ++p) EXPECT_EQ(b[p], std::byte{0}) << p;
  std::uint32_t crc = Crc32c(std::span<const std::byte>(b).first(164));
  crc = Crc32c(std::span<const std::byte>(b).subspan(168), crc);
  EXPECT_EQ(At<std::uint32_t>(b, 164), crc);
  // The last z layer of slots (nodes 16..19) lies > 8 voxels from the sphere: uniform and
  // flagged, at band_outside (the free-space bound of a slot next to the band is 0).
  for (std::size_t s = 2; s < 12; s += 3) {
    const auto e = At<std::uint32_t>(b, 168 + 4 * s);
    EXPECT_NE(e & kSlotEmpty, 0u) << s;
    EXPECT_EQ(static_cast<std::int16_t>(e & 0xFFFF), 2 * 256) << s;
  }
}

TEST(BlobV2, EveryOneByteFlipIsRejectedNamingAFieldAndByte) {
  const SphereGrid& g = Small();
  const auto good = EncodeV2(Meta(g), g.q16);
  ASSERT_TRUE(Verify(good).has_value());
  for (std::size_t i = 0; i < good.size(); ++i) {
    auto bad = good;
    bad[i] ^= std::byte{0x5A};
    const auto v = Verify(bad);
    ASSERT_FALSE(v.has_value()) << "flip at byte " << i << " was accepted";
    ASSERT_NE(std::string(v.error().what()).find(" at byte "), std::string::npos);
  }
}

TEST(BlobV2, TruncationAtEveryLengthIsRejected) {
  const SphereGrid& g = Small();
  const auto good = EncodeV2(Meta(g), g.q16);
  for (std::size_t n = 0; n < good.size(); ++n) {
    const std::vector<std::byte> cut(good.begin(), good.begin() + static_cast<std::ptrdiff_t>(n));
    ASSERT_FALSE(Verify(cut).has_value()) << n;
  }
  auto longer = good;
  longer.push_back(std::byte{0});
  const auto v = Verify(longer);
  ASSERT_FALSE(v.has_value());
  EXPECT_EQ(v.error().offset, good.size());
}

// Structural faults behind a valid CRC: the verifier still names the field and byte.
TEST(BlobV2, StructuralFaultsNameTheirFieldAndOffset) {
  const SphereGrid& g = Small();
  const auto good = EncodeV2(Meta(g), g.q16);
  const auto expect = [&](auto mutate, const char* field, std::size_t offset) {
    auto b = good;
    mutate(b);
    FixCrc(b);
    const auto v = Verify(b);
    ASSERT_FALSE(v.has_value()) << field;
    EXPECT_STREQ(v.error().field, field) << v.error().what();
    EXPECT_EQ(v.error().offset, offset) << v.error().what();
  };
  const auto put32 = [](std::vector<std::byte>& b, std::size_t off, std::uint32_t x) {
    std::memcpy(b.data() + off, &x, 4);
  };
  expect([&](auto& b) { put32(b, 28, 1); }, "value_format", 28);
  expect([&](auto& b) { put32(b, 68, 0); }, "band_outside", 68);
  expect([&](auto& b) { put32(b, 124, 3); }, "brick_dims", 124);
  expect([&](auto& b) { put32(b, 132, 13); }, "brick_count", 132);
  expect([&](auto& b) { put32(b, 136, 8 * At<std::uint32_t>(good, 132) + 1); }, "octant_count", 136);
  expect([&](auto& b) { put32(b, 140, 1); }, "reserved0", 140);
  expect([&](auto& b) { put32(b, 160, 1); }, "reserved1", 160);
  const std::size_t tables_end = 168 + 48 + 32 * At<std::uint32_t>(good, 132);
  const auto octants_at = static_cast<std::size_t>(At<std::uint64_t>(good, 144));
  if (tables_end < octants_at) expect([&](auto& b) { b[octants_at - 1] = std::byte{1}; }, "padding", octants_at - 1);
  // The first stored slot points at a brick number that is not the next one.
  std::size_t first = 0;
  while (At<std::uint32_t>(good, 168 + 4 * first) & kSlotEmpty) ++first;
  ASSERT_LT(first, 12u);
  expect([&](auto& b) { put32(b, 168 + 4 * first, 5); }, "index", 168 + 4 * first);
  // A uniform slot below −band_inside.
  std::size_t empty = 0;
  while (!(At<std::uint32_t>(good, 168 + 4 * empty) & kSlotEmpty)) ++empty;
  ASSERT_LT(empty, 12u);
  expect([&](auto& b) { put32(b, 168 + 4 * empty, kSlotEmpty | 0x8000U); }, "index", 168 + 4 * empty);
  // Brick 0's first stored octant renumbered.
  std::size_t t = 0;
  while (At<std::uint32_t>(good, 216 + 4 * t) & kSlotEmpty) ++t;
  ASSERT_LT(t, 8u);
  expect([&](auto& b) { put32(b, 216 + 4 * t, 99); }, "tables", 216 + 4 * t);
  // A value past +band_outside in octant 0 (its node 0 is inside the grid).
  expect(
      [&](auto& b) {
        const std::int16_t x = 2 * 256 + 1;
        std::memcpy(b.data() + octants_at, &x, 2);
      },
      "octants", octants_at);
}

TEST(BlobV2, NewerVersionIsRefusedNamingTheByte) {
  const SphereGrid& g = Small();
  auto b = EncodeV2(Meta(g), g.q16);
  b[8] = std::byte{3};
  const auto v = Verify(b);
  ASSERT_FALSE(v.has_value());
  EXPECT_EQ(v.error().offset, 8u);
  EXPECT_NE(std::string(v.error().what()).find("rebuild"), std::string::npos);
}

// The brick sampler against the dense sampler over the very same node values: Phi and At bit for
// bit at random points, points on and next to brick borders (multiples of 8), band edges and the
// grid's last nodes.
TEST(BlobV2, SamplerInPlaceEqualsDenseSamplingBitForBit) {
  const SphereGrid g = MakeSphere({45, 38, 30}, {21.3, 18.6, 14.2}, 9.7);
  const auto bytes = EncodeV2(Meta(g), g.q16);
  const auto v2 = Verify(bytes).value();
  ASSERT_GT(v2.bricks()->octant_count(), 0u);
  // A v1 blob of the very same node values (its band wide enough to hold the free-space bounds),
  // sampled with the brick sampler's background.
  const std::vector<std::int32_t> dense = DenseQ16(v2);
  BlobMeta m = Meta(g).meta;
  m.band_voxels =
      static_cast<std::uint32_t>((std::ranges::max(dense, {}, [](std::int32_t x) { return std::abs(x); }) >> 16) + 1);
  const auto dense_bytes = Encode(m, dense);
  const auto v1 = Verify(dense_bytes).value();
  const sampler::BrickSampler s2(*v2.bricks(), v2.band_outside);
  const sampler::DenseSampler s1(*v1.dense(), v2.band_outside);
  ASSERT_EQ(s1.background(), s2.background());
  std::mt19937 rng(11);
  int compared = 0;
  const auto check = [&](std::int32_t x, std::int32_t y, std::int32_t z) {
    const sampler::GridPos p{x, y, z};
    ASSERT_EQ(s2.Phi(p), s1.Phi(p)) << x << ' ' << y << ' ' << z;
    const auto a = s2.At(p), b = s1.At(p);
    ASSERT_EQ(a.phi, b.phi);
    ASSERT_EQ(a.grad, b.grad) << x << ' ' << y << ' ' << z;
    ASSERT_EQ(a.in_grid, b.in_grid);
    ++compared;
  };
  std::uniform_int_distribution<std::int32_t> u(-3 << 16, 48 << 16);
  for (int n = 0; n < 200000; ++n) check(u(rng), u(rng), u(rng));
  // Brick borders: node 8m − 1 .. 8m + 1 on every axis, with small and large fractions.
  std::uniform_int_distribution<std::int32_t> frac(0, 65535);
  for (std::int32_t a = 0; a < 45; ++a)
    for (std::int32_t b = 0; b < 38; ++b)
      for (std::int32_t c = 0; c < 30; ++c) {
        const bool border = ((a + 1) % 8 <= 2) || ((b + 1) % 8 <= 2) || ((c + 1) % 8 <= 2);
        if (!border) continue;
        check((a << 16) + frac(rng) % 3, (b << 16) + 65535 - frac(rng) % 3, (c << 16) + frac(rng));
      }
  // Band edges: along rays from the centre, radii from r − 6.5 to r + 2.5 voxels.
  std::normal_distribution<double> nd;
  for (int n = 0; n < 20000; ++n) {
    double d[3] = {nd(rng), nd(rng), nd(rng)};
    const double l = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    const double rad = g.r - 6.5 + 9.0 * (n % 1000) / 1000.0;
    check(static_cast<std::int32_t>((g.c[0] + rad * d[0] / l) * 65536),
          static_cast<std::int32_t>((g.c[1] + rad * d[1] / l) * 65536),
          static_cast<std::int32_t>((g.c[2] + rad * d[2] / l) * 65536));
  }
  // Every cell's 32 wide-stencil values, as the float64 reference reads them (CopyWide): interior
  // cells through RowView's 16 forms, face cells through the general gather.
  for (std::int32_t a = 0; a + 1 < 45; ++a)
    for (std::int32_t b = 0; b + 1 < 38; ++b)
      for (std::int32_t c = 0; c + 1 < 30; ++c) {
        const auto w2 = s2.CopyWide(a, b, c), w1 = s1.CopyWide(a, b, c);
        ASSERT_EQ(w2.corner, w1.corner) << a << ' ' << b << ' ' << c;
        ASSERT_EQ(w2.x_out, w1.x_out) << a << ' ' << b << ' ' << c;
        ASSERT_EQ(w2.y_out, w1.y_out) << a << ' ' << b << ' ' << c;
        ASSERT_EQ(w2.z_out, w1.z_out) << a << ' ' << b << ' ' << c;
      }
  // The last nodes of the grid (the outer-face clamps of the wide stencil).
  check(44 << 16, 37 << 16, 29 << 16);
  check((44 << 16) - 1, (37 << 16) - 7, 29 << 16);
  check(0, 0, 0);
  EXPECT_GT(compared, 250000);
}

// Empty slots in free space carry a lower bound: never above the true distance by more than a cell
// diagonal (docs/blob-format.md § Free-space bound), and far above band_outside far away.
TEST(BlobV2, FreeSpaceBoundsAreBelowTheTrueDistance) {
  const SphereGrid g = MakeSphere({120, 100, 90}, {40.2, 50.7, 44.9}, 12.3);
  const auto bytes = EncodeV2(Meta(g), g.q16);
  const auto v = Verify(bytes).value();
  double largest = 0;
  for (std::int32_t i = 0; i < 120; ++i)
    for (std::int32_t j = 0; j < 100; ++j)
      for (std::int32_t k = 0; k < 90; ++k) {
        const double phi = v.NodeQ16(i, j, k) / 65536.0;
        if (phi <= 2.0) continue;
        ASSERT_LE(phi, g.Sdf(i, j, k) + std::sqrt(3.0)) << i << ' ' << j << ' ' << k;
        largest = std::max(largest, phi);
      }
  EXPECT_GT(largest, 50.0);  // the far corner is > 80 voxels from the sphere
}

// A HIP moving at 2 m/s in free space (10 voxels per tick at 1 kHz and 0.2 mm voxels) past a
// sphere: with the free-space bounds the proxy reaches it within every tick; with the plain
// outside band (2 voxels) the proxy's 4 samples per tick cannot keep up.
int TicksLagging(bool bounds) {
  const SphereGrid g = MakeSphere({160, 160, 160}, {50.0, 80.0, 80.0}, 20.0);
  const auto bytes = EncodeV2(Meta(g, 6, 2, bounds), g.q16);
  const auto view = Verify(bytes).value();
  const sampler::TrilinearSampler field(view);
  const auto params = proxy::MakeProxyParams(proxy::ProxyConfig{}, view.voxel_m).value();
  proxy::ProxyState state;
  int lagging = 0;
  const double speed_voxels_per_tick = 2.0 * 1e-3 / kVoxel;  // 2 m/s · 1 ms
  for (int t = 0; t < 14; ++t) {
    // From (6, 6, 6) along +x+y: passes 25..50 voxels from the sphere's surface.
    const double s = 6.0 + t * speed_voxels_per_tick / std::sqrt(2.0);
    const sampler::GridPos hip{static_cast<std::int32_t>(s * 65536), static_cast<std::int32_t>(s * 65536),
                               static_cast<std::int32_t>(150.0 * 65536)};
    const auto r = proxy::ProxyTick(field, params, state, hip);
    EXPECT_FALSE(r.contact);
    if (t > 0 && !(r.proxy == hip)) ++lagging;
  }
  return lagging;
}

TEST(BlobV2, FreeSpaceBoundLetsTheProxyCatchUpAtTwoMetresPerSecond) {
  EXPECT_EQ(TicksLagging(true), 0);
  EXPECT_GT(TicksLagging(false), 0);  // the lever is the bound, not the test's geometry
}

}  // namespace
}  // namespace palpa::blob
