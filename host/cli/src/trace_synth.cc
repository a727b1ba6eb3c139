// palpa trace synth: HIP traces from documented models of human motion (docs/trace-format.md):
//  - minimum-jerk point-to-point moves (Flash & Hogan 1985): s(τ) = 10τ³ − 15τ⁴ + 6τ⁵;
//  - curved strokes under the two-thirds power law (Lacquaniti, Terzuolo & Viviani 1983): angular
//    velocity A = K·κ^(2/3), equivalently speed v = K·κ^(−1/3); an ellipse traced with harmonic
//    components obeys it exactly, so strokes are ellipses whose phase advances with a
//    minimum-jerk gain K(t) (rest to rest);
//  - force-constant stroking: the hand presses with a constant force F, so the HIP stays
//    F/k below the surface it slides on (--force, --k);
//  - physiological tremor: 8–12 Hz, sub-millimetre (Elble & Koller 1990), three sinusoids per
//    axis with seeded frequencies in [8, 12] Hz and phases, scaled to an RMS amplitude (--tremor);
//  - fast taps: minimum-jerk down-and-up moves with peak speeds 0.1–0.5 m/s (--speeds).
// Every trace is checked against the reader's rules (workspace, monotonic time) before writing.
#include <algorithm>
#include <cmath>
#include <expected>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include <fmt/core.h>
#include <fmt/format.h>
#include <fmt/ranges.h>
#include <Eigen/Geometry>

#include "commands.h"
#include "palpa/blob/blob.h"
#include "palpa/io/atomic_file.h"
#include "palpa/mesh/field_file.h"
#include "palpa/mesh/field_sampler.h"
#include "palpa/trace/trace.h"

namespace palpa::cli {
namespace {

using Eigen::Vector3d;

// Minimum-jerk position profile, τ in [0, 1]; peak speed 1.875·distance/duration.
double MinimumJerk(double tau) {
  tau = std::clamp(tau, 0.0, 1.0);
  return tau * tau * tau * (10 + tau * (-15 + 6 * tau));
}
constexpr double kMinJerkPeak = 1.875;

constexpr double kStandoffM = 0.010;   // start and end 10 mm off the surface
constexpr double kApproachS = 0.6;     // approach and retract durations
constexpr double kRestS = 0.1;         // still at start and end
constexpr double kHoldS = 0.3;         // poke: held at depth
constexpr double kClearanceM = 0.003;  // free-space moves keep φ ≥ 3 mm (or beyond the band)

struct SynthError {
  std::string message;
};

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
  // Minimum-jerk move whose peak speed is `speed_m_s`.
  void MoveAtPeak(const Vector3d& to, double speed_m_s) {
    Move(to, std::max(kMinJerkPeak * (to - last_).norm() / speed_m_s, 2 * dt_));
  }
  void Start(const Vector3d& p) {
    samples_.clear();
    last_ = p;
    samples_.push_back({0.0, {p[0], p[1], p[2]}, 0});
  }
  void Push(const Vector3d& p) {
    last_ = p;
    samples_.push_back({static_cast<double>(samples_.size()) * dt_, {p[0], p[1], p[2]}, 0});
  }
  const Vector3d& last() const { return last_; }
  double dt() const { return dt_; }
  std::vector<trace::TraceSample>& samples() { return samples_; }

 private:
  double dt_;
  Vector3d last_ = Vector3d::Zero();
  std::vector<trace::TraceSample> samples_;
};

struct Touch {
  Vector3d surface, normal;
  Vector3d ray;  // unit: the touch point was the first hit coming from surface + s·ray, s > 0
};

class Synth {
 public:
  Synth(const TraceSynthArgs& a, const mesh::FieldSampler& field)
      : a_(a), field_(field), rng_(a.seed), t_(a.rate_hz), lo_(field.GridMin()), hi_(field.GridMax()) {
    centre_ = 0.5 * (lo_ + hi_);
    diagonal_ = (hi_ - lo_).norm();
  }

  std::optional<SynthError> Run(std::string& note) {
    const std::string& k = a_.kind;
    std::optional<SynthError> e;
    if (k == "poke" || k == "stroke")
      e = PokeOrStroke(note);
    else if (k == "strokes")
      e = Strokes(note);
    else if (k == "poke-grid")
      e = PokeGrid(note);
    else if (k == "taps")
      e = Taps(note);
    else if (k == "pass-through")
      e = PassThrough(note);
    else if (k == "free")
      e = Free(note);
    else if (k == "excursion")
      e = Excursion(note);
    else
      e = SynthError{"unknown kind '" + k + "'"};
    if (e) return e;
    AddTremor();
    return std::nullopt;
  }

  std::vector<trace::TraceSample>& samples() { return t_.samples(); }

 private:
  double Depth() const { return a_.force_n ? *a_.force_n / a_.k_n_per_m : a_.depth_m; }

  // The first surface hit on a ray towards the grid centre from direction `d`.
  std::optional<Touch> TouchFrom(Vector3d d) const {
    if (d.norm() < 1e-9) return std::nullopt;
    d.normalize();
    Vector3d hit;
    if (!field_.RayHit(centre_ + d * diagonal_, -d, 2 * diagonal_, hit)) return std::nullopt;
    const Vector3d g = field_.Gradient(hit);
    if (g.norm() < 0.2) return std::nullopt;
    return Touch{hit, g.normalized(), d};
  }

  // A touch direction drawn from the seed, upper hemisphere (+z) first.
  std::optional<Touch> RandomTouch() {
    std::normal_distribution<double> gauss;
    for (int attempt = 0; attempt < 200; ++attempt) {
      Vector3d d(gauss(rng_), gauss(rng_), gauss(rng_));
      if (d.norm() < 1e-9) continue;
      d.normalize();
      if (attempt < 100 && d.z() < 0.5) continue;
      if (auto t = TouchFrom(d)) return t;
    }
    return std::nullopt;
  }

  // φ saturates at +band·voxel beyond the band: "clear" is 3 mm or beyond the band, whichever is nearer.
  double Clearance() const { return std::min(kClearanceM, 0.95 * BandVoxels() * field_.voxel_m()); }

  // Smallest φ along the segment, sampled every ½ voxel.
  double MinPhiAlong(const Vector3d& a, const Vector3d& b) const {
    const int n = std::max(1, static_cast<int>(std::ceil((b - a).norm() / (0.5 * field_.voxel_m()))));
    double m = field_.Phi(a);
    for (int i = 1; i <= n; ++i) m = std::min(m, field_.Phi(a + (b - a) * (static_cast<double>(i) / n)));
    return m;
  }

  // A free-space trip: straight if clear, else out along the rays from the grid centre, across,
  // and back in, lifting further until every leg is clear.
  // `from_dir`/`to_dir` (unit, optional): the lift directions, e.g. the surface normals there.
  std::optional<SynthError> TravelTo(const Vector3d& to, double speed_m_s, const Vector3d* from_dir = nullptr,
                                     const Vector3d* to_dir = nullptr) {
    const Vector3d from = t_.last();
    if (MinPhiAlong(from, to) >= Clearance()) return FreeMove(to, speed_m_s);
    Vector3d lo, hi;
    TravelBox(lo, hi);
    auto lift = [&](const Vector3d& p, const Vector3d* dir, double by) {
      Vector3d d = (p - centre_).norm() > 1e-9 ? (p - centre_).normalized() : Vector3d(0, 0, 1);
      if (dir != nullptr) d = *dir;
      return Vector3d((p + by * d).cwiseMax(lo).cwiseMin(hi));
    };
    for (double by = 0.005; by <= 0.04; by += 0.005) {
      const Vector3d a = lift(from, from_dir, by), b = lift(to, to_dir, by);
      if (MinPhiAlong(from, a) >= Clearance() && MinPhiAlong(a, b) >= Clearance() &&
          MinPhiAlong(b, to) >= Clearance()) {
        t_.MoveAtPeak(a, speed_m_s);
        t_.MoveAtPeak(b, speed_m_s);
        t_.MoveAtPeak(to, speed_m_s);
        return std::nullopt;
      }
    }
    // Over the roof: up, across above the grid, down.
    const double roof = std::min(hi_.z() + 0.005, hi.z());
    const Vector3d a(from.x(), from.y(), roof), b(to.x(), to.y(), roof);
    if (MinPhiAlong(from, a) >= Clearance() && MinPhiAlong(a, b) >= Clearance() && MinPhiAlong(b, to) >= Clearance()) {
      t_.MoveAtPeak(a, speed_m_s);
      t_.MoveAtPeak(b, speed_m_s);
      t_.MoveAtPeak(to, speed_m_s);
      return std::nullopt;
    }
    return FreeMove(to, speed_m_s);  // reports the blocked move
  }

  // Where the ray p + s·dir (s ≥ 0) leaves the grid, 3 mm beyond, kept inside the travel box.
  Vector3d ExitAlong(const Vector3d& p, const Vector3d& dir) const {
    double s_min = 1.0;  // the first face crossed
    for (int k = 0; k < 3; ++k) {
      if (dir[k] > 1e-9) s_min = std::min(s_min, (hi_[k] - p[k]) / dir[k]);
      if (dir[k] < -1e-9) s_min = std::min(s_min, (lo_[k] - p[k]) / dir[k]);
    }
    Vector3d lo, hi;
    TravelBox(lo, hi);
    return Vector3d((p + (std::max(s_min, 0.0) + 0.003) * dir).cwiseMax(lo).cwiseMin(hi));
  }

  // A free-space move: refuses to cut through the object.
  std::optional<SynthError> FreeMove(const Vector3d& to, double speed_m_s) {
    if (MinPhiAlong(t_.last(), to) < Clearance())
      return SynthError{
          fmt::format("the free-space move to ({:.4f}, {:.4f}, {:.4f}) m would pass within {:.2f} mm "
                      "of the surface",
                      to.x(), to.y(), to.z(), 1e3 * Clearance())};
    t_.MoveAtPeak(to, speed_m_s);
    return std::nullopt;
  }

  // A random touch point, with the trace started at rest kStandoffM above it along the normal.
  std::expected<Touch, SynthError> StartAboveRandomTouch() {
    auto touch = RandomTouch();
    if (!touch) return std::unexpected(SynthError{"no surface (φ = 0) found in the field"});
    t_.Start(touch->surface + kStandoffM * touch->normal);
    t_.Rest(kRestS);
    return *touch;
  }

  std::optional<SynthError> PokeOrStroke(std::string& note) {
    const auto touch = StartAboveRandomTouch();
    if (!touch) return touch.error();
    const Vector3d surface = touch->surface, normal = touch->normal;
    const Vector3d start = surface + kStandoffM * normal;
    t_.Move(surface - Depth() * normal, kApproachS);
    Vector3d end = start;
    if (a_.kind == "poke") {
      t_.Rest(kHoldS);
    } else {
      // Slide: walk along the surface by arc length, re-projecting onto φ = 0 and keeping the
      // heading tangent; the HIP stays `depth` below the walked surface point.
      std::normal_distribution<double> gauss;
      Vector3d tangent(gauss(rng_), gauss(rng_), gauss(rng_));
      tangent -= tangent.dot(normal) * normal;
      if (tangent.norm() < 1e-9) tangent = normal.unitOrthogonal();
      tangent.normalize();
      const double duration = kMinJerkPeak * a_.stroke_m / a_.speed_m_s;
      const int n = std::max(1, static_cast<int>(std::lround(duration / t_.dt())));
      Vector3d sp = surface, nrm = normal;
      double walked = 0;
      for (int i = 1; i <= n; ++i) {
        const double target = a_.stroke_m * MinimumJerk(static_cast<double>(i) / n);
        Vector3d next = sp + (target - walked) * tangent;
        if (!field_.Project(next)) break;  // left the band or the grid: stop sliding here
        const Vector3d g = field_.Gradient(next);
        if (g.norm() < 0.2) break;
        sp = next;
        walked = target;
        nrm = g.normalized();
        tangent -= tangent.dot(nrm) * nrm;
        tangent.normalize();
        t_.Push(sp - Depth() * nrm);
      }
      end = sp + kStandoffM * nrm;
    }
    t_.Move(end, kApproachS);
    t_.Rest(kRestS);
    note = fmt::format("touch point ({:.6f}, {:.6f}, {:.6f}) m, normal ({:.4f}, {:.4f}, {:.4f})", surface.x(),
                       surface.y(), surface.z(), normal.x(), normal.y(), normal.z());
    return std::nullopt;
  }

  // Ellipse strokes at each depth, one lap per depth, in contact throughout (paper Fig. 9 style).
  std::optional<SynthError> Strokes(std::string& note) {
    auto touch = RandomTouch();
    if (!touch) return SynthError{"no surface (φ = 0) found in the field"};
    const auto [surface, normal, ray_unused] = *touch;
    (void)ray_unused;
    const double ax = 0.5 * a_.stroke_m, bx = 0.25 * a_.stroke_m;  // semi-axes, m
    // The ellipse is laid on the surface by walking: each planar step (du, dv) is taken in the
    // current tangent frame, then re-projected onto φ = 0 (the frame is transported along).
    Vector3d sp = surface, nrm = normal, fu = normal.unitOrthogonal();
    double last_theta = 0;
    auto step_to = [&](double theta) {
      const double du = ax * (std::cos(theta) - std::cos(last_theta));
      const double dv = bx * (std::sin(theta) - std::sin(last_theta));
      last_theta = theta;
      Vector3d next = sp + du * fu + dv * nrm.cross(fu);
      if (!field_.Project(next)) return false;
      const Vector3d g = field_.Gradient(next);
      if (g.norm() < 0.2) return false;
      sp = next;
      nrm = g.normalized();
      fu = (fu - fu.dot(nrm) * nrm).normalized();
      return true;
    };
    // Ramanujan's perimeter; the lap lasts so that the peak speed is --speed.
    const double h = std::pow(ax - bx, 2) / std::pow(ax + bx, 2);
    const double perimeter = std::numbers::pi * (ax + bx) * (1 + 3 * h / (10 + std::sqrt(4 - 3 * h)));
    const double lap_s = kMinJerkPeak * perimeter / a_.speed_m_s * 1.3;  // 1.3: ellipse speed varies ±(a/b)^(1/3)

    t_.Start(surface + kStandoffM * normal);
    t_.Rest(kRestS);
    std::vector<double> depths = a_.depths;
    if (depths.empty()) depths = {Depth()};
    t_.Move(surface - depths.front() * normal, kApproachS);
    for (std::size_t d = 0; d < depths.size(); ++d) {
      if (d > 0) t_.Move(sp - depths[d] * nrm, 0.4);  // press deeper in place
      const int n = std::max(1, static_cast<int>(std::lround(lap_s / t_.dt())));
      for (int i = 1; i <= n; ++i) {
        const double theta = 2 * std::numbers::pi * MinimumJerk(static_cast<double>(i) / n);
        if (!step_to(theta)) return SynthError{"the stroke ellipse leaves the narrow band (use a shorter --length)"};
        t_.Push(sp - depths[d] * nrm);
      }
    }
    t_.Move(sp + kStandoffM * nrm, kApproachS);
    t_.Rest(kRestS);
    note = fmt::format(
        "touch point ({:.6f}, {:.6f}, {:.6f}) m, normal ({:.4f}, {:.4f}, {:.4f}); ellipse {:.1f} x {:.1f} mm, "
        "lap {:.2f} s, depths {} m",
        surface.x(), surface.y(), surface.z(), normal.x(), normal.y(), normal.z(), 2e3 * ax, 2e3 * bx, lap_s,
        fmt::join(depths, ","));
    return std::nullopt;
  }

  // A grid of vertical pokes over the object's x-y extent, travelling above the grid.
  std::optional<SynthError> PokeGrid(std::string& note) {
    const int side = std::max(1, static_cast<int>(std::lround(std::sqrt(static_cast<double>(a_.count)))));
    const double margin = 0.2;  // stay off the outer fifth of the grid (empty margin)
    const double travel_z = std::min(hi_.z() + 0.005, trace::kFalconWorkspace.max_m[2] - 0.002);
    int pokes = 0;
    bool started = false;
    for (int j = 0; j < side; ++j) {
      for (int ii = 0; ii < side; ++ii) {
        const int i = (j % 2 == 0) ? ii : side - 1 - ii;  // boustrophedon: short travel moves
        const double fx = side == 1 ? 0.5 : margin + (1 - 2 * margin) * i / (side - 1.0);
        const double fy = side == 1 ? 0.5 : margin + (1 - 2 * margin) * j / (side - 1.0);
        const Vector3d above(lo_.x() + fx * (hi_.x() - lo_.x()), lo_.y() + fy * (hi_.y() - lo_.y()), travel_z);
        Vector3d hit;
        if (!field_.RayHit(above, Vector3d(0, 0, -1), travel_z - lo_.z(), hit)) continue;
        const Vector3d g = field_.Gradient(hit);
        if (g.norm() < 0.2) continue;
        const Vector3d n = g.normalized();
        if (!started) {
          t_.Start(above);
          t_.Rest(kRestS);
          started = true;
        } else if (auto e = TravelTo(above, a_.speed_m_s)) {
          return e;
        }
        t_.Move(hit + Vector3d(0, 0, kStandoffM), 0.25);
        t_.Move(hit - Depth() * n, 0.3);
        t_.Rest(0.1);
        t_.Move(hit + Vector3d(0, 0, kStandoffM), 0.3);
        t_.Move(above, 0.2);
        ++pokes;
      }
    }
    if (pokes == 0) return SynthError{"no poke of the grid hits the surface"};
    t_.Rest(kRestS);
    note = fmt::format("{} pokes on a {}x{} grid, travel at z = {:.4f} m, depth {} m", pokes, side, side, travel_z,
                       Depth());
    return std::nullopt;
  }

  std::vector<double> Speeds() const {
    if (!a_.speeds.empty()) return a_.speeds;
    std::vector<double> s;
    const int n = std::max(1, a_.count);
    for (int i = 0; i < n; ++i) s.push_back(n == 1 ? 0.3 : 0.1 + 0.4 * i / (n - 1.0));  // 0.1..0.5 m/s
    return s;
  }

  // Fast taps on one touch point, one per speed.
  std::optional<SynthError> Taps(std::string& note) {
    auto touch = RandomTouch();
    if (!touch) return SynthError{"no surface (φ = 0) found in the field"};
    const auto [surface, normal, ray_unused] = *touch;
    (void)ray_unused;
    const Vector3d up = surface + 0.5 * kStandoffM * normal;
    t_.Start(surface + kStandoffM * normal);
    t_.Rest(kRestS);
    t_.Move(up, 0.3);
    const auto speeds = Speeds();
    for (const double s : speeds) {
      t_.MoveAtPeak(surface - Depth() * normal, s);
      t_.MoveAtPeak(up, s);
      t_.Rest(0.15);
    }
    t_.Move(surface + kStandoffM * normal, 0.3);
    t_.Rest(kRestS);
    note = fmt::format("touch point ({:.6f}, {:.6f}, {:.6f}) m; taps from 5 mm to {} m deep at peak speeds {} m/s",
                       surface.x(), surface.y(), surface.z(), Depth(), fmt::join(speeds, ","));
    return std::nullopt;
  }

  // Attempts to push straight through a thin part: in along −n, out past the far side, back.
  std::optional<SynthError> PassThrough(std::string& note) {
    const auto speeds = Speeds();
    std::string where;
    bool started = false;
    Vector3d last_out, last_ray;
    for (std::size_t attempt = 0; attempt < speeds.size(); ++attempt) {
      std::optional<Touch> touch;
      double thickness = 0;
      for (int tries = 0; tries < 100 && !touch; ++tries) {
        touch = RandomTouch();
        if (!touch) break;
        // Far side: φ back above 0 along −n within 80 mm (a thin part, or a whole object).
        thickness = 0;
        for (double s = field_.voxel_m(); s < 0.08; s += 0.1 * field_.voxel_m()) {
          if (field_.Phi(touch->surface - s * touch->normal) > 0) {
            thickness = s;
            break;
          }
        }
        if (thickness == 0) {
          touch.reset();
          continue;
        }
        // The approach along the touch ray must be clear from the grid face to the start point.
        const Vector3d start = touch->surface + kStandoffM * touch->ray;
        if (MinPhiAlong(ExitAlong(start, touch->ray), start) < Clearance()) touch.reset();
      }
      if (!touch) return SynthError{"no part to pass through found (the far side must be within 80 mm)"};
      const auto [surface, normal, ray] = *touch;
      // Attempts start on the touch ray (free by construction, it came from outside the grid),
      // and travel between attempts leaves the grid along it and comes back along the next.
      const Vector3d out = surface + kStandoffM * ray;
      const Vector3d beyond = surface - (thickness + a_.through_m) * normal;
      if (!started) {
        t_.Start(out);
        t_.Rest(kRestS);
        started = true;
      } else {
        if (auto e = FreeMove(ExitAlong(last_out, last_ray), 0.1)) return e;
        if (auto e = TravelTo(ExitAlong(out, ray), 0.1)) return e;
        if (auto e = FreeMove(out, 0.1)) return e;
      }
      last_out = out;
      last_ray = ray;
      t_.MoveAtPeak(beyond, speeds[attempt]);
      t_.Rest(0.1);
      t_.MoveAtPeak(out, speeds[attempt]);
      t_.Rest(0.1);
      where += fmt::format("{}({:.4f},{:.4f},{:.4f}) thick {:.2f} mm at {} m/s", where.empty() ? "" : "; ", surface.x(),
                           surface.y(), surface.z(), 1e3 * thickness, speeds[attempt]);
    }
    t_.Rest(kRestS);
    note = "pass-through attempts, " + fmt::format("{} m past the far side: ", a_.through_m) + where;
    return std::nullopt;
  }

  // A point of the box [lo, hi] drawn uniformly, with φ ≥ clearance.
  std::optional<Vector3d> FreePoint(const Vector3d& lo, const Vector3d& hi) {
    std::uniform_real_distribution<double> u01(0.0, 1.0);
    for (int tries = 0; tries < 1000; ++tries) {
      const Vector3d p(lo.x() + u01(rng_) * (hi.x() - lo.x()), lo.y() + u01(rng_) * (hi.y() - lo.y()),
                       lo.z() + u01(rng_) * (hi.z() - lo.z()));
      if (MinPhiAlong(t_.samples().empty() ? p : t_.last(), p) >= Clearance()) return p;
    }
    return std::nullopt;
  }

  double BandVoxels() const {
    // The background outside the band is +band·voxel: far from the surface φ saturates there.
    return field_.Phi(hi_ + Vector3d::Constant(1.0)) / field_.voxel_m();
  }

  // Box around the grid, 10 mm larger, within the workspace (2 mm inside its faces).
  void TravelBox(Vector3d& lo, Vector3d& hi) const {
    for (int k = 0; k < 3; ++k) {
      const auto kk = static_cast<std::size_t>(k);
      lo[k] = std::max(lo_[k] - 0.01, trace::kFalconWorkspace.min_m[kk] + 0.002);
      hi[k] = std::min(hi_[k] + 0.01, trace::kFalconWorkspace.max_m[kk] - 0.002);
    }
  }

  // Free-space motion between waypoints that never come near the surface.
  std::optional<SynthError> Free(std::string& note) {
    Vector3d lo, hi;
    TravelBox(lo, hi);
    const int n = std::max(2, a_.count);
    for (int i = 0; i < n; ++i) {
      std::optional<Vector3d> p;
      for (int tries = 0; tries < 50 && !p; ++tries) p = FreePoint(lo, hi);
      if (!p) return SynthError{"no free-space waypoint found"};
      if (i == 0) {
        t_.Start(*p);
        t_.Rest(kRestS);
      } else {
        t_.MoveAtPeak(*p, a_.speed_m_s);
        t_.Rest(0.05);
      }
    }
    t_.Rest(kRestS);
    note =
        fmt::format("{} free-space waypoints in [{:.3f},{:.3f}]x[{:.3f},{:.3f}]x[{:.3f},{:.3f}] m, clearance {:.2f} mm",
                    n, lo.x(), hi.x(), lo.y(), hi.y(), lo.z(), hi.z(), 1e3 * Clearance());
    return std::nullopt;
  }

  // Grid-edge crossings and a poke deeper than the narrow band.
  std::optional<SynthError> Excursion(std::string& note) {
    const auto touch = StartAboveRandomTouch();
    if (!touch) return touch.error();
    const Vector3d surface = touch->surface, normal = touch->normal;
    const Vector3d start = surface + kStandoffM * normal;
    // 1. Out of the grid through each face the workspace leaves room beyond, and back.
    Vector3d lo, hi;
    TravelBox(lo, hi);
    int crossings = 0;
    for (int axis = 0; axis < 3; ++axis) {
      for (const int side : {1, -1}) {
        Vector3d out = start;
        out[axis] = side > 0 ? hi[axis] : lo[axis];
        const bool leaves = side > 0 ? out[axis] > hi_[axis] : out[axis] < lo_[axis];
        if (!leaves) continue;
        if (MinPhiAlong(start, out) < Clearance()) continue;
        if (auto e = FreeMove(out, a_.speed_m_s)) return e;
        t_.Rest(0.05);
        if (auto e = FreeMove(start, a_.speed_m_s)) return e;
        ++crossings;
      }
    }
    if (crossings == 0) return SynthError{"no grid face can be crossed from the touch point"};
    // 2. A poke deeper than the narrow band (the field is flat at −band·voxel there).
    const double band_m = BandVoxels() * field_.voxel_m();
    const double deep = band_m + std::max(Depth(), 0.001);
    t_.Move(surface - deep * normal, 0.8);
    t_.Rest(kHoldS);
    t_.Move(start, 0.8);
    t_.Rest(kRestS);
    note = fmt::format(
        "touch point ({:.6f}, {:.6f}, {:.6f}) m; {} grid-face crossings to the travel box, then a poke {:.2f} mm "
        "deep (band {:.2f} mm)",
        surface.x(), surface.y(), surface.z(), crossings, 1e3 * deep, 1e3 * band_m);
    return std::nullopt;
  }

  void AddTremor() {
    if (a_.tremor_m <= 0) return;
    std::uniform_real_distribution<double> freq(8.0, 12.0), phase(0.0, 2 * std::numbers::pi);
    struct Wave {
      double w, p;
    };
    Wave waves[3][3];
    for (auto& axis : waves)
      for (auto& wave : axis) wave = {2 * std::numbers::pi * freq(rng_), phase(rng_)};
    const double c = a_.tremor_m / std::sqrt(4.5);  // 9 sinusoids of amplitude c: RMS |d| = tremor
    for (auto& s : t_.samples())
      for (std::size_t k = 0; k < 3; ++k)
        for (const Wave& wave : waves[k]) s.hip_m[k] += c * std::sin(wave.w * s.t_s + wave.p);
  }

  const TraceSynthArgs& a_;
  const mesh::FieldSampler& field_;
  std::mt19937 rng_;
  TraceBuilder t_;
  Vector3d lo_, hi_, centre_;
  double diagonal_ = 0;
};

}  // namespace

int RunTraceSynth(const TraceSynthArgs& a) {
  if (const int refused = CheckOutput("trace synth", a.output, {a.field}); refused != kExitOk) return refused;
  const auto loaded = mesh::LoadField(a.field);  // v2 sampled in place
  if (!loaded) {
    fmt::print(stderr, "palpa trace synth: {}\n", loaded.error().message);
    return kExitBadInput;
  }
  const mesh::FieldSampler field(loaded->view());
  Synth synth(a, field);
  std::string note;
  if (auto e = synth.Run(note)) {
    fmt::print(stderr, "palpa trace synth: {}: {}\n", a.field, e->message);
    return kExitBadInput;
  }
  auto& samples = synth.samples();
  if (!a.button_window.empty()) {
    if (!(a.button_window[0] < a.button_window[1])) {
      fmt::print(stderr, "palpa trace synth: --button {},{}: the window is empty\n", a.button_window[0],
                 a.button_window[1]);
      return kExitBadInput;
    }
    for (auto& s : samples)
      if (s.t_s >= a.button_window[0] && s.t_s < a.button_window[1])
        s.buttons = static_cast<std::uint8_t>(s.buttons | (1u << a.button_bit));
  }
  if (auto ok = trace::CheckSamples(samples); !ok) {
    fmt::print(stderr, "palpa trace synth: the {} trace breaks the trace rules: {}\n", a.kind, ok.error().message);
    return kExitBadInput;
  }

  std::string command = fmt::format("palpa trace synth --kind {} --rate {} --seed {}", a.kind, a.rate_hz, a.seed);
  if (a.force_n)
    command += fmt::format(" --force {} --k {}", *a.force_n, a.k_n_per_m);
  else
    command += fmt::format(" --depth {}", a.depth_m);
  if (!a.depths.empty()) command += fmt::format(" --depths {}", fmt::join(a.depths, ","));
  if (!a.speeds.empty()) command += fmt::format(" --speeds {}", fmt::join(a.speeds, ","));
  command += fmt::format(" --length {} --speed {} --count {} --through {} --tremor {}", a.stroke_m, a.speed_m_s,
                         a.count, a.through_m, a.tremor_m);
  if (!a.button_window.empty())
    command += fmt::format(" --button {},{} --button-bit {}", a.button_window[0], a.button_window[1], a.button_bit);
  // The field by file name only, so the trace does not depend on where it was built.
  const std::string comment = command + "\nfield " + a.field.substr(a.field.find_last_of('/') + 1) + "\n" + note;

  const bool binary = a.output.ends_with(".ptb");
  std::string out;
  if (binary) {
    auto encoded = trace::EncodeBinaryTrace(samples, comment);
    if (!encoded) {
      fmt::print(stderr, "palpa trace synth: {}: {}\n", a.output, encoded.error().message);
      return kExitBadInput;
    }
    out = std::move(*encoded);
  } else {
    out = trace::FormatTrace(samples, comment);
  }
  if (auto w =
          io::WriteFileAtomically(a.output, std::as_bytes(std::span(out.data(), out.size())), {.inputs = {a.field}});
      !w) {
    fmt::print(stderr, "palpa trace synth: {}\n", w.error());
    return kExitIo;
  }
  fmt::print("{}: {} {} samples over {:.3f} s at {} Hz ({} bytes, {})\n", a.output, a.kind, samples.size(),
             samples.back().t_s, a.rate_hz, out.size(), binary ? "binary v2" : "text v2");
  return kExitOk;
}

namespace {

// A regular file of at most 64 MB, whole (recordings at 1 kHz are ~40 bytes a sample).
std::expected<std::string, std::string> ReadSmallTextFile(const std::string& path) {
  std::error_code ec;
  const auto status = std::filesystem::status(path, ec);
  if (ec || !std::filesystem::is_regular_file(status)) return std::unexpected(path + ": not a regular file");
  const auto size = std::filesystem::file_size(path, ec);
  if (ec || size > (std::uintmax_t{64} << 20)) return std::unexpected(path + ": larger than 64 MB or unreadable");
  std::ifstream in(path, std::ios::binary);
  std::string text(static_cast<std::size_t>(size), '\0');
  if (!in.read(text.data(), static_cast<std::streamsize>(size))) return std::unexpected(path + ": read failed");
  return text;
}

}  // namespace

int RunTraceImport(const TraceImportArgs& a) {
  const auto fail = [&](const std::string& m) {
    fmt::print(stderr, "palpa trace import: {}\n", m);
    return kExitBadInput;
  };
  auto text = ReadSmallTextFile(a.input);
  if (!text) return fail(text.error());
  // Rows after the header: t_s,x_m,y_m,z_m, finite, time strictly increasing; the window only.
  std::vector<trace::TraceSample> rows;
  std::size_t pos = 0, line = 0;
  while (pos < text->size()) {
    std::size_t end = text->find('\n', pos);
    if (end == std::string::npos) end = text->size();
    const std::string row = text->substr(pos, end - pos);
    pos = end + 1;
    if (++line == 1) {
      if (!row.starts_with("t_s,x_m,y_m,z_m")) return fail(fmt::format("{}:1: header is not t_s,x_m,y_m,z_m", a.input));
      continue;
    }
    if (row.empty() || row == "\r") continue;
    double v[4];
    const char* p = row.c_str();
    for (int i = 0; i < 4; ++i) {
      char* next = nullptr;
      v[i] = std::strtod(p, &next);
      if (next == p || !std::isfinite(v[i]) || (i < 3 && *next != ','))
        return fail(fmt::format("{}:{}: not a row of four numbers", a.input, line));
      p = next + 1;
    }
    if (!rows.empty() && !(v[0] > rows.back().t_s) && v[0] >= a.from_s)
      return fail(fmt::format("{}:{}: time {} s does not increase", a.input, line, v[0]));
    if (v[0] < a.from_s || (a.duration_s > 0 && v[0] > a.from_s + a.duration_s)) continue;
    rows.push_back({v[0], {v[1], v[2], v[3]}, 0});
  }
  if (rows.size() < 2) return fail(fmt::format("{}: fewer than 2 samples in the window", a.input));
  Vector3d lo = Vector3d::Constant(1e300), hi = -lo;
  for (const auto& r : rows)
    for (int k = 0; k < 3; ++k) {
      lo[k] = std::min(lo[k], r.hip_m[static_cast<std::size_t>(k)]);
      hi[k] = std::max(hi[k], r.hip_m[static_cast<std::size_t>(k)]);
    }
  const Vector3d centre = 0.5 * (lo + hi);
  const Vector3d offset =
      a.offset_m.size() == 3 ? Vector3d(a.offset_m[0], a.offset_m[1], a.offset_m[2]) : Vector3d::Zero();
  const double t0 = rows.front().t_s;
  for (auto& r : rows) {
    r.t_s -= t0;
    for (std::size_t k = 0; k < 3; ++k)
      r.hip_m[k] = a.scale * (r.hip_m[k] - centre[static_cast<Eigen::Index>(k)]) + offset[static_cast<Eigen::Index>(k)];
  }
  if (auto ok = trace::CheckSamples(rows); !ok)
    return fail(fmt::format("{} scaled by {}: {} (choose a smaller --scale)", a.input, a.scale, ok.error().message));
  const Vector3d ext = a.scale * (hi - lo);
  const std::string comment = fmt::format(
      "palpa trace import {} --scale {} --offset {},{},{} --from {} --duration {}\n"
      "recorded motion, scaled uniformly by {} about its bounding-box centre ({:.4f}, {:.4f}, {:.4f}) m, which is "
      "put at ({}, {}, {}) m; extent {:.1f} x {:.1f} x {:.1f} mm; time from 0\n{}",
      a.input.substr(a.input.find_last_of('/') + 1), a.scale, offset[0], offset[1], offset[2], a.from_s, a.duration_s,
      a.scale, centre[0], centre[1], centre[2], offset[0], offset[1], offset[2], 1e3 * ext[0], 1e3 * ext[1],
      1e3 * ext[2], a.note);
  std::string out;
  const bool binary = a.output.ends_with(".ptb");
  if (binary) {
    auto encoded = trace::EncodeBinaryTrace(rows, comment);
    if (!encoded) return fail(fmt::format("{}: {}", a.output, encoded.error().message));
    out = std::move(*encoded);
  } else {
    out = trace::FormatTrace(rows, comment);
  }
  if (auto w = io::WriteFileAtomically(a.output, std::as_bytes(std::span(out.data(), out.size()))); !w) {
    fmt::print(stderr, "palpa trace import: {}\n", w.error());
    return kExitIo;
  }
  fmt::print("{}: {} samples over {:.3f} s, extent {:.1f} x {:.1f} x {:.1f} mm ({} bytes)\n", a.output, rows.size(),
             rows.back().t_s, 1e3 * ext[0], 1e3 * ext[1], 1e3 * ext[2], out.size());
  return kExitOk;
}

}  // namespace palpa::cli
