// Distinct indices into ascending order, for loops whose result must not depend on the order a
// k-d tree search found them in (GuardPacking's shrink, hermite_field.cc). Host only, non-RT.
#pragma once

#include <algorithm>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace palpa::field {

/// Sorts `indices` (distinct) ascending: by std::sort, or, when they are many for the span they
/// cover, by marking them in `marks` (a bit per index, all zero before and after; grown as
/// needed) and reading the marks in order: linear instead of n log n where a sphere's outer ball
/// crosses a fifth of its samples' planes (CGAL's radar.xyz: thousands for each of 20,000 balls).
inline void SortDistinctIndices(std::vector<std::size_t>& indices, std::vector<std::uint64_t>& marks) {
  if (indices.size() < 64) {
    std::sort(indices.begin(), indices.end());
    return;
  }
  const auto [lo, hi] = std::minmax_element(indices.begin(), indices.end());
  const std::size_t first = *lo / 64, last = *hi / 64;
  if (last - first > 4 * indices.size()) {
    std::sort(indices.begin(), indices.end());
    return;
  }
  if (marks.size() <= last) marks.resize(last + 1, 0);
  for (const std::size_t j : indices) marks[j / 64] |= std::uint64_t{1} << (j % 64);
  indices.clear();
  for (std::size_t word = first; word <= last; ++word) {
    for (std::uint64_t bits = marks[word]; bits != 0; bits &= bits - 1)
      indices.push_back(word * 64 + static_cast<std::size_t>(std::countr_zero(bits)));
    marks[word] = 0;
  }
}

}  // namespace palpa::field
