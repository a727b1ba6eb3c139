#include "palpa/palpad/options.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include "palpa/palpad/config.h"

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

// Upload options (issue 7; docs/upload.md).
TEST(PalpadOptions, ListenNeedsAKeyAndParsesHostAndPort) {
  const auto o = Parse({"--field", "f", "--trace", "t", "--out", "o", "--listen", "127.0.0.1:0", "--key-file", "k",
                        "--max-blob", "1000000", "--swap-ramp-ms", "20"});
  ASSERT_TRUE(o.has_value()) << o.error();
  EXPECT_EQ(o->listen_host, "127.0.0.1");
  EXPECT_EQ(o->listen_port, 0);
  EXPECT_EQ(o->max_blob, 1000000);
  EXPECT_EQ(o->swap_ramp_ms, 20);
  const auto v6 = Parse({"--field", "f", "--trace", "t", "--out", "o", "--listen", "[::1]:7700", "--key-file", "k"});
  ASSERT_TRUE(v6.has_value()) << v6.error();
  EXPECT_EQ(v6->listen_host, "::1");
  EXPECT_EQ(v6->listen_port, 7700);
  const auto no_key = Parse({"--field", "f", "--trace", "t", "--out", "o", "--listen", "127.0.0.1:7700"});
  ASSERT_FALSE(no_key.has_value());
  EXPECT_NE(no_key.error().find("--listen needs --key-file"), std::string::npos) << no_key.error();
  EXPECT_FALSE(Parse({"--field", "f", "--trace", "t", "--out", "o", "--key-file", "k"}).has_value());
  EXPECT_FALSE(
      Parse({"--field", "f", "--trace", "t", "--out", "o", "--listen", "host", "--key-file", "k"}).has_value());
  EXPECT_FALSE(
      Parse({"--field", "f", "--trace", "t", "--out", "o", "--listen", "h:70000", "--key-file", "k"}).has_value());
  EXPECT_FALSE(
      Parse({"--field", "f", "--trace", "t", "--out", "o", "--listen", "h:1", "--key-file", "k", "--max-blob", "100"})
          .has_value());
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

// ---------------------------------------------------------------- runtime options and --config

std::string WriteFile(const std::string& name, const std::string& text) {
  const std::string path = ::testing::TempDir() + "/" + name;
  std::ofstream(path, std::ios::binary) << text;
  return path;
}

TEST(PalpadOptions, RuntimeDefaultsAndValues) {
  const auto d = Parse({"--field", "f", "--trace", "t", "--out", "o"});
  ASSERT_TRUE(d.has_value()) << d.error();
  EXPECT_EQ(d->cpu, -1);
  EXPECT_EQ(d->priority, 80);
  EXPECT_EQ(d->overrun_limit, 10);
  EXPECT_EQ(d->watchdog_ms, 50);
  EXPECT_FALSE(d->estop_line.has_value());
  EXPECT_FALSE(d->tick_line.has_value());

  const auto o = Parse({"--field",
                        "f",
                        "--trace",
                        "t",
                        "--out",
                        "o",
                        "--cpu",
                        "1",
                        "--priority",
                        "90",
                        "--estop",
                        "gpiochip0:17",
                        "--estop-active",
                        "low",
                        "--estop-debounce",
                        "3",
                        "--ramp-ms",
                        "250",
                        "--tick-gpio",
                        "/dev/gpiochip1:4",
                        "--overrun-limit",
                        "0",
                        "--watchdog-ms=20",
                        "--status",
                        "/run/palpa/status.json"});
  ASSERT_TRUE(o.has_value()) << o.error();
  EXPECT_EQ(o->cpu, 1);
  EXPECT_EQ(o->priority, 90);
  ASSERT_TRUE(o->estop_line.has_value());
  EXPECT_EQ(o->estop_line->chip, "gpiochip0");
  EXPECT_EQ(o->estop_line->line, 17u);
  EXPECT_FALSE(o->estop_active_high);
  EXPECT_EQ(o->estop_debounce, 3);
  EXPECT_EQ(o->ramp_ms, 250);
  ASSERT_TRUE(o->tick_line.has_value());
  EXPECT_EQ(o->tick_line->chip, "/dev/gpiochip1");
  EXPECT_EQ(o->overrun_limit, 0);
  EXPECT_EQ(o->watchdog_ms, 20);
  EXPECT_EQ(o->status_path, "/run/palpa/status.json");
}

TEST(PalpadOptions, EstopOnAGripButton) {
  const auto o = Parse({"--field", "f", "--trace", "t", "--out", "o", "--estop", "button:3", "--estop-debounce", "2"});
  ASSERT_TRUE(o.has_value()) << o.error();
  EXPECT_EQ(o->estop_button, 3);
  EXPECT_FALSE(o->estop_line.has_value());
  EXPECT_EQ(o->estop_debounce, 2);
  const auto none = Parse({"--field", "f", "--trace", "t", "--out", "o"});
  ASSERT_TRUE(none.has_value()) << none.error();
  EXPECT_EQ(none->estop_button, -1);
  const auto swap = Parse({"--field", "f", "--trace", "t", "--out", "o", "--swap-at", "1500:/tmp/a:b.palpa"});
  ASSERT_TRUE(swap.has_value()) << swap.error();
  EXPECT_EQ(swap->swap_at_tick, 1500u);
  EXPECT_EQ(swap->swap_at_field, "/tmp/a:b.palpa");  // the first colon splits: paths may hold colons
}

TEST(PalpadOptions, RuntimeErrors) {
  const std::vector<std::pair<std::vector<const char*>, const char*>> cases = {
      {{"--cpu", "-2"}, "--cpu must be a whole number"},
      {{"--cpu", "1.5"}, "--cpu must be a whole number"},
      {{"--priority", "0"}, "--priority must be a whole number in 1..99"},
      {{"--priority", "100"}, "--priority must be a whole number in 1..99"},
      {{"--estop", "gpiochip0"}, "--estop: 'gpiochip0' is not CHIP:LINE"},
      {{"--tick-gpio", "gpiochip0:x"}, "--tick-gpio: 'gpiochip0:x' has no line number"},
      {{"--estop", "c:1", "--estop-active", "up"}, "--estop-active: 'up' is not high or low"},
      {{"--estop-debounce", "3"}, "--estop-debounce needs --estop"},
      {{"--estop", "c:1", "--estop-debounce", "0"}, "--estop-debounce must be a whole number"},
      {{"--estop", "c:1", "--tick-gpio", "c:1"}, "name the same line"},
      {{"--watchdog-ms", "-1"}, "--watchdog-ms must be in 0..10000"},
      {{"--overrun-limit", "2.5"}, "--overrun-limit must be a whole number"},
      {{"--estop", "button:8"}, "--estop button:N needs a button bit N in 0..7"},
      {{"--estop", "button:"}, "--estop button:N needs a button bit N in 0..7"},
      {{"--estop", "button:12"}, "--estop button:N needs a button bit N in 0..7"},
      {{"--swap-at", "f.palpa"}, "--swap-at 'f.palpa': expected TICK:FIELD.palpa"},
      {{"--swap-at", "-1:f.palpa"}, "expected TICK:FIELD.palpa"},
      {{"--swap-at", "12:"}, "expected TICK:FIELD.palpa"},
  };
  for (const auto& [extra, message] : cases) {
    std::vector<const char*> args = {"--field", "f", "--trace", "t", "--out", "o"};
    args.insert(args.end(), extra.begin(), extra.end());
    const auto o = Parse(args);
    ASSERT_FALSE(o.has_value()) << message;
    EXPECT_NE(o.error().find(message), std::string::npos) << o.error();
  }
}

TEST(PalpadConfig, FileSetsOptionsAndTheCommandLineWins) {
  const std::string path = WriteFile("palpad_ok.toml",
                                     "# a comment\n"
                                     "device = \"sim\"\n"
                                     "field = \"/var/lib/palpa/field.palpa\"\n"
                                     "trace = \"t.csv\"\n"
                                     "out = \"o.csv\"\n"
                                     "rate = 2000\n"
                                     "max-force = 3.5\n"
                                     "fast = true\n"
                                     "estop = \"gpiochip0:17\"\n"
                                     "estop-active = \"low\"\n"
                                     "cpu = 1\n");
  const auto o = Parse({"--config", path.c_str(), "--rate", "500", "--out=cli.csv"});
  ASSERT_TRUE(o.has_value()) << o.error();
  EXPECT_EQ(o->field_path, "/var/lib/palpa/field.palpa");
  EXPECT_EQ(o->rate_hz, 500) << "the command line wins";
  EXPECT_EQ(o->out_path, "cli.csv");
  EXPECT_EQ(o->max_force_n, 3.5);
  EXPECT_TRUE(o->fast);
  EXPECT_EQ(o->cpu, 1);
  ASSERT_TRUE(o->estop_line.has_value());
  EXPECT_EQ(o->estop_line->line, 17u);
  EXPECT_FALSE(o->estop_active_high);
  // --check-config prints what was parsed as a config that parses back to the same options.
  const std::string again = WriteFile("palpad_again.toml", OptionsToml(*o));
  const auto p = Parse({"--config", again.c_str()});
  ASSERT_TRUE(p.has_value()) << p.error() << "\n" << OptionsToml(*o);
  EXPECT_EQ(OptionsToml(*p), OptionsToml(*o));
  EXPECT_EQ(p->rate_hz, 500);
}

TEST(PalpadConfig, BadFilesNameTheFileLineAndKey) {
  struct Case {
    const char* text;
    const char* message;
  };
  const Case cases[] = {
      {"field = \"f\"\nrat = 10\n", ":2: unknown key 'rat'"},
      {"field = \"f\"\n\nrate = \"fast\"\n", ":3: key 'rate': must be a number"},
      {"fast = 1\n", ":1: key 'fast': must be true or false"},
      {"field = 7\n", ":1: key 'field': must be a string"},
      {"[gpio]\nestop = \"c:1\"\n", ":1: unknown key 'gpio'"},
      {"field = \"f\"\nrate = = 3\n", ":2:"},  // TOML syntax error: file:line:column
      {"config = \"other.toml\"\n", ":1: unknown key 'config'"},
      {"field = \"\"\n", ":1: key 'field': must not be empty"},
  };
  for (const Case& c : cases) {
    const std::string path = WriteFile("palpad_bad.toml", c.text);
    const auto o = Parse({"--config", path.c_str(), "--trace", "t", "--out", "o"});
    ASSERT_FALSE(o.has_value()) << c.text;
    EXPECT_TRUE(o.error().starts_with(path + c.message)) << o.error();
  }
  const auto missing = Parse({"--config", "/nonexistent/palpad.toml"});
  ASSERT_FALSE(missing.has_value());
  EXPECT_EQ(missing.error(), "/nonexistent/palpad.toml: cannot read the config file: No such file or directory");
  // A value out of range from the file is refused like one from the command line.
  const std::string range =
      WriteFile("palpad_range.toml", "field = \"f\"\ntrace = \"t\"\nout = \"o\"\npriority = 120\n");
  const auto r = Parse({"--config", range.c_str()});
  ASSERT_FALSE(r.has_value());
  EXPECT_NE(r.error().find("--priority must be a whole number in 1..99"), std::string::npos) << r.error();
}

// The example config shipped in the .deb parses (with the paths it leaves to the user).
TEST(PalpadConfig, ShippedExampleParses) {
  const auto entries = ReadConfigFile(PALPA_EXAMPLE_CONFIG);
  ASSERT_TRUE(entries.has_value()) << entries.error();
  const auto o = Parse({"--config", PALPA_EXAMPLE_CONFIG});
  ASSERT_TRUE(o.has_value()) << o.error();
  EXPECT_EQ(o->device, "falcon");
  EXPECT_EQ(o->priority, 80);
}

}  // namespace
}  // namespace palpa::palpad
