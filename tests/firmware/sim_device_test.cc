#include "palpa/device_sim/sim_device.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

namespace palpa::device_sim {
namespace {

using device::HipReading;
using device::IoStatus;

std::vector<trace::TraceSample> ThreeSamples() {
  return {{0.0, {0.0, 0.0, 0.0}}, {1.0, {1.0, 2.0, 3.0}}, {3.0, {3.0, 2.0, 1.0}}};
}

TEST(SimDevice, InterpolatesAtTickTimesThenEnds) {
  SimDevice dev(ThreeSamples(), 4.0);  // ticks at 0, 0.25, …, 3.0
  ASSERT_EQ(dev.TickCount(), 13u);
  // Hand-computed: t = n/4; before t = 1: (t, 2t, 3t); after: (1,2,3) + (t−1)/2·(2,0,−2).
  const double expected[13][3] = {{0, 0, 0}, {0.25, 0.5, 0.75}, {0.5, 1, 1.5}, {0.75, 1.5, 2.25},
                                  {1, 2, 3}, {1.25, 2, 2.75},   {1.5, 2, 2.5}, {1.75, 2, 2.25},
                                  {2, 2, 2}, {2.25, 2, 1.75},   {2.5, 2, 1.5}, {2.75, 2, 1.25},
                                  {3, 2, 1}};
  for (int n = 0; n < 13; ++n) {
    HipReading r;
    ASSERT_EQ(dev.Read(r), IoStatus::kOk) << "tick " << n;
    EXPECT_DOUBLE_EQ(r.t_s, n / 4.0);
    for (std::size_t a = 0; a < 3; ++a) EXPECT_NEAR(r.hip_m[a], expected[n][a], 1e-12) << "tick " << n << " axis " << a;
  }
  HipReading r;
  EXPECT_EQ(dev.Read(r), IoStatus::kEnd);
  EXPECT_EQ(dev.Read(r), IoStatus::kEnd);  // stays ended
  EXPECT_EQ(dev.reads(), 13u);
}

TEST(SimDevice, TickCountIncludesATickExactlyOnTheLastTime) {
  EXPECT_EQ(SimDevice({{0.0, {}}, {1.0, {}}}, 3.0).TickCount(), 4u);   // 0, 1/3, 2/3, 1
  EXPECT_EQ(SimDevice({{0.0, {}}, {0.3, {}}}, 10.0).TickCount(), 4u);  // 0, .1, .2, .3
  EXPECT_EQ(SimDevice({{0.0, {}}, {0.299, {}}}, 10.0).TickCount(), 3u);
  EXPECT_EQ(SimDevice({{0.0, {}}, {10.0, {}}}, 1000.0).TickCount(), 10001u);
}

TEST(SimDevice, BeforeTheFirstSampleHoldsIt) {
  SimDevice dev({{0.5, {1.0, 1.0, 1.0}}, {1.0, {2.0, 2.0, 2.0}}}, 4.0);
  HipReading r;
  ASSERT_EQ(dev.Read(r), IoStatus::kOk);  // t = 0
  EXPECT_EQ(r.hip_m, (std::array<double, 3>{1.0, 1.0, 1.0}));
  ASSERT_EQ(dev.Read(r), IoStatus::kOk);  // t = 0.25
  EXPECT_EQ(r.hip_m, (std::array<double, 3>{1.0, 1.0, 1.0}));
  ASSERT_EQ(dev.Read(r), IoStatus::kOk);  // t = 0.5
  ASSERT_EQ(dev.Read(r), IoStatus::kOk);  // t = 0.75
  EXPECT_NEAR(r.hip_m[0], 1.5, 1e-12);
}

TEST(SimDevice, RecordsWritesAndRejectsNonFiniteForce) {
  SimDevice dev(ThreeSamples(), 1.0);
  EXPECT_EQ(dev.Write({1.0, -2.0, 0.5}), IoStatus::kOk);
  EXPECT_EQ(dev.last_force_n(), (std::array<double, 3>{1.0, -2.0, 0.5}));
  // NVI check: a NaN force never reaches the device; it gets zero instead.
  EXPECT_EQ(dev.Write({std::numeric_limits<double>::quiet_NaN(), 0.0, 0.0}), IoStatus::kError);
  EXPECT_EQ(dev.last_force_n(), (std::array<double, 3>{0.0, 0.0, 0.0}));
  EXPECT_EQ(dev.writes(), 2u);
}

TEST(SimDevice, NonFiniteTraceValueIsAReadError) {
  // ReadTrace refuses non-finite values; the NVI check is the second line of defence.
  SimDevice dev({{0.0, {std::numeric_limits<double>::infinity(), 0, 0}}, {1.0, {0, 0, 0}}}, 1.0);
  HipReading r;
  EXPECT_EQ(dev.Read(r), IoStatus::kError);
}

}  // namespace
}  // namespace palpa::device_sim
