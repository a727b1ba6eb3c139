#include "palpa/mesh/slice.h"

#include <stb/stb_easy_font.h>
#include <stb/stb_image_write.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>

#include <fmt/core.h>

#include "palpa/mesh/iso_surface.h"

namespace palpa::mesh {
namespace {

constexpr int kFontScale = 2;  // stb_easy_font pixels → image pixels
constexpr int kMargin = 16;
constexpr int kBarWidth = 24;
constexpr int kTargetPanel = 600;
constexpr int kMaxPanel = 8192;
constexpr std::array<char, 3> kAxisName{'x', 'y', 'z'};

class Canvas {
 public:
  Canvas(int w, int h) : w_(w), h_(h), rgb_(static_cast<std::size_t>(w) * static_cast<std::size_t>(h) * 3, 255) {}
  void Set(int x, int y, const std::array<std::uint8_t, 3>& c) {
    if (x < 0 || y < 0 || x >= w_ || y >= h_) return;
    const std::size_t o =
        3 * (static_cast<std::size_t>(y) * static_cast<std::size_t>(w_) + static_cast<std::size_t>(x));
    rgb_[o] = c[0];
    rgb_[o + 1] = c[1];
    rgb_[o + 2] = c[2];
  }
  void Fill(int x0, int y0, int x1, int y1, const std::array<std::uint8_t, 3>& c) {  // [x0, x1) × [y0, y1)
    for (int y = y0; y < y1; ++y)
      for (int x = x0; x < x1; ++x) Set(x, y, c);
  }
  // Text with its top-left corner at (x, y), black, via stb_easy_font's quads.
  void Text(int x, int y, const std::string& text) {
    std::string mutable_text = text;  // the stb API takes char*
    std::vector<char> buffer(text.size() * 300 + 64);
    const int quads =
        stb_easy_font_print(0, 0, mutable_text.data(), nullptr, buffer.data(), static_cast<int>(buffer.size()));
    for (int q = 0; q < quads; ++q) {
      float v[4][4];  // x, y, z, colour: 16 bytes per vertex
      std::memcpy(v, buffer.data() + static_cast<std::size_t>(q) * 64, 64);
      const auto x0 = static_cast<int>(std::lround(v[0][0] * kFontScale));
      const auto y0 = static_cast<int>(std::lround(v[0][1] * kFontScale));
      const auto x1 = static_cast<int>(std::lround(v[2][0] * kFontScale));
      const auto y1 = static_cast<int>(std::lround(v[2][1] * kFontScale));
      Fill(x + std::min(x0, x1), y + std::min(y0, y1), x + std::max(x0, x1), y + std::max(y0, y1), {0, 0, 0});
    }
  }
  std::vector<std::uint8_t> Take() { return std::move(rgb_); }

 private:
  int w_;
  int h_;
  std::vector<std::uint8_t> rgb_;
};

int TextWidth(const std::string& text) {
  std::string t = text;
  return stb_easy_font_width(t.data()) * kFontScale;
}
constexpr int kTextHeight = 7 * kFontScale;  // glyph cap height of stb_easy_font

std::string Mm(double metres) { return fmt::format("{:.2f}", metres * 1e3); }

}  // namespace

std::array<std::uint8_t, 3> CoolWarm(double s) {
  // Moreland (2009), "Diverging Color Maps for Scientific Visualization", cool to warm, sampled
  // at 9 equally spaced points (as in matplotlib's "coolwarm").
  static constexpr std::array<std::array<double, 3>, 9> kKnots{{{59, 76, 192},
                                                                {98, 130, 234},
                                                                {141, 176, 254},
                                                                {184, 208, 249},
                                                                {221, 221, 221},
                                                                {245, 196, 173},
                                                                {244, 154, 123},
                                                                {222, 96, 77},
                                                                {180, 4, 38}}};
  const double x = std::clamp(s, 0.0, 1.0) * 8;
  const auto i = std::min(static_cast<std::size_t>(x), std::size_t{7});
  const double t = x - static_cast<double>(i);
  std::array<std::uint8_t, 3> c{};
  for (std::size_t a = 0; a < 3; ++a)
    c[a] = static_cast<std::uint8_t>(std::lround((1 - t) * kKnots[i][a] + t * kKnots[i + 1][a]));
  return c;
}

Eigen::Vector3d SliceImage::PixelCentre(const blob::FieldView& field, int px, int py) const {
  const double s = pixels_per_voxel;
  Eigen::Vector3d p;
  p[axis] = (at_m - field.origin_m[static_cast<std::size_t>(axis)]) / field.voxel_m;
  p[u_axis] = (px - panel.x + 0.5) / s - 0.5;
  p[v_axis] = (panel.h - (py - panel.y) - 0.5) / s - 0.5;
  return Eigen::Vector3d(field.origin_m[0], field.origin_m[1], field.origin_m[2]) + field.voxel_m * p;
}

std::expected<SliceImage, Error> RenderSlice(const blob::FieldView& field, int axis, double at_m,
                                             int pixels_per_voxel) {
  if (axis < 0 || axis > 2)
    return std::unexpected(Error{fmt::format("axis must be 0, 1 or 2 (x, y, z), got {}", axis)});
  const auto a = static_cast<std::size_t>(axis);
  const double lo = field.origin_m[a];
  const double hi = lo + (field.dims[a] - 1) * field.voxel_m;
  if (!(at_m >= lo && at_m <= hi))
    return std::unexpected(
        Error{fmt::format("--at {} m is outside the grid: {} spans [{:.6f}, {:.6f}] m", at_m, kAxisName[a], lo, hi)});
  SliceImage img;
  img.axis = axis;
  img.at_m = at_m;
  img.u_axis = axis == 0 ? 1 : 0;
  img.v_axis = axis == 2 ? 1 : 2;
  const int nu = field.dims[static_cast<std::size_t>(img.u_axis)];
  const int nv = field.dims[static_cast<std::size_t>(img.v_axis)];
  if (pixels_per_voxel < 0)
    return std::unexpected(Error{fmt::format("pixels per voxel must be positive, got {}", pixels_per_voxel)});
  const int s =
      pixels_per_voxel > 0 ? pixels_per_voxel : std::max(1, (kTargetPanel + std::max(nu, nv) - 1) / std::max(nu, nv));
  if (static_cast<long long>(s) * std::max(nu, nv) > kMaxPanel)
    return std::unexpected(Error{fmt::format("a panel of {} pixels per voxel would exceed {} pixels", s, kMaxPanel)});
  img.pixels_per_voxel = s;

  // Layout: title, then [v labels | panel | gap | bar | ticks + labels], then the u labels.
  // The dense equivalent's band (a v2 blob read in place: the wider of its two; v1: its own).
  const int band_nodes = std::max(field.band_voxels, field.band_outside);
  const double band = band_nodes;
  const int tick_every = std::max(1, static_cast<int>(std::ceil(2 * band / 12)));
  int label_w = TextWidth("phi (mm)");
  for (int l = -band_nodes; l <= band_nodes; ++l) label_w = std::max(label_w, TextWidth(Mm(l * field.voxel_m)));
  const double u_lo = field.origin_m[static_cast<std::size_t>(img.u_axis)];
  const double v_lo = field.origin_m[static_cast<std::size_t>(img.v_axis)];
  const double u_hi = u_lo + (nu - 1) * field.voxel_m;
  const double v_hi = v_lo + (nv - 1) * field.voxel_m;
  const int v_label_w =
      std::max({TextWidth(Mm(v_lo)), TextWidth(Mm(v_hi)),
                TextWidth(std::string(1, kAxisName[static_cast<std::size_t>(img.v_axis)]) + " (mm)")});
  const std::string title = fmt::format("{} = {} mm   voxel {:.3f} mm   band {} voxels", kAxisName[a], Mm(at_m),
                                        field.voxel_m * 1e3, band_nodes);
  const int title_h = kTextHeight + 12;   // the title line
  const int header_h = kTextHeight + 10;  // axis name over the v labels, "phi (mm)" over the bar
  img.panel = {kMargin + v_label_w + 8, kMargin + title_h + header_h, nu * s, nv * s};
  img.colour_bar = {img.panel.x + img.panel.w + 32, img.panel.y, kBarWidth, img.panel.h};
  img.width = std::max(img.colour_bar.x + kBarWidth + 10 + label_w, kMargin + TextWidth(title)) + kMargin;
  img.height = img.panel.y + img.panel.h + 8 + kTextHeight + kMargin;
  Canvas canvas(img.width, img.height);

  // φ at every panel pixel centre (trilinear), then colours, level lines and the zero contour.
  const SliceImage::Rect& p = img.panel;
  std::vector<double> phi(static_cast<std::size_t>(p.w) * static_cast<std::size_t>(p.h));
  const Eigen::Vector3d origin(field.origin_m[0], field.origin_m[1], field.origin_m[2]);
  for (int r = 0; r < p.h; ++r)
    for (int c = 0; c < p.w; ++c) {
      const Eigen::Vector3d x = (img.PixelCentre(field, p.x + c, p.y + r) - origin) / field.voxel_m;
      phi[static_cast<std::size_t>(r) * static_cast<std::size_t>(p.w) + static_cast<std::size_t>(c)] =
          TrilinearPhi(field, x);
    }
  auto at = [&](int r, int c) {
    return phi[static_cast<std::size_t>(r) * static_cast<std::size_t>(p.w) + static_cast<std::size_t>(c)];
  };
  for (int r = 0; r < p.h; ++r)
    for (int c = 0; c < p.w; ++c) {
      const double f = at(r, c);
      auto colour = CoolWarm(0.5 + 0.5 * std::clamp(f / band, -1.0, 1.0));
      bool level = false;
      bool zero = false;
      for (const auto& [dr, dc] : {std::pair{0, 1}, std::pair{1, 0}, std::pair{0, -1}, std::pair{-1, 0}}) {
        const int rr = r + dr;
        const int cc = c + dc;
        if (rr < 0 || cc < 0 || rr >= p.h || cc >= p.w) continue;
        const double g = at(rr, cc);
        zero = zero || ((f <= 0) != (g <= 0));
        // One pixel per level line: the pixel on the lower side of each integer crossing.
        level = level || (std::floor(g) > std::floor(f) && std::abs(f) < band);
      }
      if (level)
        for (auto& ch : colour) ch = static_cast<std::uint8_t>(ch * 4 / 5);
      canvas.Set(p.x + c, p.y + r, zero ? kContourColour : colour);
    }

  // Colour bar with ticks labelled in mm; the zero level drawn like the contour.
  const SliceImage::Rect& b = img.colour_bar;
  for (int r = 0; r < b.h; ++r) {
    const double f = band * (1 - 2 * (r + 0.5) / b.h);
    canvas.Fill(b.x, b.y + r, b.x + b.w, b.y + r + 1, CoolWarm(0.5 + 0.5 * f / band));
  }
  canvas.Fill(b.x - 1, b.y - 1, b.x + b.w + 1, b.y, {0, 0, 0});
  canvas.Fill(b.x - 1, b.y + b.h, b.x + b.w + 1, b.y + b.h + 1, {0, 0, 0});
  canvas.Fill(b.x - 1, b.y, b.x, b.y + b.h, {0, 0, 0});
  canvas.Fill(b.x + b.w, b.y, b.x + b.w + 1, b.y + b.h, {0, 0, 0});
  for (int l = -band_nodes; l <= band_nodes; ++l) {
    if (l % tick_every != 0) continue;
    const int y = b.y + static_cast<int>(std::lround((band - l) / (2 * band) * b.h));
    canvas.Fill(b.x + b.w, y, b.x + b.w + 6, y + 1, {0, 0, 0});
    if (l == 0) canvas.Fill(b.x, y - 1, b.x + b.w, y + 1, kContourColour);
    canvas.Text(b.x + b.w + 10, y - kTextHeight / 2, Mm(l * field.voxel_m));
  }
  const int header_y = kMargin + title_h;
  canvas.Text(b.x, header_y, "phi (mm)");

  // Title and axis labels.
  canvas.Text(kMargin, kMargin, title);
  const std::string u_name = std::string(1, kAxisName[static_cast<std::size_t>(img.u_axis)]) + " (mm)";
  const std::string v_name = std::string(1, kAxisName[static_cast<std::size_t>(img.v_axis)]) + " (mm)";
  const int below = p.y + p.h + 8;
  canvas.Text(p.x, below, Mm(u_lo));
  canvas.Text(p.x + p.w - TextWidth(Mm(u_hi)), below, Mm(u_hi));
  canvas.Text(p.x + (p.w - TextWidth(u_name)) / 2, below, u_name);
  canvas.Text(p.x - 8 - TextWidth(Mm(v_hi)), p.y, Mm(v_hi));
  canvas.Text(p.x - 8 - TextWidth(Mm(v_lo)), p.y + p.h - kTextHeight, Mm(v_lo));
  canvas.Text(p.x - 8 - TextWidth(v_name), header_y, v_name);
  img.rgb = canvas.Take();
  return img;
}

std::vector<std::byte> EncodePng(const SliceImage& image) {
  std::vector<std::byte> out;
  stbi_write_png_to_func(
      [](void* context, void* data, int size) {
        auto* o = static_cast<std::vector<std::byte>*>(context);
        const auto* d = static_cast<const std::byte*>(data);
        o->insert(o->end(), d, d + size);
      },
      &out, image.width, image.height, 3, image.rgb.data(), image.width * 3);
  return out;
}

}  // namespace palpa::mesh
