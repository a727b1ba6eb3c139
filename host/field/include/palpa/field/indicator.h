// Indicator (characteristic) function of the packed-ball union on the grid, paper §3.1.
#pragma once

#include <cstdint>
#include <vector>

#include "palpa/field/grid.h"
#include "palpa/field/packing.h"

namespace palpa::field {

// 1 on every node strictly inside at least one packed ball (|x - c_i| < r_i), 0 elsewhere.
// Size grid.NodeCount(), C order (k fastest). `packing` must be in the grid's units (metres).
// Rasterises each ball as k-spans in parallel over i-slabs (TBB); deterministic.
std::vector<std::uint8_t> Indicator(const GridSpec& grid, const Packing& packing);

}  // namespace palpa::field
