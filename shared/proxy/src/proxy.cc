#include "palpa/proxy/proxy.h"

#include <cmath>
#include <cstdlib>
#include <limits>

namespace palpa::proxy {
namespace {

using fixed::DivRound;
using fixed::ISqrt;
using fixed::Round;
using fixed::SaturateToInt32;
using fixed::ShiftRight;

struct Delta {
  std::int64_t v[3];
};

Delta Diff(GridPos to, GridPos from) {
  return {{std::int64_t{to.x} - from.x, std::int64_t{to.y} - from.y, std::int64_t{to.z} - from.z}};
}

std::int64_t Length(const Delta& d) {
  return static_cast<std::int64_t>(ISqrt(d.v[0] * d.v[0] + d.v[1] * d.v[1] + d.v[2] * d.v[2]));
}

GridPos Add(GridPos p, const Delta& d) {
  return {SaturateToInt32(p.x + d.v[0]), SaturateToInt32(p.y + d.v[1]), SaturateToInt32(p.z + d.v[2])};
}

// Scales d to length `len` (raw), given its current length `cur` > 0.
Delta ScaleTo(const Delta& d, std::int64_t len, std::int64_t cur) {
  return {{DivRound(d.v[0] * len, cur), DivRound(d.v[1] * len, cur), DivRound(d.v[2] * len, cur)}};
}

}  // namespace

GridPos GridFrame::ToGrid(const std::array<double, 3>& x_m) const {
  std::int32_t out[3];
  for (int a = 0; a < 3; ++a) {
    const double g = (x_m[static_cast<std::size_t>(a)] - origin_m[static_cast<std::size_t>(a)]) / voxel_m * 65536.0;
    if (!(g == g)) {
      out[a] = std::numeric_limits<std::int32_t>::min();  // NaN: far outside, free space
    } else if (g >= 2147483647.0) {
      out[a] = std::numeric_limits<std::int32_t>::max();
    } else if (g <= -2147483648.0) {
      out[a] = std::numeric_limits<std::int32_t>::min();
    } else {
      out[a] = static_cast<std::int32_t>(std::lround(g));
    }
  }
  return {out[0], out[1], out[2]};
}

std::array<double, 3> GridFrame::ToMetres(GridPos p) const {
  return {origin_m[0] + static_cast<double>(p.x) / 65536.0 * voxel_m,
          origin_m[1] + static_cast<double>(p.y) / 65536.0 * voxel_m,
          origin_m[2] + static_cast<double>(p.z) / 65536.0 * voxel_m};
}

std::expected<ProxyParams, const char*> MakeProxyParams(const ProxyConfig& c, double voxel_m) {
  if (!(std::isfinite(c.k_n_per_m) && c.k_n_per_m > 0 && c.k_n_per_m <= 1e5))
    return std::unexpected("stiffness k must be in (0, 1e5] N/m");
  if (!(std::isfinite(voxel_m) && voxel_m > 0 && voxel_m < 1)) return std::unexpected("voxel size must be in (0, 1) m");
  const double k_per_voxel = c.k_n_per_m * voxel_m;
  if (k_per_voxel < 1e-3)
    return std::unexpected("k·voxel below 1e-3 N/voxel: Q16.16 would resolve k to worse than 1.5 %");
  if (k_per_voxel > 32767) return std::unexpected("k·voxel above 32767 N/voxel overflows Q16.16");
  if (!(std::isfinite(c.max_force_n) && c.max_force_n > 0 && c.max_force_n <= 100))
    return std::unexpected("max force must be in (0, 100] N");
  if (!(std::isfinite(c.gamma) && c.gamma > 0 && c.gamma <= 1)) return std::unexpected("gamma must be in (0, 1]");
  if (!(std::isfinite(c.beta) && c.beta > 0 && c.beta <= 1)) return std::unexpected("beta must be in (0, 1]");
  if (c.max_iterations < 1 || c.max_iterations > 256) return std::unexpected("iterations must be in 1..256");
  ProxyParams p;
  p.gamma_q16 = fixed::Q16::FromDouble(c.gamma).raw();
  p.beta_q16 = fixed::Q16::FromDouble(c.beta).raw();
  p.max_iterations = c.max_iterations;
  p.k = {fixed::Q16::FromDouble(k_per_voxel)};
  p.max_force = {fixed::Q16::FromDouble(c.max_force_n)};
  p.voxel_m = voxel_m;
  return p;
}

TickResult ProxyTick(const sampler::TrilinearSampler& field, const ProxyParams& params, ProxyState& state,
                     GridPos hip) {
  TickResult r;
  GridPos p = state.valid ? state.proxy : hip;

  // Phase 1: free motion by sphere tracing; cannot cross φ = 0.
  for (int step = 0; step < kMaxTraceSteps && !(p == hip); ++step) {
    const std::int32_t phi = field.At(p).phi;
    ++r.iterations;
    if (phi <= params.contact_eps_q16) break;
    const Delta d = Diff(hip, p);
    const std::int64_t len = Length(d);
    const std::int64_t safe = ShiftRight(std::int64_t{phi} * kInvLipschitzQ16, 16, Round::kFloor);
    if (safe >= len) {
      p = hip;
      break;
    }
    p = Add(p, ScaleTo(d, safe, len));
  }

  // Phase 2: eq. 9 as a γ step towards the HIP followed by a normalised φ step back to φ = 0.
  for (int it = 0; it < params.max_iterations && !(p == hip); ++it) {
    Delta d = Diff(hip, p);
    Delta step{{ShiftRight(d.v[0] * params.gamma_q16, 16, Round::kNearest),
                ShiftRight(d.v[1] * params.gamma_q16, 16, Round::kNearest),
                ShiftRight(d.v[2] * params.gamma_q16, 16, Round::kNearest)}};
    const std::int64_t step_len = Length(step);
    if (step_len > params.max_step_q16) step = ScaleTo(step, params.max_step_q16, step_len);
    GridPos q = Add(p, step);
    const sampler::Sample s = field.At(q);
    ++r.iterations;
    if (s.phi < 0) {
      const std::int64_t g2 = std::int64_t{s.grad[0]} * s.grad[0] + std::int64_t{s.grad[1]} * s.grad[1] +
                              std::int64_t{s.grad[2]} * s.grad[2];  // Q32.32
      // A vanishing gradient (flat, clamped interior) gives no direction to project along: keep
      // the proxy where it was rather than push it somewhere arbitrary.
      // |∇φ| ≥ 1/4 also bounds the projection to 4·|φ|, a fraction of a voxel near the surface.
      if (g2 < (std::int64_t{1} << 28)) break;
      // ratio = β φ / |∇φ|² in Q16.16.
      const std::int64_t ratio =
          ShiftRight(DivRound(std::int64_t{s.phi} << 32, g2) * params.beta_q16, 16, Round::kNearest);
      for (int a = 0; a < 3; ++a) {
        const std::int64_t back = ShiftRight(ratio * s.grad[static_cast<std::size_t>(a)], 16, Round::kNearest);
        step.v[a] -= back;
      }
      q = Add(p, step);
    }
    const bool converged = std::llabs(step.v[0]) <= params.tolerance_q16 &&
                           std::llabs(step.v[1]) <= params.tolerance_q16 &&
                           std::llabs(step.v[2]) <= params.tolerance_q16;
    p = q;
    if (converged) break;
  }

  state.proxy = p;
  state.valid = true;
  r.proxy = p;
  if (p == hip) return r;

  // Eq. 10: f = −k (X_h − X_p) = k·h·(X_p − X_h), clamped with its direction kept.
  const Delta pen = Diff(p, hip);
  const std::int64_t pen_len = Length(pen);
  r.contact = true;
  r.penetration_q16 = SaturateToInt32(pen_len);
  const std::int64_t k = params.k.value.raw();
  const std::int64_t magnitude = ShiftRight(k * pen_len, 16, Round::kNearest);
  const std::int64_t max_f = params.max_force.value.raw();
  for (int a = 0; a < 3; ++a) {
    std::int64_t f = 0;
    if (magnitude > max_f) {
      f = DivRound(max_f * pen.v[a], pen_len);
    } else {
      f = ShiftRight(k * pen.v[a], 16, Round::kNearest);
    }
    r.force[static_cast<std::size_t>(a)] = {fixed::Q16::FromRaw(SaturateToInt32(f))};
  }
  r.clamped = magnitude > max_f;
  return r;
}

}  // namespace palpa::proxy
