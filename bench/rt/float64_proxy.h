// A plain float64 implementation of the same equations as shared/ (trilinear φ, continuous
// gradient, the certified proxy tick of paper eq. 9 and the force of eq. 10), written for the
// benchmark: the fixed-point tick must not be slower than this and must agree with it within the
// tolerances in docs/realtime-core.md § Float64 reference. Same control flow, same field data in the
// same storage (a dense blob's int32 values; on blob v2 the bricks, gathered by the fixed-point
// sampler's own Fetch and CopyWide, since storage is not what the comparison is about), scaled by
// 2^−16 when fetched, same Lipschitz bound; positions in voxels (grid frame) as double. Like shared/, the sampler and
// the tick are out of line (float64_proxy.cc), compiled with the same flags.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>

#include "palpa/blob/blob.h"
#include "palpa/proxy/proxy.h"
#include "palpa/sampler/trilinear.h"

namespace palpa::bench {

using Vec3d = std::array<double, 3>;

struct Float64Sample {
  double phi = 0;
  Vec3d grad{};
};

/// A Lipschitz bound in double (sampler::LipschitzBound).
class Float64Bound {
 public:
  explicit Float64Bound(const sampler::LipschitzBound& lb)
      : norm_(lb.norm / 65536.0),
        norm_helps_(lb.norm_helps),
        axis_{lb.axis[0] / 65536.0, lb.axis[1] / 65536.0, lb.axis[2] / 65536.0} {}
  double norm() const { return norm_; }
  bool norm_helps() const { return norm_helps_; }
  const Vec3d& axis() const { return axis_; }

 private:
  double norm_;
  bool norm_helps_;
  Vec3d axis_;
};

class Float64Field {
 public:
  /// `s` samples `f` (its Lipschitz bound and background are used; on blob v2 it also fetches).
  Float64Field(const blob::FieldView& f, const sampler::TrilinearSampler& s)
      : phi_(f.dense() != nullptr ? f.dense()->data() : nullptr),  // v2: fetched through the sampler
        sampler_(&s),
        dims_(f.dims),
        si_(static_cast<std::ptrdiff_t>(f.dims[1]) * f.dims[2]),
        background_(s.background() / 65536.0),
        whole_(s.lipschitz()),
        band_(s.lipschitz_band()) {}

  double norm() const { return whole_.norm(); }
  bool norm_helps() const { return whole_.norm_helps(); }
  const Vec3d& axis() const { return whole_.axis(); }
  /// The band's own bound, for pieces whose ends both have φ ≤ background() (proxy::ContactRun).
  const Float64Bound& band() const { return band_; }
  double background() const { return background_; }

  double Phi(const Vec3d& x) const;
  Float64Sample At(const Vec3d& x) const;

 private:
  double PhiInline(const Vec3d& x) const {
    Cell c;
    if (!Locate(x, c)) return background_;
    if (phi_ == nullptr) {  // blob v2: the bricks' values, fetched as the fixed-point sampler does
      const sampler::Stencil v = sampler_->Fetch(c.i[0], c.i[1], c.i[2]);
      return Tri(V(v[0]), V(v[1]), V(v[2]), V(v[3]), V(v[4]), V(v[5]), V(v[6]), V(v[7]), c.f);
    }
    const std::int32_t* b = phi_ + Offset(c);
    const std::ptrdiff_t sj = dims_[2];
    return Tri(V(b[0]), V(b[1]), V(b[sj]), V(b[sj + 1]), V(b[si_]), V(b[si_ + 1]), V(b[si_ + sj]), V(b[si_ + sj + 1]),
               c.f);
  }

  Float64Sample AtInline(const Vec3d& x) const {
    Cell c;
    Float64Sample s;
    if (!Locate(x, c)) {
      s.phi = background_;
      return s;
    }
    if (phi_ == nullptr) return FromWide(sampler_->CopyWide(c.i[0], c.i[1], c.i[2]), c);
    const std::int32_t* b = phi_ + Offset(c);
    const std::ptrdiff_t si = si_, sj = dims_[2];
    const std::ptrdiff_t xm = c.i[0] > 0 ? -si : 0, xp = c.i[0] + 2 < dims_[0] ? 2 * si : si;
    const std::ptrdiff_t ym = c.i[1] > 0 ? -sj : 0, yp = c.i[1] + 2 < dims_[1] ? 2 * sj : sj;
    const std::ptrdiff_t zm = c.i[2] > 0 ? -1 : 0, zp = c.i[2] + 2 < dims_[2] ? 2 : 1;
    const std::ptrdiff_t off[8] = {0, 1, sj, sj + 1, si, si + 1, si + sj, si + sj + 1};
    double v[8], gx[8], gy[8], gz[8];
    for (int n = 0; n < 8; ++n) v[n] = V(b[off[n]]);
    for (int n = 0; n < 8; ++n) {
      const std::ptrdiff_t o = off[n];
      gx[n] = (n & 4) ? V(b[o - si + xp]) - v[n - 4] : v[n + 4] - V(b[o + xm]);
      gy[n] = (n & 2) ? V(b[o - sj + yp]) - v[n - 2] : v[n + 2] - V(b[o + ym]);
      gz[n] = (n & 1) ? V(b[o - 1 + zp]) - v[n - 1] : v[n + 1] - V(b[o + zm]);
    }
    return Interpolate(v, gx, gy, gz, c);
  }

  struct Cell {
    std::array<std::int32_t, 3> i;
    Vec3d f;
  };
  // φ and the gradient at fractions c.f from the corner values and the doubled central differences.
  static Float64Sample Interpolate(const double (&v)[8], const double (&gx)[8], const double (&gy)[8],
                                   const double (&gz)[8], const Cell& c) {
    Float64Sample s;
    s.phi = Tri(v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], c.f);
    s.grad = {0.5 * Tri(gx[0], gx[1], gx[2], gx[3], gx[4], gx[5], gx[6], gx[7], c.f),
              0.5 * Tri(gy[0], gy[1], gy[2], gy[3], gy[4], gy[5], gy[6], gy[7], c.f),
              0.5 * Tri(gz[0], gz[1], gz[2], gz[3], gz[4], gz[5], gz[6], gz[7], c.f)};
    return s;
  }
  // φ and the gradient from the 32 values of a wide stencil (blob v2), as AtInline's dense path.
  static Float64Sample FromWide(const sampler::WideStencil& w, const Cell& c) {
    double v[8], gx[8], gy[8], gz[8];
    for (std::size_t n = 0; n < 8; ++n) v[n] = V(w.corner[n]);
    for (std::size_t n = 0; n < 8; ++n) {
      gx[n] = (n & 4) ? V(w.x_out[n]) - v[n - 4] : v[n + 4] - V(w.x_out[n]);
      gy[n] = (n & 2) ? V(w.y_out[n]) - v[n - 2] : v[n + 2] - V(w.y_out[n]);
      gz[n] = (n & 1) ? V(w.z_out[n]) - v[n - 1] : v[n + 1] - V(w.z_out[n]);
    }
    return Interpolate(v, gx, gy, gz, c);
  }
  static double V(std::int32_t raw) { return raw * (1.0 / 65536.0); }
  static double Lerp(double a, double b, double t) { return a + (b - a) * t; }
  static double Tri(double v0, double v1, double v2, double v3, double v4, double v5, double v6, double v7,
                    const Vec3d& f) {
    return Lerp(Lerp(Lerp(v0, v1, f[2]), Lerp(v2, v3, f[2]), f[1]), Lerp(Lerp(v4, v5, f[2]), Lerp(v6, v7, f[2]), f[1]),
                f[0]);
  }
  bool Locate(const Vec3d& x, Cell& c) const {
    for (std::size_t a = 0; a < 3; ++a) {
      const double last = dims_[a] - 1;
      if (!(x[a] >= 0 && x[a] <= last)) return false;
      auto i = static_cast<std::int32_t>(x[a]);
      if (i == dims_[a] - 1) --i;
      c.i[a] = i;
      c.f[a] = x[a] - i;
    }
    return true;
  }
  std::ptrdiff_t Offset(const Cell& c) const {
    return static_cast<std::ptrdiff_t>(c.i[0]) * si_ + static_cast<std::ptrdiff_t>(c.i[1]) * dims_[2] + c.i[2];
  }

  const std::int32_t* phi_;  // dense values, or null: blob v2, fetched through sampler_
  const sampler::TrilinearSampler* sampler_;
  std::array<std::int32_t, 3> dims_;
  std::ptrdiff_t si_;
  double background_;
  Float64Bound whole_;
  Float64Bound band_;
};

/// proxy::ProxyParams in double (voxels, N per voxel, N).
struct Float64Params {
  double gamma, beta, delta, near, tolerance, k, max_force, mu_s, mu_d;
  int max_iterations, gradient_samples, settle_samples;
  static Float64Params Of(const proxy::ProxyParams& p) {
    return {p.gamma.ToDouble(),
            p.beta.ToDouble(),
            p.depth_tolerance.value.ToDouble(),
            p.near.value.ToDouble(),
            p.tolerance.value.ToDouble(),
            p.k.value.ToDouble(),
            p.max_force.value.ToDouble(),
            p.mu_static.ToDouble(),
            p.mu_dynamic.ToDouble(),
            p.max_iterations,
            p.gradient_samples,
            p.settle_samples};
  }
};

struct Float64State {
  Vec3d proxy{};
  double phi = 0;
  Vec3d grad{};
  Vec3d last_hip{};
  bool grad_valid = false, seated = false, valid = false;
  double pull = 0;               // last tick's |f| bound, N (proxy::ProxyState::pull)
  double hip_phi_bound = 1e300;  // an upper bound of φ(last_hip), voxels (none: 1e300)
};

/// A grid position (Q16.16 voxels) in double voxels.
inline Vec3d ToVoxels(sampler::GridPos p) { return {p.x / 65536.0, p.y / 65536.0, p.z / 65536.0}; }

/// The fixed-point tick's carried state in double, so both ticks can start from the same state.
inline Float64State ToFloat64(const proxy::ProxyState& s) {
  Float64State f;
  f.proxy = ToVoxels(s.proxy);
  f.phi = s.phi / 65536.0;
  f.grad = {s.grad[0] / 65536.0, s.grad[1] / 65536.0, s.grad[2] / 65536.0};
  f.last_hip = ToVoxels(s.last_hip);
  f.grad_valid = s.grad_valid;
  f.seated = s.seated;
  f.valid = s.valid;
  f.pull = s.pull.value.ToDouble();
  f.hip_phi_bound = s.hip_phi_bound.value.raw() == std::numeric_limits<std::int32_t>::max()
                        ? 1e300
                        : s.hip_phi_bound.value.ToDouble();
  return f;
}

struct Float64Result {
  Vec3d proxy{};
  Vec3d force{};
  bool contact = false, converged = false;
  int iterations = 0;
};

namespace detail {
inline double Dot(const Vec3d& a, const Vec3d& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
inline Vec3d Sub(const Vec3d& a, const Vec3d& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
inline double Len(const Vec3d& a) { return std::sqrt(Dot(a, a)); }
inline double MaxAbs(const Vec3d& a) { return std::max({std::abs(a[0]), std::abs(a[1]), std::abs(a[2])}); }
// B: Float64Field (the whole field's bound) or Float64Bound.
template <typename B>
double AxisVariation(const Vec3d& d, const B& f) {
  return std::abs(d[0]) * f.axis()[0] + std::abs(d[1]) * f.axis()[1] + std::abs(d[2]) * f.axis()[2];
}
template <typename B>
double Variation(const Vec3d& d, const B& f, double need) {
  const double axis = AxisVariation(d, f);
  if (axis <= need || !f.norm_helps()) return axis;
  return std::min(axis, f.norm() * Len(d));
}
template <typename B>
bool Certified(double phi_a, double phi_b, const Vec3d& d, const B& f, double delta) {
  const double s = phi_a + phi_b + 2 * delta;
  return s >= 0 && Variation(d, f, s) <= s;
}
}  // namespace detail

/// The tick of proxy::ProxyTick in double; `hip` in grid voxels. Out of line (float64_proxy.cc),
/// like ProxyTick, so that the benchmark compares two calls, not a call with an inlined loop.
Float64Result Float64Tick(const Float64Field& field, const Float64Params& prm, Float64State& st, const Vec3d& hip);

}  // namespace palpa::bench
