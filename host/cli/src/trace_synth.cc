#include <cmath>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include <fmt/core.h>
#include <Eigen/Geometry>

#include "atomic_file.h"
#include "commands.h"
#include "field_sampler.h"
#include "palpa/blob/blob.h"
#include "palpa/trace/trace.h"

namespace palpa::cli {
namespace {

using Eigen::Vector3d;

// Minimum-jerk position profile (Flash & Hogan 1985): s(τ) = 10τ³ − 15τ⁴ + 6τ⁵, τ in [0, 1];
// peak speed 1.875·distance/duration.
double MinimumJerk(double tau) {
  tau = std::clamp(tau, 0.0, 1.0);
  return tau * tau * tau * (10 + tau * (-15 + 6 * tau));
}

constexpr double kStandoffM = 0.010;  // start and end 10 mm off the surface
constexpr double kApproachS = 0.6;    // approach and retract durations
constexpr double kRestS = 0.1;        // still at start and end
constexpr double kHoldS = 0.3;        // poke: held at depth

class TraceBuilder {
 public:
  explicit TraceBuilder(double rate_hz) : dt_(1.0 / rate_hz) {}
  void Rest(double seconds) { Move(last_, seconds); }
  // Minimum-jerk straight move from the current point.
  void Move(const Vector3d& to, double seconds) {
    const Vector3d from = last_;
    const int n = std::max(1, static_cast<int>(std::lround(seconds / dt_)));
    for (int i = 1; i <= n; ++i) Push(from + (to - from) * MinimumJerk(static_cast<double>(i) / n));
  }
  void Start(const Vector3d& p) {
    samples_.clear();
    last_ = p;
    samples_.push_back({0.0, {p[0], p[1], p[2]}});
  }
  void Push(const Vector3d& p) {
    last_ = p;
    samples_.push_back({static_cast<double>(samples_.size()) * dt_, {p[0], p[1], p[2]}});
  }
  const Vector3d& last() const { return last_; }
  double dt() const { return dt_; }
  const std::vector<trace::TraceSample>& samples() const { return samples_; }

 private:
  double dt_;
  Vector3d last_ = Vector3d::Zero();
  std::vector<trace::TraceSample> samples_;
};

}  // namespace

int RunTraceSynth(const TraceSynthArgs& a) {
  auto bytes = blob::ReadFile(a.field.c_str());
  if (!bytes) {
    fmt::print(stderr, "palpa trace synth: {}\n", bytes.error().what());
    return kExitBadInput;
  }
  auto view = blob::Verify(*bytes);
  if (!view) {
    fmt::print(stderr, "palpa trace synth: {}: {}\n", a.field, view.error().what());
    return kExitBadInput;
  }
  const FieldSampler field(*view);
  const Vector3d lo = field.GridMin(), hi = field.GridMax();
  const Vector3d centre = 0.5 * (lo + hi);
  const double diagonal = (hi - lo).norm();

  // Touch point: the first surface hit on a ray towards the grid centre from a direction drawn
  // from the seed (upper hemisphere first, so that seed 1 touches the "top" when +z is up).
  std::mt19937 rng(a.seed);
  std::normal_distribution<double> gauss;
  Vector3d surface, normal;
  bool found = false;
  for (int attempt = 0; attempt < 200 && !found; ++attempt) {
    Vector3d d(gauss(rng), gauss(rng), gauss(rng));
    if (d.norm() < 1e-9) continue;
    d.normalize();
    if (attempt < 100 && d.z() < 0.5) continue;
    Vector3d hit;
    if (!field.RayHit(centre + d * diagonal, -d, 2 * diagonal, hit)) continue;
    const Vector3d g = field.Gradient(hit);
    if (g.norm() < 0.2) continue;
    surface = hit;
    normal = g.normalized();
    found = true;
  }
  if (!found) {
    fmt::print(stderr, "palpa trace synth: {}: no surface (φ = 0) found in the field\n", a.field);
    return kExitBadInput;
  }

  TraceBuilder t(a.rate_hz);
  const Vector3d start = surface + kStandoffM * normal;
  t.Start(start);
  t.Rest(kRestS);
  t.Move(surface - a.depth_m * normal, kApproachS);
  Vector3d end = start;
  if (a.kind == "poke") {
    t.Rest(kHoldS);
  } else {
    // Slide: walk along the surface by arc length, re-projecting onto φ = 0 and keeping the
    // heading tangent; the HIP stays `depth` below the walked surface point.
    Vector3d tangent(gauss(rng), gauss(rng), gauss(rng));
    tangent -= tangent.dot(normal) * normal;
    if (tangent.norm() < 1e-9) tangent = normal.unitOrthogonal();
    tangent.normalize();
    const double duration = 1.875 * a.stroke_m / a.speed_m_s;
    const int n = std::max(1, static_cast<int>(std::lround(duration / t.dt())));
    Vector3d sp = surface, nrm = normal;
    double walked = 0;
    for (int i = 1; i <= n; ++i) {
      const double target = a.stroke_m * MinimumJerk(static_cast<double>(i) / n);
      Vector3d next = sp + (target - walked) * tangent;
      if (!field.Project(next)) break;  // left the band or the grid: stop sliding here
      const Vector3d g = field.Gradient(next);
      if (g.norm() < 0.2) break;
      sp = next;
      walked = target;
      nrm = g.normalized();
      tangent -= tangent.dot(nrm) * nrm;
      tangent.normalize();
      t.Push(sp - a.depth_m * nrm);
    }
    end = sp + kStandoffM * nrm;
  }
  t.Move(end, kApproachS);
  t.Rest(kRestS);

  const std::string comment = fmt::format(
      "palpa trace synth --kind {} --depth {} --length {} --speed {} --rate {} --seed {} on {} (minimum-jerk); "
      "touch point ({:.6f}, {:.6f}, {:.6f}) m, normal ({:.4f}, {:.4f}, {:.4f})",
      a.kind, a.depth_m, a.stroke_m, a.speed_m_s, a.rate_hz, a.seed, a.field, surface.x(), surface.y(), surface.z(),
      normal.x(), normal.y(), normal.z());
  const std::string text = trace::FormatTrace(t.samples(), comment);
  if (auto w = WriteFileAtomically(a.output, std::as_bytes(std::span(text.data(), text.size()))); !w) {
    fmt::print(stderr, "palpa trace synth: {}\n", w.error());
    return kExitIo;
  }
  fmt::print("{}: {} {} samples over {:.3f} s at {} Hz\n", a.output, a.kind, t.samples().size(), t.samples().back().t_s,
             a.rate_hz);
  return kExitOk;
}

}  // namespace palpa::cli
