// SparseField's brick labelling and Lipschitz projection against hand-computed values and an
// independent dense reference (Bellman-Ford on the projection's definition).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include "palpa/field/sparse_field.h"

namespace palpa::field {
namespace {

constexpr float kStep = SparseField::kLipschitzStep;

GridSpec Grid(int nx, int ny, int nz, int band) {
  GridSpec g;
  g.dims = {nx, ny, nz};
  g.voxel_m = 1.0;
  g.band_voxels = band;
  return g;
}

// Allocates every brick and writes `phi(i, j, k)` into every grid node.
template <class F>
SparseField AllAllocated(const GridSpec& g, F&& phi) {
  SparseField f(g);
  const auto& bd = f.brick_dims();
  std::vector<std::uint8_t> all(static_cast<std::size_t>(bd[0] * bd[1] * bd[2]), 1);
  f.AllocateAll(all);
  constexpr int kB = SparseField::kBrick;
  for (int i = 0; i < g.dims[0]; ++i)
    for (int j = 0; j < g.dims[1]; ++j)
      for (int k = 0; k < g.dims[2]; ++k)
        f.BrickValues(f.BrickIndex(i / kB, j / kB, k / kB))[((i % kB) * kB + (j % kB)) * kB + (k % kB)] = phi(i, j, k);
  return f;
}

float MaxNeighbourDifference(const SparseField& f) {
  const GridSpec& g = f.grid();
  float worst = 0.0f;
  for (int i = 0; i < g.dims[0]; ++i)
    for (int j = 0; j < g.dims[1]; ++j)
      for (int k = 0; k < g.dims[2]; ++k) {
        const float v = f.Value(i, j, k);
        if (i + 1 < g.dims[0]) worst = std::max(worst, std::abs(f.Value(i + 1, j, k) - v));
        if (j + 1 < g.dims[1]) worst = std::max(worst, std::abs(f.Value(i, j + 1, k) - v));
        if (k + 1 < g.dims[2]) worst = std::max(worst, std::abs(f.Value(i, j, k + 1) - v));
      }
  return worst;
}

// A profile along x (the same on every row), worked by hand:
//   input   6    6    6    5    1    0.3  -0.2  -3   -6   -6 ...
//   the pair (0.3, -0.2) sums to 0.5 <= step: no interface scaling;
//   outside, from the 1 at i = 4: 1 + step, 1 + 2 step, ... wherever the input is larger;
//   inside, from -0.2 at i = 6: -(0.2 + step), -(0.2 + 2 step), ...
TEST(ProjectLipschitz, HandComputedProfile) {
  const std::vector<float> input = {6, 6, 6, 5, 1, 0.3f, -0.2f, -3, -6, -6, -6, -6, -6, -6, -6, -6, -6, -6};
  const GridSpec g = Grid(static_cast<int>(input.size()), 9, 5, 6);
  SparseField f = AllAllocated(g, [&](int i, int, int) { return input[static_cast<std::size_t>(i)]; });
  const SparseField::LipschitzStats st = f.ProjectLipschitz();
  std::vector<float> expected(input.size());
  for (std::size_t i = 0; i < input.size(); ++i) {
    if (i <= 4) {
      float v = 1.0f;
      for (std::size_t s = i; s < 4; ++s) v = v + kStep;  // the projection's own float steps
      expected[i] = std::min(input[i], v);
    } else if (i == 5) {
      expected[i] = 0.3f;
    } else {
      float v = 0.2f;
      for (std::size_t s = 6; s < i; ++s) v = v + kStep;
      expected[i] = -std::min(-input[i], v);
    }
  }
  for (int i = 0; i < g.dims[0]; ++i)
    for (int j = 0; j < g.dims[1]; ++j)
      for (int k = 0; k < g.dims[2]; ++k) ASSERT_EQ(f.Value(i, j, k), expected[static_cast<std::size_t>(i)]) << i;
  EXPECT_EQ(st.interface_nodes_scaled, 0u);
  EXPECT_EQ(st.sign_conflict_nodes, 0u);
  EXPECT_LE(MaxNeighbourDifference(f), kStep * (1 + 1e-6f));  // (1 + step) - 1 rounds
}

// Opposite signs summing to more than a step are scaled together: 0.8 and -0.6 (sum 1.4) become
// 0.8 step/1.4 and -0.6 step/1.4, so the linear zero crossing stays at 0.8/1.4 of the edge.
TEST(ProjectLipschitz, InterfaceScalingKeepsTheZeroCrossing) {
  const GridSpec g = Grid(8, 8, 8, 6);
  SparseField f = AllAllocated(g, [](int i, int, int) {
    return i < 4 ? 0.8f + static_cast<float>(3 - i) * 0.5f : -0.6f - static_cast<float>(i - 4) * 0.5f;
  });
  const SparseField::LipschitzStats st = f.ProjectLipschitz();
  const float a = f.Value(3, 2, 2), b = f.Value(4, 2, 2);
  EXPECT_FLOAT_EQ(a, 0.8f * kStep / 1.4f);
  EXPECT_FLOAT_EQ(b, -0.6f * kStep / 1.4f);
  EXPECT_NEAR(a / (a - b), 0.8 / 1.4, 1e-6);
  EXPECT_EQ(st.interface_nodes_scaled, 2u * 64u);
  EXPECT_LE(MaxNeighbourDifference(f), kStep * (1 + 1e-6f));
}

// The projection's definition, computed independently on a dense array: the interface pass as
// stated, then Bellman-Ford (Jacobi) on |phi(x)| <- min(|phi(x)|, |phi(y)| + step) over same-sign
// axis neighbours until nothing changes.
std::vector<float> DenseReference(const GridSpec& g, std::vector<float> phi) {
  const int nx = g.dims[0], ny = g.dims[1], nz = g.dims[2];
  const auto neighbours = [&](int i, int j, int k, auto&& fn) {
    const int d[6][3] = {{-1, 0, 0}, {1, 0, 0}, {0, -1, 0}, {0, 1, 0}, {0, 0, -1}, {0, 0, 1}};
    for (const auto& o : d) {
      const int a = i + o[0], b = j + o[1], c = k + o[2];
      if (a >= 0 && b >= 0 && c >= 0 && a < nx && b < ny && c < nz) fn(g.Index(a, b, c));
    }
  };
  std::vector<float> scaled = phi;
  for (int i = 0; i < nx; ++i)
    for (int j = 0; j < ny; ++j)
      for (int k = 0; k < nz; ++k) {
        const float v = phi[g.Index(i, j, k)];
        float s = 1.0f;
        neighbours(i, j, k, [&](std::size_t y) {
          const float u = phi[y];
          if ((u <= 0.0f) != (v <= 0.0f) && std::abs(v) + std::abs(u) > kStep)
            s = std::min(s, kStep / (std::abs(v) + std::abs(u)));
        });
        if (s < 1.0f) scaled[g.Index(i, j, k)] = v <= 0.0f ? v * s : std::max(v * s, 1.17549435e-38f);
      }
  for (bool changed = true; changed;) {
    changed = false;
    std::vector<float> next = scaled;
    for (int i = 0; i < nx; ++i)
      for (int j = 0; j < ny; ++j)
        for (int k = 0; k < nz; ++k) {
          const std::size_t x = g.Index(i, j, k);
          const float v = scaled[x];
          float m = std::abs(v);
          neighbours(i, j, k, [&](std::size_t y) {
            if ((scaled[y] <= 0.0f) == (v <= 0.0f)) m = std::min(m, std::abs(scaled[y]) + kStep);
          });
          if (m < std::abs(v)) {
            next[x] = v <= 0.0f ? -m : m;
            changed = true;
          }
        }
    scaled.swap(next);
  }
  return scaled;
}

TEST(ProjectLipschitz, EqualsDenseReferenceOnRoughFieldsForAnyThreadCount) {
  const GridSpec g = Grid(29, 21, 17, 6);  // partial bricks on every axis
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<float> noise(-2.5f, 2.5f);
  std::vector<float> input(g.NodeCount());
  for (int i = 0; i < g.dims[0]; ++i)
    for (int j = 0; j < g.dims[1]; ++j)
      for (int k = 0; k < g.dims[2]; ++k) {
        // Two blobs (a wavy surface) plus noise that breaks the 1-Lipschitz property everywhere.
        const double d =
            std::min(std::hypot(i - 9.0, j - 10.0, k - 8.0) - 6.0, std::hypot(i - 21.0, j - 9.0, k - 7.0) - 5.0);
        input[g.Index(i, j, k)] = std::clamp(1.6f * static_cast<float>(d) + noise(rng), -6.0f, 6.0f);
      }
  const std::vector<float> reference = DenseReference(g, input);
  for (const std::size_t threads : {1u, 2u}) {
    const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    SparseField f = AllAllocated(g, [&](int i, int j, int k) { return input[g.Index(i, j, k)]; });
    const SparseField::LipschitzStats st = f.ProjectLipschitz();
    std::size_t mismatches = 0, sign_changes = 0, raised = 0;
    for (int i = 0; i < g.dims[0]; ++i)
      for (int j = 0; j < g.dims[1]; ++j)
        for (int k = 0; k < g.dims[2]; ++k) {
          const std::size_t x = g.Index(i, j, k);
          const float v = f.Value(i, j, k);
          mismatches += v != reference[x] ? 1u : 0u;
          sign_changes += (v <= 0.0f) != (input[x] <= 0.0f) ? 1u : 0u;
          raised += std::abs(v) > std::abs(input[x]) ? 1u : 0u;
        }
    std::printf("[ rough field, %zu threads ] %zu interface nodes scaled, %zu updates, %d sweeps\n", threads,
                st.interface_nodes_scaled, st.node_updates, st.sweeps);
    EXPECT_EQ(mismatches, 0u);
    EXPECT_EQ(sign_changes, 0u);
    EXPECT_EQ(raised, 0u);
    EXPECT_GT(st.node_updates, 1000u);
    EXPECT_LE(MaxNeighbourDifference(f), 1.0f);
  }
}

// A uniform brick next to an allocated brick whose values are far below the band must take
// values (allocated with its uniform value, then lowered).
TEST(ProjectLipschitz, AllocatesUniformBricksThatMustChange) {
  const GridSpec g = Grid(24, 8, 8, 6);  // bricks 0, 1, 2 along x
  SparseField f(g);
  float* v = f.Allocate(f.BrickIndex(1, 0, 0));
  std::fill(v, v + SparseField::kBrickNodes, 2.0f);  // outside, 2 voxels: its neighbours at +6 break the bound
  const SparseField::LipschitzStats st = f.ProjectLipschitz();
  EXPECT_EQ(st.bricks_allocated, 2u);
  EXPECT_EQ(f.Value(7, 3, 3), 2.0f + kStep);
  EXPECT_EQ(f.Value(16, 3, 3), 2.0f + kStep);
  EXPECT_EQ(f.Value(0, 3, 3), 6.0f);  // 2 + 8 steps > band
  EXPECT_LE(MaxNeighbourDifference(f), kStep * (1 + 1e-6f));
}

// Labelling by the evaluated nodes facing each component: a hollow ball (solid shell between radii
// 20 and 30) whose cavity is outside. A flood fill from the grid boundary would call the cavity
// inside; the component vote gets both the cavity and the shell's interior right.
TEST(LabelUnallocatedBricks, HollowBallCavityIsOutside) {
  const GridSpec g = Grid(80, 80, 80, 3);
  const auto sdf = [](double i, double j, double k) {
    const double r = std::hypot(i - 39.5, j - 39.5, k - 39.5);
    return std::max(20.0 - r, r - 30.0);  // negative in the shell 20 < r < 30
  };
  SparseField f(g);
  constexpr int kB = SparseField::kBrick;
  const auto& bd = f.brick_dims();
  for (int bi = 0; bi < bd[0]; ++bi)
    for (int bj = 0; bj < bd[1]; ++bj)
      for (int bk = 0; bk < bd[2]; ++bk) {
        const double centre = sdf(bi * kB + 3.5, bj * kB + 3.5, bk * kB + 3.5);
        if (std::abs(centre) >= 3 + 6.1) continue;  // no band node in this brick
        float* v = f.Allocate(f.BrickIndex(bi, bj, bk));
        for (int a = 0; a < kB; ++a)
          for (int b = 0; b < kB; ++b)
            for (int c = 0; c < kB; ++c)
              v[(a * kB + b) * kB + c] =
                  static_cast<float>(std::clamp(sdf(bi * kB + a, bj * kB + b, bk * kB + c), -3.0, 3.0));
      }
  const std::size_t minority = f.LabelUnallocatedBricks();
  EXPECT_EQ(minority, 0u);
  std::size_t wrong = 0, uniform = 0, cavity = 0;
  for (int bi = 0; bi < bd[0]; ++bi)
    for (int bj = 0; bj < bd[1]; ++bj)
      for (int bk = 0; bk < bd[2]; ++bk) {
        const std::int32_t slot = f.Slot(f.BrickIndex(bi, bj, bk));
        if (slot >= 0) continue;
        ++uniform;
        const double centre = sdf(bi * kB + 3.5, bj * kB + 3.5, bk * kB + 3.5);
        cavity += std::hypot(bi * kB + 3.5 - 39.5, bj * kB + 3.5 - 39.5, bk * kB + 3.5 - 39.5) < 20.0 ? 1u : 0u;
        wrong += (slot == SparseField::kUniformInside) != (centre < 0) ? 1u : 0u;
      }
  EXPECT_GT(uniform, 0u);
  EXPECT_GT(cavity, 0u);
  EXPECT_EQ(wrong, 0u);
}

// The payload's rounding (Q16.16 voxels, nearest, halves away from 0) never turns a node outside
// into 0, which readers take for the surface and `palpa eval` for inside: the build's side
// decisions keep outside nodes at 1e-6 voxel, 0.066 of the last place. CGAL's dino with 500
// samples had such a node 30 voxels from its surface (the v2 blob then rounded it to 0 too).
TEST(WriteQ16, NodesOutsideStayOutside) {
  const float values[] = {1e-6f, 7.6e-6f, 7.7e-6f, 1e-3f, 0.0f, -0.0f, -1e-6f, -7.7e-6f, 1.0f, -1.0f};
  const std::int32_t want[] = {1, 1, 1, 66, 0, 0, 0, -1, 65536, -65536};
  const GridSpec g = Grid(10, 1, 1, 6);
  const SparseField f = AllAllocated(g, [&](int i, int, int) { return values[i]; });
  std::vector<std::int32_t> dense(10);
  f.WriteQ16(dense);
  for (int i = 0; i < 10; ++i) {
    EXPECT_EQ(f.ValueQ16(i, 0, 0), want[i]) << values[i];
    EXPECT_EQ(dense[static_cast<std::size_t>(i)], want[i]) << values[i];
  }
}

// A brick's neighbourhood reads every node within one brick of it, and its rows, as Value does: stored bricks,
// uniform inside and outside ones, and the grid's last, partial bricks (21 nodes: 8 + 8 + 5).
TEST(SparseField, NeighbourhoodReadsAsValue) {
  const GridSpec g = Grid(21, 17, 19, 4);
  SparseField f(g);
  const auto& bd = f.brick_dims();
  std::vector<std::uint8_t> some(static_cast<std::size_t>(bd[0] * bd[1] * bd[2]), 0);
  for (std::size_t b = 0; b < some.size(); b += 2) some[b] = 1;
  f.AllocateAll(some);
  f.SetUniform(f.BrickIndex(1, 1, 0), true);
  f.SetUniform(f.BrickIndex(2, 0, 1), true);
  constexpr int kB = SparseField::kBrick;
  for (std::size_t b = 0; b < some.size(); ++b) {
    float* v = f.BrickValues(b);
    for (int n = 0; v != nullptr && n < SparseField::kBrickNodes; ++n)
      v[n] = static_cast<float>((static_cast<int>(b) * 37 + n * 11) % 71) / 10.0f - 3.5f;
  }
  int checked = 0, rows = 0;
  for (int bi = 0; bi < bd[0]; ++bi)
    for (int bj = 0; bj < bd[1]; ++bj)
      for (int bk = 0; bk < bd[2]; ++bk) {
        const SparseField::Neighbourhood near = f.Neighbours({bi, bj, bk});
        for (int i = std::max(0, bi * kB - kB); i < std::min(g.dims[0], bi * kB + 2 * kB); ++i)
          for (int j = std::max(0, bj * kB - kB); j < std::min(g.dims[1], bj * kB + 2 * kB); ++j)
            for (int k = std::max(0, bk * kB - kB); k < std::min(g.dims[2], bk * kB + 2 * kB); ++k, ++checked)
              ASSERT_EQ(near.Value(i, j, k), f.Value(i, j, k)) << bi << bj << bk << " " << i << " " << j << " " << k;
        // Rows: node k of the brick dk along k, where the grid has it.
        for (int i = std::max(0, bi * kB - kB); i < std::min(g.dims[0], bi * kB + 2 * kB); ++i)
          for (int j = std::max(0, bj * kB - kB); j < std::min(g.dims[1], bj * kB + 2 * kB); ++j)
            for (int dk = -1; dk <= 1; ++dk)
              for (int k = (bk + dk) * kB; k < std::min(g.dims[2], (bk + dk + 1) * kB); ++k) {
                if (k < 0) continue;
                float uniform = 0.0f;
                const float* row = near.Row(i, j, dk, &uniform);
                ASSERT_EQ(row != nullptr ? row[k % kB] : uniform, f.Value(i, j, k)) << i << " " << j << " " << k;
                ++rows;
              }
      }
  EXPECT_GT(rows, checked / 2);
  EXPECT_GT(checked, 27 * 21 * 17 * 19 / 2);
  EXPECT_EQ(f.Value(10, 10, 3), -4.0f);  // a uniform inside brick is read
}

// SmoothBand's [1 2 1] / 4 per axis: exact on a linear field, and node noise of RMS e left at
// e * (6/16)^(3/2) = 0.23 e (the kernel's sum of squared weights).
TEST(SmoothBand, KeepsALinearFieldAndAveragesNodeNoise) {
  const GridSpec g = Grid(24, 24, 24, 6);
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> noise(-0.2f, 0.2f);
  std::vector<float> e(24 * 24 * 24);
  for (float& x : e) x = noise(rng);
  const auto plane = [](int i, int j, int k) {
    return static_cast<float>(0.3 * (i - 12) + 0.2 * (j - 12) + 0.5 * (k - 12.3));
  };
  const auto at = [](int i, int j, int k) { return static_cast<std::size_t>((i * 24 + j) * 24 + k); };
  SparseField linear = AllAllocated(g, plane);
  SparseField noisy = AllAllocated(g, [&](int i, int j, int k) { return plane(i, j, k) + e[at(i, j, k)]; });
  linear.SmoothBand();
  noisy.SmoothBand();
  double before = 0.0, after = 0.0;
  int count = 0;
  for (int i = 1; i < 23; ++i)
    for (int j = 1; j < 23; ++j)
      for (int k = 1; k < 23; ++k) {
        const float p = plane(i, j, k);
        if (std::abs(p) > 5.0f) continue;  // the filter reads no clamped node
        EXPECT_NEAR(linear.Value(i, j, k), p, 1e-5f) << i << " " << j << " " << k;
        const double x = e[at(i, j, k)], y = noisy.Value(i, j, k) - p;
        before += x * x;
        after += y * y;
        ++count;
      }
  ASSERT_GT(count, 1000);
  const double ratio = std::sqrt(after / before);
  EXPECT_GT(ratio, 0.18);
  EXPECT_LT(ratio, 0.28);
}

// The grid's face nodes keep their values (HermiteField leaves them at least half a voxel
// outside; averaged with inside neighbours they would fall): a face node at +0.5 beside nodes at
// -0.45 stays +0.5, while an interior node of the same field moves.
TEST(SmoothBand, KeepsTheGridFaceNodes) {
  const GridSpec g = Grid(16, 16, 16, 6);
  const auto value = [](int i, int j, int k) {
    return (i == 0 ? 0.5f : -0.45f) + 0.05f * static_cast<float>((j + 2 * k) % 3);
  };
  SparseField f = AllAllocated(g, value);
  f.SmoothBand();
  std::size_t faces = 0, moved = 0;
  for (int i = 0; i < 16; ++i)
    for (int j = 0; j < 16; ++j)
      for (int k = 0; k < 16; ++k) {
        const bool face = i == 0 || j == 0 || k == 0 || i == 15 || j == 15 || k == 15;
        if (face) {
          ++faces;
          EXPECT_EQ(f.Value(i, j, k), value(i, j, k)) << i << " " << j << " " << k;
        } else {
          moved += f.Value(i, j, k) != value(i, j, k) ? 1u : 0u;
        }
      }
  EXPECT_EQ(faces, 16u * 16u * 16u - 14u * 14u * 14u);
  EXPECT_GT(moved, 1000u);
}

// The heat equation for t = 1/4 voxel^2: a sphere's signed distance r - R rises by
// t * laplacian = (1/4)(2/r) = 0.5/r voxels, so its surface moves inward by 0.05 voxel at R = 10.
// Bricks away from the surface stay uniform; values stay within the band and Lipschitz.
TEST(SmoothBand, MovesASphereInwardByItsMeanCurvature) {
  const GridSpec g = Grid(40, 40, 40, 4);
  const auto r = [](int i, int j, int k) { return std::hypot(i - 19.7, j - 20.2, k - 20.1); };
  std::vector<float> dense(40 * 40 * 40);
  for (int i = 0; i < 40; ++i)
    for (int j = 0; j < 40; ++j)
      for (int k = 0; k < 40; ++k)
        dense[static_cast<std::size_t>((i * 40 + j) * 40 + k)] =
            static_cast<float>(std::clamp(r(i, j, k) - 10.0, -4.0, 4.0));
  SparseField f = SparseField::FromDense(g, dense);
  f.ProjectLipschitz();
  const std::size_t bricks = f.AllocatedBricks();
  SparseField before = f;
  f.SmoothBand();
  EXPECT_EQ(f.AllocatedBricks(), bricks);
  EXPECT_LE(MaxNeighbourDifference(f), kStep + 1e-5f);
  double rise = 0.0, expected = 0.0;
  int count = 0;
  for (int i = 0; i < 40; ++i)
    for (int j = 0; j < 40; ++j)
      for (int k = 0; k < 40; ++k) {
        const float v = f.Value(i, j, k);
        ASSERT_LE(std::abs(v), 4.0f);
        const double d = r(i, j, k) - 10.0;
        if (std::abs(d) > 1.0) continue;
        rise += v - before.Value(i, j, k);
        expected += 0.5 / r(i, j, k);
        ++count;
      }
  ASSERT_GT(count, 500);
  EXPECT_NEAR(rise / count, expected / count, 0.15 * expected / count);
}

}  // namespace
}  // namespace palpa::field
