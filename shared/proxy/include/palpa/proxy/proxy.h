// The god-object proxy on a signed distance field (paper §3.3, eq. 9) and its force (eq. 10), in
// fixed point. RT-safe after construction: no allocation, no exceptions, no syscalls, bounded
// iterations (kMaxTraceSteps + max_iterations samples per tick).
//
// Formats (all int32 unless noted):
//   position, HIP, proxy   Q16.16 voxel units (grid frame)   range ±32768 voxel, LSB 1/65536 voxel
//   φ (field values)       Q16.16 voxel units                |φ| ≤ band ≤ 64 voxels
//   ∇φ                     Q16.16, voxel per voxel           |component| ≤ 2·band (neighbour diff)
//   γ, β (eq. 9)           Q16.16, dimensionless             γ in (0, 1], β in (0, 1]
//   k·h (stiffness)        Q16.16 N per voxel                (0, 32768) N/voxel, LSB 1.5e-5 N/voxel
//   force                  Q16.16 N                          |f| ≤ max_force ≤ 100 N, LSB 1.5e-5 N
// Overflow analysis: grid ≤ 4096 nodes per axis, so positions ≤ 2^28 raw and differences ≤ 2^29;
// squared lengths ≤ 3·2^58 < 2^63. k·h·Δ is formed in int64 (≤ 2^31·2^29) and saturated. φ·∇φ
// products ≤ 2^22·2^23. MakeProxyParams rejects parameters outside these ranges at start-up.
#pragma once

#include <array>
#include <cstdint>
#include <expected>

#include "palpa/blob/blob.h"
#include "palpa/fixed/units.h"
#include "palpa/sampler/trilinear.h"

namespace palpa::proxy {

using sampler::GridPos;

/// Sphere-tracing steps per tick for free motion (phase 1).
inline constexpr int kMaxTraceSteps = 16;
/// 1/√3 in Q0.16, rounded down: the safe step factor for a trilinear field whose neighbour
/// differences are at most 1 voxel (|∇φ| ≤ √3 inside any cell).
inline constexpr std::int32_t kInvLipschitzQ16 = 37837;

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

/// Parameters of eq. 9/10 in loop formats. Build with MakeProxyParams.
struct ProxyParams {
  std::int32_t gamma_q16 = 1 << 15;        ///< eq. 9 γ: fraction of (X_h − X_p) taken per iteration
  std::int32_t beta_q16 = 1 << 16;         ///< eq. 9 β, applied to the Gauss–Newton normalised term
  std::int32_t max_step_q16 = 1 << 14;     ///< step cap per iteration, voxels (0.25): keeps steps
                                           ///< far below a 2-voxel wall so projection stays on the entry side
  std::int32_t tolerance_q16 = 4;          ///< convergence: max |ΔX_p| component per iteration, voxels
  std::int32_t contact_eps_q16 = 1 << 10;  ///< phase 1 stops this close to φ = 0 (1/64 voxel)
  int max_iterations = 32;                 ///< eq. 9 iterations per tick (phase 2)
  fixed::NewtonsPerVoxel k;                ///< k·h
  fixed::Newtons max_force;                ///< force clamp, N
  double voxel_m = 1;                      ///< for reporting only
};

/// SI inputs of the proxy.
struct ProxyConfig {
  double k_n_per_m = 800;   ///< stiffness k, N/m (paper eq. 10)
  double max_force_n = 8;   ///< force clamp, N (direction preserved)
  double gamma = 0.5;       ///< eq. 9 γ
  double beta = 1.0;        ///< eq. 9 β (normalised, see ProxyTick)
  int max_iterations = 32;  ///< 1..256
};

/// Validates `config` for a field with voxel size `voxel_m` and converts it to loop formats.
/// Errors (a static sentence) for: k ≤ 0 or > 1e5 N/m, k·h outside [1e-3, 32767] N/voxel (too
/// coarse or overflowing Q16.16), max force ≤ 0 or > 100 N, γ or β outside (0, 1], iterations
/// outside 1..256, non-finite input. Non-RT.
std::expected<ProxyParams, const char*> MakeProxyParams(const ProxyConfig& config, double voxel_m);

/// Proxy state carried between ticks.
struct ProxyState {
  GridPos proxy;
  bool valid = false;  ///< false: next tick starts the proxy at the HIP (start-up, reset)
};

/// What one tick produced.
struct TickResult {
  GridPos proxy;
  std::array<fixed::Newtons, 3> force{};  ///< eq. 10: f = −k (X_h − X_p), clamped
  std::int32_t penetration_q16 = 0;       ///< |X_p − X_h| in voxels when in contact, else 0
  bool contact = false;                   ///< proxy held apart from the HIP by the surface
  bool clamped = false;                   ///< |f| hit max_force
  int iterations = 0;                     ///< samples taken (phase 1 + phase 2)
};

/// One servo tick of the proxy (paper eq. 9, 10). RT-safe, bounded.
///
/// Phase 1 (free motion): sphere-traces from X_p towards X_h with steps φ(X_p)/√3, which cannot
/// cross φ = 0 for a field whose neighbour differences are ≤ 1 voxel; reaching X_h ends the tick
/// with zero force (exactly). Phase 2 (contact): iterates eq. 9,
///   X_p ← X_p − γ (X_p − X_h) − β φ(X_p) ∇φ(X_p) / |∇φ(X_p)|²,
/// as two half-steps (the γ step, capped at max_step, then the φ step evaluated at the moved
/// point, only where φ < 0). Normalising by |∇φ|² makes β = 1 a Gauss–Newton projection onto
/// φ = 0, so the iteration converges to the constrained minimum of eq. 5 (proxy on the surface,
/// nearest to the HIP) rather than the penalty minimum of eq. 6, whose proxy sinks by
/// penetration/λ. Stops when no component moves more than `tolerance` or after max_iterations.
/// Force: f = k·h·(X_p − X_h), magnitude clamped to max_force with its direction kept.
TickResult ProxyTick(const sampler::TrilinearSampler& field, const ProxyParams& params, ProxyState& state, GridPos hip);

}  // namespace palpa::proxy
