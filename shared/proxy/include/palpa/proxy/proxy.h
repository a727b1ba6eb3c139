// The god-object proxy on a signed distance field (paper §3.3, eq. 9), its force (eq. 10), Coulomb
// friction (optional) and a passivity observer, in fixed point. RT-safe after start-up: no
// allocation, no exceptions, no syscalls, at most `max_iterations` field samples per tick.
//
// Formats (int32 unless noted; docs/realtime-core.md has the full table and overflow analysis):
//   HIP, proxy           Q16.16 voxels (grid frame)     HIP clamped to the grid ± 4096 voxels
//   φ                    Q16.16 voxels                  |φ| ≤ band ≤ 64
//   ∇φ                   Q16.16 voxel/voxel             |component| ≤ band
//   γ, β, μs, μd, δ      Q16.16                         γ, β in (0, 1]; μ in [0, 4]; δ in (0, 1/2]
//   k·h (stiffness)      Q16.16 N per voxel             [1e-3, 32767]
//   force                Q16.16 N                       |f| ≤ max_force ≤ 100 N
//   energy (observer)    int64 Q32.32 N·voxel           saturating
// MakeProxyParams rejects anything outside these ranges at start-up, so no intermediate can
// overflow in the loop; the analysis is in docs/realtime-core.md § Overflow.
#pragma once

#include <array>
#include <cstdint>
#include <expected>
#include <limits>

#include "palpa/blob/blob.h"
#include "palpa/fixed/units.h"
#include "palpa/sampler/trilinear.h"

namespace palpa::proxy {

using sampler::GridPos;

/// How far outside the grid the HIP is followed, Q16.16 voxels (4096 voxels). Beyond it the HIP
/// is clamped for the proxy (it is free space either way), which bounds every difference of
/// positions by 2^29.6 raw.
inline constexpr std::int32_t kHipMarginQ16 = std::int32_t{1} << 28;

/// Converts between device-frame metres and the grid frame. Non-RT construction; conversions
/// are used at the device boundary of the tick (IEEE double, same bits on every target with
/// -ffp-contract=off).
struct GridFrame {
  std::array<double, 3> origin_m{};
  double voxel_m = 1;

  static GridFrame Of(const blob::FieldView& f) { return {f.origin_m, f.voxel_m}; }
  /// Device metres → grid Q16.16, rounded to nearest, saturating far outside the grid.
  GridPos ToGrid(const std::array<double, 3>& x_m) const;
  /// Grid Q16.16 → device metres.
  std::array<double, 3> ToMetres(GridPos p) const;
};

/// Parameters of the tick in loop formats. Build with MakeProxyParams.
struct ProxyParams {
  fixed::Q16 gamma = fixed::Q16::FromInt(1);                    ///< eq. 9 γ on the (tangential) HIP term
  fixed::Q16 beta = fixed::Q16::FromInt(1);                     ///< eq. 9 β on the normalised φ term
  fixed::Voxels depth_tolerance{fixed::Q16::FromRaw(1 << 14)};  ///< δ: no point of the proxy's path has φ < −δ
  fixed::Voxels near{fixed::Q16::FromRaw(1 << 15)};             ///< below this φ (1/2 voxel) eq. 9 holds the proxy
  fixed::Voxels tolerance{fixed::Q16::FromRaw(1 << 8)};  ///< convergence: a move or update |Δ|₁ ≤ 1/256 voxel
  int max_iterations = 4;                                ///< field samples per tick, the hard bound on its work
  int settle_samples = 1;                                ///< samples per tick unless the proxy lags its target
  int gradient_samples = 1;                              ///< of which with ∇φ (32 values; the rest φ, 8)
  fixed::NewtonsPerVoxel k;                              ///< k·h
  fixed::Newtons max_force;                              ///< force clamp, N
  fixed::Q16 mu_static;                                  ///< Coulomb μs; 0 = friction off
  fixed::Q16 mu_dynamic;                                 ///< Coulomb μd ≤ μs
  double voxel_m = 1;                                    ///< for reporting only
};

/// SI inputs of the proxy.
struct ProxyConfig {
  double k_n_per_m = 800;                ///< stiffness k, N/m (paper eq. 10)
  double max_force_n = 8;                ///< force clamp, N (direction preserved)
  double gamma = 1.0;                    ///< eq. 9 γ, (0, 1]
  double beta = 1.0;                     ///< eq. 9 β, (0, 1] (normalised, see ProxyTick)
  int max_iterations = 4;                ///< field samples per tick (hard bound), 2..64
  int settle_samples = 1;                ///< samples per tick while the proxy keeps up, 1..max_iterations
  int gradient_samples = 1;              ///< of those, how many also sample ∇φ, 1..max_iterations
  double mu_static = 0;                  ///< Coulomb static friction coefficient, [0, 4]; 0 = off
  double mu_dynamic = 0;                 ///< Coulomb dynamic friction coefficient, [0, μs]
  double depth_tolerance_voxels = 0.25;  ///< δ, (0, 0.5]: the deepest any path point may be
};

/// Validates `config` for a field with voxel size `voxel_m` and converts it to loop formats.
/// Errors (a static sentence) for: k ≤ 0 or > 1e5 N/m, k·h outside [1e-3, 32767] N/voxel, max
/// force ≤ 0 or > 100 N, γ or β outside (0, 1], iterations outside 2..64, gradient samples
/// outside 1..iterations, μs outside [0, 4], μd
/// outside [0, μs], δ outside (0, 0.5], non-finite input. Non-RT.
std::expected<ProxyParams, const char*> MakeProxyParams(const ProxyConfig& config, double voxel_m);

/// Proxy state carried between ticks. The field must not change while it is valid (set
/// valid = false after swapping the field: the next tick restarts the proxy at the HIP).
struct ProxyState {
  GridPos proxy;
  std::int32_t phi = 0;  ///< φ(proxy) as sampled, Q16.16 voxels; off the surface (> 1/2 voxel) a lower bound
  std::array<std::int32_t, 3> grad{};  ///< ∇φ at or near the proxy (see gradient_samples), if grad_valid
  std::int64_t inv_grad2 = 0;          ///< 2^56/|∇φ|² in raw units (Q24 of 1/|∇φ|²); 0 if |∇φ| < 1/4
  bool grad_valid = false;
  GridPos last_hip;     ///< the HIP of the last tick (its speed decides the contact sample budget)
  bool seated = false;  ///< the HIP has been outside the object since the (re)start
  /// An upper bound of |f| last tick, Q16.16 N (0 without contact): the next tick's force may rise
  /// above it only by k·(|ΔX_h| + min(|ΔX_p|, 1 voxel)) + max_force/1024, and falls by
  /// max_force/1024 a tick while the proxy is held with the HIP outside (overpower fade).
  fixed::Newtons pull;
  /// An upper bound of φ(last_hip), Q16.16 (INT32_MAX: none). While it shows the HIP inside by
  /// more than it can have moved (Λ·|ΔX_h|), a contact tick need not sample φ(X_h).
  fixed::Voxels hip_phi_bound{fixed::Q16::FromRaw(std::numeric_limits<std::int32_t>::max())};
  bool valid = false;  ///< false: next tick starts the proxy at the HIP (start-up, reset)
  /// Blob v2: the cells last sampled at the proxy and at the HIP (sampler::PhiCache), which a tick
  /// mostly samples again. They change how fast a sample is read, never its value, and record
  /// their sampler, so they need no reset (not even after a field swap).
  sampler::PhiCache proxy_phi_cache;
  sampler::GradientCache proxy_gradient_cache;
  sampler::PhiCache hip_phi_cache;
};

/// What one tick produced.
struct TickResult {
  GridPos proxy;
  std::array<fixed::Newtons, 3> force{};  ///< eq. 10: f = −k (X_h − X_p), clamped
  fixed::Voxels penetration;              ///< |X_p − X_h| when in contact, else 0
  bool contact = false;                   ///< a non-zero force: the surface holds the proxy from the HIP
  bool clamped = false;                   ///< |f| hit max_force
  bool converged = false;                 ///< eq. 9 reached its fixed point (update ≤ tolerance)
  int iterations = 0;                     ///< field samples at or towards the proxy, ≤ max_iterations (φ(X_h) apart)
};

/// One servo tick of the proxy (paper eq. 9, 10). RT-safe, bounded: at most max_iterations field
/// samples and a fixed amount of arithmetic per sample.
///
/// Invariant (the no-tunnelling guarantee): every point of the proxy's path, over all ticks, has
/// φ > −3δ/2, and the proxy rests only where φ ≥ −δ (a contact move's end ≥ −δ/2). Each move is a
/// straight segment [a, b] accepted only if φ(a) + φ(b) + 2δ_w ≥ Λ·|b − a| (δ_w = δ in free
/// motion, 3δ/2 in contact and leaving), where Λ bounds |∇φ·(b−a)/|b−a|| over the whole grid (min
/// of the field's Lipschitz norm and Σ|d_i|·max|∂_iφ|, see sampler::LipschitzBound): then
/// φ ≥ (φ(a) + φ(b) − Λ|b−a|)/2 ≥ −δ_w all along it. A part whose interior reaches φ ≤ −3δ/2
/// across its whole cross-section (a 2-voxel plate reaches −1/2) cannot be crossed.
///
/// Free motion (φ(X_p) > 1/2 voxel): move to X_h without a sample if it lies in the ball where
/// φ > 1/2 (carrying a lower bound of φ), else jump to X_h if [X_p, X_h] is certified and
/// φ(X_h) > 0, else sphere-trace towards X_h in steps of φ/Λ (which never reach φ = 0).
/// Near the surface: eq. 9 in projected, normalised form,
///   X_p ← X_p + γ P_T (X_h − X_p) − β φ(X_p) ∇φ / |∇φ|²,   P_T = I − ∇φ∇φᵀ/|∇φ|²,
/// i.e. with γ = β = 1 the projection of X_h onto the surface linearised at X_p (Gauss–Newton).
/// Projecting the HIP term onto the tangent plane and normalising the φ term makes the fixed
/// point the constrained minimum of eq. 5 (proxy on φ = 0 nearest the HIP), not the penalty
/// minimum of eq. 6. A move runs in pieces: the first carries the normal part and as much of the
/// tangential one as φ(X_p) + 3δ/2 allows, each further piece 3δ/2/Λ more; every piece end is
/// sampled and every piece certified, a failing piece ends the move (the next is halved). Caps:
/// max_iterations samples (hard); the tick settles after settle_samples unless the proxy lags a
/// fast HIP; gradient_samples of them read ∇φ. Besides them, φ(X_h) once a tick (not while an
/// upper bound shows the HIP inside). Convergence test: a move (or computed update) of
/// |Δ|₁ ≤ tolerance ends the iteration. If the HIP is outside the field, the proxy marches towards
/// it instead (leaving contact); the way is blocked only where a march end has φ < −δ (δ/2 deeper
/// than any contact rest), and then the proxy is held and slides round the part.
/// Friction (μs > 0, CHAI3D-style cone): the proxy sticks while its tangential offset from the
/// HIP is ≤ μs × depth, and otherwise slides to the edge of the μd cone.
/// Force (eq. 10): f = k·h·(X_p − X_h) when the proxy is at the surface (φ ≤ 1/2 voxel) and the
/// HIP is inside (φ(X_h) < 0) or the way to it is blocked; zero otherwise (free space, a clear
/// way, or a proxy still catching up). Magnitude limited to max_force (components rounded towards
/// zero: Σf² ≤ max² exactly), to last tick's + k·(|ΔX_h| + min(|ΔX_p|, 1 voxel)) + max_force/1024
/// (no step), and, held with the HIP outside, to last tick's − max_force/1024 (the overpower
/// fade); direction kept. With the HIP inside, the proxy never leaves the near band (no drop).
/// docs/realtime-core.md § Hold, release and overpower policy. A proxy started inside the object
/// follows the HIP with zero force until the HIP has been outside once.
/// One instantiation per storage (no storage branch inside the tick); the TrilinearSampler overload
/// picks one with a single branch at the top of the tick.
TickResult ProxyTick(const sampler::DenseSampler& field, const ProxyParams& params, ProxyState& state, GridPos hip);
TickResult ProxyTick(const sampler::BrickSampler& field, const ProxyParams& params, ProxyState& state, GridPos hip);
inline TickResult ProxyTick(const sampler::TrilinearSampler& field, const ProxyParams& params, ProxyState& state,
                            GridPos hip) {
  return field.Visit([&](const auto& typed) { return ProxyTick(typed, params, state, hip); });
}

/// Eq. 10 alone: f = k·h·(proxy − hip), its magnitude clamped to max_force with its direction kept.
/// Components (Q16.16 N) are rounded towards zero and |u| up, so Σ f_i² ≤ max_force² holds exactly
/// in raw units (no overshoot by a bit). RT-safe.
std::array<fixed::Newtons, 3> SpringForce(const ProxyParams& params, GridPos proxy, GridPos hip);

/// The upper bound of |SpringForce| that ProxyTick keeps in ProxyState::pull_q16 (Q16.16 N), for a
/// proxy seated at `proxy` by someone else (a field swap): its rise limit then starts from the
/// spring's own force, not from 0. RT-safe.
std::int32_t SpringPullBound(const ProxyParams& params, GridPos proxy, GridPos hip);

/// Passivity observer (Hannaford & Ryu 2002) for the sampled spring of eq. 10. Call Update once
/// per tick with the tick's HIP and result. RT-safe, integer only.
///
///   energy_q32  E_n = −Σ_{m<n} f_m · (X_h,m+1 − X_h,m)   energy the user put into the virtual
///               environment, the force f_m held over the period (zero-order hold)
///   zoh_bound_q32  B_n = (k·h/2) Σ |ΔX_h,m|² over the intervals m < n that start or end in
///               contact: the most a sampled spring can give back beyond what it stored. For a
///               proxy at its constrained minimum (with or without friction, clamped or not)
///               E_n ≥ W(u_n) − B_n ≥ −B_n, W the clamped spring's convex potential
///               (docs/realtime-core.md § Passivity observer): E below −B_n flags an active tick.
/// Both in Q32.32 N·voxel (multiply by voxel_m for joules), saturating.
struct PassivityObserver {
  std::int64_t energy_q32 = 0;
  std::int64_t zoh_bound_q32 = 0;
  GridPos last_hip;
  std::array<std::int32_t, 3> last_force{};
  bool primed = false;

  void Update(GridPos hip, const TickResult& r, const ProxyParams& params);
  double EnergyJ(double voxel_m) const { return static_cast<double>(energy_q32) / 4294967296.0 * voxel_m; }
  double ZohBoundJ(double voxel_m) const { return static_cast<double>(zoh_bound_q32) / 4294967296.0 * voxel_m; }
};

}  // namespace palpa::proxy
