// Unit wrappers over Q16.16 so that, e.g., voxels plus newtons does not compile. Each wrapper
// names its unit; conversions between units go through named functions in the proxy, which own
// the scale factors (voxel size, stiffness). The static_asserts below pin the result types, in
// the manner of CNL's tests: a change of rule fails the build, not a run.
#pragma once

#include <concepts>
#include <type_traits>

#include "palpa/fixed/q.h"

namespace palpa::fixed {

/// A Q16.16 quantity tagged with a unit. Same-unit addition and subtraction only.
template <typename UnitTag>
struct Quantity {
  Q16 value;
  friend constexpr Quantity operator+(Quantity a, Quantity b) { return {a.value + b.value}; }
  friend constexpr Quantity operator-(Quantity a, Quantity b) { return {a.value - b.value}; }
  friend constexpr Quantity operator-(Quantity a) { return {-a.value}; }
  friend constexpr bool operator==(Quantity a, Quantity b) = default;
  friend constexpr auto operator<=>(Quantity a, Quantity b) = default;
};

struct VoxelTag {};           ///< length in grid voxels (position, φ)
struct NewtonTag {};          ///< force, N
struct NewtonPerVoxelTag {};  ///< stiffness k·h, N per voxel

using Voxels = Quantity<VoxelTag>;
using Newtons = Quantity<NewtonTag>;
using NewtonsPerVoxel = Quantity<NewtonPerVoxelTag>;

/// Hooke's law in fixed point (paper eq. 10 per axis): N/voxel × voxel → N, the product exact
/// in int64 and rounded towards zero. The one rounding rule of eq. 10: towards zero never makes a
/// component larger, so |f| ≤ k·|x| holds exactly (proxy::ProxyTick relies on it; the caller then
/// limits the vector's magnitude, keeping its direction). Precondition: |k·x| < 32768 N, which a
/// caller that has bounded the force already knows (the servo tick: k·|x| ≤ max_force ≤ 100 N).
constexpr Newtons HookeUnsaturated(NewtonsPerVoxel k, Voxels x) {
  return {Q16::FromRaw(static_cast<std::int32_t>(ShiftRight(Mul(k.value, x.value).raw, 16, Round::kTowardZero)))};
}

/// HookeUnsaturated without the precondition: the same rounding, saturating at ±32768 N.
constexpr Newtons operator*(NewtonsPerVoxel k, Voxels x) {
  return {Narrow<16>(Mul(k.value, x.value), Round::kTowardZero)};
}

namespace detail {
template <typename A, typename B>
concept Addable = requires(A a, B b) {
  a + b;
};
}  // namespace detail

static_assert(std::is_same_v<decltype(NewtonsPerVoxel{} * Voxels{}), Newtons>);
static_assert(std::is_same_v<decltype(HookeUnsaturated(NewtonsPerVoxel{}, Voxels{})), Newtons>);
static_assert(std::is_same_v<decltype(Voxels{} + Voxels{}), Voxels>);
static_assert(std::is_same_v<decltype(Newtons{} - Newtons{}), Newtons>);
static_assert(!detail::Addable<Voxels, Newtons> && !detail::Addable<Newtons, NewtonsPerVoxel>);
static_assert(!std::is_convertible_v<Voxels, Newtons> && !std::is_convertible_v<Q16, Voxels>);
static_assert(sizeof(Voxels) == 4 && std::is_trivially_copyable_v<Voxels>);                          // costs nothing
static_assert((NewtonsPerVoxel{Q16::FromRaw(3)} * Voxels{Q16::FromRaw(-65535)}).value.raw() == -2);  // not −3
static_assert(HookeUnsaturated(NewtonsPerVoxel{Q16::FromRaw(3)}, Voxels{Q16::FromRaw(-65535)}).value.raw() == -2);
static_assert((NewtonsPerVoxel{Q16::FromInt(30000)} * Voxels{Q16::FromInt(2)}).value.raw() == INT32_MAX);

}  // namespace palpa::fixed
