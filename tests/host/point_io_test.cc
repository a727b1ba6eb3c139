#include <sys/resource.h>
#include <sys/stat.h>

#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "palpa/field/point_io.h"
#include "palpa/field/samples.h"
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

TEST(ReadPoints, TinyAndHugeNormalsComeOutUnitLength) {
  // |n|² of 1e-160 per axis is subnormal (bits lost) and of 1e200 overflows: both were wrong
  // before the reader scaled by the largest component (found by fuzz/ply_fuzz.cc).
  const TempFile file("extreme.xyz", std::string(kFourPoints) + "0 0 0 1e-160 1e-160 1e-160\n0 0 0 1e200 0 -1e200\n");
  const auto points = ReadPoints(file.path());
  ASSERT_TRUE(points.has_value()) << points.error().message;
  ASSERT_EQ(points->normals.size(), 6u);
  const double r3 = 1 / std::sqrt(3.0), r2 = 1 / std::sqrt(2.0);
  EXPECT_TRUE(points->normals[4].isApprox(Eigen::Vector3d(r3, r3, r3), 1e-15)) << points->normals[4].transpose();
  EXPECT_TRUE(points->normals[5].isApprox(Eigen::Vector3d(r2, 0, -r2), 1e-15)) << points->normals[5].transpose();
}

TEST(ReadPoints, FewerThanFourPoints) {
  const TempFile file("three.xyz", "0 0 0 1 0 0\n1 0 0 1 0 0\n0 1 0 1 0 0\n");
  const auto points = ReadPoints(file.path());
  ASSERT_FALSE(points.has_value());
  EXPECT_THAT(points.error().message, HasSubstr(file.path().string()));

  const TempFile empty("empty.xyz", "# nothing\n");
  EXPECT_FALSE(ReadPoints(empty.path()).has_value());
}

// PLY (docs/input-formats.md). The expected values are the ones written into each file.

constexpr char kAsciiPly[] =
    "ply\n"
    "format ascii 1.0\n"
    "comment written by hand\n"
    "element vertex 4\n"
    "property double x\n"
    "property double y\n"
    "property float z\n"
    "property uchar red\n"
    "property float nx\n"
    "property float ny\n"
    "property int nz\n"
    "element face 1\n"
    "property list uchar int vertex_indices\n"
    "end_header\n"
    "0 0 0 255 1 0 0\n"
    "1 0 0 7 0 2 0\n"
    "0 1 0.5 9 0 0 3\n"
    "0 0 1 0 -1 0 0\n"
    "3 0 1 2\n";

TEST(ReadPly, AsciiWithExtraPropertiesAndFaces) {
  const TempFile file("points.PLY", kAsciiPly);
  const auto points = ReadPoints(file.path());
  ASSERT_TRUE(points.has_value()) << points.error().message;
  ASSERT_EQ(points->positions.size(), 4u);
  EXPECT_EQ(points->positions[2], Eigen::Vector3d(0, 1, 0.5));
  EXPECT_EQ(points->normals[1], Eigen::Vector3d(0, 1, 0));  // (0, 2, 0) normalised
  EXPECT_EQ(points->normals[2], Eigen::Vector3d(0, 0, 1));  // int nz = 3
  EXPECT_EQ(points->normals[3], Eigen::Vector3d(-1, 0, 0));
}

// Appends `v` as PLY type T in the given byte order.
template <typename T>
void Put(std::string& out, T v, bool big) {
  unsigned char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  const bool swap = big == (std::endian::native == std::endian::little);
  for (std::size_t i = 0; i < sizeof(T); ++i) out.push_back(static_cast<char>(b[swap ? sizeof(T) - 1 - i : i]));
}

// A binary PLY of `points` (x y z float, a ushort, nx ny nz double), after an element that
// comes first and holds a list (skipped), and followed by faces (never read). Header bytes first.
std::string BinaryPly(const std::vector<std::array<double, 6>>& points, bool big, std::size_t& header_bytes) {
  std::string out = std::string("ply\nformat ") + (big ? "binary_big_endian" : "binary_little_endian") +
                    " 1.0\n"
                    "element material 2\n"
                    "property list uchar short ids\n"
                    "property int8 kind\n"
                    "element vertex " +
                    std::to_string(points.size()) +
                    "\n"
                    "property float32 x\nproperty float32 y\nproperty float32 z\n"
                    "property ushort quality\n"
                    "property float64 nx\nproperty float64 ny\nproperty float64 nz\n"
                    "element face 1\nproperty list uchar int vertex_indices\n"
                    "end_header\n";
  header_bytes = out.size();
  Put<std::uint8_t>(out, 2, big), Put<std::int16_t>(out, -5, big), Put<std::int16_t>(out, 300, big);
  Put<std::int8_t>(out, -1, big);
  Put<std::uint8_t>(out, 0, big), Put<std::int8_t>(out, 4, big);
  for (const auto& p : points) {
    for (std::size_t a = 0; a < 3; ++a) Put<float>(out, static_cast<float>(p[a]), big);
    Put<std::uint16_t>(out, 65535, big);
    for (std::size_t a = 3; a < 6; ++a) Put<double>(out, p[a], big);
  }
  Put<std::uint8_t>(out, 3, big);
  for (int v = 0; v < 3; ++v) Put<std::int32_t>(out, v, big);
  return out;
}

const std::vector<std::array<double, 6>> kBinaryPoints = {
    {0, 0, 0, 1, 0, 0}, {1.5, 0, 0, 0, 2, 0}, {0, -1, 0, 0, 0, 3}, {0, 0, 1, -1, 0, 0}, {0.25, 0.5, 2, 1, 1, 0}};

TEST(ReadPly, PclNormalNamesAreRead) {
  std::string text = kAsciiPly;
  for (const char* axis : {"x", "y", "z"}) {
    const std::string from = std::string("float n") + axis, to = std::string("float normal_") + axis;
    const std::size_t at = text.find(from);
    if (at != std::string::npos) text.replace(at, from.size(), to);
  }
  text.replace(text.find("int nz"), 6, "int normal_z");
  const TempFile file("pcl.ply", text);
  const auto points = ReadPoints(file.path());
  ASSERT_TRUE(points.has_value()) << points.error().message;
  ASSERT_EQ(points->normals.size(), 4u);
  EXPECT_EQ(points->normals[1], Eigen::Vector3d(0, 1, 0));
  EXPECT_EQ(points->normals[2], Eigen::Vector3d(0, 0, 1));
}

TEST(ReadPly, BinaryLittleAndBigEndianReadTheSamePoints) {
  for (const bool big : {false, true}) {
    std::size_t header = 0;
    const TempFile file(big ? "big.ply" : "little.ply", BinaryPly(kBinaryPoints, big, header));
    const auto points = ReadPoints(file.path());
    ASSERT_TRUE(points.has_value()) << points.error().message;
    ASSERT_EQ(points->positions.size(), kBinaryPoints.size());
    for (std::size_t i = 0; i < kBinaryPoints.size(); ++i) {
      const auto& p = kBinaryPoints[i];
      EXPECT_EQ(points->positions[i], Eigen::Vector3d(p[0], p[1], p[2])) << big << " " << i;
      EXPECT_TRUE(points->normals[i].isApprox(Eigen::Vector3d(p[3], p[4], p[5]).normalized(), 1e-15)) << i;
    }
  }
}

TEST(ReadPly, TruncatedBinaryNamesTheByte) {
  std::size_t header = 0;
  std::string bytes = BinaryPly(kBinaryPoints, false, header);
  // Materials: 1 + 4 + 1 and 1 + 0 + 1 bytes (8); a vertex 12 + 2 + 24 = 38 bytes. Cut vertex 3
  // inside its nz (byte 30 of the vertex): 2 of its 8 bytes are there.
  const std::size_t vertex3 = header + 8 + 3 * 38;
  bytes.resize(vertex3 + 32);
  const TempFile file("cut.ply", bytes);
  const auto points = ReadPoints(file.path());
  ASSERT_FALSE(points.has_value());
  EXPECT_EQ(points.error().message, file.path().string() + ": byte " + std::to_string(vertex3 + 30) +
                                        ": the file ends inside vertex 3 of 5 'nz' (2 of 8 bytes there)");
}

TEST(ReadPly, BadPointNamesTheVertex) {
  auto zero = kBinaryPoints;
  zero[2] = {0, 0, 0, 0, 0, 0};
  std::size_t header = 0;
  const TempFile file("zero.ply", BinaryPly(zero, true, header));
  const auto points = ReadPoints(file.path());
  ASSERT_FALSE(points.has_value());
  EXPECT_EQ(points.error().message, file.path().string() + ": byte " + std::to_string(header + 8 + 2 * 38) +
                                        " (vertex 2): normal has zero length");

  std::string ascii = kAsciiPly;
  ascii.replace(ascii.find("0 1 0.5"), 7, "0 nan 0.5");
  const TempFile nan("nan.ply", ascii);
  const auto b = ReadPoints(nan.path());
  ASSERT_FALSE(b.has_value());
  EXPECT_EQ(b.error().message, nan.path().string() + ":17 (vertex 2): position is not finite");
}

TEST(ReadPly, BadHeadersNameTheLine) {
  const auto error_of = [](std::string_view name, std::string text) {
    const TempFile file(name, text);
    const auto points = ReadPoints(file.path());
    EXPECT_FALSE(points.has_value()) << name;
    return points ? std::string() : points.error().message.substr(file.path().string().size());
  };
  std::string text = kAsciiPly;
  EXPECT_EQ(error_of("magic.ply", "PLY\n" + text.substr(4)), ":1: not a PLY file (the first line is not 'ply')");
  EXPECT_EQ(error_of("format.ply", "ply\nformat binary 1.0\n" + text.substr(21)),
            ":2: unknown format 'binary' (ascii, binary_little_endian or binary_big_endian)");
  std::string no_nz = text;
  no_nz.replace(no_nz.find("property int nz"), 15, "property int w");
  EXPECT_EQ(error_of("nz.ply", no_nz), ": the vertex element has no scalar nz (oriented points need x y z nx ny nz)");
  std::string bad_type = text;
  bad_type.replace(bad_type.find("uchar red"), 5, "byte");
  EXPECT_EQ(error_of("type.ply", bad_type), ":8: unknown property type 'byte'");
  EXPECT_EQ(error_of("open.ply", text.substr(0, text.find("end_header"))), ": the header has no 'end_header' line");
  std::string word = text;
  word.replace(word.find("1 0 0 7"), 7, "1 0 0 x");
  EXPECT_EQ(error_of("word.ply", word), ":16: 'x' is not a valid integer for vertex 1 of 4 'red'");
  EXPECT_EQ(error_of("short.ply", text.substr(0, text.find("0 0 1 0 -1"))),
            ":18: the file ends before vertex 3 of 4 'x'");
}

// Issue 18, finding 5: ascii PLY is read per line; a vertex line with a value too few or too many
// no longer shifts every later vertex.
TEST(ReadPly, AsciiLineWithTheWrongValueCountIsRefusedNamingTheLine) {
  const auto error_of = [](std::string_view name, std::string text) {
    const TempFile file(name, text);
    const auto points = ReadPoints(file.path());
    EXPECT_FALSE(points.has_value()) << name;
    return points ? std::string() : points.error().message.substr(file.path().string().size());
  };
  std::string five = kAsciiPly;  // vertex 1 (line 16) loses its nz
  five.replace(five.find("1 0 0 7 0 2 0\n"), 14, "1 0 0 7 0 2\n");
  EXPECT_EQ(error_of("five.ply", five),
            ":16: the line ends before vertex 1 of 4 'nz' (6 values on the line, more expected)");
  std::string seven = kAsciiPly;  // vertex 1 gains an eighth value
  seven.replace(seven.find("1 0 0 7 0 2 0\n"), 14, "1 0 0 7 0 2 0 5\n");
  EXPECT_EQ(error_of("seven.ply", seven),
            ":16: vertex 1 of 4 has more values than the header's properties (8 on the line, 7 expected)");
}

// Finding 5: a count of 2^64 or more read as 0 (from_chars' overflow went unchecked); a count far
// beyond what the file holds is refused before the body is read.
TEST(ReadPly, ElementCountsBeyondTwoToTheSixtyFourOrTheFileAreRefused) {
  std::string huge = kAsciiPly;
  huge.replace(huge.find("element vertex 4"), 16, "element vertex 18446744073709551616");
  const TempFile a("huge.ply", huge);
  const auto ra = ReadPoints(a.path());
  ASSERT_FALSE(ra.has_value());
  EXPECT_EQ(ra.error().message, a.path().string() + ":4: element count '18446744073709551616' is not below 2^64");
  std::string absurd = kAsciiPly;
  absurd.replace(absurd.find("element vertex 4"), 16, "element vertex 18446744073709551615");
  const TempFile b("absurd.ply", absurd);
  const auto rb = ReadPoints(b.path());
  ASSERT_FALSE(rb.has_value());
  EXPECT_THAT(rb.error().message,
              HasSubstr("declares 18446744073709551615 'vertex' elements, but the 69 bytes after it hold at most 5"));
}

// Findings 6 and 8: a file that is not a regular file is refused before any read; a line or header
// without end is refused after a bounded read; messages quote input bytes escaped and cut.
TEST(ReadPoints, NonRegularFilesAreRefusedAtOnce) {
  const std::filesystem::path dir = std::filesystem::path(::testing::TempDir()) / "nonregular";
  std::filesystem::create_directories(dir);
  const std::filesystem::path fifo = dir / "fifo.xyz";
  std::filesystem::remove(fifo);
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  const auto f = ReadPoints(fifo);  // used to block in open() for ever
  ASSERT_FALSE(f.has_value());
  EXPECT_THAT(f.error().message, HasSubstr("fifo.xyz: is a FIFO, not a regular file"));
  std::filesystem::remove(fifo);
  std::filesystem::create_symlink("/dev/zero", dir / "zero.ply");
  const auto z = ReadPoints(dir / "zero.ply");
  ASSERT_FALSE(z.has_value());
  EXPECT_THAT(z.error().message, HasSubstr("zero.ply: is a character device, not a regular file"));
  std::filesystem::remove_all(dir);
}

long MaxRssKiB() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_maxrss;
}

TEST(ReadPoints, HugeFilesAreRefusedAfterABoundedRead) {
  // 2 GiB of NULs (sparse: no disk used). The old reader held it all (6.3 GB), then put the whole
  // file in its message.
  const long rss0 = MaxRssKiB();
  for (const char* name : {"nul.xyz", "nul.ply", "comments.ply"}) {
    const std::filesystem::path path = std::filesystem::path(::testing::TempDir()) / name;
    {
      std::ofstream out(path, std::ios::binary);
      if (std::string_view(name) == "comments.ply") {
        out << "ply\nformat ascii 1.0\n";
        for (int i = 0; i < 10000; ++i) out << "comment no end of header in sight\n";
      }
    }
    if (std::string_view(name) != "comments.ply") std::filesystem::resize_file(path, std::uint64_t{2} << 30);
    const auto r = ReadPoints(path);
    std::filesystem::remove(path);
    ASSERT_FALSE(r.has_value()) << name;
    EXPECT_LT(r.error().message.size(), 400U) << name;
    if (std::string_view(name) == "nul.xyz") {
      EXPECT_EQ(r.error().message,
                path.string() + ":1: the line is longer than 4096 bytes (a point is one line of six numbers)");
    }
    if (std::string_view(name) == "nul.ply") {
      EXPECT_EQ(r.error().message, path.string() + ": the PLY file holds 2147483648 bytes; at most 1 GiB are read");
    }
    if (std::string_view(name) == "comments.ply") {
      EXPECT_EQ(r.error().message, path.string() + ": the header has no 'end_header' line in its first 64 KiB");
    }
  }
  EXPECT_LT(MaxRssKiB() - rss0, 64 * 1024);  // bounded: well under 64 MiB more than before
}

TEST(ReadPoints, MessagesEscapeAndCutInputBytes) {
  const TempFile esc("esc.xyz", "0 0 0 0 0 1\n1 \x1b]0;owned\x07 0 0 0 1\n");
  const auto e = ReadPoints(esc.path());
  ASSERT_FALSE(e.has_value());
  EXPECT_EQ(e.error().message, esc.path().string() + ":2: '\\x1b]0;owned\\x07' is not a number");
  std::string digits = kAsciiPly;
  digits.replace(digits.find("1 0 0 7"), 1, std::string(100000, '9') + "x");
  const TempFile big("digits.ply", digits);
  const auto d = ReadPoints(big.path());
  ASSERT_FALSE(d.has_value());
  EXPECT_EQ(d.error().message,
            big.path().string() + ":16: '" + std::string(64, '9') + "…' is not a valid number for vertex 1 of 4 'x'");
}

TEST(ReadPly, BundledKittenAsBinaryPlyEqualsTheXyz) {
  const auto xyz = ReadPoints(DataFile("kitten.xyz"));
  ASSERT_TRUE(xyz.has_value()) << xyz.error().message;
  std::string ply = "ply\nformat binary_little_endian 1.0\nelement vertex " + std::to_string(xyz->positions.size()) +
                    "\nproperty double x\nproperty double y\nproperty double z\n"
                    "property double nx\nproperty double ny\nproperty double nz\nend_header\n";
  for (std::size_t i = 0; i < xyz->positions.size(); ++i) {
    for (int a = 0; a < 3; ++a) Put<double>(ply, xyz->positions[i][a], false);
    for (int a = 0; a < 3; ++a) Put<double>(ply, xyz->normals[i][a], false);
  }
  const TempFile file("kitten.ply", ply);
  const auto read = ReadPoints(file.path());
  ASSERT_TRUE(read.has_value()) << read.error().message;
  EXPECT_EQ(read->positions, xyz->positions);
  ASSERT_EQ(read->normals.size(), xyz->normals.size());
  for (std::size_t i = 0; i < read->normals.size(); ++i) {
    EXPECT_EQ(read->normals[i], xyz->normals[i] / xyz->normals[i].norm()) << i;  // normalised once more
  }
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

// Issue 20: degenerate samples are kept by the reader on request and dropped before the build,
// counted, the first of each kind named by its line (.xyz) or vertex (PLY).
TEST(DropDegenerateSamples, BadNormalsAndExactDuplicatesAreDroppedAndNamed) {
  const TempFile file("scan.xyz",
                      "0 0 0 1 0 0\n"
                      "1 0 0 0 0 0\n"  // line 2: zero normal
                      "# comment\n"
                      "0 1 0 0 0 3\n"    // line 4
                      "0 0 1 inf 0 0\n"  // line 5: non-finite normal
                      "0 1 0 0 1 0\n"    // line 6: duplicate of line 4 (another normal)
                      "0 0 2 0 0 1\n"
                      "0 0 0 1 0 0\n"  // line 8: duplicate of line 1
                      "2 0 0 1 0 0\n");
  EXPECT_FALSE(ReadPoints(file.path()).has_value());  // the default stays strict
  auto points = ReadPoints(file.path(), ReadOptions{.keep_bad_normals = true});
  ASSERT_TRUE(points.has_value()) << points.error().message;
  ASSERT_EQ(points->positions.size(), 8u);
  EXPECT_EQ(points->normals[1], Eigen::Vector3d::Zero());
  EXPECT_EQ(points->normals[3], Eigen::Vector3d::Zero());
  EXPECT_EQ(points->lines, (std::vector<std::size_t>{1, 2, 4, 5, 6, 7, 8, 9}));
  const DroppedSamples d = DropDegenerateSamples(*points, "scan.xyz");
  EXPECT_EQ(d.bad_normals, 2u);
  EXPECT_EQ(d.duplicates, 2u);
  EXPECT_EQ(d.kept, 4u);
  EXPECT_EQ(d.Describe(),
            "2 samples with a zero-length or non-finite normal (first: scan.xyz:2) and 2 exact duplicates (first: "
            "scan.xyz:6, the position of scan.xyz:4)");
  EXPECT_EQ(points->positions, (std::vector<Eigen::Vector3d>{{0, 0, 0}, {0, 1, 0}, {0, 0, 2}, {2, 0, 0}}));
  EXPECT_EQ(points->normals, (std::vector<Eigen::Vector3d>{{1, 0, 0}, {0, 0, 1}, {0, 0, 1}, {1, 0, 0}}));
  EXPECT_EQ(points->lines, (std::vector<std::size_t>{1, 4, 7, 9}));
  // A clean set is untouched.
  const DroppedSamples none = DropDegenerateSamples(*points, "scan.xyz");
  EXPECT_EQ(none.Total(), 0u);
  EXPECT_EQ(none.Describe(), "");
  EXPECT_EQ(points->positions.size(), 4u);
}

TEST(DropDegenerateSamples, PlyPointsAreNamedByVertex) {
  const TempFile file("scan.ply",
                      "ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\n"
                      "property float z\nproperty float nx\nproperty float ny\nproperty float nz\nend_header\n"
                      "0 0 0 1 0 0\n1 0 0 1 0 0\n0 1 0 0 0 0\n0 0 1 0 0 1\n1 1 1 1 0 0\n");
  EXPECT_FALSE(ReadPoints(file.path()).has_value());
  auto points = ReadPoints(file.path(), ReadOptions{.keep_bad_normals = true});
  ASSERT_TRUE(points.has_value()) << points.error().message;
  const DroppedSamples d = DropDegenerateSamples(*points, "scan.ply");
  EXPECT_EQ(d.Describe(), "1 sample with a zero-length or non-finite normal (first: scan.ply: vertex 2)");
  EXPECT_EQ(points->positions.size(), 4u);
}

}  // namespace
}  // namespace palpa::field
