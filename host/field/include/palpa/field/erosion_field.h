// Narrow-band signed distance field from the indicator by erosion, paper §3.2 eq. 4.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "palpa/field/grid.h"

namespace palpa::field {

struct DenseField {
  GridSpec grid;
  // One value per node, C order (k fastest), in voxels, negative inside, clamped to
  // [-band_voxels, +band_voxels].
  std::vector<float> phi_voxels;
  std::size_t inside_nodes = 0;  // nodes in S (indicator 1, not on a grid face)
};

// S = nodes with indicator 1, except that nodes on the outer grid faces are always taken as
// outside (a leaking ball must not make the field open at the grid boundary).
//   Inside (eq. 4, erosion by the unit 6-neighbourhood): phi = -(d_out - 1), where d_out >= 1 is
//     the 6-connected (city-block) node distance to the nearest node not in S. Boundary nodes of
//     S get 0, the next layer -1, and so on.
//   Outside (the same erosion applied to the complement): phi = +d_in, d_in >= 1 the city-block
//     distance to S.
// Both sides stop at the band: phi is clamped to [-band, +band]. City-block distance is computed
// exactly (equal to multi-source BFS) by separable 1-D passes, parallel with TBB; deterministic.
// `indicator` must have grid.NodeCount() entries (else phi_voxels is empty).
DenseField ErosionField(const GridSpec& grid, const std::vector<std::uint8_t>& indicator);

}  // namespace palpa::field
