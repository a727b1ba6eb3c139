// SortDistinctIndices (palpa/field/index_order.h) against std::sort: few indices, many in a
// narrow span (the marks), many in a wide span (a sort), and the marks left all zero.
#include "palpa/field/index_order.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <numeric>
#include <random>
#include <vector>

namespace {

using palpa::field::SortDistinctIndices;

TEST(SortDistinctIndices, AscendingAsStdSort) {
  std::mt19937 rng(3);
  std::vector<std::uint64_t> marks;
  for (const auto& [count, span, offset] :
       {std::array<std::size_t, 3>{10, 1000, 0}, std::array<std::size_t, 3>{5000, 20000, 0},
        std::array<std::size_t, 3>{700, 800, 123457}, std::array<std::size_t, 3>{100, 1000000, 64},
        std::array<std::size_t, 3>{64, 64, 0}}) {
    std::vector<std::size_t> all(span);
    std::iota(all.begin(), all.end(), offset);
    std::shuffle(all.begin(), all.end(), rng);
    std::vector<std::size_t> indices(all.begin(), all.begin() + static_cast<std::ptrdiff_t>(count));
    std::vector<std::size_t> expected = indices;
    std::sort(expected.begin(), expected.end());
    SortDistinctIndices(indices, marks);
    EXPECT_EQ(indices, expected) << count << " of " << span;
    EXPECT_TRUE(std::all_of(marks.begin(), marks.end(), [](std::uint64_t w) { return w == 0; }));
  }
  EXPECT_FALSE(marks.empty());  // the marks were used
}

}  // namespace
