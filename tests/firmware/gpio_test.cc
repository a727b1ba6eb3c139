// GPIO: the CHIP:LINE parser, the simulated lines (recording, scripts, failures), and the libgpiod
// backend's one real path on a machine without a GPIO chip: the error names the chip.

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <string>

#include "palpa/gpio/gpio.h"
#include "palpa/gpio_linux/gpiod_lines.h"
#include "palpa/gpio_sim/sim_gpio.h"
#include "runtime_fixtures.h"

namespace palpa::gpio {
namespace {

TEST(LineSpec, ParsesChipNamesAndPaths) {
  auto a = ParseLineSpec("--estop", "gpiochip0:17");
  ASSERT_TRUE(a.has_value()) << a.error();
  EXPECT_EQ(a->chip, "gpiochip0");
  EXPECT_EQ(a->line, 17u);
  auto b = ParseLineSpec("--estop", "/dev/gpiochip4:0");
  ASSERT_TRUE(b.has_value());
  EXPECT_EQ(b->chip, "/dev/gpiochip4");
  EXPECT_EQ(b->line, 0u);
}

TEST(LineSpec, ErrorsNameTheOptionAndTheText) {
  for (const char* bad :
       {"gpiochip0", ":17", "gpiochip0:", "gpiochip0:x", "gpiochip0:-1", "gpiochip0:65536", "gpiochip0:1.5"}) {
    auto r = ParseLineSpec("--tick-gpio", bad);
    ASSERT_FALSE(r.has_value()) << bad;
    EXPECT_TRUE(r.error().starts_with(std::string("--tick-gpio: '") + bad + "'")) << r.error();
  }
  EXPECT_TRUE(ParseActiveLevel("--estop-active", "low").has_value());
  EXPECT_FALSE(*ParseActiveLevel("--estop-active", "low"));
  EXPECT_TRUE(*ParseActiveLevel("--estop-active", "high"));
  EXPECT_FALSE(ParseActiveLevel("--estop-active", "HIGH").has_value());
}

TEST(SimGpio, OutputRecordsTimestampedLevelsUpToItsCapacity) {
  firmware_test::FakeClock clock;
  gpio_sim::SimOutput out(clock, 3);
  for (int i = 0; i < 5; ++i) {
    clock.now_ns += 100;
    EXPECT_EQ(out.Set(i % 2 == 0), GpioStatus::kOk);
  }
  ASSERT_EQ(out.log().size(), 3u);
  EXPECT_EQ(out.log()[0], (gpio_sim::LevelSample{1'000'000'100, true}));
  EXPECT_EQ(out.log()[2], (gpio_sim::LevelSample{1'000'000'300, true}));
  EXPECT_EQ(out.sets(), 5u);
  EXPECT_EQ(out.dropped(), 2u);
  out.set_fail(true);
  EXPECT_EQ(out.Set(false), GpioStatus::kError);
  EXPECT_EQ(out.sets(), 5u);
}

TEST(SimGpio, InputPlaysItsScriptOnTheClockAndCanBeForced) {
  firmware_test::FakeClock clock;
  clock.now_ns = 0;
  gpio_sim::SimInput in(clock, {{10, true}, {20, false}, {20, true}}, /*initial=*/false);
  bool level = true;
  ASSERT_EQ(in.Read(level), GpioStatus::kOk);
  EXPECT_FALSE(level);  // before the first step
  clock.now_ns = 10;
  in.Read(level);
  EXPECT_TRUE(level);
  clock.now_ns = 20;
  in.Read(level);
  EXPECT_TRUE(level) << "the last step at t = 20 wins";
  in.Force(false);
  in.Read(level);
  EXPECT_FALSE(level);
  in.ClearForce();
  in.Read(level);
  EXPECT_TRUE(level);
  in.set_fail(true);
  EXPECT_EQ(in.Read(level), GpioStatus::kError);
  EXPECT_EQ(in.reads(), 6u);
}

// This one is real: the development and CI machines have no GPIO chip (no CONFIG_GPIOLIB), so
// opening one must fail with a message naming the option, the chip and the cause.
TEST(GpiodLines, AMissingChipIsAClearErrorNamingIt) {
  struct stat st {};
  if (stat("/dev/gpiochip7", &st) == 0) GTEST_SKIP() << "this machine has /dev/gpiochip7";
  auto in = gpio_linux::GpiodInput::Open("--estop", {"gpiochip7", 3}, "palpa-test");
  ASSERT_FALSE(in.has_value());
  EXPECT_EQ(in.error(),
            "--estop gpiochip7:3: cannot open GPIO chip 'gpiochip7': No such file or directory (this system has no "
            "such chip; `gpiodetect` lists the chips)");
  auto out = gpio_linux::GpiodOutput::Open("--tick-gpio", {"/dev/gpiochip7", 1}, "palpa-test", false);
  ASSERT_FALSE(out.has_value());
  EXPECT_TRUE(
      out.error().starts_with("--tick-gpio /dev/gpiochip7:1: cannot open GPIO chip '/dev/gpiochip7': No such "
                              "file or directory"))
      << out.error();
}

}  // namespace
}  // namespace palpa::gpio
