// palpa mesh: the zero iso-surface of analytic fields (sphere, torus) against their closed forms,
// closedness, topology (Euler characteristic), normals, and the PLY/OBJ writers.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <set>
#include <string>

#include "field_fixtures.h"
#include "palpa/blob/blob.h"
#include "palpa/mesh/field_file.h"
#include "palpa/mesh/iso_surface.h"
#include "tools_test_util.h"

namespace palpa::tools_test {
namespace {

// V − E + F for a closed triangle mesh (E = 3F/2): 2 for a sphere, 0 for a torus.
long EulerCharacteristic(const mesh::TriangleMesh& m) {
  std::set<std::pair<int, int>> edges;
  for (const auto& f : m.faces)
    for (std::size_t a = 0; a < 3; ++a) edges.insert(std::minmax(f[a], f[(a + 1) % 3]));
  return static_cast<long>(m.vertices.size()) - static_cast<long>(edges.size()) + static_cast<long>(m.faces.size());
}

TEST(ExtractZeroSurface, SphereVerticesOnTheRadiusClosedAndOutward) {
  const BlobSpec s = SphereSpec();
  const auto bytes = MakeBlob(s, [&](const Eigen::Vector3d& x) { return SphereSdfVoxels(s, x); });
  auto m = mesh::ExtractZeroSurface(View(bytes));
  ASSERT_TRUE(m) << m.error().message;
  const double r_m = s.fit_scale * kSphereRadiusModel;
  ASSERT_GT(m->vertices.size(), 1000u);
  ASSERT_EQ(m->normals.size(), m->vertices.size());
  for (std::size_t v = 0; v < m->vertices.size(); ++v) {
    const Eigen::Vector3d d = m->vertices[v] - s.fit_offset_m;
    ASSERT_LE(std::abs(d.norm() - r_m), 0.1 * s.voxel_m) << v;
    ASSERT_NEAR(m->normals[v].norm(), 1.0, 1e-9);
    ASSERT_GT(m->normals[v].dot(d.normalized()), std::cos(3.0 * M_PI / 180)) << v;  // ∇φ is radial
  }
  // Closed: every edge in exactly two triangles, once in each direction.
  EXPECT_TRUE(mesh::CheckClosedOriented(*m, "surface"));
  EXPECT_EQ(EulerCharacteristic(*m), 2);
  // Outward winding: the enclosed volume is positive and close to 4/3 π r³.
  EXPECT_NEAR(mesh::SignedVolume(*m), 4.0 / 3.0 * M_PI * r_m * r_m * r_m, 0.01 * 4.0 / 3.0 * M_PI * r_m * r_m * r_m);
  for (std::size_t f = 0; f < m->faces.size(); ++f) {
    const Eigen::Vector3d c =
        (m->vertices[static_cast<std::size_t>(m->faces[f][0])] + m->vertices[static_cast<std::size_t>(m->faces[f][1])] +
         m->vertices[static_cast<std::size_t>(m->faces[f][2])]) /
        3;
    ASSERT_GT(mesh::FaceNormal(*m, f).dot((c - s.fit_offset_m).normalized()), 0.5) << f;
  }
}

// φ ≤ 0 is inside: a plateau of exact zeros deep inside the sphere is not a surface (OpenVDB's own
// convention, value < isovalue, would wrap it in a second sphere of radius 15 voxels).
TEST(ExtractZeroSurface, ZeroPlateauCountsAsInside) {
  const BlobSpec s = SphereSpec();
  const auto bytes = MakeBlob(s, [&](const Eigen::Vector3d& x) {
    const double t = SphereSdfVoxels(s, x);
    return t < -5 ? 0.0 : t;
  });
  auto m = mesh::ExtractZeroSurface(View(bytes));
  ASSERT_TRUE(m) << m.error().message;
  EXPECT_EQ(EulerCharacteristic(*m), 2);
  const double r_m = s.fit_scale * kSphereRadiusModel;
  for (const auto& v : m->vertices) ASSERT_LE(std::abs((v - s.fit_offset_m).norm() - r_m), 0.1 * s.voxel_m);
}

TEST(ExtractZeroSurface, TorusHasGenusOne) {
  BlobSpec s;
  s.dims = {56, 56, 24};
  s.voxel_m = 1e-3;
  s.origin_m = Eigen::Vector3d(-0.0275, -0.0275, -0.0115);
  const double big = 0.016;
  const double small = 0.006;
  auto torus = [&](const Eigen::Vector3d& x) {
    const double q = std::hypot(x.x(), x.y()) - big;
    return (std::hypot(q, x.z()) - small) / s.voxel_m;
  };
  const auto bytes = MakeBlob(s, torus);
  auto m = mesh::ExtractZeroSurface(View(bytes));
  ASSERT_TRUE(m) << m.error().message;
  EXPECT_TRUE(mesh::CheckClosedOriented(*m, "torus"));
  EXPECT_EQ(EulerCharacteristic(*m), 0);
  for (const auto& v : m->vertices) ASSERT_LE(std::abs(torus(v)), 0.1);
  EXPECT_NEAR(mesh::SignedVolume(*m), 2 * M_PI * M_PI * big * small * small,
              0.02 * 2 * M_PI * M_PI * big * small * small);
}

TEST(ExtractZeroSurface, NoZeroCrossingIsAnError) {
  BlobSpec s;
  s.dims = {8, 8, 8};
  const auto bytes = MakeBlob(s, [](const Eigen::Vector3d&) { return 2.0; });
  auto m = mesh::ExtractZeroSurface(View(bytes));
  ASSERT_FALSE(m);
  EXPECT_NE(m.error().message.find("no zero crossing"), std::string::npos);
}

TEST(TrilinearGradient, ExactOnALinearField) {
  BlobSpec s;
  s.dims = {6, 7, 8};
  s.voxel_m = 1e-3;
  // φ = 0.3 i − 0.2 j + 0.5 k − 1 (voxels): trilinear interpolation reproduces it exactly.
  const auto bytes = MakeBlob(s, [&](const Eigen::Vector3d& x) {
    const Eigen::Vector3d p = x / s.voxel_m;
    return 0.3 * p.x() - 0.2 * p.y() + 0.5 * p.z() - 1;
  });
  const blob::FieldView v = View(bytes);
  for (const Eigen::Vector3d& p :
       {Eigen::Vector3d(0.2, 0.7, 3.3), Eigen::Vector3d(4.9, 5.5, 6.99), Eigen::Vector3d(2, 3, 4)}) {
    EXPECT_NEAR(mesh::TrilinearPhi(v, p), 0.3 * p.x() - 0.2 * p.y() + 0.5 * p.z() - 1, 1e-4);
    EXPECT_TRUE(mesh::TrilinearGradient(v, p).isApprox(Eigen::Vector3d(0.3, -0.2, 0.5), 1e-4));
  }
}

mesh::TriangleMesh Tetrahedron() {
  mesh::TriangleMesh m;
  m.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  m.faces = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  m.normals = {{-1, -1, -1}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  return m;
}

TEST(MeshFormats, PlyIsBinaryLittleEndianWithExactCounts) {
  const auto bytes = mesh::ToPly(Tetrahedron());
  const std::string text(reinterpret_cast<const char*>(bytes.data()), bytes.size());
  const auto end = text.find("end_header\n");
  ASSERT_NE(end, std::string::npos);
  EXPECT_EQ(text.rfind("ply\nformat binary_little_endian 1.0\n", 0), 0u);
  EXPECT_NE(text.find("element vertex 4\n"), std::string::npos);
  EXPECT_NE(text.find("element face 4\n"), std::string::npos);
  const std::size_t body = end + std::strlen("end_header\n");
  EXPECT_EQ(bytes.size(), body + 4 * 6 * sizeof(float) + 4 * (1 + 3 * sizeof(std::int32_t)));
  float x1 = 0;  // vertex 1's x
  std::memcpy(&x1, bytes.data() + body + 6 * sizeof(float), sizeof x1);
  EXPECT_EQ(x1, 1.0f);
  std::int32_t last = 0;  // the last face's third index
  std::memcpy(&last, bytes.data() + bytes.size() - 4, 4);
  EXPECT_EQ(last, 3);
}

TEST(MeshFormats, ObjIsOneBased) {
  const std::string obj = mesh::ToObj(Tetrahedron());
  EXPECT_NE(obj.find("v 1 0 0\n"), std::string::npos) << obj;
  EXPECT_NE(obj.find("f 2//2 3//3 4//4\n"), std::string::npos) << obj;
  EXPECT_EQ(std::count(obj.begin(), obj.end(), '\n'), 1 + 4 + 4 + 4);
}

class MeshCli : public TempDirTest {};

TEST_F(MeshCli, WritesPlyAndObjAndRefusesOtherExtensions) {
  const BlobSpec s = SphereSpec();
  const auto bytes = MakeBlob(s, [&](const Eigen::Vector3d& x) { return SphereSdfVoxels(s, x); });
  const std::string field = Path("sphere.palpa");
  {
    std::ofstream(field, std::ios::binary)
        .write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  }
  const Outcome ply = Palpa("mesh " + field + " -o " + Path("s.ply"));
  ASSERT_EQ(ply.code, 0) << ply.out;
  EXPECT_NE(ply.out.find("closed"), std::string::npos) << ply.out;
  EXPECT_EQ(ReadText(Path("s.ply")).rfind("ply\n", 0), 0u);
  const Outcome obj = Palpa("mesh " + field + " -o " + Path("s.OBJ") + " -q");
  ASSERT_EQ(obj.code, 0) << obj.out;
  EXPECT_EQ(ReadText(Path("s.OBJ")).rfind("# palpa mesh", 0), 0u);
  const Outcome stl = Palpa("mesh " + field + " -o " + Path("s.stl"));
  EXPECT_EQ(stl.code, 2) << stl.out;
  EXPECT_NE(stl.out.find("use .ply or .obj"), std::string::npos) << stl.out;
  EXPECT_FALSE(fs::exists(Path("s.stl")));
  const Outcome missing = Palpa("mesh " + Path("none.palpa") + " -o " + Path("n.ply"));
  EXPECT_EQ(missing.code, 2) << missing.out;
  EXPECT_NE(missing.out.find("none.palpa"), std::string::npos) << missing.out;
  EXPECT_FALSE(fs::exists(Path("n.ply")));
}

}  // namespace
}  // namespace palpa::tools_test

namespace palpa::tools_test {
namespace {

// Issue 5: the zero iso-surface of the field palpa builds from sphere926 (default method) lies
// within 0.1 voxel of the true sphere |x| = 10 (model units) at every vertex, and is closed.
class Sphere926Mesh : public TempDirTest {};

TEST_F(Sphere926Mesh, EveryVertexWithinATenthOfAVoxelOfRadiusTenAndClosed) {
  const std::string field = Path("s926.palpa");
  const Outcome b = Palpa("build " + DataFile("sphere926.pwn").string() + " -o " + field + " --cells 150 -q");
  ASSERT_EQ(b.code, 0) << b.out;
  auto stored = blob::LoadFile(field.c_str());
  ASSERT_TRUE(stored.has_value()) << stored.error().what();
  const auto dense = blob::VerifyOwned(blob::DenseV1(stored->view()));  // the dense equivalent
  ASSERT_TRUE(dense.has_value()) << dense.error().what();
  const blob::FieldView* view = &dense->view();
  auto m = mesh::ExtractZeroSurface(*view);
  ASSERT_TRUE(m) << m.error().message;
  ASSERT_GT(m->vertices.size(), 1000u);
  const Eigen::Vector3d centre(view->fit_offset_m[0], view->fit_offset_m[1], view->fit_offset_m[2]);
  const double r_m = 10.0 * view->fit_scale;
  double worst = 0;
  for (const auto& v : m->vertices) worst = std::max(worst, std::abs((v - centre).norm() - r_m) / view->voxel_m);
  RecordProperty("max_vertex_error_voxels", std::to_string(worst));
  EXPECT_LE(worst, 0.1);
  EXPECT_TRUE(mesh::CheckClosedOriented(*m, "surface"));
  EXPECT_EQ(EulerCharacteristic(*m), 2);
}

// Issue 21: palpa mesh reads a v2 blob in place (no dense copy: memory follows the band, and
// OpenVDB gets leaves only where an edge can cross the surface). The mesh is the one of the
// blob::DenseV1 grid of the same field, vertex for vertex and bit for bit, and PhiRangeQ16 (block
// by block, in place) is the dense grid's range.
TEST_F(Sphere926Mesh, InPlaceV2MeshIsTheDenseGridsMeshBitForBit) {
  const std::string field = Path("s926v2.palpa");
  const Outcome b = Palpa("build " + DataFile("sphere926.pwn").string() + " -o " + field + " --cells 150 -q");
  ASSERT_EQ(b.code, 0) << b.out;
  auto stored = blob::ReadFile(field.c_str());
  ASSERT_TRUE(stored.has_value());
  const auto v2 = blob::Verify(*stored);
  ASSERT_TRUE(v2.has_value()) << v2.error().what();
  ASSERT_EQ(v2->version, blob::kVersion2);
  const std::vector<std::byte> dense_bytes = blob::DenseV1(*v2);
  const auto v1 = blob::Verify(dense_bytes);
  ASSERT_TRUE(v1.has_value()) << v1.error().what();

  const std::vector<std::int32_t> dense = blob::DenseQ16(*v1);
  const auto [lo, hi] = std::minmax_element(dense.begin(), dense.end());
  EXPECT_EQ(mesh::PhiRangeQ16(*v2), std::make_pair(*lo, *hi));
  EXPECT_EQ(mesh::PhiRangeQ16(*v1), std::make_pair(*lo, *hi));

  auto in_place = mesh::ExtractZeroSurface(*v2);
  auto from_dense = mesh::ExtractZeroSurface(*v1);
  ASSERT_TRUE(in_place) << in_place.error().message;
  ASSERT_TRUE(from_dense) << from_dense.error().message;
  ASSERT_EQ(in_place->vertices.size(), from_dense->vertices.size());
  ASSERT_EQ(in_place->faces, from_dense->faces);
  for (std::size_t v = 0; v < in_place->vertices.size(); ++v) {
    ASSERT_EQ(in_place->vertices[v], from_dense->vertices[v]) << v;
    ASSERT_EQ(in_place->normals[v], from_dense->normals[v]) << v;
  }
  EXPECT_EQ(mesh::ToPly(*in_place), mesh::ToPly(*from_dense));
}

}  // namespace
}  // namespace palpa::tools_test
