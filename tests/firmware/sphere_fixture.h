// Test fixtures for firmware tests: an analytic sphere field blob and HIP traces around it.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <vector>

#include "palpa/blob/blob.h"
#include "palpa/trace/trace.h"

namespace palpa::firmware_test {

/// φ = clamp(|x − c| − R, ±band) voxels at every node, as Q16.16, encoded and verified in place.
/// Not movable (callers keep references to its view).
class SphereField {
 public:
  /// `center_vox`: sphere centre in grid coordinates (voxels); node (0,0,0) at `origin_m`.
  SphereField(int n = 64, double radius_vox = 20, std::uint32_t band = 6, double voxel_m = 0.5e-3,
              std::array<double, 3> center_vox = {32.3, 31.6, 32.1});
  SphereField(const SphereField&) = delete;
  SphereField& operator=(const SphereField&) = delete;

  const blob::FieldView& view() const { return field_->view(); }
  std::span<const std::byte> bytes() const { return field_->bytes(); }
  std::array<double, 3> center_m() const { return center_m_; }
  double radius_m() const { return radius_m_; }
  double voxel_m() const { return voxel_m_; }

  /// center + r·dir (dir normalised here), m.
  std::array<double, 3> PointAt(double r_m, std::array<double, 3> dir) const;

 private:
  std::optional<blob::VerifiedField> field_;
  std::array<double, 3> center_m_{};
  double radius_m_ = 0;
  double voxel_m_ = 0;
};

/// A key frame of a trace in sphere coordinates: time, radius from the centre, direction.
struct KeyFrame {
  double t_s;
  double r_m;
  std::array<double, 3> dir;
};

/// Samples the key frames every `dt_s` (linear in r and dir, dir re-normalised).
std::vector<trace::TraceSample> TraceFromKeys(const SphereField& field, const std::vector<KeyFrame>& keys,
                                              double dt_s = 0.01);

/// 10 s: 1 s free 3 mm outside, 1 s press to 2 mm deep, 1 s hold, 2 s slide 0.5 rad over the
/// surface, 1 s leave to 3 mm outside, 4 s free. At 1 kHz: 10001 ticks, free and contact ones.
std::vector<trace::TraceSample> PressSlideLeaveTrace(const SphereField& field);

/// |v|
double Norm(const std::array<double, 3>& v);

}  // namespace palpa::firmware_test
