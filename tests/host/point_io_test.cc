#include <cmath>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "palpa/field/point_io.h"
#include "palpa/field/transform.h"
#include "test_util.h"

namespace palpa::field {
namespace {

using testing::DataFile;
using ::testing::HasSubstr;
using testing::TempFile;

constexpr char kFourPoints[] =
    "0 0 0 1 0 0\n"
    "1 0 0 0 2 0\n"
    "0 1 0 0 0 3\n"
    "0 0 1 -1 0 0\n";

TEST(ReadPoints, GoodFileNormalisesNormals) {
  const TempFile file("good.xyz", kFourPoints);
  const auto points = ReadPoints(file.path());
  ASSERT_TRUE(points.has_value()) << points.error().message;
  ASSERT_EQ(points->positions.size(), 4u);
  ASSERT_EQ(points->normals.size(), 4u);
  EXPECT_EQ(points->positions[1], Eigen::Vector3d(1, 0, 0));
  EXPECT_EQ(points->normals[1], Eigen::Vector3d(0, 1, 0));  // (0, 2, 0) normalised
  EXPECT_EQ(points->normals[2], Eigen::Vector3d(0, 0, 1));
  for (const auto& n : points->normals) EXPECT_NEAR(n.norm(), 1.0, 1e-15);
}

TEST(ReadPoints, CommentsBlankLinesAndWhitespace) {
  const TempFile file("comments.PWN",
                      "# header comment\n"
                      "\n"
                      "   \t\n"
                      "0 0 0 1 0 0   # trailing comment\n"
                      "\t1   0 0  0 1 0 \t \r\n"
                      "0 1 0 0 0 1\r\n"
                      "+0 0 1e0 -1 0 0");  // no final newline, leading '+'
  const auto points = ReadPoints(file.path());
  ASSERT_TRUE(points.has_value()) << points.error().message;
  ASSERT_EQ(points->positions.size(), 4u);
  EXPECT_EQ(points->positions[3], Eigen::Vector3d(0, 0, 1));
  EXPECT_EQ(points->normals[3], Eigen::Vector3d(-1, 0, 0));
}

TEST(ReadPoints, BundledFilesParse) {
  // sphere_20k_normal.xyz has a trailing space on every line.
  const auto sphere = ReadPoints(DataFile("sphere_20k_normal.xyz"));
  ASSERT_TRUE(sphere.has_value()) << sphere.error().message;
  EXPECT_EQ(sphere->positions.size(), 21000u);
  // First line: "-0.708819 0.473145 0.631157 -0.339610 0.062178 0.938509 ".
  EXPECT_EQ(sphere->positions.front(), Eigen::Vector3d(-0.708819, 0.473145, 0.631157));
  EXPECT_TRUE(sphere->normals.front().isApprox(Eigen::Vector3d(-0.339610, 0.062178, 0.938509).normalized(), 1e-15));

  const auto kitten = ReadPoints(DataFile("kitten.xyz"));
  ASSERT_TRUE(kitten.has_value()) << kitten.error().message;
  EXPECT_EQ(kitten->positions.size(), 5210u);

  const auto sphere926 = ReadPoints(DataFile("sphere926.pwn"));
  ASSERT_TRUE(sphere926.has_value()) << sphere926.error().message;
  EXPECT_EQ(sphere926->positions.size(), 926u);
}

TEST(ReadPoints, MissingFile) {
  const auto points = ReadPoints("/nonexistent/dir/none.xyz");
  ASSERT_FALSE(points.has_value());
  EXPECT_THAT(points.error().message, HasSubstr("/nonexistent/dir/none.xyz"));
}

TEST(ReadPoints, UnknownExtension) {
  const TempFile file("points.txt", kFourPoints);
  const auto points = ReadPoints(file.path());
  ASSERT_FALSE(points.has_value());
  EXPECT_THAT(points.error().message, HasSubstr(file.path().string()));
  EXPECT_THAT(points.error().message, HasSubstr("extension"));
}

TEST(ReadPoints, WrongNumberCountNamesFileAndLine) {
  const TempFile file("short_line.xyz", std::string(kFourPoints) + "# c\n\n1 2 3 4 5\n");
  const auto points = ReadPoints(file.path());
  ASSERT_FALSE(points.has_value());
  EXPECT_EQ(points.error().message, file.path().string() + ":7: expected 6 numbers, found 5");

  const TempFile file7("long_line.pwn", "0 0 0 1 0 0 9\n");
  const auto seven = ReadPoints(file7.path());
  ASSERT_FALSE(seven.has_value());
  EXPECT_EQ(seven.error().message, file7.path().string() + ":1: expected 6 numbers, found 7");
}

TEST(ReadPoints, NotANumber) {
  const TempFile file("garbage.xyz", "0 0 0 1 0 0\n0 0 x 1 0 0\n");
  const auto points = ReadPoints(file.path());
  ASSERT_FALSE(points.has_value());
  EXPECT_THAT(points.error().message, HasSubstr(file.path().string() + ":2:"));
}

TEST(ReadPoints, NanPositionAndNormal) {
  const TempFile pos("nan_pos.xyz", std::string(kFourPoints) + "nan 0 0 1 0 0\n");
  const auto a = ReadPoints(pos.path());
  ASSERT_FALSE(a.has_value());
  EXPECT_THAT(a.error().message, HasSubstr(pos.path().string() + ":5:"));

  const TempFile nrm("nan_normal.xyz", "0 0 0 1 nan 0\n" + std::string(kFourPoints));
  const auto b = ReadPoints(nrm.path());
  ASSERT_FALSE(b.has_value());
  EXPECT_THAT(b.error().message, HasSubstr(nrm.path().string() + ":1:"));

  const TempFile inf("inf_pos.xyz", "0 inf 0 1 0 0\n" + std::string(kFourPoints));
  EXPECT_FALSE(ReadPoints(inf.path()).has_value());
}

TEST(ReadPoints, ZeroNormal) {
  const TempFile file("zero_normal.xyz", std::string(kFourPoints) + "1 1 1 0 0 0\n");
  const auto points = ReadPoints(file.path());
  ASSERT_FALSE(points.has_value());
  EXPECT_THAT(points.error().message, HasSubstr(file.path().string() + ":5:"));
  EXPECT_THAT(points.error().message, HasSubstr("zero"));
}

TEST(ReadPoints, FewerThanFourPoints) {
  const TempFile file("three.xyz", "0 0 0 1 0 0\n1 0 0 1 0 0\n0 1 0 1 0 0\n");
  const auto points = ReadPoints(file.path());
  ASSERT_FALSE(points.has_value());
  EXPECT_THAT(points.error().message, HasSubstr(file.path().string()));

  const TempFile empty("empty.xyz", "# nothing\n");
  EXPECT_FALSE(ReadPoints(empty.path()).has_value());
}

TEST(Transform, FitsLongestSideAndCentres) {
  PointSet points;
  points.positions = {{1, 2, 3}, {5, 2, 3}, {1, 4, 3}, {1, 2, 4}};  // bbox [1,5]x[2,4]x[3,4]
  points.normals.assign(4, Eigen::Vector3d(0, 0, 1));
  const Transform t = FitTransform(points, 0.06);
  EXPECT_DOUBLE_EQ(t.scale, 0.06 / 4.0);
  const PointSet device = ApplyTransform(t, points);
  EXPECT_TRUE(device.positions[0].isApprox(Eigen::Vector3d(-0.03, -0.015, -0.0075), 1e-12));
  EXPECT_TRUE(device.positions[1].isApprox(Eigen::Vector3d(0.03, -0.015, -0.0075), 1e-12));
  EXPECT_EQ(device.normals, points.normals);
}

}  // namespace
}  // namespace palpa::field
