// The libgpiod backend against a scripted fake of libgpiod v1.6, linked in with
// -Wl,--wrap=gpiod_… (house style §8; docs/cross-rt.md §3): the real call sites,
// compiled against the real gpiod.h, call __wrap_gpiod_… here instead of the library. The fake
// knows one chip, "gpiochip0" (= /dev/gpiochip0) with 32 lines; line 5 is held by another program.

#include <gpiod.h>
#include <gtest/gtest.h>

#include <cerrno>
#include <cstring>
#include <string>
#include <vector>

#include "palpa/gpio_linux/gpiod_lines.h"

namespace {

// Opaque handles: addresses inside these arrays.
char g_chip_storage[1];
char g_line_storage[32];
gpiod_chip* const kChip = reinterpret_cast<gpiod_chip*>(g_chip_storage);

std::vector<std::string> g_calls;  // the call log, "name(args)"
int g_open_chips = 0;
int g_requested_lines = 0;
int g_line_value = 0;      // what get_value returns
bool g_get_fails = false;  // get_value returns -1 (EIO)
std::vector<int> g_set_values;

unsigned LineOf(gpiod_line* line) { return static_cast<unsigned>(reinterpret_cast<char*>(line) - g_line_storage); }

gpiod_chip* OpenNamed(const std::string& path) {
  if (path != "/dev/gpiochip0") {
    errno = ENOENT;
    return nullptr;
  }
  ++g_open_chips;
  return kChip;
}

}  // namespace

extern "C" {
gpiod_chip* __wrap_gpiod_chip_open_by_name(const char* name) {
  g_calls.push_back(std::string("open_by_name(") + name + ")");
  return OpenNamed(std::string("/dev/") + name);
}
gpiod_chip* __wrap_gpiod_chip_open(const char* path) {
  g_calls.push_back(std::string("open(") + path + ")");
  return OpenNamed(path);
}
unsigned int __wrap_gpiod_chip_num_lines(gpiod_chip*) { return 32; }
gpiod_line* __wrap_gpiod_chip_get_line(gpiod_chip* chip, unsigned int offset) {
  if (chip != kChip || offset >= 32) {
    errno = EINVAL;
    return nullptr;
  }
  return reinterpret_cast<gpiod_line*>(g_line_storage + offset);
}
int __wrap_gpiod_line_request_input(gpiod_line* line, const char* consumer) {
  g_calls.push_back("request_input(" + std::to_string(LineOf(line)) + "," + consumer + ")");
  if (LineOf(line) == 5) {
    errno = EBUSY;
    return -1;
  }
  ++g_requested_lines;
  return 0;
}
int __wrap_gpiod_line_request_output(gpiod_line* line, const char* consumer, int initial) {
  g_calls.push_back("request_output(" + std::to_string(LineOf(line)) + "," + consumer + "," + std::to_string(initial) +
                    ")");
  if (LineOf(line) == 5) {
    errno = EBUSY;
    return -1;
  }
  ++g_requested_lines;
  return 0;
}
int __wrap_gpiod_line_get_value(gpiod_line*) {
  if (g_get_fails) {
    errno = EIO;
    return -1;
  }
  return g_line_value;
}
int __wrap_gpiod_line_set_value(gpiod_line*, int value) {
  g_set_values.push_back(value);
  return 0;
}
void __wrap_gpiod_line_release(gpiod_line* line) {
  g_calls.push_back("release(" + std::to_string(LineOf(line)) + ")");
  --g_requested_lines;
}
void __wrap_gpiod_chip_close(gpiod_chip*) {
  g_calls.push_back("close");
  --g_open_chips;
}
}

namespace palpa::gpio_linux {
namespace {

void Reset() {
  g_calls.clear();
  g_open_chips = 0;
  g_requested_lines = 0;
  g_line_value = 0;
  g_get_fails = false;
  g_set_values.clear();
}

TEST(GpiodFake, InputReadsTheLineAndReleasesEverything) {
  Reset();
  {
    auto in = GpiodInput::Open("--estop", {"gpiochip0", 17}, "palpad-estop");
    ASSERT_TRUE(in.has_value()) << in.error();
    bool level = false;
    g_line_value = 1;
    ASSERT_EQ((*in)->Read(level), gpio::GpioStatus::kOk);
    EXPECT_TRUE(level);
    g_line_value = 0;
    (*in)->Read(level);
    EXPECT_FALSE(level);
    g_get_fails = true;
    EXPECT_EQ((*in)->Read(level), gpio::GpioStatus::kError);
    EXPECT_EQ(g_open_chips, 1);
    EXPECT_EQ(g_requested_lines, 1);
  }
  EXPECT_EQ(g_open_chips, 0);
  EXPECT_EQ(g_requested_lines, 0);
  EXPECT_EQ(g_calls, (std::vector<std::string>{"open_by_name(gpiochip0)", "request_input(17,palpad-estop)",
                                               "release(17)", "close"}));
}

TEST(GpiodFake, OutputStartsAtItsInitialLevelAndSetsValues) {
  Reset();
  {
    auto out = GpiodOutput::Open("--tick-gpio", {"/dev/gpiochip0", 3}, "palpad-tick", false);
    ASSERT_TRUE(out.has_value()) << out.error();
    for (const bool level : {true, false, true}) EXPECT_EQ((*out)->Set(level), gpio::GpioStatus::kOk);
  }
  EXPECT_EQ(g_set_values, (std::vector<int>{1, 0, 1}));
  EXPECT_EQ(g_calls, (std::vector<std::string>{"open(/dev/gpiochip0)", "request_output(3,palpad-tick,0)", "release(3)",
                                               "close"}));
  EXPECT_EQ(g_open_chips, 0);
}

TEST(GpiodFake, ErrorsNameOptionChipLineAndCauseAndLeakNothing) {
  Reset();
  auto missing = GpiodInput::Open("--estop", {"gpiochip9", 1}, "c");
  ASSERT_FALSE(missing.has_value());
  EXPECT_EQ(missing.error(),
            "--estop gpiochip9:1: cannot open GPIO chip 'gpiochip9': No such file or directory (this system has no "
            "such chip; `gpiodetect` lists the chips)");

  auto range = GpiodInput::Open("--estop", {"gpiochip0", 40}, "c");
  ASSERT_FALSE(range.has_value());
  EXPECT_EQ(range.error(), "--estop gpiochip0:40: GPIO chip 'gpiochip0' has lines 0..31 only");

  auto busy = GpiodOutput::Open("--tick-gpio", {"gpiochip0", 5}, "c", false);
  ASSERT_FALSE(busy.has_value());
  EXPECT_EQ(busy.error(),
            "--tick-gpio gpiochip0:5: cannot request line 5 as output: Device or resource busy (another program "
            "holds it; `gpioinfo` shows the consumer)");
  EXPECT_EQ(g_open_chips, 0) << "every failed open closed its chip";
  EXPECT_EQ(g_requested_lines, 0);
}

}  // namespace
}  // namespace palpa::gpio_linux
