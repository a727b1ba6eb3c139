// Novint Falcon kinematics: encoder counts → joint angles → grip position (forward kinematics by
// Newton), the Jacobian, and Cartesian force → joint torque → motor command counts.
//
// Frame (docs/falcon.md §3.1; libnifalcon FalconKinematicStamper): metres, viewed from the user:
// +x right, +y up, +z toward the user (out of the device); origin inside the device, so the grip
// lives at z ≈ 0.075…0.175 m. Geometry (R. E. Stamper's delta-type mechanism, libnifalcon
// FalconGeometry.h; docs/falcon.md §3.2): three legs at φ = 105°, −15°, −135°; per leg the motor
// angle θ1 (from the encoder), the knee angle θ2 and the parallelogram angle θ3.
//
// Arithmetic: IEEE double (see docs/falcon.md "Fixed or float in the loop" for why not Q16.16).
// Every function is RT-safe (no allocation, no exceptions, bounded loops) and pure except
// ForwardKinematics' warm start, which the caller passes in.
#pragma once

#include <array>
#include <cstdint>
#include <optional>

namespace palpa::falcon {

using Vec3 = std::array<double, 3>;
using Mat3 = std::array<Vec3, 3>;  ///< row-major: m[row][col]

/// Geometry constants, m (libnifalcon include/falcon/core/FalconGeometry.h).
struct Geometry {
  static constexpr double a = 0.060;     ///< leg base to knee (thigh)
  static constexpr double b = 0.1025;    ///< shin parallelogram side
  static constexpr double c = 0.01443;   ///< shin joint to end-effector centre, u component
  static constexpr double d = 0.01125;   ///< shin to end-effector joint
  static constexpr double e = 0.01125;   ///< knee to shin joint
  static constexpr double f = -0.025;    ///< shin joint to end-effector centre, v component
  static constexpr double r = 0.0400;    ///< fixed origin to leg base, u component
  static constexpr double s = -0.02309;  ///< fixed origin to leg base, v component
};

/// Leg angles φ, rad: 90°+15°, −30°+15°, −150°+15° (top, right, left).
inline constexpr std::array<double, 3> kLegPhiRad = {1.8325957145940461, -0.26179938779914941, -2.3561944901923448};

/// Encoder → θ1 (libnifalcon FalconKinematic.h getTheta): 320 slots × 4 (quadrature) per motor
/// turn, capstan 0.01425 m on an arm sector of 0.110 m diameter; θ1 = 35° at encoder 0 (homed).
inline constexpr double kEncoderDegPerCount = 0.01425 * 360.0 / (320.0 * 4.0 * 0.110);  // 0.0364346591°
inline constexpr double kThetaAtZeroDeg = 35.0;

/// Command gain: counts per N·m of joint torque, command = −τ·gain (empirical, libnifalcon
/// FalconKinematicStamper::getForces; Ouellet's "gain 10000"). Positive counts pull the grip in (−z).
inline constexpr double kCountsPerNm = 10000.0;
/// Command saturation, counts (|command| ≤ 4095; notes §2.6: motors saturate at ±4096).
inline constexpr int kMaxCommandCounts = 4095;

/// θ1 of each leg, rad, from encoder counts (homed).
Vec3 EncodersToTheta(const std::array<std::int16_t, 3>& encoders);
/// Encoder count (real, not rounded) for θ1, rad — the inverse of EncodersToTheta per leg.
double ThetaToEncoder(double theta1_rad);

/// Joint angles of one leg, rad.
struct LegAngles {
  double theta1 = 0, theta2 = 0, theta3 = 0;
};

/// Inverse kinematics (libnifalcon FalconKinematicStamper::IK; docs/falcon.md §3.4): the angles
/// of all three legs for grip position `p_m`. nullopt when `p_m` is outside the reachable set
/// (an acos argument beyond ±1, no real root) — never NaN.
std::optional<std::array<LegAngles, 3>> InverseKinematics(const Vec3& p_m);

/// Jacobian J (rad/m): row i = ∂θ1_i/∂(x, y, z) at the pose `legs` (Stamper eq. 4.12 form,
/// docs/falcon.md §3.6, with the correct third column sinθ2·sinθ3 — libnifalcon's sin²θ2 is a
/// transcription error). θ̇1 = J·ẋ.
Mat3 Jacobian(const std::array<LegAngles, 3>& legs);

/// Inverse of a 3×3 matrix by the adjugate; nullopt when |det| ≤ 1e-12·(product of row norms)
/// (singular pose).
std::optional<Mat3> Invert(const Mat3& m);

/// Limits of the forward-kinematics solver.
struct FkConfig {
  int max_iterations = 12;           ///< Newton iterations per start or continuation stage
  int max_halvings = 6;              ///< step halvings per iteration when a step would not improve
  double tolerance_rad = 1e-12;      ///< converged when max |θ1(p) − θ1 measured| ≤ this
  Vec3 cold_start_m = {0, 0, 0.12};  ///< second start when the warm start fails
};

/// Why forward kinematics gave up.
enum class FkError {
  kNoConvergence,  ///< Newton did not reach the tolerance within the bounds from either start
  kSingular,       ///< the Jacobian became singular on the way
  kOutOfRange,     ///< the angles match no reachable pose near the starts
};

struct FkResult {
  Vec3 p_m{};          ///< grip position
  int iterations = 0;  ///< Newton iterations used (both starts)
  double residual_rad = 0;
};

/// Forward kinematics: the grip position whose IK gives the measured θ1 (rad) of all legs.
/// Newton's method on IK(p) = θ1 with the analytic Jacobian, backtracking when a step leaves the
/// reachable set or grows ‖residual‖₂; first from `warm_start_m` (the last solution), then by
/// continuation from config.cold_start_m (the angles approached in 4 stages, Newton at each).
/// Bounded: ≤ 5·max_iterations Newton iterations, each ≤ max_halvings + 2 IK evaluations.
/// Fails safe: an error, never a half-converged position (libnifalcon kept its previous one
/// silently).
struct FkOutcome {
  std::optional<FkResult> result;
  FkError error = FkError::kNoConvergence;  ///< meaningful when !result
  int iterations = 0;
};
FkOutcome ForwardKinematics(const Vec3& theta1_rad, const Vec3& warm_start_m, const FkConfig& config = {});

/// Forward kinematics of one leg from all three of its angles (docs/falcon.md §3.5, the closed
/// form IK inverts): the grip position. Used by tests and the virtual Falcon.
Vec3 LegForward(int leg, const LegAngles& angles);

/// Joint torques τ (N·m) that make the grip push with `force_n` (N): τ = J⁻ᵀ·F (virtual work:
/// τ·θ̇ = F·ẋ with θ̇ = J·ẋ). nullopt at a singular pose or for a non-finite force.
std::optional<Vec3> ForceToTorque(const Mat3& jacobian, const Vec3& force_n);

/// The Cartesian force (N) that joint torques τ (N·m) produce at the grip: F = Jᵀ·τ.
Vec3 TorqueToForce(const Mat3& jacobian, const Vec3& torque_nm);

/// Motor command counts for joint torques τ: −τ·kCountsPerNm, then, if any magnitude exceeds
/// kMaxCommandCounts, all three scaled by the same factor so the largest is exactly 4095 (the
/// torque direction is kept; never a 16-bit wraparound), then rounded to the nearest count
/// (libnifalcon truncates). A non-finite τ gives zero counts. `saturated` tells whether scaling
/// happened.
std::array<std::int16_t, 3> TorqueToCounts(const Vec3& torque_nm, bool& saturated);

/// Joint torque (N·m) a command count stands for: −counts / kCountsPerNm.
Vec3 CountsToTorque(const std::array<std::int16_t, 3>& counts);

}  // namespace palpa::falcon
