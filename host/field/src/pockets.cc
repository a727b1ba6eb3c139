// Enclosed outside pockets and floating inside islands that no sample bounds: palpa/field/pockets.h.
#include "palpa/field/pockets.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstdint>
#include <optional>
#include <utility>
#include <vector>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <nanoflann.hpp>

#include "pockets_internal.h"
#include "point_cloud.h"

namespace palpa::field {

namespace {

using V3 = Eigen::Vector3d;

// Samples asked at a pocket's surface node whether one bounds it: more than the 8 that a spacing
// (the 8th nearest) holds about a sample.
// Why facing, not distance alone: the bundled oni's open neck (data/oni.pwn, 1,435 samples, 300
// cells) kept 1,494 outside nodes in 3 pockets 13-30 voxels from every sample, which the far
// pass's node-by-node rules left in the closure and HIL's recorded hands push into. Its samples
// are sparse (the 8th nearest 12.9 voxels away, median; 28 at the neck's rim), so the pockets lie
// within 0.47-0.61 of a spacing of some sample, where a sampled surface may pass. But every sample
// within a spacing of them has them behind it, 6.5-8.4 voxels deep.
constexpr std::size_t kBoundNeighbours = 16;

// FillSamplelessPockets (`inside` false: outside pockets, filled) and CutSamplelessIslands (true:
// inside islands, cut), one flood: "ours" is the side searched, the other side's uniform bricks
// are walls. The outside is seeded at the grid faces, the inside at its nodes within
// reach_voxels of a sample. `tree`: a k-d tree over `positions`, or null to build one only when
// something is enclosed.
PocketFill FillUnbounded(SparseField& field, bool inside, const std::vector<V3>& positions,
                         const std::vector<V3>& normals, const std::vector<double>& spacing, const detail::KdTree* tree,
                         double reach_voxels, double reach_spacings) {
  const GridSpec& grid = field.grid();
  const double h = grid.voxel_m;
  const auto band = static_cast<float>(grid.band_voxels);
  constexpr int kB = SparseField::kBrick;
  static_assert(kB == 8, "a brick's layer is one 64-bit word");
  // A brick's nodes as bits: word a, bit c * 8 + e for node (a, c, e), the brick's own local
  // index within the layer.
  using Mask = std::array<std::uint64_t, kB>;
  constexpr std::uint64_t kByteLow = 0x0101010101010101ull;  // e = 0 in every row
  constexpr std::uint64_t kNotE0 = ~kByteLow, kNotE7 = ~(kByteLow << 7);
  const std::int32_t kOurs = inside ? SparseField::kUniformInside : SparseField::kUniformOutside;
  const std::int32_t kWall = inside ? SparseField::kUniformOutside : SparseField::kUniformInside;
  const auto ours = [inside](float x) { return inside ? x <= 0.0f : x > 0.0f; };
  const auto& bd = field.brick_dims();
  const std::array<int, 3> dims = grid.dims;
  const std::size_t n_bricks =
      static_cast<std::size_t>(bd[0]) * static_cast<std::size_t>(bd[1]) * static_cast<std::size_t>(bd[2]);
  const auto extent = [&](const std::array<int, 3>& bc) {
    return std::array<int, 3>{std::min(kB, dims[0] - bc[0] * kB), std::min(kB, dims[1] - bc[1] * kB),
                              std::min(kB, dims[2] - bc[2] * kB)};
  };
  // The brick's grid nodes (the last brick of an axis may reach past the grid).
  const auto in_grid = [&](const std::array<int, 3>& bc) {
    const auto [na, nc, ne] = extent(bc);
    const std::uint64_t row = (1ull << ne) - 1ull;
    std::uint64_t layer = 0;
    for (int c = 0; c < nc; ++c) layer |= row << (8 * c);
    Mask m{};
    for (int a = 0; a < na; ++a) m[static_cast<std::size_t>(a)] = layer;
    return m;
  };
  const auto empty = [](const Mask& m) {
    return std::all_of(m.begin(), m.end(), [](std::uint64_t x) { return x == 0; });
  };
  // Masks of allocated bricks (and later of our unreached uniform ones): our side's nodes, and
  // those the flood reached.
  std::vector<std::int32_t> index(n_bricks, -1);
  std::vector<Mask> side, reach;
  std::vector<std::uint8_t> full;  // per allocated brick: every grid node on our side
  std::vector<std::size_t> allocated;
  for (std::size_t b = 0; b < n_bricks; ++b)
    if (field.BrickValues(b) != nullptr) {
      index[b] = static_cast<std::int32_t>(allocated.size());
      allocated.push_back(b);
    }
  side.resize(allocated.size());
  full.resize(allocated.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, allocated.size(), 64), [&](const auto& range) {
    for (std::size_t m = range.begin(); m != range.end(); ++m) {
      const float* v = field.BrickValues(allocated[m]);
      const Mask grid_nodes = in_grid(field.BrickCoords(allocated[m]));
      for (std::size_t a = 0; a < side[m].size(); ++a) {
        std::uint64_t bits = 0;
        for (std::size_t q = 0; q < 64; ++q) bits |= static_cast<std::uint64_t>(ours(v[a * 64 + q])) << q;
        side[m][a] = bits & grid_nodes[a];
      }
      full[m] = side[m] == grid_nodes ? 1 : 0;
    }
  });
  reach.assign(side.size(), Mask{});
  std::vector<std::uint8_t> uniform_reached(n_bricks, 0), queued(n_bricks, 0);
  std::vector<std::size_t> work;
  const auto push = [&](std::size_t b) {
    if (queued[b] == 0) {
      queued[b] = 1;
      work.push_back(b);
    }
  };
  // Adds `s` (nodes of brick b) to what the flood reached.
  const auto seed = [&](std::size_t b, const Mask& s) {
    const std::int32_t slot = field.Slot(b);
    if (slot == kWall) return;
    if (slot == kOurs) {
      if (uniform_reached[b] == 0 && !empty(s)) {
        uniform_reached[b] = 1;
        push(b);
      }
      return;
    }
    const auto m = static_cast<std::size_t>(index[b]);
    bool grew = false;
    for (std::size_t a = 0; a < s.size(); ++a) {
      const std::uint64_t add = s[a] & side[m][a] & ~reach[m][a];
      reach[m][a] |= add;
      grew = grew || add != 0;
    }
    if (grew) push(b);
  };
  if (!inside) {
    for (int bi = 0; bi < bd[0]; ++bi)
      for (int bj = 0; bj < bd[1]; ++bj)
        for (int bk = 0; bk < bd[2]; ++bk) {
          if (bi != 0 && bj != 0 && bk != 0 && bi != bd[0] - 1 && bj != bd[1] - 1 && bk != bd[2] - 1) continue;
          const std::size_t b = field.BrickIndex(bi, bj, bk);
          if (field.Slot(b) == kOurs) {
            uniform_reached[b] = 1;
            push(b);
            continue;
          }
          if (field.Slot(b) == kWall) continue;
          // The brick's nodes on a grid face: whole layers on the i faces, rows on the j faces, end
          // bits on the k faces.
          const std::array<int, 3> bc = {bi, bj, bk};
          const auto [na, nc, ne] = extent(bc);
          const Mask grid_nodes = in_grid(bc);
          std::uint64_t sides = 0;
          if (bj == 0) sides |= 0xFFull;
          if (bj == bd[1] - 1) sides |= 0xFFull << (8 * (nc - 1));
          if (bk == 0) sides |= kByteLow;
          if (bk == bd[2] - 1) sides |= kByteLow << (ne - 1);
          Mask face{};
          for (int a = 0; a < na; ++a) {
            const bool whole = (bi == 0 && a == 0) || (bi == bd[0] - 1 && a == na - 1);
            face[static_cast<std::size_t>(a)] = grid_nodes[static_cast<std::size_t>(a)] & (whole ? ~0ull : sides);
          }
          seed(b, face);
        }
  } else {
    // Every node within reach_voxels of a sample: a sphere of nodes about each one, as bits, in
    // parallel (an OR into the allocated bricks' masks; a uniform brick is flagged whole).
    const double r = reach_voxels, r2 = r * r;
    std::vector<Mask> near(allocated.size(), Mask{});
    std::vector<std::uint8_t> near_uniform(n_bricks, 0);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, positions.size(), 256), [&](const auto& range) {
      for (std::size_t t = range.begin(); t != range.end(); ++t) {
        const V3 g = (positions[t] - grid.origin_m) / h;
        bool beside = true;  // within reach of the grid (a far sample's index would not fit an int)
        for (std::size_t a = 0; a < 3; ++a) {
          const double x = g[static_cast<Eigen::Index>(a)];
          beside = beside && x >= -r && x <= dims[a] - 1 + r;
        }
        if (!beside) continue;
        std::array<int, 3> lo{}, hi{};
        for (std::size_t a = 0; a < 3; ++a) {
          lo[a] = std::max(0, static_cast<int>(std::ceil(g[static_cast<Eigen::Index>(a)] - r)));
          hi[a] = std::min(dims[a] - 1, static_cast<int>(std::floor(g[static_cast<Eigen::Index>(a)] + r)));
        }
        for (int i = lo[0]; i <= hi[0]; ++i)
          for (int j = lo[1]; j <= hi[1]; ++j)
            for (int k = lo[2]; k <= hi[2]; ++k) {
              if ((V3(i, j, k) - g).squaredNorm() > r2) continue;
              const std::size_t b = field.BrickIndex(i / kB, j / kB, k / kB);
              if (index[b] < 0) {
                std::atomic_ref<std::uint8_t>(near_uniform[b]).store(1, std::memory_order_relaxed);
                continue;
              }
              std::atomic_ref<std::uint64_t>(near[static_cast<std::size_t>(index[b])][static_cast<std::size_t>(i % kB)])
                  .fetch_or(1ull << (j % kB * kB + k % kB), std::memory_order_relaxed);
            }
      }
    });
    for (std::size_t b = 0; b < n_bricks; ++b) {
      if (index[b] >= 0)
        seed(b, near[static_cast<std::size_t>(index[b])]);
      else if (near_uniform[b] != 0)
        seed(b, in_grid(field.BrickCoords(b)));
    }
  }
  while (!work.empty()) {
    const std::size_t b = work.back();
    work.pop_back();
    queued[b] = 0;
    const std::array<int, 3> bc = field.BrickCoords(b);
    const bool uniform = field.Slot(b) == kOurs;
    Mask r;
    if (uniform) {
      r = in_grid(bc);
    } else {
      const auto m = static_cast<std::size_t>(index[b]);
      const Mask& o = side[m];
      if (full[m] != 0) {
        r = o;  // all ours: reached whole (for the outside, most of a band's outer bricks)
      } else {
        // Dilated by one node a step (every layer at once), masked to our side's nodes, to the
        // fixed point: as many steps as the flood's depth in the brick.
        r = reach[m];
        for (bool changed = true; changed;) {
          changed = false;
          std::uint64_t below = 0;  // layer a - 1 before this step
          for (std::size_t a = 0; a < r.size(); ++a) {
            const std::uint64_t x = r[a];
            const std::uint64_t y = (x | x << 8 | x >> 8 | (x << 1 & kNotE0) | (x >> 1 & kNotE7) | below |
                                     (a + 1 < r.size() ? r[a + 1] : 0)) &
                                    o[a];
            below = x;
            changed = changed || y != x;
            r[a] = y;
          }
        }
      }
      reach[m] = r;
    }
    // Across the six faces.
    for (int f = 0; f < 6; ++f) {
      const auto axis = static_cast<std::size_t>(f / 2);
      const bool up = f % 2 == 1;
      std::array<int, 3> nb = bc;
      nb[axis] += up ? 1 : -1;
      if (nb[axis] < 0 || nb[axis] >= bd[axis]) continue;
      const std::size_t nbi = field.BrickIndex(nb[0], nb[1], nb[2]);
      const std::int32_t slot = field.Slot(nbi);
      if (slot == kWall) continue;
      if (slot == kOurs && (uniform_reached[nbi] != 0 || uniform)) {
        // A uniform brick's face reaches all of the next brick's face (the grid's nodes on it).
        if (uniform_reached[nbi] == 0) {
          uniform_reached[nbi] = 1;
          push(nbi);
        }
        continue;
      }
      Mask s{};
      if (axis == 0) {
        s[up ? 0 : kB - 1] = r[up ? kB - 1 : 0];
      } else {
        for (std::size_t a = 0; a < s.size(); ++a) {
          if (axis == 1)
            s[a] = up ? r[a] >> 56 : (r[a] & 0xFFull) << 56;
          else
            s[a] = up ? (r[a] >> 7) & kByteLow : (r[a] & kByteLow) << 7;
        }
      }
      seed(nbi, s);
    }
  }
  // Our nodes the flood did not reach: masks for our unreached uniform bricks too.
  for (std::size_t b = 0; b < n_bricks; ++b)
    if (field.Slot(b) == kOurs && uniform_reached[b] == 0) {
      index[b] = static_cast<std::int32_t>(side.size());
      side.push_back(in_grid(field.BrickCoords(b)));
      reach.push_back(Mask{});
    }
  std::vector<Mask>& enclosed = side;  // side & ~reach, cleared node by node as the pockets are visited
  bool any = false;
  for (std::size_t m = 0; m < side.size(); ++m)
    for (std::size_t a = 0; a < side[m].size(); ++a) {
      enclosed[m][a] = side[m][a] & ~reach[m][a];
      any = any || enclosed[m][a] != 0;
    }
  if (!any || positions.empty()) return {};
  const detail::PointCloud cloud{&positions};
  std::optional<detail::KdTree> own;
  if (tree == nullptr) tree = &own.emplace(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(detail::kRangeLeaf));
  const detail::KdTree& wide = *tree;

  using Node = std::array<int, 3>;
  const auto take = [&](const Node& n) {
    const std::size_t b = field.BrickIndex(n[0] / kB, n[1] / kB, n[2] / kB);
    if (index[b] < 0) return false;
    std::uint64_t& bits = enclosed[static_cast<std::size_t>(index[b])][static_cast<std::size_t>(n[0] % kB)];
    const std::uint64_t bit = 1ull << (n[1] % kB * kB + n[2] % kB);
    if ((bits & bit) == 0) return false;
    bits &= ~bit;
    return true;
  };
  const auto nearest = [&](const Node& n, double* d) {
    const V3 p = grid.Node(n[0], n[1], n[2]);
    std::size_t idx = 0;
    double d2 = 0.0;
    wide.knnSearch(p.data(), 1, &idx, &d2);
    *d = std::sqrt(d2);
    return idx;
  };
  // Does a sample bound the component at its node n beside the other side: a sample within
  // reach_voxels, or one within reach_spacings of its spacing that says n is on our side (n in
  // front of it for the outside, behind it for the inside)?
  const auto bounds = [&](const Node& n) {
    const V3 p = grid.Node(n[0], n[1], n[2]);
    std::array<std::size_t, kBoundNeighbours> idx{};
    std::array<double, kBoundNeighbours> d2{};
    const std::size_t got = wide.knnSearch(p.data(), kBoundNeighbours, idx.data(), d2.data());
    for (std::size_t m = 0; m < got; ++m) {
      const double d = std::sqrt(d2[m]);
      if (d <= reach_voxels * h) return true;
      const double front = (p - positions[idx[m]]).dot(normals[idx[m]]);
      if (d <= reach_spacings * spacing[idx[m]] && (inside ? front < 0.0 : front > 0.0)) return true;
    }
    return false;
  };
  // Gives node n the other side at depth (voxels, > 0), where deeper than its value.
  const auto set_other = [&](const Node& n, float depth) {
    float* v = field.Allocate(field.BrickIndex(n[0] / kB, n[1] / kB, n[2] / kB));
    float& x = v[(n[0] % kB * kB + n[1] % kB) * kB + n[2] % kB];
    x = inside ? std::max(x, depth) : std::min(x, -depth);
  };
  const std::array<Node, 6> steps = {Node{-1, 0, 0}, Node{1, 0, 0},  Node{0, -1, 0},
                                     Node{0, 1, 0},  Node{0, 0, -1}, Node{0, 0, 1}};
  const auto within = [&](const Node& n) {
    return n[0] >= 0 && n[1] >= 0 && n[2] >= 0 && n[0] < dims[0] && n[1] < dims[1] && n[2] < dims[2];
  };
  std::vector<Node> filled, pocket, stack;
  std::size_t components = 0;
  for (int bi = 0; bi < bd[0]; ++bi)
    for (int bj = 0; bj < bd[1]; ++bj)
      for (int bk = 0; bk < bd[2]; ++bk) {
        const std::int32_t m = index[field.BrickIndex(bi, bj, bk)];
        if (m < 0) continue;
        for (std::size_t a = 0; a < static_cast<std::size_t>(kB); ++a)
          while (enclosed[static_cast<std::size_t>(m)][a] != 0) {
            const int bit = std::countr_zero(enclosed[static_cast<std::size_t>(m)][a]);
            const Node start = {bi * kB + static_cast<int>(a), bj * kB + bit / kB, bk * kB + bit % kB};
            take(start);
            pocket.assign(1, start);
            stack.assign(1, start);
            bool bounded = false;  // a sample bounds it
            while (!stack.empty()) {
              const Node n = stack.back();
              stack.pop_back();
              bool edge = false;
              for (const Node& s : steps) {
                const Node nb = {n[0] + s[0], n[1] + s[1], n[2] + s[2]};
                if (!within(nb)) continue;
                if (!ours(field.Value(nb[0], nb[1], nb[2]))) {
                  edge = true;
                } else if (take(nb)) {
                  pocket.push_back(nb);
                  stack.push_back(nb);
                }
              }
              if (edge && !bounded && bounds(n)) bounded = true;
            }
            if (bounded) continue;
            ++components;
            for (const Node& n : pocket) {
              double d = 0.0;
              nearest(n, &d);
              set_other(n, std::min(band, std::max(1e-6f, static_cast<float>(d / h))));
            }
            filled.insert(filled.end(), pocket.begin(), pocket.end());
          }
      }
  if (filled.empty()) return {};
  // The other side's nodes within a band's steps of the changed components, breadth first; a bit
  // per grid node marks those seen (a changed component's nodes first).
  const int ring = static_cast<int>(std::ceil(band));
  std::vector<std::uint64_t> seen(
      (static_cast<std::size_t>(dims[0]) * static_cast<std::size_t>(dims[1]) * static_cast<std::size_t>(dims[2]) + 63) /
          64,
      0);
  const auto first_visit = [&](const Node& n) {
    const std::size_t key =
        (static_cast<std::size_t>(n[0]) * static_cast<std::size_t>(dims[1]) + static_cast<std::size_t>(n[1])) *
            static_cast<std::size_t>(dims[2]) +
        static_cast<std::size_t>(n[2]);
    const std::uint64_t bit = 1ull << (key % 64);
    if ((seen[key / 64] & bit) != 0) return false;
    seen[key / 64] |= bit;
    return true;
  };
  for (const Node& n : filled) first_visit(n);
  std::vector<Node> front = filled, next;
  for (int step = 0; step < ring && !front.empty(); ++step) {
    next.clear();
    for (const Node& n : front)
      for (const Node& s : steps) {
        const Node nb = {n[0] + s[0], n[1] + s[1], n[2] + s[2]};
        if (!within(nb) || !first_visit(nb)) continue;
        const float x = field.Value(nb[0], nb[1], nb[2]);
        if (ours(x) || std::abs(x) >= band) continue;
        next.push_back(nb);
        double d = 0.0;
        nearest(nb, &d);
        if (d > reach_voxels * h) set_other(nb, std::min(band, static_cast<float>(d / h)));
      }
    std::swap(front, next);
  }
  return {components, filled.size()};
}

}  // namespace

PocketFill FillSamplelessPockets(SparseField& field, const std::vector<V3>& positions, const std::vector<V3>& normals,
                                 const std::vector<double>& spacing, double reach_voxels, double reach_spacings) {
  return FillUnbounded(field, false, positions, normals, spacing, nullptr, reach_voxels, reach_spacings);
}

PocketFill CutSamplelessIslands(SparseField& field, const std::vector<V3>& positions, const std::vector<V3>& normals,
                                const std::vector<double>& spacing, double reach_voxels, double reach_spacings) {
  return FillUnbounded(field, true, positions, normals, spacing, nullptr, reach_voxels, reach_spacings);
}

namespace detail {

PocketFill FillSamplelessPockets(SparseField& field, const std::vector<V3>& positions, const std::vector<V3>& normals,
                                 const std::vector<double>& spacing, const KdTree& tree) {
  return FillUnbounded(field, false, positions, normals, spacing, &tree, kPocketReachVoxels, kPocketReachSpacings);
}

PocketFill CutSamplelessIslands(SparseField& field, const std::vector<V3>& positions, const std::vector<V3>& normals,
                                const std::vector<double>& spacing, const KdTree& tree) {
  return FillUnbounded(field, true, positions, normals, spacing, &tree, kPocketReachVoxels, kPocketReachSpacings);
}

}  // namespace detail

}  // namespace palpa::field
