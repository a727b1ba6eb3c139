// palpa slice: image layout against the grid, the zero contour against the analytic sphere,
// colours at known φ, the PNG round trip (stb_image), and bad planes.
#include <gtest/gtest.h>
#include <stb/stb_image.h>

#include <cmath>
#include <string>
#include <vector>

#include "field_fixtures.h"
#include "palpa/blob/blob.h"
#include "palpa/mesh/slice.h"
#include "tools_test_util.h"

namespace palpa::tools_test {
namespace {

TEST(RenderSlice, PanelMatchesTheGridSliceOnEveryAxis) {
  const BlobSpec s = SphereSpec();  // 64 × 60 × 66 nodes
  const auto bytes = MakeBlob(s, [&](const Eigen::Vector3d& x) { return SphereSdfVoxels(s, x); });
  const blob::FieldView v = View(bytes);
  struct Case {
    int axis, nu, nv;
  };
  for (const Case c : {Case{0, 60, 66}, Case{1, 64, 66}, Case{2, 64, 60}}) {
    auto img = mesh::RenderSlice(v, c.axis, s.fit_offset_m[c.axis], 3);
    ASSERT_TRUE(img) << img.error().message;
    EXPECT_EQ(img->pixels_per_voxel, 3);
    EXPECT_EQ(img->panel.w, c.nu * 3) << c.axis;
    EXPECT_EQ(img->panel.h, c.nv * 3) << c.axis;
    EXPECT_EQ(img->colour_bar.h, img->panel.h);
    EXPECT_LE(img->panel.x + img->panel.w, img->colour_bar.x);
    EXPECT_LE(img->colour_bar.x + img->colour_bar.w, img->width);
    EXPECT_LE(img->panel.y + img->panel.h, img->height);
    EXPECT_EQ(img->rgb.size(), static_cast<std::size_t>(img->width) * static_cast<std::size_t>(img->height) * 3);
  }
  // Automatic scale: the longer panel side reaches 600 pixels with the smallest integer scale.
  auto img = mesh::RenderSlice(v, 2, 0.0);
  ASSERT_TRUE(img);
  EXPECT_EQ(img->pixels_per_voxel, 10);  // ceil(600 / 64)
}

// Through the sphere's centre, contour pixels lie on the circle of radius R (20 voxels) to within
// one pixel plus the trilinear error, and go all the way round.
TEST(RenderSlice, ZeroContourFollowsTheAnalyticSphere) {
  const BlobSpec s = SphereSpec();
  const auto bytes = MakeBlob(s, [&](const Eigen::Vector3d& x) { return SphereSdfVoxels(s, x); });
  const blob::FieldView v = View(bytes);
  const int ppv = 4;
  auto img = mesh::RenderSlice(v, 2, s.fit_offset_m.z(), ppv);
  ASSERT_TRUE(img) << img.error().message;
  const double r_m = s.fit_scale * kSphereRadiusModel;
  std::array<int, 72> per_angle{};
  int contour = 0;
  for (int py = img->panel.y; py < img->panel.y + img->panel.h; ++py)
    for (int px = img->panel.x; px < img->panel.x + img->panel.w; ++px) {
      if (img->At(px, py) != mesh::kContourColour) continue;
      ++contour;
      const Eigen::Vector3d d = img->PixelCentre(v, px, py) - s.fit_offset_m;
      ASSERT_NEAR(d.z(), 0.0, 1e-12);
      ASSERT_NEAR(d.norm(), r_m, (1.0 / ppv + 0.05) * s.voxel_m) << px << " " << py;
      ++per_angle[static_cast<std::size_t>((std::atan2(d.y(), d.x()) + M_PI) / (2 * M_PI) * 72) % 72];
    }
  // Two pixels across the line (one each side) around a circumference of 2π·20·4 ≈ 503 pixels.
  EXPECT_GT(contour, 2 * 450);
  for (const int n : per_angle) EXPECT_GT(n, 0);
  // Colours at known φ: the centre is deep inside (saturated blue), the panel corner outside.
  const int cx = img->panel.x + static_cast<int>((s.fit_offset_m.x() - s.origin_m.x()) / s.voxel_m * ppv);
  const int cy =
      img->panel.y + img->panel.h - 1 - static_cast<int>((s.fit_offset_m.y() - s.origin_m.y()) / s.voxel_m * ppv);
  EXPECT_EQ(img->At(cx, cy), mesh::CoolWarm(0.0));
  EXPECT_EQ(img->At(img->panel.x, img->panel.y), mesh::CoolWarm(1.0));
  EXPECT_EQ(mesh::CoolWarm(0.0), (std::array<std::uint8_t, 3>{59, 76, 192}));
  EXPECT_EQ(mesh::CoolWarm(0.5), (std::array<std::uint8_t, 3>{221, 221, 221}));
  EXPECT_EQ(mesh::CoolWarm(1.0), (std::array<std::uint8_t, 3>{180, 4, 38}));
}

class SliceCli : public TempDirTest {};

TEST_F(SliceCli, PngRoundTripsAndBadPlanesExitTwo) {
  const BlobSpec s = SphereSpec();
  const auto bytes = MakeBlob(s, [&](const Eigen::Vector3d& x) { return SphereSdfVoxels(s, x); });
  const std::string field = Path("sphere.palpa");
  {
    std::ofstream(field, std::ios::binary)
        .write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  }
  const Outcome r = Palpa("slice " + field + " --axis y --at 0.001 -o " + Path("s.png") + " --scale 2");
  ASSERT_EQ(r.code, 0) << r.out;
  const std::string png = ReadText(Path("s.png"));
  int w = 0, h = 0, ch = 0;
  stbi_uc* pixels =
      stbi_load_from_memory(reinterpret_cast<const stbi_uc*>(png.data()), static_cast<int>(png.size()), &w, &h, &ch, 3);
  ASSERT_NE(pixels, nullptr);
  auto img = mesh::RenderSlice(View(bytes), 1, 0.001, 2);
  ASSERT_TRUE(img);
  EXPECT_EQ(w, img->width);
  EXPECT_EQ(h, img->height);
  EXPECT_EQ(0, std::memcmp(pixels, img->rgb.data(), img->rgb.size()));
  stbi_image_free(pixels);

  const Outcome out = Palpa("slice " + field + " --axis z --at 0.5 -o " + Path("bad.png"));
  EXPECT_EQ(out.code, 2) << out.out;
  EXPECT_NE(out.out.find("--at 0.5 m is outside the grid: z spans [-0.033000, 0.032000] m"), std::string::npos)
      << out.out;
  EXPECT_FALSE(fs::exists(Path("bad.png")));
  const Outcome axis = Palpa("slice " + field + " --axis w --at 0 -o " + Path("bad.png"));
  EXPECT_EQ(axis.code, 2) << axis.out;
  EXPECT_FALSE(fs::exists(Path("bad.png")));
}

// Issue 21: palpa slice and palpa view read a v2 blob in place. The picture is the one of the
// blob::DenseV1 grid, pixel for pixel, also when the band outside is the wider one (the colour
// scale is the dense equivalent's ±max(band_inside, band_outside)).
class InPlaceSlice : public TempDirTest {};

TEST_F(InPlaceSlice, V2SliceIsTheDenseGridsSlicePixelForPixel) {
  const std::string field = Path("k.palpa");
  const Outcome b =
      Palpa("build " + DataFile("kitten.xyz").string() + " -o " + field + " --cells 90 --band 2 --band-outside 5 -q");
  ASSERT_EQ(b.code, 0) << b.out;
  auto stored = blob::ReadFile(field.c_str());
  ASSERT_TRUE(stored.has_value());
  const auto v2 = blob::Verify(*stored);
  ASSERT_TRUE(v2.has_value()) << v2.error().what();
  const std::vector<std::byte> dense_bytes = blob::DenseV1(*v2);
  const auto v1 = blob::Verify(dense_bytes);
  ASSERT_TRUE(v1.has_value()) << v1.error().what();
  ASSERT_EQ(v1->band_voxels, 5);
  for (int axis = 0; axis < 3; ++axis) {
    const double at = v2->origin_m[static_cast<std::size_t>(axis)] +
                      0.5 * (v2->dims[static_cast<std::size_t>(axis)] - 1) * v2->voxel_m;
    auto in_place = mesh::RenderSlice(*v2, axis, at, 2);
    auto dense = mesh::RenderSlice(*v1, axis, at, 2);
    ASSERT_TRUE(in_place && dense);
    EXPECT_EQ(in_place->rgb, dense->rgb) << axis;
    EXPECT_EQ(mesh::EncodePng(*in_place), mesh::EncodePng(*dense)) << axis;
  }
}

}  // namespace
}  // namespace palpa::tools_test
