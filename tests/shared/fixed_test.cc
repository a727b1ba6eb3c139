#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <type_traits>

#include "palpa/fixed/q.h"
#include "palpa/fixed/units.h"

namespace palpa::fixed {
namespace {

// Compile-time checks of value and type.
static_assert(Q16::FromInt(3).raw() == 3 * 65536);
static_assert(std::is_same_v<decltype(Mul(Q16{}, Q<8>{})), Wide<24>>);
static_assert(Narrow<16>(Mul(Q16::FromDouble(1.5), Q16::FromDouble(2.0)), Round::kNearest) == Q16::FromDouble(3.0));
static_assert(ShiftRight(-3, 1, Round::kFloor) == -2);
static_assert(ShiftRight(-3, 1, Round::kNearest) == -2);  // −1.5 → −2 (ties away from zero)
static_assert(ShiftRight(3, 1, Round::kNearest) == 2);

TEST(Fixed, NarrowSaturatesInsteadOfWrapping) {
  const Q16 big = Q16::FromInt(30000);
  const Q16 product = Narrow<16>(Mul(big, big), Round::kNearest);
  EXPECT_EQ(product.raw(), std::numeric_limits<std::int32_t>::max());
  const Q16 negative = Narrow<16>(Mul(big, -big), Round::kNearest);
  EXPECT_EQ(negative.raw(), std::numeric_limits<std::int32_t>::min());
  EXPECT_EQ((Q16::FromInt(30000) + Q16::FromInt(30000)).raw(), std::numeric_limits<std::int32_t>::max());
}

TEST(Fixed, RoundingIsSymmetric) {
  for (std::int64_t v = -70000; v <= 70000; v += 7) {
    EXPECT_EQ(ShiftRight(-v, 16, Round::kNearest), -ShiftRight(v, 16, Round::kNearest)) << v;
    const double exact = static_cast<double>(v) / 65536.0;
    EXPECT_LE(std::abs(static_cast<double>(ShiftRight(v, 16, Round::kNearest)) - exact), 0.5) << v;
  }
}

static_assert(ISqrtBitwise(0) == 0 && ISqrtBitwise(15) == 3 && ISqrtBitwise(16) == 4);
static_assert(ISqrtBitwise(INT64_MAX) == 3037000499ULL);

bool IsFloorSqrt(std::int64_t v, std::uint64_t r) {
  const auto u = static_cast<std::uint64_t>(v);
  return r * r <= u && (r + 1) * (r + 1) > u;
}

TEST(Fixed, ISqrtIsFloorOfSquareRoot) {
  // Every value below 2^20, squares and their neighbours at every scale, and random values of
  // every bit length, against the definition and the bit-by-bit reference.
  for (std::int64_t v = 0; v < (1 << 20); ++v) ASSERT_EQ(ISqrt(v), ISqrtBitwise(v)) << v;
  for (std::int64_t r = 1; r < 3037000499LL; r = r * 3 / 2 + 1) {
    for (std::int64_t v : {r * r - 1, r * r, r * r + 1, r * r + 2 * r}) {
      ASSERT_TRUE(IsFloorSqrt(v, ISqrt(v))) << v;
      ASSERT_EQ(ISqrt(v), ISqrtBitwise(v)) << v;
    }
  }
  std::mt19937_64 rng(1);
  for (int bits = 1; bits <= 63; ++bits) {
    for (int t = 0; t < 2000; ++t) {
      const auto v = static_cast<std::int64_t>(rng() >> (64 - bits));
      ASSERT_TRUE(IsFloorSqrt(v, ISqrt(v))) << v;
    }
  }
  for (std::int64_t v :
       {std::int64_t{(1LL << 62) - 1}, std::int64_t{1LL << 62}, std::int64_t{3LL << 60}, std::int64_t{INT64_MAX}})
    EXPECT_TRUE(IsFloorSqrt(v, ISqrt(v))) << v;
  EXPECT_EQ(ISqrt(-5), 0u);
  EXPECT_EQ(ISqrt(INT64_MAX), 3037000499ULL);
}

TEST(Fixed, FloorDivIsExact) {
  // Against the hardware's exact integer division, at every scale the loop uses (quotients up
  // to 2^50), and at exact multiples and their neighbours where a double estimate rounds across.
  std::mt19937_64 rng(2);
  for (int bits_d = 1; bits_d < 62; bits_d += 3) {
    for (int t = 0; t < 3000; ++t) {
      const auto d = static_cast<std::int64_t>((rng() >> (64 - bits_d)) | 1);
      const std::int64_t q_max = std::min<std::int64_t>((std::int64_t{1} << 61) / d, std::int64_t{1} << 50);
      const auto q = static_cast<std::int64_t>(rng() % static_cast<std::uint64_t>(q_max + 1));
      for (std::int64_t n : {q * d - 1, q * d, q * d + 1, q * d + d - 1}) {
        if (n < 0) continue;
        ASSERT_EQ(FloorDiv(n, d), n / d) << n << " / " << d;
      }
    }
  }
  EXPECT_EQ(FloorDiv(std::int64_t{1} << 56, std::int64_t{1} << 28), std::int64_t{1} << 28);
  EXPECT_EQ(FloorDiv(0, 7), 0);
}

TEST(Fixed, DivRoundTiesAwayFromZero) {
  EXPECT_EQ(DivRound(7, 2), 4);
  EXPECT_EQ(DivRound(-7, 2), -4);
  EXPECT_EQ(DivRound(7, -2), -4);
  EXPECT_EQ(DivRound(6, 4), 2);
  EXPECT_EQ(DivRound(5, 4), 1);
}

TEST(Units, HookesLawInFixedPoint) {
  // k·h = 0.16 N/voxel (800 N/m at 0.2 mm), 10 voxels → 1.6 N.
  const NewtonsPerVoxel k{Q16::FromDouble(0.16)};
  const Newtons f = k * Voxels{Q16::FromInt(10)};
  EXPECT_NEAR(f.value.ToDouble(), 1.6, 2e-4);
}

}  // namespace
}  // namespace palpa::fixed
