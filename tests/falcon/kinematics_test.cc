// Falcon kinematics against independent truths: the IK/FK/force vectors of docs/falcon.md §5.3-5.5
// (computed from the published formulas in a separate scratch re-implementation), finite
// differences of IK and of FK over the whole workspace, Eigen's matrix inverse, and virtual work.

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>

#include "palpa/falcon/kinematics.h"

namespace palpa::falcon {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

double Norm(const Vec3& v) { return std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]); }

struct IkVector {
  Vec3 p;
  Vec3 t1, t2, t3;  // degrees
};

TEST(FalconKinematics, EncoderScaleIsTheGearTrain) {
  // 320 slots × 4 per motor turn, capstan 0.01425 m driving an arm sector of 0.110 m diameter.
  EXPECT_NEAR(kEncoderDegPerCount, 0.0364346591, 1e-10);
  const Vec3 t = EncodersToTheta({0, -1000, 1000});
  EXPECT_NEAR(t[0] / kDeg, 35.0, 1e-12);
  EXPECT_NEAR(t[1] / kDeg, -1.4347, 5e-5);
  EXPECT_NEAR(t[2] / kDeg, 71.4347, 5e-5);
  EXPECT_NEAR(ThetaToEncoder(t[1]), -1000.0, 1e-9);
  // ≈ 27.4464 counts per degree.
  EXPECT_NEAR(1.0 / kEncoderDegPerCount, 27.4464, 1e-4);
}

TEST(FalconKinematics, InverseKinematicsMatchesTheNotes) {
  const IkVector vectors[] = {
      {{0, 0, 0.11}, {16.188, 16.188, 16.188}, {131.730, 131.730, 131.730}, {91.068, 91.068, 91.068}},
      {{0, 0, 0.15}, {47.2433, 47.2433, 47.2433}, {122.039, 122.039, 122.039}, {91.068, 91.068, 91.068}},
      {{0.03, 0, 0.11}, {26.6885, -1.2173, 33.9661}, {136.311, 116.952, 141.616}, {107.538, 86.726, 79.145}},
      {{0, 0.03, 0.11}, {-0.9032, 25.5434, 34.7745}, {117.023, 136.116, 141.733}, {95.416, 74.688, 103.038}},
      {{0.02, -0.02, 0.13}, {48.474, 19.908, 34.785}, {136.559, 117.685, 128.009}, {99.010, 99.010, 75.089}},
      {{-0.03, 0.02, 0.10}, {-7.744, 37.649, 10.582}, {118.194, 149.426, 131.047}, {77.668, 84.601, 111.319}},
  };
  for (const IkVector& v : vectors) {
    const auto legs = InverseKinematics(v.p);
    ASSERT_TRUE(legs.has_value());
    for (std::size_t i = 0; i < 3; ++i) {
      // The notes give 3-4 decimals: half a unit of the third decimal plus rounding slack.
      EXPECT_NEAR((*legs)[i].theta1 / kDeg, v.t1[i], 6e-4) << v.p[0] << "," << v.p[1] << "," << v.p[2] << " leg " << i;
      EXPECT_NEAR((*legs)[i].theta2 / kDeg, v.t2[i], 6e-4);
      EXPECT_NEAR((*legs)[i].theta3 / kDeg, v.t3[i], 6e-4);
      // The closed-form forward equations (§3.5) give the position back from each leg's angles.
      const Vec3 back = LegForward(static_cast<int>(i), (*legs)[i]);
      for (std::size_t a = 0; a < 3; ++a) EXPECT_NEAR(back[a], v.p[a], 1e-12);
    }
  }
}

TEST(FalconKinematics, UnreachablePositionsGiveNoAnglesNotNaN) {
  for (const Vec3& p :
       {Vec3{0.06, 0.06, 0.15}, Vec3{0.03, 0.06, 0.17}, Vec3{0.06, 0.03, 0.17}, Vec3{0, 0, 0.5}, Vec3{0.3, 0, 0.1}}) {
    EXPECT_FALSE(InverseKinematics(p).has_value()) << p[0] << "," << p[1] << "," << p[2];
  }
  EXPECT_TRUE(InverseKinematics({0.06, 0.06, 0.11}).has_value());  // the notes: this one is reachable
}

struct FkVector {
  std::array<std::int16_t, 3> enc;
  Vec3 p;
};

TEST(FalconKinematics, ForwardKinematicsMatchesTheNotes) {
  const FkVector vectors[] = {
      {{0, 0, 0}, {0, 0, 0.134602}},
      {{-1000, -1000, -1000}, {0, 0, 0.089611}},
      {{-500, -500, -500}, {0, 0, 0.110754}},
      {{500, 500, 500}, {0, 0, 0.156860}},
      {{1000, 1000, 1000}, {0, 0, 0.173603}},
      {{300, -200, 100}, {0.014528, -0.011579, 0.136148}},
      {{-800, 400, 0}, {-0.026125, 0.030923, 0.120021}},
      {{1200, 200, -300}, {0.004814, -0.064846, 0.131359}},
      {{0, 500, 1000}, {0.012726, 0.038535, 0.149508}},
      {{-300, -300, 600}, {0.027679, 0.029256, 0.126961}},
  };
  for (const FkVector& v : vectors) {
    // Cold (the fixed start) and warm from libnifalcon's (0, 0, 0.11) both land on the same point.
    for (const Vec3& start : {Vec3{0, 0, 0.12}, Vec3{0, 0, 0.11}}) {
      const FkOutcome fk = ForwardKinematics(EncodersToTheta(v.enc), start);
      ASSERT_TRUE(fk.result.has_value()) << v.enc[0] << "," << v.enc[1] << "," << v.enc[2];
      for (std::size_t a = 0; a < 3; ++a) EXPECT_NEAR(fk.result->p_m[a], v.p[a], 6e-7) << a;
      EXPECT_LE(fk.result->residual_rad, 1e-12);
      EXPECT_LE(fk.iterations, 8) << "Newton with the exact Jacobian converges in a few steps";
    }
  }
}

// Positions on a 1 cm grid over the Falcon's reach (x, y ±6 cm, z 7-18 cm) that IK accepts with
// a margin (no pose within 2 mm of a singular or unreachable one).
std::vector<Vec3> WorkspaceGrid() {
  std::vector<Vec3> out;
  for (int ix = -6; ix <= 6; ++ix)
    for (int iy = -6; iy <= 6; ++iy)
      for (int iz = 7; iz <= 18; ++iz) {
        const Vec3 p = {ix * 0.01, iy * 0.01, iz * 0.01};
        bool ok = true;
        for (int k = 0; k < 27 && ok; ++k) {
          const Vec3 q = {p[0] + (k % 3 - 1) * 0.002, p[1] + (k / 3 % 3 - 1) * 0.002, p[2] + (k / 9 - 1) * 0.002};
          const auto legs = InverseKinematics(q);
          ok = legs.has_value() && Invert(Jacobian(*legs)).has_value();
          if (ok)
            for (const LegAngles& l : *legs)
              ok = ok && std::fabs(std::sin(l.theta2 - l.theta1) * std::sin(l.theta3)) > 0.05;
        }
        if (ok) out.push_back(p);
      }
  return out;
}

double ColumnRelError(const Mat3& got, const Mat3& want, std::size_t col) {
  Vec3 d{}, w{};
  for (std::size_t r = 0; r < 3; ++r) {
    d[r] = got[r][col] - want[r][col];
    w[r] = want[r][col];
  }
  return Norm(d) / Norm(w);
}

TEST(FalconKinematics, JacobianMatchesFiniteDifferencesOfIkAcrossTheWorkspace) {
  const auto grid = WorkspaceGrid();
  ASSERT_GT(grid.size(), 500u) << "the grid must cover the workspace";
  const double h = 1e-6;  // m
  double worst[3] = {0, 0, 0};
  for (const Vec3& p : grid) {
    const Mat3 j = Jacobian(*InverseKinematics(p));
    Mat3 fd{};
    for (std::size_t c = 0; c < 3; ++c) {
      Vec3 plus = p, minus = p;
      plus[c] += h;
      minus[c] -= h;
      const auto lp = *InverseKinematics(plus), lm = *InverseKinematics(minus);
      for (std::size_t r = 0; r < 3; ++r) fd[r][c] = (lp[r].theta1 - lm[r].theta1) / (2 * h);
    }
    for (std::size_t c = 0; c < 3; ++c) worst[c] = std::max(worst[c], ColumnRelError(j, fd, c));
  }
  std::printf("[ info ] %zu workspace points; worst relative column error vs FD of IK: %.2e %.2e %.2e\n", grid.size(),
              worst[0], worst[1], worst[2]);
  for (double w : worst) EXPECT_LE(w, 1e-6);
}

TEST(FalconKinematics, InverseJacobianMatchesFiniteDifferencesOfFkAcrossTheWorkspace) {
  // FK is Newton on IK; its converged result does not depend on the Jacobian used for the steps,
  // so its finite differences are an independent check of J⁻¹ (the FK Jacobian).
  const auto grid = WorkspaceGrid();
  const double h = 1e-5;  // rad
  double worst[3] = {0, 0, 0};
  double worst_inverse = 0;
  for (const Vec3& p : grid) {
    const auto legs = *InverseKinematics(p);
    const Mat3 j = Jacobian(legs);
    const Mat3 jinv = *Invert(j);
    // Eigen's LU inverse: an independent 3×3 inversion.
    Eigen::Matrix3d ej;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) ej(r, c) = j[static_cast<std::size_t>(r)][static_cast<std::size_t>(c)];
    const Eigen::Matrix3d einv = ej.inverse();
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c)
        worst_inverse = std::max(
            worst_inverse,
            std::fabs(einv(r, c) - jinv[static_cast<std::size_t>(r)][static_cast<std::size_t>(c)]) / einv.norm());
    const Vec3 theta = {legs[0].theta1, legs[1].theta1, legs[2].theta1};
    Mat3 fd{};
    for (std::size_t c = 0; c < 3; ++c) {
      Vec3 tp = theta, tm = theta;
      tp[c] += h;
      tm[c] -= h;
      const FkOutcome a = ForwardKinematics(tp, p), b = ForwardKinematics(tm, p);
      ASSERT_TRUE(a.result && b.result);
      for (std::size_t r = 0; r < 3; ++r) fd[r][c] = (a.result->p_m[r] - b.result->p_m[r]) / (2 * h);
    }
    for (std::size_t c = 0; c < 3; ++c) worst[c] = std::max(worst[c], ColumnRelError(jinv, fd, c));
  }
  std::printf("[ info ] worst relative column error of J^-1 vs FD of FK: %.2e %.2e %.2e; vs Eigen inverse %.1e\n",
              worst[0], worst[1], worst[2], worst_inverse);
  for (double w : worst) EXPECT_LE(w, 1e-6);
  EXPECT_LE(worst_inverse, 1e-12);
}

TEST(FalconKinematics, TheSinSquaredThirdColumnWouldFailTheCheck) {
  // libnifalcon's z column sin²θ2/den differs from the finite differences by 2-60 %; at
  // (0, 0, 0.11) the notes give FD 13.785 rad/m vs 10.290.
  const Vec3 p = {0, 0, 0.11};
  const auto legs = *InverseKinematics(p);
  const Mat3 j = Jacobian(legs);
  const double h = 1e-6;
  const double fd =
      ((*InverseKinematics({0, 0, 0.11 + h}))[0].theta1 - (*InverseKinematics({0, 0, 0.11 - h}))[0].theta1) / (2 * h);
  EXPECT_NEAR(fd, 13.785, 1e-3);
  EXPECT_NEAR(j[0][2], fd, 1e-6 * fd);
  const LegAngles& q = legs[0];
  const double buggy =
      std::sin(q.theta2) * std::sin(q.theta2) / (Geometry::a * std::sin(q.theta2 - q.theta1) * std::sin(q.theta3));
  EXPECT_NEAR(buggy, 10.290, 1e-3);
  EXPECT_GT(std::fabs(buggy - fd) / fd, 0.2);
}

TEST(FalconKinematics, ForwardKinematicsRoundTripsAndIsBounded) {
  int max_iterations = 0;
  for (const Vec3& p : WorkspaceGrid()) {
    const auto legs = *InverseKinematics(p);
    const FkOutcome fk = ForwardKinematics({legs[0].theta1, legs[1].theta1, legs[2].theta1}, {0, 0, 0.12});
    ASSERT_TRUE(fk.result.has_value()) << p[0] << "," << p[1] << "," << p[2] << " error " << static_cast<int>(fk.error)
                                       << " after " << fk.iterations;
    for (std::size_t a = 0; a < 3; ++a) EXPECT_NEAR(fk.result->p_m[a], p[a], 1e-9);
    max_iterations = std::max(max_iterations, fk.iterations);
  }
  std::printf("[ info ] cold-start FK over the grid: at most %d Newton iterations\n", max_iterations);
  EXPECT_LE(max_iterations, 5 * FkConfig{}.max_iterations);
}

TEST(FalconKinematics, ForwardKinematicsFailsSafe) {
  // Angles no pose has, and non-finite angles: an error, never a NaN or a stale position.
  for (const Vec3& t : {Vec3{150 * kDeg, 150 * kDeg, 150 * kDeg}, Vec3{-80 * kDeg, 100 * kDeg, -80 * kDeg},
                        Vec3{NAN, 0, 0}, Vec3{INFINITY, 0, 0}}) {
    const FkOutcome fk = ForwardKinematics(t, {0, 0, 0.12});
    EXPECT_FALSE(fk.result.has_value());
    EXPECT_LE(fk.iterations, 5 * FkConfig{}.max_iterations);
  }
}

struct ForceVector {
  Vec3 p, f;
  std::array<int, 3> counts;
};

TEST(FalconKinematics, ForceToCountsMatchesTheNotes) {
  // §5.5 "fixed-Jacobian commands" (unclamped, ×10000, truncated); all within ±4095 here.
  const ForceVector vectors[] = {
      {{0, 0, 0.11}, {0, 0, -12.5}, {3022, 3022, 3022}},   {{0, 0, 0.11}, {1, 0, 0}, {-154, 527, -372}},
      {{0, 0, 0.11}, {0, 1, 0}, {519, -125, -393}},        {{0, 0, 0.11}, {0, 0, 10}, {-2418, -2418, -2418}},
      {{0.02, -0.02, 0.13}, {1, 0, 0}, {-190, 531, -436}}, {{0.02, -0.02, 0.13}, {0, 0, -5}, {390, 1909, 1298}},
      {{-0.03, 0.02, 0.10}, {0, 1, 0}, {368, -139, -371}}, {{0, 0.04, 0.12}, {0, 0, 1}, {-437, -197, -54}},
  };
  for (const ForceVector& v : vectors) {
    const Mat3 j = Jacobian(*InverseKinematics(v.p));
    const auto tau = ForceToTorque(j, v.f);
    ASSERT_TRUE(tau.has_value());
    bool saturated = true;
    const auto c = TorqueToCounts(*tau, saturated);
    EXPECT_FALSE(saturated);
    for (std::size_t i = 0; i < 3; ++i) EXPECT_NEAR(c[i], v.counts[i], 1) << "motor " << i;
  }
  // Joint torques at (0, 0, 0.11) for F = (1, 0, 0): (0.0155, −0.0527, 0.0372) N·m.
  const auto tau = *ForceToTorque(Jacobian(*InverseKinematics({0, 0, 0.11})), {1, 0, 0});
  EXPECT_NEAR(tau[0], 0.0155, 1e-4);
  EXPECT_NEAR(tau[1], -0.0527, 1e-4);
  EXPECT_NEAR(tau[2], 0.0372, 1e-4);
}

TEST(FalconKinematics, VirtualWorkRoundTrip) {
  // τ = J⁻ᵀF and F = Jᵀτ are inverse maps; τ·θ̇ = F·ẋ for any ẋ.
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-10, 10);
  for (const Vec3& p : WorkspaceGrid()) {
    const Mat3 j = Jacobian(*InverseKinematics(p));
    const Vec3 f = {u(rng), u(rng), u(rng)};
    const Vec3 tau = *ForceToTorque(j, f);
    const Vec3 back = TorqueToForce(j, tau);
    for (std::size_t a = 0; a < 3; ++a) EXPECT_NEAR(back[a], f[a], 1e-9 * Norm(f));
    const Vec3 xdot = {u(rng), u(rng), u(rng)};
    Vec3 thetadot{};
    for (std::size_t r = 0; r < 3; ++r) thetadot[r] = j[r][0] * xdot[0] + j[r][1] * xdot[1] + j[r][2] * xdot[2];
    const double power_joint = tau[0] * thetadot[0] + tau[1] * thetadot[1] + tau[2] * thetadot[2];
    const double power_cart = f[0] * xdot[0] + f[1] * xdot[1] + f[2] * xdot[2];
    EXPECT_NEAR(power_joint, power_cart, 1e-9 * (1 + std::fabs(power_cart)));
  }
}

TEST(FalconKinematics, SaturationKeepsDirectionAndNeverWraps) {
  // The notes' hazard: F = (0, 0, −150) N at (0, 0, 0.11) is 48 592 counts unclamped, which
  // libnifalcon sent as −16 944 (a reversed push). Here: +4095 on all three motors.
  const Mat3 j0 = Jacobian(*InverseKinematics({0, 0, 0.11}));
  bool saturated = false;
  const auto c = TorqueToCounts(*ForceToTorque(j0, {0, 0, -150}), saturated);
  EXPECT_TRUE(saturated);
  EXPECT_EQ(c, (std::array<std::int16_t, 3>{4095, 4095, 4095}));

  // (0, 0, 0.15), F = (10, 0, 0): unclamped (−2127, 7085, −4958) → scaled so that 7085 → 4095.
  const Mat3 j1 = Jacobian(*InverseKinematics({0, 0, 0.15}));
  const auto s = TorqueToCounts(*ForceToTorque(j1, {10, 0, 0}), saturated);
  EXPECT_TRUE(saturated);
  EXPECT_EQ(s[1], 4095);
  EXPECT_NEAR(s[0], -2127.0 * 4095 / 7085, 1.5);
  EXPECT_NEAR(s[2], -4958.0 * 4095 / 7085, 1.5);

  // Random forces up to 1000 N everywhere: |counts| ≤ 4095, the largest exactly 4095 when
  // saturated, and the direction kept (cross products of counts and raw commands ≈ 0).
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1000, 1000);
  for (const Vec3& p : WorkspaceGrid()) {
    const Mat3 j = Jacobian(*InverseKinematics(p));
    const Vec3 f = {u(rng), u(rng), u(rng)};
    const Vec3 tau = *ForceToTorque(j, f);
    const auto k = TorqueToCounts(tau, saturated);
    Vec3 raw{};
    double m = 0;
    for (std::size_t i = 0; i < 3; ++i) {
      raw[i] = -tau[i] * kCountsPerNm;
      m = std::max(m, std::fabs(raw[i]));
      EXPECT_LE(std::abs(k[i]), kMaxCommandCounts);
      if (raw[i] != 0) {
        EXPECT_TRUE(k[i] == 0 || (k[i] > 0) == (raw[i] > 0)) << "sign flipped";
      }
    }
    if (m > kMaxCommandCounts) {
      EXPECT_TRUE(saturated);
      EXPECT_EQ(std::max({std::abs(k[0]), std::abs(k[1]), std::abs(k[2])}), kMaxCommandCounts);
      for (std::size_t a = 0; a < 3; ++a)
        for (std::size_t b = 0; b < 3; ++b)
          EXPECT_NEAR(k[a] * raw[b] / m, k[b] * raw[a] / m, 2.0);  // truncation: ≤ 1 count each
    }
  }
}

TEST(FalconKinematics, BadForcesGiveZeroTorque) {
  const Mat3 j = Jacobian(*InverseKinematics({0, 0, 0.11}));
  EXPECT_FALSE(ForceToTorque(j, {NAN, 0, 0}).has_value());
  EXPECT_FALSE(ForceToTorque(j, {0, INFINITY, 0}).has_value());
  bool saturated = true;
  EXPECT_EQ(TorqueToCounts({NAN, 1, 1}, saturated), (std::array<std::int16_t, 3>{}));
  EXPECT_EQ(TorqueToCounts({0, 0, 0}, saturated), (std::array<std::int16_t, 3>{}));
  EXPECT_FALSE(saturated);
  const Mat3 singular = {Vec3{1, 2, 3}, Vec3{2, 4, 6}, Vec3{0, 0, 1}};
  EXPECT_FALSE(Invert(singular).has_value());
  EXPECT_FALSE(ForceToTorque(singular, {1, 0, 0}).has_value());
}

}  // namespace
}  // namespace palpa::falcon
