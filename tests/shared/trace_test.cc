#include <gtest/gtest.h>

#include "palpa/trace/trace.h"

namespace palpa::trace {
namespace {

TEST(Trace, ParsesCommentsHeaderAndSamples) {
  auto t = ParseTrace("# made by hand\nt_s,x_m,y_m,z_m\n0,0,0,0\n\n0.5, 0.01 ,0,-0.02\n1,0.02,0,0\n", "hand.csv");
  ASSERT_TRUE(t.has_value()) << t.error().message;
  ASSERT_EQ(t->size(), 3u);
  EXPECT_DOUBLE_EQ((*t)[1].hip_m[2], -0.02);
}

TEST(Trace, ErrorsNameFileAndLine) {
  auto t = ParseTrace("0,0,0,0\n0.1,0,0\n", "bad.csv");
  ASSERT_FALSE(t.has_value());
  EXPECT_EQ(t.error().line, 2u);
  EXPECT_NE(t.error().message.find("bad.csv:2:"), std::string::npos) << t.error().message;

  t = ParseTrace("0,0,0,0\n0.1,0,nan,0\n", "nan.csv");
  ASSERT_FALSE(t.has_value());
  EXPECT_EQ(t.error().line, 2u);

  t = ParseTrace("0,0,0,0\n0.2,0,0,0\n0.1,0,0,0\n", "time.csv");
  ASSERT_FALSE(t.has_value());
  EXPECT_EQ(t.error().line, 3u);

  t = ParseTrace("0,0,0,0\n", "short.csv");
  ASSERT_FALSE(t.has_value());

  EXPECT_FALSE(ReadTrace("/nonexistent/trace.csv").has_value());
}

TEST(Trace, HipAtInterpolatesLinearlyAndClamps) {
  std::vector<TraceSample> s = {{0.0, {0, 0, 0}}, {1.0, {1, 2, 3}}, {3.0, {1, 2, -1}}};
  std::size_t hint = 0;
  auto a = HipAt(s, 0.25, hint);
  EXPECT_DOUBLE_EQ(a[0], 0.25);
  EXPECT_DOUBLE_EQ(a[1], 0.5);
  a = HipAt(s, 2.0, hint);
  EXPECT_DOUBLE_EQ(a[2], 1.0);
  a = HipAt(s, 9.0, hint);
  EXPECT_DOUBLE_EQ(a[2], -1.0);
  a = HipAt(s, -1.0, hint);  // going back resets the cursor
  EXPECT_DOUBLE_EQ(a[0], 0.0);
}

}  // namespace
}  // namespace palpa::trace
