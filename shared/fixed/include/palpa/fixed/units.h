// Unit wrappers over Q16.16 so that, e.g., metres plus newtons does not compile. Each wrapper
// names its unit; conversions between units go through named functions in the proxy, which own
// the scale factors (voxel size, stiffness).
#pragma once

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

/// Hooke's law in fixed point (paper eq. 10 per axis): N/voxel × voxel → N, rounded to nearest,
/// saturating (the caller clamps the force vector's magnitude afterwards).
constexpr Newtons operator*(NewtonsPerVoxel k, Voxels x) {
  return {Narrow<16>(Mul(k.value, x.value), Round::kNearest)};
}

}  // namespace palpa::fixed
