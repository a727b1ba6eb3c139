// palpa falcon ik X,Y,Z | fk E1,E2,E3: the Falcon's kinematics from the command line, for
// bring-up (checking encoders against a ruler, or a position against the joint angles). Same
// code as palpad's loop (shared/falcon); frame and constants in docs/falcon.md §3.

#include <fmt/core.h>

#include <charconv>
#include <cmath>
#include <numbers>
#include <string>
#include <string_view>

#include "commands.h"
#include "palpa/falcon/kinematics.h"

namespace palpa::cli {
namespace {

constexpr double kDeg = 180.0 / std::numbers::pi;
// FalconConfig's default workspace origin: device frame = kinematic frame − this.
constexpr falcon::Vec3 kWorkspaceOrigin = {0.0, 0.0, 0.125};

// "a,b,c" → three finite numbers; false on anything else.
bool ParseTriple(std::string_view text, std::array<double, 3>& out) {
  for (std::size_t i = 0; i < 3; ++i) {
    const std::size_t comma = text.find(',');
    if ((i < 2) != (comma != std::string_view::npos)) return false;
    const std::string_view part = text.substr(0, comma);
    const auto [ptr, ec] = std::from_chars(part.data(), part.data() + part.size(), out[i]);
    if (part.empty() || ec != std::errc() || ptr != part.data() + part.size() || !std::isfinite(out[i])) return false;
    text = comma == std::string_view::npos ? std::string_view{} : text.substr(comma + 1);
  }
  return true;
}

// Rounds away the sign of values that print as zero ("-0.000000" reads like a bug).
double Clean(double v) { return std::fabs(v) < 5e-7 ? 0.0 : v; }

}  // namespace

int RunFalconIk(const std::string& position) {
  falcon::Vec3 p{};
  if (!ParseTriple(position, p)) {
    fmt::print(stderr, "palpa falcon ik: expected X,Y,Z in metres (Falcon frame), got '{}'\n", position);
    return kExitBadInput;
  }
  const auto legs = falcon::InverseKinematics(p);
  if (!legs) {
    fmt::print(stderr, "palpa falcon ik: ({}, {}, {}) m is outside the Falcon's reach\n", p[0], p[1], p[2]);
    return kExitBadInput;
  }
  const auto& l = *legs;
  fmt::print("position_m: {:.6f} {:.6f} {:.6f}\n", p[0], p[1], p[2]);
  fmt::print("device_frame_m: {:.6f} {:.6f} {:.6f}\n", p[0] - kWorkspaceOrigin[0], p[1] - kWorkspaceOrigin[1],
             p[2] - kWorkspaceOrigin[2]);
  fmt::print("theta1_deg: {:.4f} {:.4f} {:.4f}\n", l[0].theta1 * kDeg, l[1].theta1 * kDeg, l[2].theta1 * kDeg);
  fmt::print("theta2_deg: {:.4f} {:.4f} {:.4f}\n", l[0].theta2 * kDeg, l[1].theta2 * kDeg, l[2].theta2 * kDeg);
  fmt::print("theta3_deg: {:.4f} {:.4f} {:.4f}\n", l[0].theta3 * kDeg, l[1].theta3 * kDeg, l[2].theta3 * kDeg);
  fmt::print("encoders: {:.0f} {:.0f} {:.0f}\n", std::round(falcon::ThetaToEncoder(l[0].theta1)),
             std::round(falcon::ThetaToEncoder(l[1].theta1)), std::round(falcon::ThetaToEncoder(l[2].theta1)));
  return kExitOk;
}

int RunFalconFk(const std::string& encoders) {
  std::array<double, 3> e{};
  if (!ParseTriple(encoders, e)) {
    fmt::print(stderr, "palpa falcon fk: expected E1,E2,E3 (encoder counts), got '{}'\n", encoders);
    return kExitBadInput;
  }
  std::array<std::int16_t, 3> counts{};
  for (std::size_t i = 0; i < 3; ++i) {
    if (e[i] != std::floor(e[i]) || e[i] < -32768 || e[i] > 32767) {
      fmt::print(stderr, "palpa falcon fk: encoder {} = {} is not a 16-bit count\n", i + 1, e[i]);
      return kExitBadInput;
    }
    counts[i] = static_cast<std::int16_t>(e[i]);
  }
  const falcon::Vec3 theta = falcon::EncodersToTheta(counts);
  const falcon::FkOutcome fk = falcon::ForwardKinematics(theta, falcon::FkConfig{}.cold_start_m);
  if (!fk.result) {
    fmt::print(stderr, "palpa falcon fk: no grip position has encoders ({}, {}, {}) (forward kinematics: {})\n",
               counts[0], counts[1], counts[2],
               fk.error == falcon::FkError::kSingular ? "singular pose" : "no convergence");
    return kExitBadInput;
  }
  const falcon::Vec3& p = fk.result->p_m;
  fmt::print("theta1_deg: {:.4f} {:.4f} {:.4f}\n", theta[0] * kDeg, theta[1] * kDeg, theta[2] * kDeg);
  fmt::print("position_m: {:.6f} {:.6f} {:.6f}\n", Clean(p[0]), Clean(p[1]), Clean(p[2]));
  fmt::print("device_frame_m: {:.6f} {:.6f} {:.6f}\n", Clean(p[0] - kWorkspaceOrigin[0]),
             Clean(p[1] - kWorkspaceOrigin[1]), Clean(p[2] - kWorkspaceOrigin[2]));
  fmt::print("newton_iterations: {}\n", fk.iterations);
  return kExitOk;
}

}  // namespace palpa::cli
