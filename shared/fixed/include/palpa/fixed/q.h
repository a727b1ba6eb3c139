// Fixed-point numbers as types: a scaled integer whose multiply widens and whose narrowing names
// its rounding and overflow behaviour. RT-safe: constexpr, no allocation, no exceptions.
//
// Q16.16 (int32, 16 fraction bits) is the servo loop's working format. Positions and φ are kept
// in *voxel units* rather than metres so that one LSB is 1/65536 voxel (3 nm at a 0.2 mm voxel)
// whatever the grid size; the metre scale enters only at the device boundary (see
// palpa/proxy/proxy.h for every quantity's format, range and resolution).
#pragma once

#include <array>
#include <bit>
#include <concepts>
#include <cstddef>
#include <cstdint>
#include <limits>

namespace palpa::fixed {

static_assert(std::endian::native == std::endian::little, "palpa assumes a little-endian target");
// C++20 defines >> on negative values as arithmetic shift; the fixed-point code relies on it.
static_assert((-3 >> 1) == -2);

/// Rounding applied when dropping fraction bits.
enum class Round {
  kFloor,       ///< towards −∞ (a plain arithmetic shift)
  kNearest,     ///< to nearest, ties away from zero (symmetric, so −x rounds as −(x))
  kTowardZero,  ///< towards 0, as C++ integer division (symmetric; never grows a magnitude)
};

/// Shifts `v` right by `bits` (≥ 0) with the given rounding. Pure integer arithmetic: the same
/// bits on every target.
constexpr std::int64_t ShiftRight(std::int64_t v, int bits, Round round) {
  if (bits <= 0) return v;
  if (round == Round::kFloor) return v >> bits;
  if (round == Round::kTowardZero) return v / (std::int64_t{1} << bits);  // C++ division truncates
  const std::int64_t half = std::int64_t{1} << (bits - 1);
  return v >= 0 ? (v + half) >> bits : -((-v + half) >> bits);
}

/// Saturates a 64-bit intermediate to int32's range. Used wherever a narrowing could overflow, so
/// that nothing wraps around.
constexpr std::int32_t SaturateToInt32(std::int64_t v) {
  if (v > std::numeric_limits<std::int32_t>::max()) return std::numeric_limits<std::int32_t>::max();
  if (v < std::numeric_limits<std::int32_t>::min()) return std::numeric_limits<std::int32_t>::min();
  return static_cast<std::int32_t>(v);
}

/// A Q(31−F).F number in int32: value = raw · 2^−F.
/// Addition keeps the format; multiplication widens to Wide<F+G> (int64), and going back to a
/// narrow format is an explicit Narrow<> naming its rounding (saturating, never wrapping).
template <int F>
class Q {
 public:
  static constexpr int kFracBits = F;
  static constexpr std::int32_t kOne = std::int32_t{1} << F;

  constexpr Q() = default;
  static constexpr Q FromRaw(std::int32_t raw) { return Q(raw); }
  /// Nearest representable value, saturating. For start-up conversion and tests, not the loop.
  static constexpr Q FromDouble(double v) {
    const double scaled = v * static_cast<double>(kOne);
    if (!(scaled == scaled)) return Q(0);  // NaN → 0; callers validate before converting
    if (scaled >= 2147483647.0) return Q(std::numeric_limits<std::int32_t>::max());
    if (scaled <= -2147483648.0) return Q(std::numeric_limits<std::int32_t>::min());
    return Q(static_cast<std::int32_t>(scaled >= 0 ? scaled + 0.5 : scaled - 0.5));
  }
  static constexpr Q FromInt(std::int32_t v) { return Q(v * kOne); }

  constexpr std::int32_t raw() const { return raw_; }
  constexpr double ToDouble() const { return static_cast<double>(raw_) / static_cast<double>(kOne); }

  friend constexpr Q operator+(Q a, Q b) { return Q(SaturateToInt32(std::int64_t{a.raw_} + b.raw_)); }
  friend constexpr Q operator-(Q a, Q b) { return Q(SaturateToInt32(std::int64_t{a.raw_} - b.raw_)); }
  friend constexpr Q operator-(Q a) { return Q(SaturateToInt32(-std::int64_t{a.raw_})); }
  friend constexpr bool operator==(Q a, Q b) = default;
  friend constexpr auto operator<=>(Q a, Q b) = default;

 private:
  constexpr explicit Q(std::int32_t raw) : raw_(raw) {}
  std::int32_t raw_ = 0;
};

/// A product of two Q numbers, exact in int64: value = raw · 2^−F.
template <int F>
struct Wide {
  std::int64_t raw = 0;
};

/// Exact widening multiply, 32×32→64: Q<F>·Q<G> → Wide<F+G>.
template <int F, int G>
constexpr Wide<F + G> Mul(Q<F> a, Q<G> b) {
  return Wide<F + G>{std::int64_t{a.raw()} * std::int64_t{b.raw()}};
}

/// Narrows a wide value to Q<T> with the named rounding, saturating at int32's range.
template <int T, int F>
constexpr Q<T> Narrow(Wide<F> w, Round round) {
  static_assert(F >= T, "Narrow drops fraction bits; use a widening conversion to add them");
  return Q<T>::FromRaw(SaturateToInt32(ShiftRight(w.raw, F - T, round)));
}

using Q16 = Q<16>;  ///< Q16.16: range ±32768, resolution 1.53e-5

/// Integer square root, the reference form: ⌊√v⌋ for v ≥ 0 (0 for v ≤ 0). Bit-by-bit, at most 32
/// iterations, constexpr. The tests check ISqrt against it; the loop uses ISqrt.
constexpr std::uint64_t ISqrtBitwise(std::int64_t v) {
  if (v <= 0) return 0;
  auto x = static_cast<std::uint64_t>(v);
  std::uint64_t result = 0;
  std::uint64_t bit = std::uint64_t{1} << 62;
  while (bit > x) bit >>= 2;
  while (bit != 0) {
    if (x >= result + bit) {
      x -= result + bit;
      result = (result >> 1) + bit;
    } else {
      result >>= 1;
    }
    bit >>= 2;
  }
  return result;
}

/// Integer square root: ⌊√v⌋ for v ≥ 0 (0 for v ≤ 0), exact for every int64.
/// The FPU's correctly rounded √ of the nearest double gives an estimate within 1 of ⌊√v⌋ (for
/// v < 2^63 its relative error is ≤ 2^−52, i.e. < 2^−20 absolute); the result is then corrected
/// with integer arithmetic until r² ≤ v < (r + 1)². So the answer is the same integer on every
/// target whatever the FPU's rounding mode: floating point only speeds up finding it (one square
/// root instead of a 32-step loop or two 64-bit divisions). At most two corrections run.
inline std::uint64_t ISqrt(std::int64_t v) {
  if (v <= 0) return 0;
  const auto u = static_cast<std::uint64_t>(v);
  auto r = static_cast<std::uint64_t>(__builtin_sqrt(static_cast<double>(v)));
  // r < 2^31.5 + 1, so (r + 1)² < 2^64: no wrap.
  if (r * r > u) --r;
  if (r * r > u) --r;
  if ((r + 1) * (r + 1) <= u) ++r;
  return r;
}

/// Floor division ⌊n/d⌋ for 0 ≤ n < 2^62 and 0 < d < 2^62, exact. As ISqrt: a double estimate
/// (within 1 of the quotient for quotients below 2^50, the only ones palpa forms), then integer
/// corrections until q·d ≤ n < (q + 1)·d. Same bits on every target.
inline std::int64_t FloorDiv(std::int64_t n, std::int64_t d) {
  // n and d round to doubles within 2^−53 relative, the quotient too: below 2^50 the estimate is
  // within 0.4 of n/d, so after truncation one step either way corrects it (two are allowed).
  auto q = static_cast<std::int64_t>(static_cast<double>(n) / static_cast<double>(d));
  if (q * d > n) --q;
  if (q * d > n) --q;
  if ((q + 1) * d <= n) ++q;
  if ((q + 1) * d <= n) ++q;
  return q;
}

/// Rounded integer division n/d (d ≠ 0), ties away from zero. Start-up and rare paths.
constexpr std::int64_t DivRound(std::int64_t n, std::int64_t d) {
  const bool negative = (n < 0) != (d < 0);
  const std::uint64_t un = n < 0 ? static_cast<std::uint64_t>(-n) : static_cast<std::uint64_t>(n);
  const std::uint64_t ud = d < 0 ? static_cast<std::uint64_t>(-d) : static_cast<std::uint64_t>(d);
  const auto q = static_cast<std::int64_t>((un + ud / 2) / ud);
  return negative ? -q : q;
}

}  // namespace palpa::fixed
