// OFF reader and area-uniform oriented-point sampler, against meshes whose geometry is known
// exactly (boxes, icospheres) and the bundled CGAL meshes.
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "palpa/field/point_io.h"
#include "palpa/mesh/sample.h"
#include "palpa/mesh/triangle_mesh.h"
#include "tools_test_util.h"

namespace palpa::tools_test {
namespace {

using mesh::TriangleMesh;

// First line of `palpa sample data/knot1.off -n 1000 --seed 1`: a change detector, so that a
// change of sampling algorithm (which changes every measured figure) is a visible decision.
constexpr const char* kKnotSeed1First =
    "-0.435955253 -0.164356289 0.0731109677 -0.870767464 -0.490338402 -0.0365003452";

TEST(ReadOff, BundledMeshesAreClosedAndOriented) {
  struct Case {
    const char* name;
    std::size_t v, f;
  };
  for (const Case& c :
       {Case{"sphere.off", 162, 320}, Case{"fandisk.off", 6475, 12946}, Case{"knot1.off", 3200, 6400}}) {
    auto m = mesh::ReadOff(DataFile(c.name));
    ASSERT_TRUE(m) << m.error().message;
    EXPECT_EQ(m->vertices.size(), c.v) << c.name;
    EXPECT_EQ(m->faces.size(), c.f) << c.name;
    EXPECT_TRUE(mesh::CheckClosedOriented(*m, c.name)) << c.name;
  }
  // sphere.off: vertices on the sphere of radius 0.5 (its first vertex is (0, 0.5, 0)).
  auto m = mesh::ReadOff(DataFile("sphere.off"));
  ASSERT_TRUE(m);
  for (const auto& v : m->vertices) EXPECT_NEAR(v.norm(), 0.5, 1e-3);
  EXPECT_TRUE(m->vertices[0].isApprox(Eigen::Vector3d(0, 0.5, 0)));
}

class OffErrors : public TempDirTest {};

TEST_F(OffErrors, NameTheFileAndLine) {
  const std::string tet_v = "0 0 0\n1 0 0\n0 1 0\n0 0 1\n";
  const std::string tet_f = "3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n";
  struct Case {
    std::string text, expect;
  };
  const Case cases[] = {
      {"PLY\n", "bad.off:1: expected the 'OFF' header, found 'PLY'"},
      {"OFF\n4 4\n" + tet_v + tet_f, ""},  // valid: two counts are allowed
      {"OFF\n# comment\n4 x 0\n", "bad.off:3: vertex and face counts must be integers"},
      {"OFF\n4 4 0\n0 0 0\n1 0 zero\n", "bad.off:4: 'zero' is not a number"},
      {"OFF\n4 4 0\n0 0 0\n1 0\n", "bad.off:4: vertex 1 needs 3 coordinates"},
      {"OFF\n4 4 0\n0 0 0\n1 0 inf\n", "bad.off:4: vertex 1 has a non-finite coordinate"},
      {"OFF\n4 4 0\n" + tet_v + "2 0 1\n", "bad.off:7: face 0 has 2 vertices; a face needs at least 3"},
      {"OFF\n4 4 0\n" + tet_v + "4 0 1 2\n", "bad.off:7: face 0 lists 3 of 4 vertex indices"},
      {"OFF\n4 4 0\n" + tet_v + "4 0 1 2 1\n", "bad.off:7: face 0 repeats a vertex"},
      {"4OFF\n", "bad.off:1: '4OFF' (homogeneous or n-dimensional OFF) is not read"},
      {"nOFF\n", "bad.off:1: 'nOFF' (homogeneous or n-dimensional OFF) is not read"},
      {"XOFF\n", "bad.off:1: expected the 'OFF' header, found 'XOFF'"},
      {"OFF BINARY\n", "bad.off:1: binary OFF is not read; write it as ASCII OFF"},
      {"OFF\n4 4 0\n" + tet_v + "300 0 1 2\n", "bad.off:7: face 0 has 300 vertices; palpa reads polygons of up to 256"},
      // A pentagram crosses itself: no triangulation keeps its sides.
      {"OFF\n5 4 0\n1 0 0\n0.309 0.951 0\n-0.809 0.588 0\n-0.809 -0.588 0\n0.309 -0.951 0\n5 0 2 4 1 3\n",
       "bad.off:8: face 0 is a polygon of 5 vertices that has no triangulation"},
      {"OFF\n4 4 0\n" + tet_v + "3 0 1 4\n", "bad.off:7: vertex index 4 is out of range [0, 4)"},
      {"OFF\n4 4 0\n" + tet_v + "3 0 1 1\n", "bad.off:7: face 0 repeats a vertex"},
      {"OFF\n4 4 0\n" + tet_v + "3 0 2 1\n", "bad.off:7: file ends after 1 of 4 faces"},
      {"OFF\n4 4 0\n" + tet_v + tet_f + "1 2 3\n", "bad.off:11: unexpected data after the last face"},
  };
  for (const Case& c : cases) {
    const std::string path = Write("bad.off", c.text);
    auto m = mesh::ReadOff(path);
    if (c.expect.empty()) {
      EXPECT_TRUE(m) << c.text << (m ? "" : m.error().message);
      continue;
    }
    ASSERT_FALSE(m) << c.text;
    EXPECT_NE(m.error().message.find(c.expect), std::string::npos) << m.error().message;
    EXPECT_EQ(m.error().message.rfind(path, 0), 0u) << m.error().message;
  }
  auto missing = mesh::ReadOff(Path("missing.off"));
  ASSERT_FALSE(missing);
  EXPECT_NE(missing.error().message.find("missing.off"), std::string::npos);
}

// Geomview's OFF variants (COFF, NOFF, STCNOFF) as CGAL's data ships them (cactus.off is COFF),
// and polygon faces: a unit cube of quads, two of them pentagons through a vertex on their shared
// side, reads as 3 + 2 + 3 + 3 × 2 = 14 triangles, none of zero area, that close the cube (volume
// 1, area 6), each triangle with its face's source line.
TEST_F(OffErrors, VariantsAndPolygonsRead) {
  const std::string cube_v = "0 0 0\n1 0 0\n1 1 0\n0 1 0\n0 0 1\n1 0 1\n1 1 1\n0 1 1\n0.5 0 0\n";
  const std::string cube_f = "5 0 3 2 1 8\n4 4 5 6 7\n5 0 8 1 5 4\n4 1 2 6 5\n4 2 3 7 6\n4 3 0 4 7\n";
  for (const std::string header : {"OFF", "COFF", "NOFF", "STCNOFF", "OFF 9 6 0"}) {
    std::string text = header + "\n";
    if (header.size() <= 7) text += "9 6 0\n";
    // Extra numbers after x y z (a colour, a normal, texture coordinates) are ignored.
    for (std::size_t start = 0; start < cube_v.size();) {
      const std::size_t end = cube_v.find('\n', start);
      text += cube_v.substr(start, end - start) + (header == "OFF" ? "" : " 0.25 0.5 0.75 1 0 0") + "\n";
      start = end + 1;
    }
    text += cube_f;
    auto m = mesh::ReadClosedMesh(Write("cube.off", text));
    ASSERT_TRUE(m) << header << ": " << m.error().message;
    EXPECT_EQ(m->faces.size(), 14u) << header;
    EXPECT_EQ(m->vertices.size(), 9u) << header;
    EXPECT_NEAR(mesh::SignedVolume(*m), 1.0, 1e-12) << header;
    EXPECT_NEAR(mesh::SurfaceArea(*m), 6.0, 1e-12) << header;
    for (std::size_t f = 0; f < m->faces.size(); ++f) EXPECT_GT(mesh::FaceNormal(*m, f).norm(), 0.5) << f;
    const int first_face_line = header.size() <= 7 ? 12 : 11;
    ASSERT_EQ(m->face_lines.size(), m->faces.size());
    EXPECT_EQ(m->face_lines[0], first_face_line) << header;
    EXPECT_EQ(m->face_lines[2], first_face_line) << header;      // the pentagon's last triangle
    EXPECT_EQ(m->face_lines[3], first_face_line + 1) << header;  // the top quad
  }
}

// CGAL's double-torus-example.off has concave quads. An L-shaped prism (hexagons for the ends,
// concave at (1, 1)) reads with its exact volume 3 and area 2 × 3 + 8 × 1; a fan from a corner
// would have covered the missing square twice over or not at all.
TEST_F(OffErrors, ConcavePolygonsKeepTheirShape) {
  std::string text = "OFF\n12 8 0\n";
  const double xy[6][2] = {{0, 0}, {2, 0}, {2, 1}, {1, 1}, {1, 2}, {0, 2}};
  for (const double z : {0.0, 1.0})
    for (const auto& p : xy) text += std::to_string(p[0]) + " " + std::to_string(p[1]) + " " + std::to_string(z) + "\n";
  text += "6 5 4 3 2 1 0\n6 6 7 8 9 10 11\n";  // bottom (clockwise from above: outward −z), top
  for (int i = 0; i < 6; ++i) {                // sides, outward
    const int j = (i + 1) % 6;
    text += "4 " + std::to_string(i) + " " + std::to_string(j) + " " + std::to_string(j + 6) + " " +
            std::to_string(i + 6) + "\n";
  }
  // Start each end at the concave corner too: a fan from there would be right by luck.
  for (const bool rotated : {false, true}) {
    std::string file = text;
    if (rotated) {
      file.replace(file.find("6 5 4 3 2 1 0"), 13, "6 3 2 1 0 5 4");
      file.replace(file.find("6 6 7 8 9 10 11"), 15, "6 8 9 10 11 6 7");
    }
    auto m = mesh::ReadClosedMesh(Write("ell.off", file));
    ASSERT_TRUE(m) << m.error().message;
    EXPECT_EQ(m->faces.size(), 2u * 4 + 6 * 2);
    EXPECT_NEAR(mesh::SignedVolume(*m), 3.0, 1e-9);
    EXPECT_NEAR(mesh::SurfaceArea(*m), 14.0, 1e-9);
  }
}

TEST_F(OffErrors, OpenOrInconsistentMeshesAreRefusedWithTheFaceLine) {
  TriangleMesh box = Box({0, 0, 0}, {1, 1, 1});
  TriangleMesh open = box;
  open.faces.pop_back();
  auto m = mesh::ReadClosedMesh(Write("open.off", ToOff(open)));
  ASSERT_FALSE(m);
  EXPECT_NE(m.error().message.find("open.off:"), std::string::npos) << m.error().message;
  EXPECT_NE(m.error().message.find("no opposite face: the mesh must be closed"), std::string::npos)
      << m.error().message;

  TriangleMesh twisted = box;
  std::swap(twisted.faces[5][1], twisted.faces[5][2]);  // one face wound against its neighbours
  m = mesh::ReadClosedMesh(Write("twisted.off", ToOff(twisted)));
  ASSERT_FALSE(m);
  EXPECT_NE(m.error().message.find("inconsistently oriented"), std::string::npos) << m.error().message;

  TriangleMesh flat = box;  // closed but zero volume: the top face pushed down onto the bottom
  for (auto& v : flat.vertices) v.z() = 0;
  EXPECT_FALSE(mesh::ReadClosedMesh(Write("flat.off", ToOff(flat))));
}

TEST(SignedVolume, BoxAndIcosphere) {
  TriangleMesh box = Box({-1, 0, 2}, {1, 3, 6});
  EXPECT_NEAR(mesh::SignedVolume(box), 2 * 3 * 4, 1e-12);
  EXPECT_NEAR(mesh::SurfaceArea(box), 2 * (2 * 3 + 3 * 4 + 2 * 4), 1e-12);
  EXPECT_FALSE(mesh::OrientOutward(box));
  for (auto& f : box.faces) std::swap(f[0], f[1]);
  EXPECT_NEAR(mesh::SignedVolume(box), -24, 1e-12);
  EXPECT_TRUE(mesh::OrientOutward(box));
  EXPECT_NEAR(mesh::SignedVolume(box), 24, 1e-12);
  // A fine icosphere's volume approaches 4/3 π r³ from below.
  const double v = mesh::SignedVolume(Icosphere(5, 2.0));
  EXPECT_LT(v, 4.0 / 3.0 * M_PI * 8);
  EXPECT_GT(v, 0.999 * 4.0 / 3.0 * M_PI * 8);
}

// On a box 1×2×3, every sample lies on a face with that face's outward normal, and the number of
// samples per face follows its area (2, 3 and 6, each twice: fractions 1/11, 1.5/11, 3/11).
TEST(SampleSurface, BoxFacesByAreaWithOutwardNormals) {
  const Eigen::Vector3d hi(1, 2, 3);
  TriangleMesh box = Box(Eigen::Vector3d::Zero(), hi);
  for (bool inward : {false, true}) {
    TriangleMesh m = box;
    if (inward)
      for (auto& f : m.faces) std::swap(f[1], f[2]);
    constexpr std::size_t kN = 110000;
    auto pts = mesh::SampleSurface(m, kN, 7);
    ASSERT_TRUE(pts) << pts.error().message;
    ASSERT_EQ(pts->positions.size(), kN);
    std::array<std::size_t, 3> per_axis{};  // samples on the two faces normal to each axis
    for (std::size_t s = 0; s < kN; ++s) {
      const Eigen::Vector3d& p = pts->positions[s];
      const Eigen::Vector3d& n = pts->normals[s];
      ASSERT_NEAR(n.norm(), 1.0, 1e-12);
      int axis = -1;
      for (int a = 0; a < 3; ++a)
        if (std::abs(std::abs(n[a]) - 1) < 1e-12) axis = a;
      ASSERT_GE(axis, 0) << n.transpose();
      // On the face the normal names: p[axis] = 0 with n = −e, or hi[axis] with n = +e.
      EXPECT_NEAR(p[axis], n[axis] > 0 ? hi[axis] : 0.0, 1e-12) << p.transpose() << " / " << n.transpose();
      EXPECT_TRUE((p.array() >= -1e-12).all() && (p.array() <= hi.array() + 1e-12).all());
      ++per_axis[static_cast<std::size_t>(axis)];
    }
    // Areas of the face pairs normal to x, y, z: 2·(2·3), 2·(1·3), 2·(1·2) out of 22.
    const double expect[3] = {12.0 / 22, 6.0 / 22, 4.0 / 22};
    for (std::size_t a = 0; a < 3; ++a) {
      const double sd = std::sqrt(expect[a] * (1 - expect[a]) / kN);
      EXPECT_NEAR(static_cast<double>(per_axis[a]) / kN, expect[a], 5 * sd) << "axis " << a;
    }
  }
}

// Within one face, uniform by area: a square face fanned into four unequal triangles from an
// off-centre point still gets samples uniformly over the square (quadrant counts ∝ area).
TEST(SampleSurface, UniformInsideUnequalTriangles) {
  TriangleMesh box = Box(Eigen::Vector3d::Zero(), Eigen::Vector3d::Ones());
  // Replace the top face (z = 1, triangles 2 and 3) with a fan around (0.8, 0.3, 1).
  box.faces.erase(box.faces.begin() + 2, box.faces.begin() + 4);
  box.vertices.emplace_back(0.8, 0.3, 1.0);
  const int c = 8;
  box.faces.push_back({4, 5, c});
  box.faces.push_back({5, 7, c});
  box.faces.push_back({7, 6, c});
  box.faces.push_back({6, 4, c});
  ASSERT_TRUE(mesh::CheckClosedOriented(box, "fan"));
  auto pts = mesh::SampleSurface(box, 120000, 3);
  ASSERT_TRUE(pts) << pts.error().message;
  std::size_t top = 0;
  std::size_t lower_left = 0;  // x < 0.5 and y < 0.5 on the top face
  for (std::size_t s = 0; s < pts->positions.size(); ++s) {
    const Eigen::Vector3d& p = pts->positions[s];
    if (pts->normals[s].z() > 0.5) {
      ++top;
      EXPECT_NEAR(p.z(), 1.0, 1e-12);
      if (p.x() < 0.5 && p.y() < 0.5) ++lower_left;
    }
  }
  const double n = static_cast<double>(top);
  EXPECT_NEAR(n / 120000, 1.0 / 6, 5 * std::sqrt(1.0 / 6 * 5 / 6 / 120000));
  EXPECT_NEAR(static_cast<double>(lower_left) / n, 0.25, 5 * std::sqrt(0.25 * 0.75 / n));
}

TEST(SampleSurface, DeterministicForASeed) {
  auto m = mesh::ReadClosedMesh(DataFile("knot1.off"));
  ASSERT_TRUE(m);
  auto a = mesh::SampleSurface(*m, 1000, 1);
  auto b = mesh::SampleSurface(*m, 1000, 1);
  auto c = mesh::SampleSurface(*m, 1000, 2);
  ASSERT_TRUE(a && b && c);
  EXPECT_EQ(mesh::ToXyzText(*a), mesh::ToXyzText(*b));
  EXPECT_NE(mesh::ToXyzText(*a), mesh::ToXyzText(*c));
  // The first sample of seed 1 is pinned, so that a change of algorithm is a visible decision.
  EXPECT_EQ(mesh::ToXyzText(*a).substr(0, mesh::ToXyzText(*a).find('\n')), std::string(kKnotSeed1First));
}

TEST(SampleSurface, RefusesZeroCount) {
  EXPECT_FALSE(mesh::SampleSurface(Box(Eigen::Vector3d::Zero(), Eigen::Vector3d::Ones()), 0, 1));
}

// Issue 20: virtual range scans. Points lie on the faces hit, with those faces' outward normals;
// the underside is never seen from the upper hemisphere; what another body hides from every view
// gets no sample; the count is at most -n; the seed decides; range noise moves points along rays.
TriangleMesh TwoBoxes() {
  TriangleMesh plate = Box({0, 0, 0}, {4, 4, 0.2});
  const TriangleMesh tower = Box({1.5, 1.5, 0.201}, {2.5, 2.5, 3});  // 1/1000 above the plate
  const int offset = static_cast<int>(plate.vertices.size());
  plate.vertices.insert(plate.vertices.end(), tower.vertices.begin(), tower.vertices.end());
  for (auto f : tower.faces) plate.faces.push_back({f[0] + offset, f[1] + offset, f[2] + offset});
  return plate;
}

TEST(RangeScan, PointsOnTheFacesHitNeverUnderneathNorInTheShadow) {
  const TriangleMesh m = TwoBoxes();
  ASSERT_TRUE(mesh::CheckClosedOriented(m, "two boxes"));
  auto scan = mesh::RangeScan(m, 20000, 6, 0.0, 1);
  ASSERT_TRUE(scan) << scan.error().message;
  // 40,000 rays over views that just hold the bounding sphere: the boxes fill about a quarter.
  ASSERT_GT(scan->positions.size(), 5000u);
  ASSERT_LE(scan->positions.size(), 20000u);
  std::size_t on_plate_top = 0;
  for (std::size_t i = 0; i < scan->positions.size(); ++i) {
    const Eigen::Vector3d& p = scan->positions[i];
    const Eigen::Vector3d& n = scan->normals[i];
    int axis = -1;
    for (int a = 0; a < 3; ++a)
      if (std::abs(std::abs(n[a]) - 1) < 1e-12) axis = a;
    ASSERT_GE(axis, 0) << n.transpose();
    EXPECT_GT(n.z(), -0.5) << "a point on an underside: " << p.transpose();
    // On a face of one of the boxes, the one its normal names.
    const bool tower = p.z() > 0.2005;
    const Eigen::Vector3d lo = tower ? Eigen::Vector3d(1.5, 1.5, 0.201) : Eigen::Vector3d(0, 0, 0);
    const Eigen::Vector3d hi = tower ? Eigen::Vector3d(2.5, 2.5, 3) : Eigen::Vector3d(4, 4, 0.2);
    EXPECT_NEAR(p[axis], n[axis] > 0 ? hi[axis] : lo[axis], 1e-9) << p.transpose();
    if (!tower && axis == 2) {
      ++on_plate_top;
      // Under the tower: a ray through the 0.001 gap meets the plate at more than 10 degrees of
      // elevation (else it grazes, and is dropped), so it reaches at most 0.006 under it.
      EXPECT_FALSE(p.x() > 1.6 && p.x() < 2.4 && p.y() > 1.6 && p.y() < 2.4) << "in the shadow: " << p.transpose();
    }
  }
  EXPECT_GT(on_plate_top, 1000u);
}

TEST(RangeScan, DeterministicForASeedAndRangeNoiseAlongTheRays) {
  const TriangleMesh box = Box({0, 0, 0}, {1, 2, 3});
  auto a = mesh::RangeScan(box, 5000, 3, 0.0, 7);
  auto b = mesh::RangeScan(box, 5000, 3, 0.0, 7);
  auto c = mesh::RangeScan(box, 5000, 3, 0.0, 8);
  ASSERT_TRUE(a && b && c);
  EXPECT_EQ(a->positions, b->positions);
  EXPECT_NE(a->positions, c->positions);
  // Noise of sigma along the rays: on the top face (z = 3, normal +z), z - 3 = noise * dir.z with
  // |dir.z| between sin 10 and 1 degrees' worth: its spread is below sigma and well above 0.
  const double sigma = 0.01;
  auto noisy = mesh::RangeScan(box, 5000, 3, sigma, 7);
  ASSERT_TRUE(noisy);
  double sum = 0, sum2 = 0;
  std::size_t top = 0;
  for (std::size_t i = 0; i < noisy->positions.size(); ++i) {
    if (noisy->normals[i].z() < 0.5) continue;
    const double dz = noisy->positions[i].z() - 3.0;
    sum += dz;
    sum2 += dz * dz;
    ++top;
  }
  ASSERT_GT(top, 500u);
  const double mean = sum / static_cast<double>(top);
  const double sd = std::sqrt(sum2 / static_cast<double>(top) - mean * mean);
  EXPECT_NEAR(mean, 0.0, 4 * sigma / std::sqrt(static_cast<double>(top)));
  EXPECT_LT(sd, sigma);
  EXPECT_GT(sd, 0.2 * sigma);
  EXPECT_FALSE(mesh::RangeScan(box, 0, 3, 0.0, 1));
  EXPECT_FALSE(mesh::RangeScan(box, 10, 0, 0.0, 1));
}

class SampleCli : public TempDirTest {};

TEST_F(SampleCli, WritesReadableDeterministicPointsOnTheSphere) {
  const std::string out1 = Path("a.xyz");
  const std::string out2 = Path("b.xyz");
  const Outcome r1 = Palpa("sample " + DataFile("sphere.off").string() + " -n 2000 -o " + out1 + " --seed 5");
  ASSERT_EQ(r1.code, 0) << r1.out;
  const Outcome r2 = Palpa("sample " + DataFile("sphere.off").string() + " -n 2000 -o " + out2 + " --seed 5 -q");
  ASSERT_EQ(r2.code, 0) << r2.out;
  EXPECT_TRUE(r2.out.empty()) << r2.out;
  EXPECT_EQ(ReadText(out1), ReadText(out2));
  auto pts = field::ReadPoints(out1);
  ASSERT_TRUE(pts) << pts.error().message;
  ASSERT_EQ(pts->positions.size(), 2000u);
  // sphere.off's vertices are on radius 0.5; its flat faces lie between the inscribed radius
  // (> 0.45 for this 320-face mesh) and 0.5, and normals point outward.
  for (std::size_t i = 0; i < pts->positions.size(); ++i) {
    EXPECT_LE(pts->positions[i].norm(), 0.5 + 1e-6);
    EXPECT_GT(pts->positions[i].norm(), 0.45);
    EXPECT_GT(pts->normals[i].dot(pts->positions[i].normalized()), 0.95);
  }
}

TEST_F(SampleCli, RangeScanIsAnOpenScanAndRangeNoiseNeedsViews) {
  const Outcome r = Palpa("sample " + DataFile("knot1.off").string() + " -n 3000 --views 4 -o " + Path("scan.xyz"));
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("range scan from 4 views on the upper hemisphere"), std::string::npos) << r.out;
  auto pts = field::ReadPoints(Path("scan.xyz"));
  ASSERT_TRUE(pts) << pts.error().message;
  EXPECT_LE(pts->positions.size(), 3000u);
  EXPECT_GT(pts->positions.size(), 1000u);
  const Outcome bad =
      Palpa("sample " + DataFile("knot1.off").string() + " -n 30 --range-noise 0.1 -o " + Path("x.xyz"));
  EXPECT_NE(bad.code, 0);
  EXPECT_FALSE(fs::exists(Path("x.xyz")));
}

TEST_F(SampleCli, BadMeshExitsTwoAndWritesNothing) {
  const std::string bad = Write("bad.off", "OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 one\n");
  const Outcome r = Palpa("sample " + bad + " -n 10 -o " + Path("out.xyz"));
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_NE(r.out.find("bad.off:6:"), std::string::npos) << r.out;
  EXPECT_FALSE(fs::exists(Path("out.xyz")));
  const Outcome zero = Palpa("sample " + DataFile("sphere.off").string() + " -n 0 -o " + Path("out.xyz"));
  EXPECT_EQ(zero.code, 2) << zero.out;
  EXPECT_FALSE(fs::exists(Path("out.xyz")));
  for (const auto& e : fs::directory_iterator(dir_)) EXPECT_EQ(e.path().extension(), ".off") << e.path();
}

}  // namespace
}  // namespace palpa::tools_test
