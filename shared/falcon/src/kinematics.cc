#include "palpa/falcon/kinematics.h"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace palpa::falcon {
namespace {

using G = Geometry;
constexpr double kDegToRad = std::numbers::pi / 180.0;

double MaxAbs(const Vec3& v) { return std::max({std::fabs(v[0]), std::fabs(v[1]), std::fabs(v[2])}); }
double Norm2(const Vec3& v) { return std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]); }

// Leg frame [u, v, w] = Rz(φ)·p − [r, s, 0].
Vec3 ToLeg(int leg, const Vec3& p) {
  const double phi = kLegPhiRad[static_cast<std::size_t>(leg)];
  const double cp = std::cos(phi), sp = std::sin(phi);
  return {cp * p[0] + sp * p[1] - G::r, -sp * p[0] + cp * p[1] - G::s, p[2]};
}

std::optional<LegAngles> LegInverse(int leg, const Vec3& p) {
  const Vec3 uvw = ToLeg(leg, p);
  const double u = uvw[0], v = uvw[1], w = uvw[2];
  const double c3 = (v + G::f) / G::b;
  if (!(c3 >= -1.0 && c3 <= 1.0)) return std::nullopt;
  LegAngles q;
  q.theta3 = std::acos(c3);
  const double s3 = std::sin(q.theta3);
  const double base = w * w + u * u + 2 * G::c * u + G::a * G::a + G::c * G::c - G::d * G::d - G::e * G::e -
                      G::b * G::b * s3 * s3 - 2 * G::b * G::e * s3 - 2 * G::b * G::d * s3 - 2 * G::d * G::e;
  const double l0 = base - 2 * G::a * u - 2 * G::a * G::c;
  const double l1 = -4 * G::a * w;
  const double l2 = base + 2 * G::a * u + 2 * G::a * G::c;
  const double disc = l1 * l1 - 4 * l0 * l2;
  if (!(disc >= 0)) return std::nullopt;
  // The "−" root (−l1 − √D)/(2·l2), written as 2·l0/(−l1 + √D): same value (product of the roots
  // is l0/l2) without the cancellation when l0·l2 is small, and no division by l2 near 0.
  const double den = -l1 + std::sqrt(disc);
  if (!(std::fabs(den) > 0)) return std::nullopt;
  q.theta1 = 2 * std::atan(2 * l0 / den);
  const double k = G::d + G::e + G::b * s3;
  const double c2 = (u - G::a * std::cos(q.theta1) + G::c) / k;
  if (!(c2 >= -1.0 && c2 <= 1.0)) return std::nullopt;
  q.theta2 = std::acos(c2);
  if (!(std::isfinite(q.theta1) && std::isfinite(q.theta2))) return std::nullopt;
  return q;
}

Vec3 Theta1Of(const std::array<LegAngles, 3>& legs) { return {legs[0].theta1, legs[1].theta1, legs[2].theta1}; }

Vec3 MatVec(const Mat3& m, const Vec3& v) {
  return {m[0][0] * v[0] + m[0][1] * v[1] + m[0][2] * v[2], m[1][0] * v[0] + m[1][1] * v[1] + m[1][2] * v[2],
          m[2][0] * v[0] + m[2][1] * v[1] + m[2][2] * v[2]};
}

// Residual θ1(p) − θ1 measured, or nullopt outside the reachable set.
std::optional<Vec3> Residual(const Vec3& p, const Vec3& theta1) {
  const auto legs = InverseKinematics(p);
  if (!legs) return std::nullopt;
  const Vec3 t = Theta1Of(*legs);
  return Vec3{t[0] - theta1[0], t[1] - theta1[1], t[2] - theta1[2]};
}

// Newton from one start. Returns true and fills `out` on convergence; counts iterations.
bool Newton(const Vec3& theta1, Vec3 p, const FkConfig& cfg, FkResult& out, int& iterations, FkError& error) {
  auto r = Residual(p, theta1);
  if (!r) {
    error = FkError::kOutOfRange;
    return false;
  }
  for (int it = 0; it < cfg.max_iterations; ++it) {
    if (MaxAbs(*r) <= cfg.tolerance_rad) {
      out = {p, iterations, MaxAbs(*r)};
      return true;
    }
    ++iterations;
    const auto legs = InverseKinematics(p);  // valid: r was computed at p
    const auto jinv = Invert(Jacobian(*legs));
    if (!jinv) {
      error = FkError::kSingular;
      return false;
    }
    const Vec3 step = MatVec(*jinv, *r);  // Newton: p ← p − J⁻¹·r
    double scale = 1.0;
    bool moved = false;
    for (int h = 0; h <= cfg.max_halvings; ++h, scale *= 0.5) {
      const Vec3 q = {p[0] - scale * step[0], p[1] - scale * step[1], p[2] - scale * step[2]};
      const auto rq = Residual(q, theta1);
      // Merit ‖r‖₂: the Newton direction always decreases it for a small enough step (the max
      // norm does not, and stalls far from the solution).
      if (rq && Norm2(*rq) < Norm2(*r)) {
        p = q;
        r = rq;
        moved = true;
        break;
      }
    }
    if (!moved) {
      // No step improves: either converged to rounding (accept if close) or stuck.
      if (MaxAbs(*r) <= 1e3 * cfg.tolerance_rad) {
        out = {p, iterations, MaxAbs(*r)};
        return true;
      }
      error = FkError::kNoConvergence;
      return false;
    }
  }
  if (MaxAbs(*r) <= cfg.tolerance_rad) {
    out = {p, iterations, MaxAbs(*r)};
    return true;
  }
  error = FkError::kNoConvergence;
  return false;
}

constexpr int kContinuationSteps = 4;

}  // namespace

Vec3 EncodersToTheta(const std::array<std::int16_t, 3>& encoders) {
  Vec3 t{};
  for (std::size_t i = 0; i < 3; ++i)
    t[i] = (kEncoderDegPerCount * static_cast<double>(encoders[i]) + kThetaAtZeroDeg) * kDegToRad;
  return t;
}

double ThetaToEncoder(double theta1_rad) { return (theta1_rad / kDegToRad - kThetaAtZeroDeg) / kEncoderDegPerCount; }

std::optional<std::array<LegAngles, 3>> InverseKinematics(const Vec3& p_m) {
  std::array<LegAngles, 3> legs;
  for (int i = 0; i < 3; ++i) {
    const auto q = LegInverse(i, p_m);
    if (!q) return std::nullopt;
    legs[static_cast<std::size_t>(i)] = *q;
  }
  return legs;
}

Mat3 Jacobian(const std::array<LegAngles, 3>& legs) {
  // From the closed-form forward equations (LegForward): eliminating dθ2 and dθ3 gives
  // a·sin(θ2−θ1)·sinθ3·dθ1 = cosθ2·sinθ3·du + cosθ3·dv + sinθ2·sinθ3·dw.
  Mat3 j{};
  for (std::size_t i = 0; i < 3; ++i) {
    const LegAngles& q = legs[i];
    const double cp = std::cos(kLegPhiRad[i]), sp = std::sin(kLegPhiRad[i]);
    const double s3 = std::sin(q.theta3), c3 = std::cos(q.theta3);
    const double s2 = std::sin(q.theta2), c2 = std::cos(q.theta2);
    const double den = G::a * std::sin(q.theta2 - q.theta1) * s3;
    j[i] = {(cp * c2 * s3 - sp * c3) / den, (sp * c2 * s3 + cp * c3) / den, (s2 * s3) / den};
  }
  return j;
}

std::optional<Mat3> Invert(const Mat3& m) {
  const Mat3 adj = {Vec3{m[1][1] * m[2][2] - m[1][2] * m[2][1], m[0][2] * m[2][1] - m[0][1] * m[2][2],
                         m[0][1] * m[1][2] - m[0][2] * m[1][1]},
                    Vec3{m[1][2] * m[2][0] - m[1][0] * m[2][2], m[0][0] * m[2][2] - m[0][2] * m[2][0],
                         m[0][2] * m[1][0] - m[0][0] * m[1][2]},
                    Vec3{m[1][0] * m[2][1] - m[1][1] * m[2][0], m[0][1] * m[2][0] - m[0][0] * m[2][1],
                         m[0][0] * m[1][1] - m[0][1] * m[1][0]}};
  const double det = m[0][0] * adj[0][0] + m[0][1] * adj[1][0] + m[0][2] * adj[2][0];
  double scale = 1.0;
  for (const Vec3& row : m) scale *= std::sqrt(row[0] * row[0] + row[1] * row[1] + row[2] * row[2]);
  if (!std::isfinite(det) || !(std::fabs(det) > 1e-12 * scale)) return std::nullopt;
  Mat3 inv{};
  for (std::size_t r = 0; r < 3; ++r)
    for (std::size_t c = 0; c < 3; ++c) inv[r][c] = adj[r][c] / det;
  return inv;
}

FkOutcome ForwardKinematics(const Vec3& theta1_rad, const Vec3& warm_start_m, const FkConfig& config) {
  FkOutcome o;
  if (!(std::isfinite(theta1_rad[0]) && std::isfinite(theta1_rad[1]) && std::isfinite(theta1_rad[2]))) {
    o.error = FkError::kOutOfRange;
    return o;
  }
  FkResult r;
  FkError e = FkError::kNoConvergence;
  if (Newton(theta1_rad, warm_start_m, config, r, o.iterations, e)) {
    r.iterations = o.iterations;
    o.result = r;
    return o;
  }
  // Fallback: continuation from the cold start. The measured angles are approached in
  // kContinuationSteps stages, each solved by Newton from the previous stage's pose, so that no
  // single Newton step has to cross the strongly curved far corners of the workspace.
  const auto cold_legs = InverseKinematics(config.cold_start_m);
  if (!cold_legs) {
    o.error = FkError::kOutOfRange;
    return o;
  }
  const Vec3 t0 = {(*cold_legs)[0].theta1, (*cold_legs)[1].theta1, (*cold_legs)[2].theta1};
  Vec3 p = config.cold_start_m;
  FkConfig stage = config;
  for (int k = 1; k <= kContinuationSteps; ++k) {
    const double s = static_cast<double>(k) / kContinuationSteps;
    const Vec3 tk = {t0[0] + (theta1_rad[0] - t0[0]) * s, t0[1] + (theta1_rad[1] - t0[1]) * s,
                     t0[2] + (theta1_rad[2] - t0[2]) * s};
    stage.tolerance_rad = k < kContinuationSteps ? 1e-6 : config.tolerance_rad;
    if (!Newton(tk, p, stage, r, o.iterations, e)) {
      o.error = e;
      return o;
    }
    p = r.p_m;
  }
  r.iterations = o.iterations;
  o.result = r;
  return o;
}

Vec3 LegForward(int leg, const LegAngles& q) {
  const double k = G::d + G::e + G::b * std::sin(q.theta3);
  const double u = G::a * std::cos(q.theta1) + k * std::cos(q.theta2) - G::c;
  const double v = G::b * std::cos(q.theta3) - G::f;
  const double w = G::a * std::sin(q.theta1) + k * std::sin(q.theta2);
  // world = Rz(φ)ᵀ·([u, v, w] + [r, s, 0])
  const double phi = kLegPhiRad[static_cast<std::size_t>(leg)];
  const double cp = std::cos(phi), sp = std::sin(phi);
  const double uu = u + G::r, vv = v + G::s;
  return {cp * uu - sp * vv, sp * uu + cp * vv, w};
}

std::optional<Vec3> ForceToTorque(const Mat3& jacobian, const Vec3& force_n) {
  if (!(std::isfinite(force_n[0]) && std::isfinite(force_n[1]) && std::isfinite(force_n[2]))) return std::nullopt;
  const auto inv = Invert(jacobian);
  if (!inv) return std::nullopt;
  // τ = (J⁻¹)ᵀ·F
  Vec3 tau{};
  for (std::size_t i = 0; i < 3; ++i)
    tau[i] = (*inv)[0][i] * force_n[0] + (*inv)[1][i] * force_n[1] + (*inv)[2][i] * force_n[2];
  return tau;
}

Vec3 TorqueToForce(const Mat3& jacobian, const Vec3& torque_nm) {
  Vec3 f{};
  for (std::size_t c = 0; c < 3; ++c)
    f[c] = jacobian[0][c] * torque_nm[0] + jacobian[1][c] * torque_nm[1] + jacobian[2][c] * torque_nm[2];
  return f;
}

std::array<std::int16_t, 3> TorqueToCounts(const Vec3& torque_nm, bool& saturated) {
  saturated = false;
  std::array<std::int16_t, 3> counts{};
  Vec3 raw{};
  for (std::size_t i = 0; i < 3; ++i) {
    raw[i] = -torque_nm[i] * kCountsPerNm;
    if (!std::isfinite(raw[i])) return counts;  // zero: a bad torque must not move the motors
  }
  const double m = MaxAbs(raw);
  if (m > kMaxCommandCounts) {
    saturated = true;
    // raw/m is exactly ±1 for the largest component, so it lands on ±4095 exactly.
    for (double& x : raw) x = x / m * kMaxCommandCounts;
  }
  for (std::size_t i = 0; i < 3; ++i) {
    // Nearest count (libnifalcon truncates: up to 1 count low); |raw| ≤ 4095 already.
    const double x = std::clamp(std::round(raw[i]), -double{kMaxCommandCounts}, double{kMaxCommandCounts});
    counts[i] = static_cast<std::int16_t>(x);
  }
  return counts;
}

Vec3 CountsToTorque(const std::array<std::int16_t, 3>& counts) {
  return {-counts[0] / kCountsPerNm, -counts[1] / kCountsPerNm, -counts[2] / kCountsPerNm};
}

}  // namespace palpa::falcon
