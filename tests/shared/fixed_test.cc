#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <limits>
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
static_assert(ISqrt(0) == 0 && ISqrt(1) == 1 && ISqrt(15) == 3 && ISqrt(16) == 4);

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

TEST(Fixed, ISqrtIsFloorOfSquareRoot) {
  for (std::int64_t v : {2LL, 3LL, 99LL, 100LL, 101LL, (1LL << 40) + 12345, (1LL << 62) - 1, 3LL << 60}) {
    const std::uint64_t r = ISqrt(v);
    EXPECT_LE(r * r, static_cast<std::uint64_t>(v)) << v;
    EXPECT_GT((r + 1) * (r + 1), static_cast<std::uint64_t>(v)) << v;
  }
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
