// A colour-mapped cross-section of a field (`palpa slice`), like the paper's Figs. 6c-8c. Non-RT.
#pragma once

#include <cstddef>
#include <cstdint>
#include <expected>
#include <vector>

#include <Eigen/Core>

#include "palpa/blob/blob.h"
#include "palpa/mesh/triangle_mesh.h"

namespace palpa::mesh {

/// An RGB image of one plane of φ, and where things are in it.
///
/// Layout: a title line at the top; the field panel below it; a vertical colour bar with tick
/// labels in mm to its right. The panel shows φ by trilinear interpolation at each pixel centre
/// in the plane, coloured with Moreland's diverging "cool to warm" map: blue inside (φ < 0),
/// light grey at 0, red outside, saturating at ±band. The zero contour (the border between φ ≤ 0
/// and φ > 0 pixels) is black; each integer voxel level is a faint darker line.
struct SliceImage {
  struct Rect {
    int x = 0, y = 0, w = 0, h = 0;  ///< pixels; y grows downwards
  };
  int width = 0;
  int height = 0;
  std::vector<std::uint8_t> rgb;  ///< width·height·3 bytes, top row first
  Rect panel;                     ///< the field: panel.w = n_u·pixels_per_voxel, panel.h = n_v·pixels_per_voxel
  Rect colour_bar;                ///< bottom = −band, top = +band
  int pixels_per_voxel = 1;
  int axis = 2;     ///< 0, 1, 2 = x, y, z: the plane's normal
  int u_axis = 0;   ///< the panel's horizontal axis (grows rightwards)
  int v_axis = 1;   ///< the panel's vertical axis (grows UPwards)
  double at_m = 0;  ///< the plane's coordinate along `axis`, device metres

  /// Device position (m) of the centre of panel pixel (px, py) in image coordinates. Panel pixel
  /// (0, bottom row) is centred on node u = 0, v = 0.
  Eigen::Vector3d PixelCentre(const blob::FieldView& field, int px, int py) const;
  std::array<std::uint8_t, 3> At(int px, int py) const {
    const std::size_t o =
        3 * (static_cast<std::size_t>(py) * static_cast<std::size_t>(width) + static_cast<std::size_t>(px));
    return {rgb[o], rgb[o + 1], rgb[o + 2]};
  }
};

/// The zero contour colour (black) and the colour map, exposed for tests.
inline constexpr std::array<std::uint8_t, 3> kContourColour{0, 0, 0};
/// Moreland's cool-to-warm map at s ∈ [0, 1] (0 blue, 0.5 grey, 1 red), linear between 9 knots.
std::array<std::uint8_t, 3> CoolWarm(double s);

/// Renders the plane x_axis = at_m (device metres) of `field`. `pixels_per_voxel` 0 picks the
/// smallest integer that makes the panel's longer side at least 600 pixels.
/// Errors: axis not 0..2; at_m outside the grid ("--at 0.05 m is outside the grid: z spans
/// [-0.034, 0.034] m"); pixels_per_voxel < 0 or a panel over 8192 pixels on a side.
std::expected<SliceImage, Error> RenderSlice(const blob::FieldView& field, int axis, double at_m,
                                             int pixels_per_voxel = 0);

/// PNG bytes (stb_image_write, 8-bit RGB).
std::vector<std::byte> EncodePng(const SliceImage& image);

}  // namespace palpa::mesh
