#include "palpa/palpad/options.h"

#include <gtest/gtest.h>

#include <vector>

namespace palpa::palpad {
namespace {

std::expected<Options, std::string> Parse(std::vector<const char*> args) { return ParseArgs(args); }

TEST(PalpadOptions, DefaultsAndRequiredOptions) {
  const auto o = Parse({"--device", "sim", "--field", "f.palpa", "--trace", "t.csv", "--out", "o.csv"});
  ASSERT_TRUE(o.has_value()) << o.error();
  EXPECT_EQ(o->device, "sim");
  EXPECT_EQ(o->field_path, "f.palpa");
  EXPECT_EQ(o->trace_path, "t.csv");
  EXPECT_EQ(o->out_path, "o.csv");
  EXPECT_FALSE(o->fast);
  EXPECT_EQ(o->rate_hz, 1000);
  EXPECT_EQ(o->k_n_per_m, 800);
  EXPECT_EQ(o->max_force_n, 8);
  EXPECT_TRUE(o->summary_json_path.empty());
}

TEST(PalpadOptions, SimulatedDeviceIsTheDefault) {
  const auto o = Parse({"--field", "f.palpa", "--trace", "t.csv", "--out", "o.csv"});
  ASSERT_TRUE(o.has_value()) << o.error();
  EXPECT_EQ(o->device, "sim");
  EXPECT_FALSE(Parse({"--field", "f.palpa", "--out", "o.csv"}).has_value());  // sim needs --trace
}

TEST(PalpadOptions, AllOptionsBothForms) {
  const auto o = Parse({"--device=sim", "--field", "f", "--trace=t", "--out", "o", "--fast", "--rate", "250.5",
                        "--k=1200", "--max-force", "3", "--summary-json", "s.json"});
  ASSERT_TRUE(o.has_value()) << o.error();
  EXPECT_TRUE(o->fast);
  EXPECT_EQ(o->rate_hz, 250.5);
  EXPECT_EQ(o->k_n_per_m, 1200);
  EXPECT_EQ(o->max_force_n, 3);
  EXPECT_EQ(o->summary_json_path, "s.json");
}

TEST(PalpadOptions, Errors) {
  const std::vector<std::pair<std::vector<const char*>, const char*>> cases = {
      {{"--device", "sim", "--field", "f", "--trace", "t", "--out", "o", "--bogus"}, "unknown option"},
      {{"--device", "sim", "--field", "f", "--trace", "t", "--out"}, "needs a value"},
      {{"--device", "sim", "--field", "f", "--trace", "t", "--out", "o", "--rate", "0"}, "1..10000"},
      {{"--device", "sim", "--field", "f", "--trace", "t", "--out", "o", "--rate", "10001"}, "1..10000"},
      {{"--device", "sim", "--field", "f", "--trace", "t", "--out", "o", "--rate", "1k"}, "not a finite number"},
      {{"--device", "sim", "--field", "f", "--trace", "t", "--out", "o", "--k", "nan"}, "not a finite number"},
      {{"--device", "sim", "--field", "f", "--trace", "t", "--out", "o", "--fast=1"}, "takes no value"},
      {{"--device", "sim", "--field", "f", "--field", "g", "--trace", "t", "--out", "o"}, "given twice"},
      {{"--device", "usb", "--field", "f", "--trace", "t", "--out", "o"}, "unknown device"},
      {{"--device", "sim", "--trace", "t", "--out", "o"}, "--field is required"},
      {{"--device", "sim", "--field", "f", "--out", "o"}, "--trace is required"},
      {{"--device", "sim", "--field", "f", "--trace", "t"}, "--out is required"},
      {{"--device", "sim", "stray", "--field", "f", "--trace", "t", "--out", "o"}, "unexpected argument"},
  };
  for (const auto& [args, message] : cases) {
    const auto o = Parse(args);
    ASSERT_FALSE(o.has_value()) << message;
    EXPECT_NE(o.error().find(message), std::string::npos) << o.error();
  }
}

TEST(PalpadOptions, FalconParsesWithoutTraceAndHelpWins) {
  EXPECT_TRUE(Parse({"--device", "falcon", "--field", "f", "--out", "o"}).has_value());
  const auto help = Parse({"--bogus", "--help"});
  ASSERT_TRUE(help.has_value());
  EXPECT_TRUE(help->help);
  EXPECT_NE(std::string(Usage()).find("--device sim"), std::string::npos);
}

}  // namespace
}  // namespace palpa::palpad
