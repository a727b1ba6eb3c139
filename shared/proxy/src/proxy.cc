#include "palpa/proxy/proxy.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>

namespace palpa::proxy {
namespace {

using fixed::ISqrt;
using fixed::SaturateToInt32;
using sampler::LipschitzBound;

using Vec = std::array<std::int64_t, 3>;

// Rounding slack in Q16.16 LSB: a fixed-point φ is within 1 LSB of the exact trilinear value and
// two enter a certification, and a move's pieces are truncated per axis (≤ 1 LSB each, times the
// axis bound ≤ 2): 16 covers both with room.
constexpr std::int64_t kSlack = 16;

// Consecutive rejected steps after which the tick gives up moving (a step 2^-16 of its cap).
constexpr int kMaxHalvings = 16;

constexpr std::int64_t RoundShift(std::int64_t v, int bits) { return (v + (std::int64_t{1} << (bits - 1))) >> bits; }

Vec Diff(GridPos a, GridPos b) { return {std::int64_t{a.x} - b.x, std::int64_t{a.y} - b.y, std::int64_t{a.z} - b.z}; }

// Positions inside a tick are int64 triples (copying a 3×int32 struct as a block right after
// writing its fields one by one costs a store-forwarding stall). A grid position is in range.
Vec Pos(GridPos p) { return {p.x, p.y, p.z}; }
// Built with x and y in one 8-byte store: callers copy a GridPos as 8 + 4 bytes, and an 8-byte
// load of two separate 4-byte stores would stall store forwarding.
GridPos ToGridPos(const Vec& p) {
  GridPos g;
  const std::uint64_t xy = static_cast<std::uint32_t>(p[0]) | (std::uint64_t{static_cast<std::uint32_t>(p[1])} << 32);
  std::memcpy(static_cast<void*>(&g), &xy, sizeof xy);  // GridPos is trivially copyable
  g.z = static_cast<std::int32_t>(p[2]);
  return g;
}
Vec Sub(const Vec& a, const Vec& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
// p + d stays within the HIP box grown by a step (|coordinate| < 2^30): the proxy only ever
// moves towards the clamped HIP or by less than a voxel.
Vec Plus(const Vec& a, const Vec& b) { return {a[0] + b[0], a[1] + b[1], a[2] + b[2]}; }

// d / 2^bits per component, rounded towards zero (so never longer than d).
Vec Halve(const Vec& d, int bits) {
  if (bits == 0) return d;
  const std::int64_t div = std::int64_t{1} << bits;
  return {d[0] / div, d[1] / div, d[2] / div};
}

std::int64_t Norm2(const Vec& d) { return d[0] * d[0] + d[1] * d[1] + d[2] * d[2]; }

std::int64_t MaxAbs(const Vec& d) { return std::max({std::llabs(d[0]), std::llabs(d[1]), std::llabs(d[2])}); }

// Divides by a power of two until every |component| ≤ 2^bits: keeps the direction (up to
// truncation towards zero, which never lengthens it) and bounds the products that follow.
Vec ShrinkTo(const Vec& d, int bits) {
  const int excess = static_cast<int>(std::bit_width(static_cast<std::uint64_t>(MaxAbs(d)))) - bits;
  if (excess <= 0) return d;
  const std::int64_t div = std::int64_t{1} << excess;
  return {d[0] / div, d[1] / div, d[2] / div};
}

// d·num/den per component, rounded towards zero (never longer than exact); 0 ≤ num ≤ den,
// |d_i| < 2^32. One division: the ratio in Q30, then a multiply per component.
[[gnu::always_inline]] inline Vec Scale(const Vec& d, std::int64_t num, std::int64_t den) {
  // num/den ≤ 1; if num ≥ 2^33 both are shifted first so that num << 30 fits.
  const int excess = std::max(0, static_cast<int>(std::bit_width(static_cast<std::uint64_t>(num))) - 33);
  const std::int64_t ratio = fixed::FloorDiv((num >> excess) << 30, (den >> excess) + (excess > 0 ? 1 : 0));  // ≤ 2^30
  const auto scale = [&](std::int64_t v) { return v >= 0 ? (v * ratio) >> 30 : -((-v * ratio) >> 30); };
  return {scale(d[0]), scale(d[1]), scale(d[2])};
}

// Σ|d_i|·max|∂_iφ|, Q32: bounds |φ(a + d) − φ(a)| without a root.
std::int64_t AxisVariation(const Vec& d, const LipschitzBound& lb) {
  return std::llabs(d[0]) * lb.axis[0] + std::llabs(d[1]) * lb.axis[1] + std::llabs(d[2]) * lb.axis[2];
}

// Λ·|d| in Q32: the smaller of the axis bound and the Lipschitz-norm bound. The norm bound costs
// a root, so it is computed only when the axis bound exceeds `need`.
std::int64_t Variation(const Vec& d, const LipschitzBound& lb, std::int64_t need) {
  const std::int64_t axis = AxisVariation(d, lb);
  // (|d_i| ≥ 2^30 happens only for a free jump far outside the grid, where Norm2 could overflow.)
  if (axis <= need || !lb.norm_helps || MaxAbs(d) >= (std::int64_t{1} << 30)) return axis;
  return std::min(axis, std::int64_t{lb.norm} * static_cast<std::int64_t>(ISqrt(Norm2(d))));
}

// True if the trilinear φ stays above −δ all along [a, a + d], given the sampled φ(a), φ(a + d).
bool Certified(std::int64_t phi_a, std::int64_t phi_b, const Vec& d, const LipschitzBound& lb, std::int64_t delta) {
  const std::int64_t s = phi_a + phi_b + 2 * delta - kSlack;
  if (s < 0) return false;
  const std::int64_t need = s << 16;
  return Variation(d, lb, need) <= need;
}

// Whether every coordinate of h lies within the grid ± kHipMarginQ16 (one unsigned compare each).
template <typename Field>
bool InHipBox(GridPos h, const Field& field) {
  const auto in = [&](std::int32_t v, std::size_t a) {
    return static_cast<std::uint32_t>(v) + static_cast<std::uint32_t>(kHipMarginQ16) <=
           field.last_node(a) + 2u * kHipMarginQ16;
  };
  return in(h.x, 0) & in(h.y, 1) & in(h.z, 2);
}

// The HIP clamped to the grid ± kHipMarginQ16.
template <typename Field>
GridPos ClampHip(GridPos h, const Field& field) {
  const auto clamp = [&](std::int32_t v, std::size_t a) {
    return std::clamp<std::int64_t>(v, -std::int64_t{kHipMarginQ16}, std::int64_t{field.last_node(a)} + kHipMarginQ16);
  };
  return ToGridPos({clamp(h.x, 0), clamp(h.y, 1), clamp(h.z, 2)});
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
  if (c.max_iterations < 2 || c.max_iterations > 64) return std::unexpected("iterations must be in 2..64");
  if (c.gradient_samples < 1 || c.gradient_samples > c.max_iterations)
    return std::unexpected("gradient samples must be in 1..iterations");
  if (c.settle_samples < 1 || c.settle_samples > c.max_iterations)
    return std::unexpected("settle samples must be in 1..iterations");
  if (!(std::isfinite(c.mu_static) && c.mu_static >= 0 && c.mu_static <= 4))
    return std::unexpected("static friction coefficient must be in [0, 4]");
  if (!(std::isfinite(c.mu_dynamic) && c.mu_dynamic >= 0 && c.mu_dynamic <= c.mu_static))
    return std::unexpected("dynamic friction coefficient must be in [0, mu_static]");
  if (!(std::isfinite(c.depth_tolerance_voxels) && c.depth_tolerance_voxels > 0 && c.depth_tolerance_voxels <= 0.5))
    return std::unexpected("depth tolerance must be in (0, 0.5] voxel");
  ProxyParams p;
  p.gamma = fixed::Q16::FromDouble(c.gamma);
  p.beta = fixed::Q16::FromDouble(c.beta);
  p.max_iterations = c.max_iterations;
  p.gradient_samples = c.gradient_samples;
  p.settle_samples = c.settle_samples;
  p.k = {fixed::Q16::FromDouble(k_per_voxel)};
  p.max_force = {fixed::Q16::FromDouble(c.max_force_n)};
  p.mu_static = fixed::Q16::FromDouble(c.mu_static);
  p.mu_dynamic = fixed::Q16::FromDouble(c.mu_dynamic);
  p.depth_tolerance = {fixed::Q16::FromDouble(c.depth_tolerance_voxels)};
  p.voxel_m = voxel_m;
  return p;
}

namespace {

// The sampled φ and ∇φ at a point, with 1/|∇φ|² (Q24, from one division) for the projections.
// (Kept in int64 and filled field by field: copying the sample's int32 array as a block would
// load 8 bytes over two 4-byte stores, a store-forwarding stall.)
struct Local {
  std::int64_t phi;
  std::array<std::int64_t, 3> grad;
  std::int64_t inv_grad2;  // 0: |∇φ| < 1/4, no normal to project along
};

Local FromSample(const sampler::Sample& s) {
  const std::int64_t gx = s.grad[0], gy = s.grad[1], gz = s.grad[2];
  const std::int64_t gg = gx * gx + gy * gy + gz * gz;
  // |∇φ|² ≥ 1/16 (Q32: 2^28) keeps 2^56/gg ≤ 2^28 and the projections below in range.
  return {s.phi, {gx, gy, gz}, gg >= (std::int64_t{1} << 28) ? fixed::FloorDiv(std::int64_t{1} << 56, gg) : 0};
}

// One tick's working state. The tick is a loop of steps, each taking at most one field sample;
// the steps are separate functions so that each keeps its few values in registers.
template <typename Field>  // sampler::DenseSampler or BrickSampler
struct Tick {
  const Field& field;
  ProxyState& caches;  // its sampling caches only (the rest is written back at the end of the tick)
  const ProxyParams& params;
  const LipschitzBound& lb;
  const LipschitzBound& band;  // lb without v2's free-space floor: for pieces whose ends are ≤ band_top
  std::int64_t band_top;       // the field's background (free space), Q16.16
  Vec h;
  std::int64_t delta;
  bool far;   // HIP more than 32 voxels away: d is shrunk for the projection products
  bool fast;  // the HIP moved further since the last tick than settle_samples pieces reach
  Vec p;
  Local at;
  bool grad_valid;
  bool phi_h_known;
  bool converged;
  std::int64_t phi_h;
  int samples;      // at or towards the proxy: the budget of max_iterations
  int hip_samples;  // φ(X_h), once a tick besides (outside the budget)
  int gradient_samples;
  int halvings;        // consecutive rejected steps: the next move is halved this often
  bool leave_blocked;  // the straight way to an outside HIP runs into the object: slide instead

  // Member by member (an aggregate initialisation here compiles to a block clear first).
  Tick(const Field& f, ProxyState& s, const ProxyParams& prm, Vec hip, std::int64_t d, bool is_far, bool is_fast,
       Vec proxy, const Local& local, bool have_grad, std::int64_t phi_at_hip, bool have_phi_h)
      : field(f),
        caches(s),
        params(prm),
        lb(f.lipschitz()),
        band(f.lipschitz_band()),
        band_top(f.background()),
        h(hip),
        delta(d),
        far(is_far),
        fast(is_fast),
        p(proxy),
        at(local),
        grad_valid(have_grad),
        phi_h_known(have_phi_h),
        converged(false),
        phi_h(phi_at_hip),
        samples(0),
        hip_samples(have_phi_h ? 1 : 0),
        gradient_samples(0),
        halvings(0),
        leave_blocked(false) {}
};

enum class Next { kContinue, kDone };

template <typename Field>
Next SamplePhiAtHip(Tick<Field>& t) {
  t.phi_h = t.field.Phi(static_cast<std::int32_t>(t.h[0]), static_cast<std::int32_t>(t.h[1]),
                        static_cast<std::int32_t>(t.h[2]), t.caches.hip_phi_cache);
  t.phi_h_known = true;
  ++t.hip_samples;
  return Next::kContinue;
}

// Free motion (φ(X_p) above the near band): jump to X_h if [X_p, X_h] is certified and X_h is
// outside, else one sphere-tracing step of φ/Λ towards it, which cannot reach φ = 0.
template <typename Field>
[[gnu::noinline]] Next FreeStep(Tick<Field>& t) {
  if (!t.phi_h_known) return SamplePhiAtHip(t);
  const Vec d = Sub(t.h, t.p);
  if (t.phi_h > 0 && Certified(t.at.phi, t.phi_h, d, t.lb, t.delta)) {
    t.p = t.h;
    t.at.phi = t.phi_h;
    t.grad_valid = false;
    return Next::kDone;
  }
  const auto len = static_cast<std::int64_t>(ISqrt(Norm2(d)));
  // Λ along d, rounded up; 0 only for a constant field.
  const std::int64_t rate = std::min<std::int64_t>(t.lb.norm, fixed::FloorDiv(AxisVariation(d, t.lb) + len - 1, len));
  // φ budget after the rounding slack and the truncation of the new position (≤ 1 LSB per axis).
  const std::int64_t budget = t.at.phi - kSlack - ((2 * std::int64_t{t.lb.norm}) >> 16) - 1;
  const std::int64_t step = rate == 0 ? len : budget <= 0 ? 0 : fixed::FloorDiv(budget << 16, rate);
  if (step >= len) {  // the ball of radius φ/Λ around X_p holds all of [X_p, X_h]
    t.p = t.h;
    t.at.phi = t.phi_h;
    t.grad_valid = false;
    return Next::kDone;
  }
  const Vec x = Plus(t.p, Scale(d, step, len));
  if (step <= 0 || x == t.p) return Next::kDone;  // cannot happen above the near band
  t.p = x;
  t.at.phi = t.field.Phi(ToGridPos(x), t.caches.proxy_phi_cache);
  t.grad_valid = false;
  ++t.samples;
  return Next::kContinue;
}

// Leaving contact: the HIP is outside the field. March straight towards it in steps that certify
// by construction: from a with φ(a) known, a step of length L whose end has φ ≥ −δ keeps the whole
// step above −3δ/2 (the way's floor) once Λ·L ≤ φ(a) + 2δ, so each step is as long as that allows
// (sphere tracing: the steps grow as the proxy leaves the surface) and only its end is sampled.
// Jump when the HIP is within reach. The clear-way test is relative to where the proxy rests:
// a resting proxy has φ ≥ −δ/2, and the way counts as blocked only where it samples φ < −δ, i.e.
// at least δ/2 deeper than any resting point (the HIP went through a part, or round the back of
// one). A blocked proxy is held and eq. 9's tangential slide takes over (ContactRun), wrapping it
// round the part while the spring keeps pulling the HIP back. Steps ending in [−δ, −δ/2) are
// taken (the way is clear; the proxy may rest there while it marches, never deeper).
template <typename Field>
[[gnu::noinline]] Next LeaveStep(Tick<Field>& t) {
  const std::int64_t way = 3 * t.delta / 2;  // the floor of every march step: φ ≥ −3δ/2 along it
  while (t.samples < t.params.max_iterations) {
    const Vec d = Sub(t.h, t.p);
    const auto len = static_cast<std::int64_t>(ISqrt(Norm2(d)));
    if (len == 0) return Next::kDone;
    // Λ along d, rounded up; 0 only for a constant field.
    const std::int64_t rate = std::min<std::int64_t>(t.lb.norm, fixed::FloorDiv(AxisVariation(d, t.lb) + len - 1, len));
    // φ budget after the rounding slack and the truncation of the new position (≤ 1 LSB per axis).
    const std::int64_t budget = t.at.phi + 2 * t.delta - kSlack - ((2 * std::int64_t{t.lb.norm}) >> 16) - 1;
    if (budget <= 0) break;
    const std::int64_t step = rate == 0 ? len : fixed::FloorDiv(budget << 16, rate);
    if (step >= len && t.phi_h >= 0) {  // the HIP itself is within a certified step
      t.p = t.h;
      t.at.phi = t.phi_h;
      t.grad_valid = false;
      return Next::kDone;
    }
    const Vec q = Plus(t.p, Scale(d, std::min(step, len), len));
    if (q == t.p) break;
    const std::int64_t phi_q = t.field.Phi(ToGridPos(q), t.caches.proxy_phi_cache);
    ++t.samples;
    if (phi_q < -t.delta || !Certified(t.at.phi, phi_q, Sub(q, t.p), t.lb, way)) break;
    t.p = q;
    t.at.phi = phi_q;
    t.grad_valid = false;
    if (phi_q > t.params.near.value.raw()) return Next::kContinue;  // off the surface: free motion next
  }
  if (t.samples < t.params.max_iterations) t.leave_blocked = true;
  return Next::kContinue;
}

// Near the surface: iterations of eq. 9, projected and normalised, split into its normal and
// tangential parts,
//   Δn = −β φ ∇φ/|∇φ|²             (Gauss–Newton back to φ = 0)
//   Δt = γ (d − (∇φ·d) ∇φ/|∇φ|²)     (towards the HIP within the tangent plane),
// each capped, sampled and certified. Runs until the budget, convergence, or a change of mode
// (kLeave: the HIP is outside the linearisation and the field; kContinue: the proxy left the near
// band). Works on locals so that the loop stays in registers.
enum class Contact { kDone, kLeave, kContinue };

template <typename Field>
[[gnu::noinline]] Contact ContactRun(Tick<Field>& t) {
  const ProxyParams& prm = t.params;
  // Pieces are planned with the band's bound: both ends of a piece normally lie in the band (the
  // proxy starts within the near band, below band_top), and a piece is certified with it only when
  // they do (see the check below), else with the whole field's.
  const std::int64_t ax = t.band.axis[0], ay = t.band.axis[1], az = t.band.axis[2];
  const std::int64_t hx = t.h[0], hy = t.h[1], hz = t.h[2];
  const std::int64_t delta = t.delta;
  std::int64_t px = t.p[0], py = t.p[1], pz = t.p[2];
  Local at = t.at;
  Contact result = Contact::kDone;
  bool lagging = false;  // the last move left its target far (see below): more samples allowed
  // (The settle budget gates moves, not leaving: a HIP in front of the surface is tested first.)
  while (t.samples < prm.max_iterations) {
    if (at.inv_grad2 == 0) break;  // |∇φ| < 1/4: no normal to project along
    const std::int64_t gx = at.grad[0], gy = at.grad[1], gz = at.grad[2];
    std::int64_t dx = hx - px, dy = hy - py, dz = hz - pz;
    std::int64_t dot16 = RoundShift(dx * gx + dy * gy + dz * gz, 16);
    const std::int64_t c = at.phi + dot16;  // φ linearised at X_p, evaluated at X_h
    // A HIP outside the field leaves (the march decides whether the way is clear), wherever it is
    // relative to the linearisation: the force holds only for a HIP inside or a blocked way.
    if (!t.leave_blocked && t.phi_h >= 0) {
      result = Contact::kLeave;
      break;
    }
    // (A held proxy's march took this tick's first samples; its slide round the part may use the
    // rest, like a lagging one.)
    if (t.samples >= prm.settle_samples && !lagging && !t.leave_blocked) break;
    if (t.far) {  // |d_i| ≤ 64 voxels, shrunk along its direction, bounds the products below
      const Vec d = ShrinkTo({dx, dy, dz}, 22);
      dx = d[0], dy = d[1], dz = d[2];
      dot16 = RoundShift(dx * gx + dy * gy + dz * gz, 16);
    }
    const std::int64_t back = (RoundShift(prm.beta.raw() * at.phi, 16) * at.inv_grad2) >> 24;  // Q16
    const std::int64_t along = (dot16 * at.inv_grad2) >> 24;                                   // Q16
    const Vec dn = {-((back * gx) >> 16), -((back * gy) >> 16), -((back * gz) >> 16)};
    Vec dt = {dx - ((along * gx) >> 16), dy - ((along * gy) >> 16), dz - ((along * gz) >> 16)};  // |dt_i| ≤ √3·2^22
    if (prm.gamma.raw() != (1 << 16)) {
      for (auto& v : dt) v = RoundShift(prm.gamma.raw() * v, 16);
    }
    if (prm.mu_static.raw() > 0) {
      // Friction cone: the HIP's tangential offset from the proxy is dt, its depth below the
      // linearised surface −c/|∇φ|. Stick inside the μs cone; else slide to the μd cone's edge.
      const auto t_len = static_cast<std::int64_t>(ISqrt(Norm2(dt)));
      const auto g_len = static_cast<std::int64_t>(ISqrt(gx * gx + gy * gy + gz * gz));
      const std::int64_t depth = std::max<std::int64_t>(0, (-c << 16) / g_len);
      if ((t_len << 16) <= prm.mu_static.raw() * depth) {
        dt = {};
      } else {
        dt = Scale(dt, t_len - RoundShift(prm.mu_dynamic.raw() * depth, 16), t_len);
      }
    }
    const std::int64_t nx = std::llabs(dn[0]), ny = std::llabs(dn[1]), nz = std::llabs(dn[2]);
    const std::int64_t tx = std::llabs(dt[0]), ty = std::llabs(dt[1]), tz = std::llabs(dt[2]);
    // Convergence test: the whole update, |Δn|₁ + |Δt|₁, within the tolerance.
    if (nx + ny + nz + tx + ty + tz <= prm.tolerance.value.raw()) {
      t.converged = true;
      break;
    }
    // The move, in pieces that each certify whenever φ at their ends is ≥ −δ/2 (the rest
    // condition): the first carries all of Δn and as much of Δt as φ(X_p) + 3δ/2 − Λ|Δn| allows,
    // each further piece (Λ|piece| ≤ 3δ/2) another stretch of Δt, as many as the sample budget
    // allows. Every piece end is sampled and every piece certified; a failing piece ends the move
    // at the last certified end. So the tangential speed is bounded by the budget (about δ per
    // sample), never by a leap that could skip through a thin part.
    const std::int64_t dn_variation = nx * ax + ny * ay + nz * az;
    std::int64_t dt_variation = tx * ax + ty * ay + tz * az;
    const std::int64_t first_room = std::max<std::int64_t>(0, ((at.phi + 3 * delta / 2 - kSlack) << 16) - dn_variation);
    if (dt_variation > first_room && t.band.norm_helps) dt_variation = Variation(dt, t.band, first_room);
    if (t.halvings > 0) {
      dt = Halve(dt, t.halvings);
      dt_variation >>= t.halvings;
    }
    const std::int64_t piece = (3 * delta / 2 - kSlack) << 16;
    // Samples this move may take: the tick settles after settle_samples unless the HIP is fast
    // and the target more than two pieces away (fast sliding): then up to max_iterations.
    // Lagging: a fast HIP and a target beyond the first piece, or a target more than five pieces
    // away whatever the HIP did (so a proxy never falls further and further behind).
    lagging = dt_variation > first_room && (t.fast || dt_variation > first_room + 4 * piece);
    const int room =
        (lagging || t.leave_blocked ? prm.max_iterations : std::min(prm.settle_samples, prm.max_iterations)) -
        t.samples;
    if (room <= 0) break;
    std::int64_t reached = 0;                // Δt's variation covered by the accepted pieces
    std::int64_t ex = px, ey = py, ez = pz;  // end of the last accepted piece
    bool moved = false, left = false;
    for (int j = 0; j < room; ++j) {
      const std::int64_t reach = std::min(dt_variation, j == 0 ? first_room : reached + piece);
      if (j > 0 && reach <= reached) break;  // all of Δt covered
      const Vec along_dt = reach >= dt_variation ? dt : Scale(dt, reach, dt_variation);
      const std::int64_t qx = px + dn[0] + along_dt[0], qy = py + dn[1] + along_dt[1], qz = pz + dn[2] + along_dt[2];
      if (qx == ex && qy == ey && qz == ez) break;
      const bool last = j == room - 1 || reach >= dt_variation;
      // The final end gets φ and ∇φ while gradient_samples allows; other ends φ alone, the
      // gradient held (refreshed at the next gradient sample, next tick at the latest).
      const bool with_gradient = last && t.gradient_samples < prm.gradient_samples;
      sampler::Sample s;
      const auto x = static_cast<std::int32_t>(qx), y = static_cast<std::int32_t>(qy),
                 z = static_cast<std::int32_t>(qz);
      if (with_gradient) {
        s = t.field.At(x, y, z, t.caches.proxy_gradient_cache);
        ++t.gradient_samples;
      } else {
        s.phi = t.field.Phi(x, y, z, t.caches.proxy_phi_cache);
      }
      ++t.samples;
      // Certification of the piece [e, q]: |∇φ·piece| ≤ |∇φ·Δn| + |∇φ·Δt-part| pointwise, so the
      // parts' bounds (Δt's scale linearly along it; truncation only shortens) bound its
      // variation without a new product; the exact bound is the fallback.
      // Certified to the way's floor −3δ/2 (a proxy may start a move from a march's rest in
      // [−δ, −δ/2)); an end must rest (φ ≥ −δ/2) and, with the HIP inside, stay in the near band,
      // so that the force holds without a gap. Held beyond a part (HIP outside), a piece may leave
      // the band round a convex edge: the proxy is then released into free motion.
      const std::int64_t way = 3 * delta / 2;
      const std::int64_t need = (at.phi + s.phi + 2 * way - kSlack) << 16;
      const std::int64_t piece_variation = (j == 0 ? dn_variation : 0) + (reach - reached);
      const bool in_band = at.phi <= t.band_top && s.phi <= t.band_top;
      if (!(s.phi >= -delta / 2 && (s.phi <= prm.near.value.raw() || t.leave_blocked) && need >= 0 &&
            ((in_band && piece_variation <= need) ||
             Certified(at.phi, s.phi, {qx - ex, qy - ey, qz - ez}, in_band ? t.band : t.lb, way)))) {
        break;
      }
      ex = qx, ey = qy, ez = qz;
      reached = reach;
      moved = true;
      if (with_gradient) {
        at = FromSample(s);
      } else {
        at.phi = s.phi;
      }
      if (at.phi > prm.near.value.raw()) {  // off the surface round a part (held only): free motion next
        left = true;
        break;
      }
    }
    if (moved) {
      // Convergence test, on the move just made: |Δ|₁ within the tolerance ends the iteration
      // (saves computing the next, smaller one).
      const bool small = std::llabs(ex - px) + std::llabs(ey - py) + std::llabs(ez - pz) <= prm.tolerance.value.raw();
      px = ex, py = ey, pz = ez;
      t.halvings = 0;
      if (left) {
        result = Contact::kContinue;
        break;
      }
      if (small) {
        t.converged = true;
        break;
      }
    } else if (++t.halvings > kMaxHalvings) {
      break;
    }
  }
  t.p = {px, py, pz};
  t.at = at;
  return result;
}

// Eq. 10, f = k·h·(X_p − X_h), its magnitude limited to min(max_force, cap) with its direction
// kept. Every component is rounded towards zero and |u| up (⌈√|u|²⌉), so |f| ≤ k·|u| and
// |f| ≤ the limit hold exactly in integers: Σ f_i² ≤ limit². Returns an upper bound of |f|.
// ⌈|u|⌉ (< 2^31).
std::int64_t CeilLength(const Vec& u) {
  const std::int64_t n2 = Norm2(u);
  auto len = static_cast<std::int64_t>(ISqrt(n2));
  return len * len < n2 ? len + 1 : len;
}

[[gnu::noinline]] std::int64_t Force(const ProxyParams& params, const Vec& u, std::int64_t len, std::int64_t cap,
                                     TickResult& r) {
  // |u_i| < 2^29.6, len = ⌈|u|⌉
  const std::int64_t k = params.k.value.raw();
  const std::int64_t limit = std::min<std::int64_t>(params.max_force.value.raw(), cap);
  r.clamped = k * len > (limit << 16);
  std::int32_t any = 0;
  for (std::size_t a = 0; a < 3; ++a) {
    // Both towards zero: eq. 10 as fixed/units.h states it (k·len ≤ limit here, so it cannot
    // saturate), or the clamped magnitude along u.
    const fixed::Voxels x{fixed::Q16::FromRaw(static_cast<std::int32_t>(u[a]))};
    r.force[a] = r.clamped ? fixed::Newtons{fixed::Q16::FromRaw(static_cast<std::int32_t>(limit * u[a] / len))}
                           : fixed::HookeUnsaturated(params.k, x);
    any |= r.force[a].value.raw();
  }
  r.contact = any != 0;
  r.penetration = {fixed::Q16::FromRaw(r.contact ? SaturateToInt32(len) : 0)};
  return r.contact ? std::min(limit, (k * len + 65535) >> 16) : 0;
}

}  // namespace

namespace {

// φ(X_h) not sampled yet (SlowTick's argument).
constexpr std::int64_t kPhiUnknown = std::numeric_limits<std::int64_t>::min();

// Everything but a free tick: start-up, the march towards a surface, contact, leaving. `phi_h`
// is φ(X_h) when ProxyTick already sampled it (one sample taken), else kPhiUnknown. (Few enough
// arguments to pass in registers, so that ProxyTick's calls are tail calls.)
template <typename Field>
[[gnu::noinline]] TickResult SlowTick(const Field& field, const ProxyParams& params, ProxyState& state,
                                      const GridPos& hip, std::int64_t phi_h) {
  // Clamp the HIP, and a free proxy that followed it, to the grid ± 4096 voxels: beyond, it is
  // free space (the proxy moves along its own side, never across the grid), and every difference
  // of positions below stays under 2^29.6.
  const bool inside = InHipBox(hip, field);
  const GridPos h = inside ? hip : ClampHip(hip, field);
  if (state.phi > params.near.value.raw() && !InHipBox(state.proxy, field)) state.proxy = ClampHip(state.proxy, field);
  const bool phi_h_known = phi_h != kPhiUnknown && inside;
  TickResult r;

  // Start-up, reset, or a HIP that has been inside since then: the proxy follows the HIP with zero
  // force until the HIP is outside once (no entry side is known before that).
  if (!state.valid || !state.seated) {
    const std::int32_t phi_start = field.Phi(h, state.hip_phi_cache);
    // Member by member: the caches stay (an aggregate would clear their 1.2 kB every such tick).
    state.proxy = h;
    state.phi = phi_start;
    state.grad = {};
    state.inv_grad2 = 0;
    state.grad_valid = false;
    state.last_hip = h;
    state.seated = phi_start >= 0;
    state.valid = true;
    state.pull = {};
    state.hip_phi_bound = {fixed::Q16::FromRaw(phi_start)};
    r.proxy = h;
    r.iterations = 1;
    return r;
  }

  const std::int64_t delta = params.depth_tolerance.value.raw();
  Tick t(field, state, params, Pos(h), delta,
         MaxAbs(Diff(h, state.proxy)) > (std::int64_t{1} << 21),  // the proxy moves < 1 voxel a sample
         AxisVariation(Diff(h, state.last_hip), field.lipschitz()) >
             std::int64_t{params.settle_samples} * ((3 * delta / 2) << 16),
         Pos(state.proxy), {state.phi, {state.grad[0], state.grad[1], state.grad[2]}, state.inv_grad2},
         state.grad_valid, phi_h, phi_h_known);
  // φ(X_h) every tick (outside the settle budget): the force holds only for a HIP inside or a
  // blocked way, never for one outside with the way clear. In contact, an upper bound does when it
  // shows the HIP inside: last tick's bound plus Λ·|ΔX_h| (the steady press and slide, no sample).
  // The band's Λ serves: from an inside point, φ cannot reach 0 without first crossing cells that
  // are not free space (φ ≤ 0 there), where the band's bound holds.
  if (!t.phi_h_known && state.phi <= params.near.value.raw() && state.hip_phi_bound.value.raw() < 0) {
    const std::int64_t up = (std::int64_t{state.hip_phi_bound.value.raw()} << 16) +
                            AxisVariation(Diff(h, state.last_hip), field.lipschitz_band()) + (kSlack << 16);
    if (up < -(std::int64_t{1} << 16)) {
      t.phi_h = -((-up) >> 16);  // rounded up: still an upper bound, < 0
      t.phi_h_known = true;
    }
  }
  if (!t.phi_h_known) SamplePhiAtHip(t);
  // In free motion that sample is one of the budget (sphere tracing towards X_h needs it anyway);
  // at the surface it is one more.
  if (t.at.phi > params.near.value.raw()) t.samples = t.hip_samples;
  // Each pass takes at most one field sample; a pass without one ends the loop or samples in the
  // next, so 2·max_iterations + 2 passes bound it.
  for (int pass = 0; pass < 2 * params.max_iterations + 2 && t.samples < params.max_iterations; ++pass) {
    if (t.p == t.h) break;
    if (t.at.phi > params.near.value.raw()) {
      if (FreeStep(t) == Next::kDone) break;
      continue;
    }
    if (!t.grad_valid) {  // arrived from free motion or leaving: φ and ∇φ at the proxy first
      t.at = FromSample(field.At(static_cast<std::int32_t>(t.p[0]), static_cast<std::int32_t>(t.p[1]),
                                 static_cast<std::int32_t>(t.p[2]), state.proxy_gradient_cache));
      t.grad_valid = true;
      ++t.samples;
      ++t.gradient_samples;
      continue;
    }
    const Contact c = ContactRun(t);
    if (c == Contact::kDone) break;
    if (c == Contact::kLeave && LeaveStep(t) == Next::kDone) break;
  }

  const GridPos p = ToGridPos(t.p);
  const GridPos last_hip = state.last_hip, last_proxy = state.proxy;
  const std::int64_t last_pull = state.pull.value.raw();
  state.hip_phi_bound = {
      fixed::Q16::FromRaw(t.phi_h_known ? SaturateToInt32(t.phi_h) : std::numeric_limits<std::int32_t>::max())};
  state.proxy = p;
  state.last_hip = h;
  state.phi = static_cast<std::int32_t>(t.at.phi);
  state.grad = {static_cast<std::int32_t>(t.at.grad[0]), static_cast<std::int32_t>(t.at.grad[1]),
                static_cast<std::int32_t>(t.at.grad[2])};
  state.inv_grad2 = t.at.inv_grad2;
  state.grad_valid = t.grad_valid;
  state.pull = {};
  r.proxy = p;
  r.iterations = t.samples;
  r.converged = t.converged;
  if (t.p == t.h) return r;

  // Eq. 10 only when the proxy is at the surface (within the near band, where eq. 9 holds it) and
  // the HIP is inside the field, or outside beyond a part the way to it runs into (held); never
  // with the HIP outside and the way clear, nor for a proxy still catching up in free space.
  const bool inside_hip = t.phi_h_known && t.phi_h < 0;
  if (t.at.phi > params.near.value.raw() || !(inside_hip || t.leave_blocked)) return r;
  // No step: the magnitude rises at most by what the spring's ends moved (k·(|ΔX_h| + |ΔX_p|), the
  // proxy's part at most a voxel) plus max_force/1024; held with the HIP outside (overpowered,
  // through a part) it fades by max_force/1024 a tick instead (1 s at 1 kHz to zero).
  const std::int64_t fade = params.max_force.value.raw() >> 10;
  const std::int64_t k = params.k.value.raw();
  const std::int64_t max_f = params.max_force.value.raw();
  std::int64_t cap = std::max<std::int64_t>(0, last_pull - fade);
  const Vec u = Diff(p, h);
  const std::int64_t len = CeilLength(u);
  if (inside_hip) {
    cap = max_f;
    // The spring's length bounds its force (k·⌈|u|⌉ ≥ |f|): within last_pull + fade the limit
    // cannot bind, and the steady press or slide needs no roots for it.
    if (k * len > ((last_pull + fade) << 16)) {
      // How far the spring's ends moved this tick (the proxy's part at most a voxel).
      const auto hip_step = static_cast<std::int64_t>(ISqrt(Norm2(Diff(h, last_hip))));
      const std::int64_t proxy_step =
          std::min<std::int64_t>(std::int64_t{1} << 16, static_cast<std::int64_t>(ISqrt(Norm2(Diff(p, last_proxy)))));
      cap = std::min(max_f,
                     last_pull + fade +
                         ((k * std::min<std::int64_t>(hip_step + proxy_step, std::int64_t{1} << 31) + 65535) >> 16));
    }
  }
  state.pull = {fixed::Q16::FromRaw(static_cast<std::int32_t>(Force(params, u, len, cap, r)))};
  return r;
}

}  // namespace

namespace {

// A free tick whose HIP left the ball around the proxy: sample φ(X_h), jump if certified, else
// the general tick (which then marches, or makes contact).
template <typename Field>
[[gnu::noinline]] TickResult FreeSampled(const Field& field, const ProxyParams& params, ProxyState& state,
                                         const GridPos& h, const Vec& d) {
  const std::int32_t phi_h = field.Phi(h, state.hip_phi_cache);
  if (phi_h > 0 && Certified(state.phi, phi_h, d, field.lipschitz(), params.depth_tolerance.value.raw())) {
    state.proxy = h;
    state.last_hip = h;
    state.phi = phi_h;
    state.grad_valid = false;
    state.hip_phi_bound = {fixed::Q16::FromRaw(phi_h)};
    TickResult r;
    r.proxy = h;
    r.iterations = 1;
    return r;
  }
  return SlowTick(field, params, state, h, phi_h);
}

}  // namespace

namespace {

template <typename Field>
TickResult TickOn(const Field& field, const ProxyParams& params, ProxyState& state, GridPos hip) {
  if (!(state.valid && state.seated && state.phi > params.near.value.raw()))
    return SlowTick(field, params, state, hip, kPhiUnknown);

  // Free motion, the common case: the proxy is off the surface and φ(X_p) is known exactly or
  // as a lower bound. Without a sample this path calls nothing (and so saves no registers). It
  // follows the HIP anywhere, even far outside the grid (|d_i| < 2^32 keeps reach < 2^57); the
  // other paths first clamp both to the grid ± 4096 voxels.
  const Vec d = Diff(hip, state.proxy);
  const std::int64_t reach = AxisVariation(d, field.lipschitz());  // ≥ |φ(x) − φ(X_p)| on [X_p, X_h]
  if (reach >= (std::int64_t{state.phi} - params.near.value.raw() - kSlack) << 16) {
    return FreeSampled(field, params, state, hip, d);
  }
  // All of [X_p, X_h] lies in the ball where φ > 1/2 voxel: move without sampling, and carry
  // φ(X_h) ≥ φ(X_p) − reach as a lower bound (it only decides when to sample again).
  state.phi -= static_cast<std::int32_t>((reach >> 16) + 1);
  state.proxy = hip;
  state.last_hip = hip;
  state.grad_valid = false;
  TickResult r;
  r.proxy = hip;
  return r;
}

}  // namespace

TickResult ProxyTick(const sampler::DenseSampler& field, const ProxyParams& params, ProxyState& state, GridPos hip) {
  return TickOn(field, params, state, hip);
}

TickResult ProxyTick(const sampler::BrickSampler& field, const ProxyParams& params, ProxyState& state, GridPos hip) {
  return TickOn(field, params, state, hip);
}

std::array<fixed::Newtons, 3> SpringForce(const ProxyParams& params, GridPos proxy, GridPos hip) {
  TickResult r;
  const Vec u = Diff(proxy, hip);
  Force(params, u, CeilLength(u), params.max_force.value.raw(), r);
  return r.force;
}

std::int32_t SpringPullBound(const ProxyParams& params, GridPos proxy, GridPos hip) {
  TickResult r;
  const Vec u = Diff(proxy, hip);
  return static_cast<std::int32_t>(Force(params, u, CeilLength(u), params.max_force.value.raw(), r));
}

namespace {

std::int64_t SaturatingAdd(std::int64_t a, std::int64_t b) {
  std::int64_t out = 0;
  if (__builtin_add_overflow(a, b, &out))
    return b > 0 ? std::numeric_limits<std::int64_t>::max() : std::numeric_limits<std::int64_t>::min();
  return out;
}

}  // namespace

void PassivityObserver::Update(GridPos hip, const TickResult& r, const ProxyParams& params) {
  const std::array<std::int32_t, 3> force = {r.force[0].value.raw(), r.force[1].value.raw(), r.force[2].value.raw()};
  const bool held = (last_force[0] | last_force[1] | last_force[2]) != 0;
  if (primed) {
    // Differences of raw int32 positions are < 2^32; clamped to ±2^30 (far beyond any grid) so
    // that every product below fits int64. f·Δh: |f| ≤ 2^23 raw.
    const auto clamp30 = [](std::int64_t v) { return std::clamp<std::int64_t>(v, -(1LL << 30), 1LL << 30); };
    const Vec d = Diff(hip, last_hip);
    const Vec dh = {clamp30(d[0]), clamp30(d[1]), clamp30(d[2])};
    std::int64_t work = 0;
    for (std::size_t a = 0; a < 3; ++a) work -= std::int64_t{last_force[a]} * dh[a];
    energy_q32 = SaturatingAdd(energy_q32, work);
    // (k/2)|ΔX_h|² over an interval that starts or ends in contact (docs/realtime-core.md
    // § Passivity observer): Q16 × (Q32 >> 16) → Q32 N·voxel, saturating. |ΔX_h|² ≤ 3·2^60.
    if (held || r.contact) {
      std::int64_t term = 0;
      if (__builtin_mul_overflow(std::int64_t{params.k.value.raw()}, Norm2(dh) >> 16, &term))
        term = std::numeric_limits<std::int64_t>::max();
      zoh_bound_q32 = SaturatingAdd(zoh_bound_q32, term / 2);
    }
  }
  last_hip = hip;
  last_force = force;
  primed = true;
}

}  // namespace palpa::proxy
