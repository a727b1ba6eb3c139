// Exact signed Euclidean distance transform of the packing indicator (issue 5, `--method edt`).
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "palpa/field/grid.h"

namespace palpa::field {

// Squared Euclidean distance transform, in place, in node units: on entry f[x] is 0 on feature
// nodes and `infinity` (any value >= the largest squared distance of interest) elsewhere; on
// exit f[x] = min over feature nodes y of |x - y|^2, capped at `infinity`. Separable: one
// lower-envelope-of-parabolas pass per axis (Felzenszwalb & Huttenlocher 2012, Theory of
// Computing 8, alg. 1), rows in parallel with TBB; exact and deterministic for any thread count.
// `f` has dims[0]*dims[1]*dims[2] values in C order (k fastest).
void SquaredEdt(const std::array<int, 3>& dims, std::vector<float>& f, float infinity);

// Signed EDT of the indicator, both sides, in voxels: S = indicator nodes except the grid faces
// (as in ErosionField). Outside S: phi = d(x, S) - 1/2; inside S: phi = -(d(x, not S) - 1/2),
// d the Euclidean node distance, so the surface sits half-way between an inside and an outside
// node. Clamped to [-band, +band]. Dense: O(volume) memory and time (the reference method).
// `indicator` must have grid.NodeCount() entries (else the result is empty).
std::vector<float> SignedEdtField(const GridSpec& grid, const std::vector<std::uint8_t>& indicator);

}  // namespace palpa::field
