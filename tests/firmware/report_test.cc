#include "palpa/servo/report.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

namespace palpa::servo {
namespace {

TEST(Report, CsvRowsRoundTripQ16Values) {
  LogRow row;
  row.t_s = 1.234;
  row.hip_m = {0.0123456789, -0.5, 1e-9};
  row.proxy_m = {0.01 + 3.0 / 65536 * 0.5e-3, 0, 0};
  row.force_n = {-1.5 + 1.0 / 65536, 8.0, 0.0};
  row.contact = true;
  std::FILE* f = std::tmpfile();
  ASSERT_NE(f, nullptr);
  ASSERT_TRUE(WriteCsv(f, std::span<const LogRow>(&row, 1)));
  std::rewind(f);
  char buf[512] = {};
  const std::size_t n = std::fread(buf, 1, sizeof buf - 1, f);
  std::fclose(f);
  const std::string text(buf, n);
  const auto nl = text.find('\n');
  EXPECT_EQ(text.substr(0, nl), "t_s,hip_x_m,hip_y_m,hip_z_m,proxy_x_m,proxy_y_m,proxy_z_m,fx_n,fy_n,fz_n,contact");
  double v[10];
  int contact = -1;
  ASSERT_EQ(std::sscanf(text.c_str() + nl + 1, "%lf,%lf,%lf,%lf,%lf,%lf,%lf,%lf,%lf,%lf,%d", &v[0], &v[1], &v[2], &v[3],
                        &v[4], &v[5], &v[6], &v[7], &v[8], &v[9], &contact),
            11);
  EXPECT_EQ(contact, 1);
  // One Q16.16 LSB of force is 1.5e-5 N, of position 7.6e-9 m at a 0.5 mm voxel.
  EXPECT_NEAR(v[7], row.force_n[0], 1e-7);
  EXPECT_EQ(std::lround((v[7] + 1.5) * 65536), 1);
  EXPECT_NEAR(v[4], row.proxy_m[0], 1e-12);
  EXPECT_NEAR(v[1], row.hip_m[0], 1e-12);
}

TEST(Report, SummaryTextAndJsonCarryEveryKey) {
  ServoSummary s;
  s.ticks = 10001;
  s.contact_ticks = 3000;
  s.max_force_n = 1.6;
  s.max_penetration_mm = 2.0;
  s.median_tick_ns = 900;
  s.p99_tick_ns = 2000;
  s.force_clamps = 3;
  s.device_errors = 0;
  s.rate_hz = 1000;
  s.fast = false;
  const std::string text = SummaryText(s);
  for (const char* line : {"ticks: 10001\n", "ticks in contact: 3000\n", "max force (N): 1.6000\n",
                           "max penetration (mm): 2.0000\n", "median tick (ns): 900\n", "p99 tick (ns): 2000\n",
                           "force clamps: 3\n", "device errors: 0\n", "mode: paced at 1000 Hz\n"}) {
    EXPECT_NE(text.find(line), std::string::npos) << line << " missing in\n" << text;
  }
  s.fast = true;
  EXPECT_NE(SummaryText(s).find("mode: fast\n"), std::string::npos);
  const std::string json = SummaryJson(s);
  for (const char* key : {"\"ticks\": 10001", "\"contact_ticks\": 3000", "\"max_force_n\": 1.6",
                          "\"max_penetration_mm\": 2", "\"median_tick_ns\": 900", "\"p99_tick_ns\": 2000",
                          "\"force_clamps\": 3", "\"device_errors\": 0", "\"rate_hz\": 1000", "\"fast\": true"}) {
    EXPECT_NE(json.find(key), std::string::npos) << key << " missing in " << json;
  }
  EXPECT_EQ(json.front(), '{');
}

}  // namespace
}  // namespace palpa::servo
