#include "palpa/field/sparse_field.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <utility>
#include <vector>

#include <tbb/blocked_range.h>
#include <tbb/combinable.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

namespace palpa::field {
namespace {

// The blob payload's rounding (WriteQ16): nearest, halves away from 0 (std::lround), clamped to
// the band. v · 2^16 and that ± 1/2 are exact in double for |v| < 2^30 (a float has 24 bits), so
// truncating the sum is lround's result at a third of its cost (a third of v2 encoding's). A
// node outside (v > 0) stays outside: it rounds to at least 1, never to 0, which readers take
// for the surface and `palpa eval` for inside (the build's side decisions keep 1e-6 voxel).
std::int32_t Q16(float v, std::int32_t band_q) {
  const double band = static_cast<double>(band_q);
  const double x = std::clamp(static_cast<double>(v) * 65536.0, -band, band);
  const auto q = static_cast<std::int32_t>(x + (x < 0.0 ? -0.5 : 0.5));
  return x > 0.0 ? std::max(q, std::int32_t{1}) : q;
}

constexpr int kB = SparseField::kBrick;
constexpr int kHalo = kB + 2;
constexpr int kHaloNodes = kHalo * kHalo * kHalo;
constexpr float kAbsent = std::numeric_limits<float>::quiet_NaN();
// Local passes over one brick before it is requeued instead (a path that winds between nodes of
// the other sign can need more than one forward + backward pass).
constexpr int kMaxLocalPasses = 16;

int Bricks(int nodes) { return (nodes + SparseField::kBrick - 1) / SparseField::kBrick; }

// Halo index of brick-local node (a, b, c), each in [-1, kB].
constexpr int H(int a, int b, int c) { return ((a + 1) * kHalo + (b + 1)) * kHalo + (c + 1); }
constexpr int L(int a, int b, int c) { return (a * kB + b) * kB + c; }
constexpr std::array<int, 6> kHaloStep = {-kHalo * kHalo, kHalo* kHalo, -kHalo, kHalo, -1, 1};

// Calls fn(local, outside) for the brick-local nodes on face f (axis f / 2, low side if f is
// even) that are grid nodes, with `outside` the local coordinates of the node across the face.
template <class Fn>
void ForFaceNodes(int f, const std::array<int, 3>& box, Fn&& fn) {
  const int axis = f / 2;
  const bool high = (f % 2) == 1;
  const int u_axis = axis == 0 ? 1 : 0;
  const int v_axis = axis == 2 ? 1 : 2;
  const int at = high ? box[static_cast<std::size_t>(axis)] - 1 : 0;
  if (high && at != kB - 1) return;  // a partial brick has no neighbour brick on its high side
  for (int u = 0; u < box[static_cast<std::size_t>(u_axis)]; ++u)
    for (int v = 0; v < box[static_cast<std::size_t>(v_axis)]; ++v) {
      std::array<int, 3> local{}, across{};
      local[static_cast<std::size_t>(axis)] = at;
      local[static_cast<std::size_t>(u_axis)] = u;
      local[static_cast<std::size_t>(v_axis)] = v;
      across = local;
      across[static_cast<std::size_t>(axis)] = high ? kB : -1;
      fn(local, across);
    }
}

// Whether any node of the box has a same-sign axis neighbour u with |v| > |u| + step (one
// branch-free pass; most bricks have none).
bool AnyViolation(const float* h, const std::array<int, 3>& box) {
  constexpr float step = SparseField::kLipschitzStep;
  std::uint32_t any = 0;  // an integer OR, so that the row loop vectorises
  for (int a = 0; a < box[0]; ++a)
    for (int b = 0; b < box[1]; ++b) {
      const float* row = h + H(a, b, 0);
      for (int c = 0; c < box[2]; ++c) {
        const float v = row[c];
        const bool inside = v <= 0.0f;
        const float mag = std::abs(v);
        for (const int o : kHaloStep) {
          const float u = row[c + o];
          // NaN (no node) fails u == u.
          any |= static_cast<std::uint32_t>(((u <= 0.0f) == inside) & (u == u) & (mag > std::abs(u) + step));
        }
      }
    }
  return any != 0;
}

// Gauss-Seidel relaxation of |phi| <- min(|phi|, |phi_nb| + step) over same-sign axis
// neighbours, forward then backward, until a pass changes nothing (or kMaxLocalPasses). Returns
// whether any node changed and sets `converged`.
bool RelaxHalo(float* h, const std::array<int, 3>& box, bool& converged) {
  constexpr float step = SparseField::kLipschitzStep;
  converged = !AnyViolation(h, box);
  if (converged) return false;
  const auto visit = [&](int a, int b, int c) {
    float& v = h[H(a, b, c)];
    const bool inside = v <= 0.0f;
    const float mag = std::abs(v);
    float m = mag;
    for (const int o : kHaloStep) {
      // Branch-free: a NaN (no node) leaves m as it is, as std::min(m, NaN) returns m.
      const float u = h[H(a, b, c) + o];
      m = (u <= 0.0f) == inside ? std::min(m, std::abs(u) + step) : m;
    }
    if (m < mag) {
      v = inside ? -m : m;
      return true;
    }
    return false;
  };
  for (int pass = 0; pass < kMaxLocalPasses; ++pass) {
    bool changed = false;
    if (pass % 2 == 0) {
      for (int a = 0; a < box[0]; ++a)
        for (int b = 0; b < box[1]; ++b)
          for (int c = 0; c < box[2]; ++c) changed = visit(a, b, c) || changed;
    } else {
      for (int a = box[0]; a-- > 0;)
        for (int b = box[1]; b-- > 0;)
          for (int c = box[2]; c-- > 0;) changed = visit(a, b, c) || changed;
    }
    if (!changed && pass > 0) {
      converged = true;
      break;
    }
  }
  return true;
}

}  // namespace

SparseField::SparseField(const GridSpec& grid)
    : grid_(grid),
      brick_dims_{Bricks(grid.dims[0]), Bricks(grid.dims[1]), Bricks(grid.dims[2])},
      slots_(static_cast<std::size_t>(brick_dims_[0]) * static_cast<std::size_t>(brick_dims_[1]) *
                 static_cast<std::size_t>(brick_dims_[2]),
             kUniformOutside) {}

float* SparseField::Allocate(std::size_t brick) {
  if (slots_[brick] < 0) {
    const auto band = static_cast<float>(grid_.band_voxels);
    const float fill = slots_[brick] == kUniformInside ? -band : band;
    if (stored_ % kPageBricks == 0) pages_.emplace_back(kPageBricks * kBrickNodes);
    slots_[brick] = static_cast<std::int32_t>(stored_++);
    std::fill_n(Stored(slots_[brick]), kBrickNodes, fill);
  }
  return BrickValues(brick);
}

void SparseField::AllocateAll(const std::vector<std::uint8_t>& active) {
  // Slots in brick order as Allocate gives them, then the values filled in parallel.
  const auto band = static_cast<float>(grid_.band_voxels);
  std::vector<std::pair<std::int32_t, float>> fresh;  // slot, fill
  for (std::size_t b = 0; b < slots_.size(); ++b) {
    if (active[b] == 0 || slots_[b] >= 0) continue;
    const float fill = slots_[b] == kUniformInside ? -band : band;
    if (stored_ % kPageBricks == 0) pages_.emplace_back(kPageBricks * kBrickNodes);
    slots_[b] = static_cast<std::int32_t>(stored_++);
    fresh.emplace_back(slots_[b], fill);
  }
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, fresh.size(), 16), [&](const auto& r) {
    for (std::size_t f = r.begin(); f != r.end(); ++f)
      std::fill_n(Stored(fresh[f].first), kBrickNodes, fresh[f].second);
  });
}

float SparseField::Value(int i, int j, int k) const {
  const std::size_t brick = BrickIndex(i >> kBrickLog2, j >> kBrickLog2, k >> kBrickLog2);
  const std::int32_t slot = slots_[brick];
  const auto band = static_cast<float>(grid_.band_voxels);
  if (slot == kUniformInside) return -band;
  if (slot < 0) return band;
  const int a = i & (kBrick - 1), b = j & (kBrick - 1), c = k & (kBrick - 1);
  return Stored(slot)[(a * kBrick + b) * kBrick + c];
}

SparseField SparseField::FromDense(const GridSpec& grid, std::span<const float> phi_voxels) {
  SparseField field(grid);
  if (phi_voxels.size() != grid.NodeCount()) return field;
  const auto band = static_cast<float>(grid.band_voxels);
  const std::size_t n_bricks = field.slots_.size();
  // 1 = needs values, 2 = uniform inside, 0 = uniform outside.
  std::vector<std::uint8_t> kind(n_bricks, 0);
  const auto& bd = field.brick_dims_;
  tbb::parallel_for(0, bd[0], [&](int bi) {
    for (int bj = 0; bj < bd[1]; ++bj) {
      for (int bk = 0; bk < bd[2]; ++bk) {
        bool near = false, inside = false;
        for (int i = bi * kBrick; i < std::min(grid.dims[0], (bi + 1) * kBrick) && !near; ++i)
          for (int j = bj * kBrick; j < std::min(grid.dims[1], (bj + 1) * kBrick) && !near; ++j)
            for (int k = bk * kBrick; k < std::min(grid.dims[2], (bk + 1) * kBrick); ++k) {
              const float v = phi_voxels[grid.Index(i, j, k)];
              inside = v <= 0.0f;
              if (std::abs(v) < band) {
                near = true;
                break;
              }
            }
        kind[field.BrickIndex(bi, bj, bk)] = near ? 1 : (inside ? 2 : 0);
      }
    }
  });
  for (std::size_t b = 0; b < n_bricks; ++b) {
    if (kind[b] == 2) field.slots_[b] = kUniformInside;
  }
  std::vector<std::uint8_t> active(n_bricks);
  for (std::size_t b = 0; b < n_bricks; ++b) active[b] = kind[b] == 1 ? 1 : 0;
  field.AllocateAll(active);
  tbb::parallel_for(0, bd[0], [&](int bi) {
    for (int bj = 0; bj < bd[1]; ++bj) {
      for (int bk = 0; bk < bd[2]; ++bk) {
        float* v = field.BrickValues(field.BrickIndex(bi, bj, bk));
        if (v == nullptr) continue;
        for (int a = 0; a < kBrick; ++a)
          for (int b = 0; b < kBrick; ++b)
            for (int c = 0; c < kBrick; ++c) {
              const int i = bi * kBrick + a, j = bj * kBrick + b, k = bk * kBrick + c;
              if (i >= grid.dims[0] || j >= grid.dims[1] || k >= grid.dims[2]) continue;
              v[(a * kBrick + b) * kBrick + c] = std::clamp(phi_voxels[grid.Index(i, j, k)], -band, band);
            }
      }
    }
  });
  return field;
}

std::size_t SparseField::CountInside() const {
  const auto& bd = brick_dims_;
  return tbb::parallel_reduce(
      tbb::blocked_range<int>(0, bd[0]), std::size_t{0},
      [&](const tbb::blocked_range<int>& r, std::size_t acc) {
        for (int bi = r.begin(); bi != r.end(); ++bi)
          for (int bj = 0; bj < bd[1]; ++bj)
            for (int bk = 0; bk < bd[2]; ++bk) {
              const BrickBox box = Box(bi, bj, bk);
              const std::int32_t slot = slots_[BrickIndex(bi, bj, bk)];
              if (slot == kUniformInside) acc += box.NodeCount();
              if (slot < 0) continue;
              const float* v = Stored(slot);
              for (int a = 0; a < box.n[0]; ++a)
                for (int b = 0; b < box.n[1]; ++b)
                  for (int c = 0; c < box.n[2]; ++c) acc += v[(a * kBrick + b) * kBrick + c] <= 0.0f ? 1u : 0u;
            }
        return acc;
      },
      [](std::size_t a, std::size_t b) { return a + b; });
}

void SparseField::WriteQ16(std::span<std::int32_t> dense) const {
  if (dense.size() != grid_.NodeCount()) return;
  const std::int32_t band_q = grid_.band_voxels * 65536;
  const int nz = grid_.dims[2];
  tbb::parallel_for(0, grid_.dims[0], [&](int i) {
    for (int j = 0; j < grid_.dims[1]; ++j) {
      std::int32_t* row = dense.data() + grid_.Index(i, j, 0);
      for (int bk = 0; bk < brick_dims_[2]; ++bk) {
        const std::size_t brick = BrickIndex(i >> kBrickLog2, j >> kBrickLog2, bk);
        const int k0 = bk * kBrick;
        const int k1 = std::min(nz, k0 + kBrick);
        const std::int32_t slot = slots_[brick];
        if (slot < 0) {
          std::fill(row + k0, row + k1, slot == kUniformInside ? -band_q : band_q);
          continue;
        }
        const float* v =
            Stored(slot) + static_cast<std::size_t>(((i & (kBrick - 1)) * kBrick + (j & (kBrick - 1))) * kBrick);
        for (int k = k0; k < k1; ++k) row[k] = Q16(v[k - k0], band_q);
      }
    }
  });
}

std::int32_t SparseField::ValueQ16(int i, int j, int k) const { return Q16(Value(i, j, k), grid_.band_voxels * 65536); }

std::optional<std::int32_t> SparseField::BrickQ16(std::size_t brick, std::span<std::int32_t, kBrickNodes> q16) const {
  const std::int32_t band_q = grid_.band_voxels * 65536;
  const std::int32_t slot = slots_[brick];
  if (slot < 0) return slot == kUniformInside ? -band_q : band_q;
  const float* v = Stored(slot);
  for (std::size_t n = 0; n < kBrickNodes; ++n) q16[n] = Q16(v[n], band_q);
  return std::nullopt;
}

std::vector<float> SparseField::ToDense() const {
  std::vector<float> dense(grid_.NodeCount());
  tbb::parallel_for(0, grid_.dims[0], [&](int i) {
    for (int j = 0; j < grid_.dims[1]; ++j)
      for (int k = 0; k < grid_.dims[2]; ++k) dense[grid_.Index(i, j, k)] = Value(i, j, k);
  });
  return dense;
}

SparseField::BrickBox SparseField::Box(int bi, int bj, int bk) const {
  return BrickBox{{std::min(kB, grid_.dims[0] - bi * kB), std::min(kB, grid_.dims[1] - bj * kB),
                   std::min(kB, grid_.dims[2] - bk * kB)}};
}

std::array<int, 3> SparseField::BrickCoords(std::size_t brick) const {
  const auto plane = static_cast<std::size_t>(brick_dims_[1]) * static_cast<std::size_t>(brick_dims_[2]);
  return {
      static_cast<int>(brick / plane),
      static_cast<int>((brick / static_cast<std::size_t>(brick_dims_[2])) % static_cast<std::size_t>(brick_dims_[1])),
      static_cast<int>(brick % static_cast<std::size_t>(brick_dims_[2]))};
}

void SparseField::GatherHalo(std::size_t brick, float* halo) const {
  std::fill(halo, halo + kHaloNodes, kAbsent);
  const auto band = static_cast<float>(grid_.band_voxels);
  const std::array<int, 3> bc = BrickCoords(brick);
  const std::array<int, 3> n = Box(bc[0], bc[1], bc[2]).n;
  const auto row_bytes = static_cast<std::size_t>(n[2]) * sizeof(float);
  const float* own = Stored(slots_[brick]);
  for (int a = 0; a < n[0]; ++a)
    for (int b = 0; b < n[1]; ++b) std::memcpy(halo + H(a, b, 0), own + L(a, b, 0), row_bytes);
  // The face neighbours' layers next to this brick: src(a, b, c) gives the neighbour's value for
  // halo node (a, b, c), or nullptr with `uniform`.
  for (int f = 0; f < 6; ++f) {
    const int axis = f / 2;
    const bool high = (f % 2) == 1;
    std::array<int, 3> nb = bc;
    nb[static_cast<std::size_t>(axis)] += high ? 1 : -1;
    if (nb[static_cast<std::size_t>(axis)] < 0 ||
        nb[static_cast<std::size_t>(axis)] >= brick_dims_[static_cast<std::size_t>(axis)])
      continue;
    if (high && n[static_cast<std::size_t>(axis)] != kB) continue;
    const std::int32_t slot = slots_[BrickIndex(nb[0], nb[1], nb[2])];
    const float* src = slot >= 0 ? Stored(slot) : nullptr;
    const float uniform = slot == kUniformInside ? -band : band;
    const int at = high ? kB : -1;       // halo layer
    const int from = high ? 0 : kB - 1;  // the neighbour's layer
    if (axis == 0) {
      for (int b = 0; b < n[1]; ++b) {
        float* row = halo + H(at, b, 0);
        if (src != nullptr) {
          std::memcpy(row, src + L(from, b, 0), row_bytes);
        } else {
          std::fill(row, row + n[2], uniform);
        }
      }
    } else if (axis == 1) {
      for (int a = 0; a < n[0]; ++a) {
        float* row = halo + H(a, at, 0);
        if (src != nullptr) {
          std::memcpy(row, src + L(a, from, 0), row_bytes);
        } else {
          std::fill(row, row + n[2], uniform);
        }
      }
    } else {
      for (int a = 0; a < n[0]; ++a)
        for (int b = 0; b < n[1]; ++b) halo[H(a, b, at)] = src != nullptr ? src[L(a, b, from)] : uniform;
    }
  }
}

std::size_t SparseField::LabelUnallocatedBricks() {
  const std::size_t n_bricks = slots_.size();
  const auto& bd = brick_dims_;
  // 6-connected components of unallocated bricks (iterative DFS; brick order, deterministic).
  std::vector<std::int32_t> component(n_bricks, -1);
  std::int32_t components = 0;
  std::vector<std::size_t> stack;
  for (std::size_t seed = 0; seed < n_bricks; ++seed) {
    if (slots_[seed] >= 0 || component[seed] >= 0) continue;
    component[seed] = components;
    stack.assign(1, seed);
    while (!stack.empty()) {
      const std::size_t b = stack.back();
      stack.pop_back();
      const std::array<int, 3> c = BrickCoords(b);
      for (int f = 0; f < 6; ++f) {
        std::array<int, 3> nb = c;
        nb[static_cast<std::size_t>(f / 2)] += (f % 2) == 1 ? 1 : -1;
        if (nb[0] < 0 || nb[1] < 0 || nb[2] < 0 || nb[0] >= bd[0] || nb[1] >= bd[1] || nb[2] >= bd[2]) continue;
        const std::size_t n = BrickIndex(nb[0], nb[1], nb[2]);
        if (slots_[n] >= 0 || component[n] >= 0) continue;
        component[n] = components;
        stack.push_back(n);
      }
    }
    ++components;
  }
  // Votes of the allocated nodes facing each component: per (brick, face) in parallel, summed in
  // brick order.
  std::vector<std::array<std::uint32_t, 2>> face_votes(n_bricks * 6, {0u, 0u});  // {inside, outside}
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n_bricks, 64), [&](const auto& r) {
    for (std::size_t b = r.begin(); b != r.end(); ++b) {
      if (slots_[b] < 0) continue;
      const std::array<int, 3> c = BrickCoords(b);
      const BrickBox box = Box(c[0], c[1], c[2]);
      const float* v = Stored(slots_[b]);
      for (int f = 0; f < 6; ++f) {
        std::array<int, 3> nb = c;
        nb[static_cast<std::size_t>(f / 2)] += (f % 2) == 1 ? 1 : -1;
        if (nb[0] < 0 || nb[1] < 0 || nb[2] < 0 || nb[0] >= bd[0] || nb[1] >= bd[1] || nb[2] >= bd[2]) continue;
        if (slots_[BrickIndex(nb[0], nb[1], nb[2])] >= 0) continue;
        auto& votes = face_votes[b * 6 + static_cast<std::size_t>(f)];
        ForFaceNodes(f, box.n, [&](const std::array<int, 3>& local, const std::array<int, 3>& /*across*/) {
          ++votes[v[L(local[0], local[1], local[2])] <= 0.0f ? 0 : 1];
        });
      }
    }
  });
  std::vector<std::array<std::uint64_t, 2>> votes(static_cast<std::size_t>(components), {0u, 0u});
  for (std::size_t b = 0; b < n_bricks; ++b) {
    if (slots_[b] < 0) continue;
    const std::array<int, 3> c = BrickCoords(b);
    for (int f = 0; f < 6; ++f) {
      const auto& fv = face_votes[b * 6 + static_cast<std::size_t>(f)];
      if (fv[0] + fv[1] == 0) continue;
      std::array<int, 3> nb = c;
      nb[static_cast<std::size_t>(f / 2)] += (f % 2) == 1 ? 1 : -1;
      auto& cv = votes[static_cast<std::size_t>(component[BrickIndex(nb[0], nb[1], nb[2])])];
      cv[0] += fv[0];
      cv[1] += fv[1];
    }
  }
  std::size_t minority = 0;
  for (const auto& cv : votes) minority += static_cast<std::size_t>(std::min(cv[0], cv[1]));
  for (std::size_t b = 0; b < n_bricks; ++b) {
    if (slots_[b] >= 0) continue;
    const auto& cv = votes[static_cast<std::size_t>(component[b])];
    slots_[b] = cv[0] > cv[1] ? kUniformInside : kUniformOutside;
  }
  return minority;
}

SparseField::Neighbourhood SparseField::Neighbours(const std::array<int, 3>& bc) const {
  const auto band = static_cast<float>(grid_.band_voxels);
  Neighbourhood near;
  near.centre_ = bc;
  for (int n = 0; n < 27; ++n) {
    const std::array<int, 3> nb{bc[0] + n / 9 - 1, bc[1] + n / 3 % 3 - 1, bc[2] + n % 3 - 1};
    if (nb[0] < 0 || nb[1] < 0 || nb[2] < 0 || nb[0] >= brick_dims_[0] || nb[1] >= brick_dims_[1] ||
        nb[2] >= brick_dims_[2])
      continue;  // no grid node lies there
    const std::int32_t slot = slots_[BrickIndex(nb[0], nb[1], nb[2])];
    near.values_[static_cast<std::size_t>(n)] = slot >= 0 ? Stored(slot) : nullptr;
    near.uniform_[static_cast<std::size_t>(n)] = slot == kUniformInside ? -band : band;
  }
  return near;
}

void SparseField::SmoothBand() {
  const auto band = static_cast<float>(grid_.band_voxels);
  std::vector<std::size_t> bricks;
  for (std::size_t b = 0; b < slots_.size(); ++b)
    if (slots_[b] >= 0) bricks.push_back(b);
  // Every brick reads the unfiltered field: the results wait here until all are computed
  // (uninitialised: every node is written).
  const auto out = std::make_unique_for_overwrite<float[]>(bricks.size() * kBrickNodes);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, bricks.size(), 4), [&](const auto& r) {
    constexpr int kH = kBrick + 2;  // one node of halo on each side
    std::array<float, kH * kH * kH> x{}, y{};
    const auto at = [](int a, int b, int c) { return static_cast<std::size_t>((a * kH + b) * kH + c); };
    for (std::size_t m = r.begin(); m != r.end(); ++m) {
      const std::array<int, 3> bc = BrickCoords(bricks[m]);
      const BrickBox box = Box(bc[0], bc[1], bc[2]);
      const Neighbourhood near = Neighbours(bc);
      // The halo, nodes past the grid's edge replaced by the nearest grid node.
      for (int a = 0; a < kH; ++a) {
        const int i = std::clamp(bc[0] * kBrick + a - 1, 0, grid_.dims[0] - 1);
        for (int b = 0; b < kH; ++b) {
          const int j = std::clamp(bc[1] * kBrick + b - 1, 0, grid_.dims[1] - 1);
          for (int c = 0; c < kH; ++c)
            x[at(a, b, c)] = near.Value(i, j, std::clamp(bc[2] * kBrick + c - 1, 0, grid_.dims[2] - 1));
        }
      }
      // Separable passes: x over the brick's rows and the halo's y, z; then y; then z.
      for (int a = 1; a <= kBrick; ++a)
        for (int b = 0; b < kH; ++b)
          for (int c = 0; c < kH; ++c)
            y[at(a, b, c)] = 0.25f * (x[at(a - 1, b, c)] + x[at(a + 1, b, c)]) + 0.5f * x[at(a, b, c)];
      for (int a = 1; a <= kBrick; ++a)
        for (int b = 1; b <= kBrick; ++b)
          for (int c = 0; c < kH; ++c)
            x[at(a, b, c)] = 0.25f * (y[at(a, b - 1, c)] + y[at(a, b + 1, c)]) + 0.5f * y[at(a, b, c)];
      float* dst = out.get() + m * kBrickNodes;
      const float* src = Stored(slots_[bricks[m]]);
      for (int a = 0; a < kBrick; ++a)
        for (int b = 0; b < kBrick; ++b)
          for (int c = 0; c < kBrick; ++c) {
            const std::size_t local = static_cast<std::size_t>((a * kBrick + b) * kBrick + c);
            // Nodes past the grid's edge (the last brick of an axis) keep their values, and so do
            // the grid's face nodes: the build leaves each at least half a voxel outside (an open
            // scan's closure cut by a face), which an inside neighbour's average would undo.
            const int i = bc[0] * kBrick + a, j = bc[1] * kBrick + b, k = bc[2] * kBrick + c;
            if (a >= box.n[0] || b >= box.n[1] || c >= box.n[2] || grid_.OnFace(i, j, k)) {
              dst[local] = src[local];
              continue;
            }
            const float v =
                0.25f * (x[at(a + 1, b + 1, c)] + x[at(a + 1, b + 1, c + 2)]) + 0.5f * x[at(a + 1, b + 1, c + 1)];
            dst[local] = std::clamp(v, -band, band);
          }
    }
  });
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, bricks.size(), 64), [&](const auto& r) {
    for (std::size_t m = r.begin(); m != r.end(); ++m)
      std::memcpy(Stored(slots_[bricks[m]]), out.get() + m * kBrickNodes, kBrickNodes * sizeof(float));
  });
}

SparseField::LipschitzStats SparseField::ProjectLipschitz() {
  LipschitzStats st;
  const std::size_t n_bricks = slots_.size();
  const auto band = static_cast<float>(grid_.band_voxels);
  const auto& bd = brick_dims_;
  const auto neighbour = [&](const std::array<int, 3>& c, int f, std::size_t& out) {
    std::array<int, 3> nb = c;
    nb[static_cast<std::size_t>(f / 2)] += (f % 2) == 1 ? 1 : -1;
    if (nb[0] < 0 || nb[1] < 0 || nb[2] < 0 || nb[0] >= bd[0] || nb[1] >= bd[1] || nb[2] >= bd[2]) return false;
    out = BrickIndex(nb[0], nb[1], nb[2]);
    return true;
  };
  // A uniform brick must take values when an allocated node across its face has the other sign,
  // or the same sign and |phi| + step < band. Flags are per (brick, face): no shared writes.
  std::vector<std::uint8_t> face_flag(n_bricks * 6, 0);
  const auto flag_uniform_faces = [&](std::size_t b, const float* v, std::size_t* conflicts) {
    const std::array<int, 3> c = BrickCoords(b);
    const BrickBox box = Box(c[0], c[1], c[2]);
    for (int f = 0; f < 6; ++f) {
      std::size_t nb = 0;
      if (!neighbour(c, f, nb) || slots_[nb] >= 0) continue;
      const bool nb_inside = slots_[nb] == kUniformInside;
      ForFaceNodes(f, box.n, [&](const std::array<int, 3>& local, const std::array<int, 3>& /*across*/) {
        const float x = v[L(local[0], local[1], local[2])];
        const bool other_sign = (x <= 0.0f) != nb_inside;
        if (other_sign && conflicts != nullptr) ++*conflicts;
        if (other_sign || std::abs(x) + kLipschitzStep < band) face_flag[b * 6 + static_cast<std::size_t>(f)] = 1;
      });
    }
  };
  // Allocates the flagged uniform bricks; returns them in brick order.
  const auto allocate_flagged = [&]() {
    std::vector<std::uint8_t> want(n_bricks, 0);
    for (std::size_t b = 0; b < n_bricks; ++b) {
      if (slots_[b] < 0) continue;
      const std::array<int, 3> c = BrickCoords(b);
      for (int f = 0; f < 6; ++f) {
        std::size_t nb = 0;
        if (face_flag[b * 6 + static_cast<std::size_t>(f)] != 0 && neighbour(c, f, nb)) want[nb] = 1;
        face_flag[b * 6 + static_cast<std::size_t>(f)] = 0;
      }
    }
    std::vector<std::size_t> fresh;
    for (std::size_t b = 0; b < n_bricks; ++b)
      if (want[b] != 0 && slots_[b] < 0) fresh.push_back(b);
    for (const std::size_t b : fresh) Allocate(b);
    st.bricks_allocated += fresh.size();
    return fresh;
  };

  // 0. Uniform bricks that already conflict with an allocated neighbour take values first, so
  // that the interface pass below treats both sides of every sign change.
  {
    tbb::combinable<std::size_t> conflicts([] { return std::size_t{0}; });
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n_bricks, 64), [&](const auto& r) {
      std::size_t& local = conflicts.local();
      for (std::size_t b = r.begin(); b != r.end(); ++b)
        if (slots_[b] >= 0) flag_uniform_faces(b, Stored(slots_[b]), &local);
    });
    st.sign_conflict_nodes = conflicts.combine(std::plus<>());
    allocate_flagged();
  }

  // 1. Interface scaling, Jacobi (reads the input values only). It also finds the bricks the
  // relaxation must visit first: a same-sign violation after scaling was there before, or sits
  // next to a scaled node (scaling only lowers |phi|); so the bricks with a violation in the
  // input and those with, or next to, a scaled node.
  std::vector<std::size_t> work;
  std::vector<std::uint8_t> first(n_bricks, 0);  // bit 0: input violation, bit 1: a node scaled
  {
    std::vector<std::size_t> allocated;
    for (std::size_t b = 0; b < n_bricks; ++b)
      if (slots_[b] >= 0) allocated.push_back(b);
    // The scaled values, kept aside until every node has read its neighbours' input values: only
    // interface nodes change, so a list of them, not a copy of the field (issue 21: the copy was
    // 60 MB of the kitten's 144 MB peak at 600 cells).
    tbb::enumerable_thread_specific<std::vector<std::pair<std::size_t, float>>> scaled;
    tbb::combinable<std::size_t> count([] { return std::size_t{0}; });
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, allocated.size(), 16), [&](const auto& r) {
      std::array<float, kHaloNodes> h;
      std::size_t& local = count.local();
      for (std::size_t w = r.begin(); w != r.end(); ++w) {
        const std::size_t b = allocated[w];
        GatherHalo(b, h.data());
        const std::array<int, 3> c = BrickCoords(b);
        const BrickBox box = Box(c[0], c[1], c[2]);
        if (AnyViolation(h.data(), box.n)) first[b] |= 1;
        const std::size_t base = static_cast<std::size_t>(slots_[b]) * kBrickNodes;
        auto& out = scaled.local();
        for (int a = 0; a < box.n[0]; ++a)
          for (int bb = 0; bb < box.n[1]; ++bb)
            for (int cc = 0; cc < box.n[2]; ++cc) {
              const float v = h[static_cast<std::size_t>(H(a, bb, cc))];
              const bool inside = v <= 0.0f;
              // min over neighbours of step / sum = step / (largest sum): division is monotone.
              float largest = 0.0f;
              for (const int o : kHaloStep) {
                // Branch-free: a NaN (no node) leaves largest, as std::max(largest, NaN) does.
                const float u = h[static_cast<std::size_t>(H(a, bb, cc) + o)];
                largest = std::max(largest, (u <= 0.0f) != inside ? std::abs(v) + std::abs(u) : 0.0f);
              }
              if (largest > kLipschitzStep) {
                const float scale = kLipschitzStep / largest;
                // An outside node stays strictly positive (phi <= 0 means inside).
                out.emplace_back(base + static_cast<std::size_t>(L(a, bb, cc)),
                                 inside ? v * scale : std::max(v * scale, std::numeric_limits<float>::min()));
                ++local;
                first[b] |= 2;
              }
            }
      }
    });
    for (const auto& list : scaled)
      for (const auto& [at, v] : list) Stored(static_cast<std::int32_t>(at / kBrickNodes))[at % kBrickNodes] = v;
    st.interface_nodes_scaled = count.combine(std::plus<>());
    for (const std::size_t b : allocated) {
      bool visit = first[b] != 0;
      const std::array<int, 3> c = BrickCoords(b);
      for (int f = 0; f < 6 && !visit; ++f) {
        std::size_t nb = 0;
        visit = neighbour(c, f, nb) && (first[nb] & 2) != 0;
      }
      if (visit) work.push_back(b);
    }
  }

  // 2. Same-sign relaxation to the fixed point. Bricks relax Gauss-Seidel on a halo of their
  // faces' neighbours; in 8 colour phases by brick parity, so that no brick is written while a
  // face neighbour reads it. A brick whose face changed requeues its allocated neighbours, and
  // flagged uniform bricks are allocated between sweeps.
  auto revisit = std::make_unique<std::atomic<std::uint8_t>[]>(n_bricks);
  for (std::size_t b = 0; b < n_bricks; ++b) revisit[b].store(0, std::memory_order_relaxed);
  std::array<std::vector<std::size_t>, 8> by_colour;
  while (!work.empty()) {
    ++st.sweeps;
    for (auto& v : by_colour) v.clear();
    for (const std::size_t b : work) {
      const std::array<int, 3> c = BrickCoords(b);
      by_colour[static_cast<std::size_t>((c[0] & 1) * 4 + (c[1] & 1) * 2 + (c[2] & 1))].push_back(b);
    }
    tbb::combinable<std::size_t> updates([] { return std::size_t{0}; });
    for (const auto& phase : by_colour) {
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, phase.size(), 8), [&](const auto& r) {
        std::array<float, kHaloNodes> h, before;
        std::size_t& local = updates.local();
        for (std::size_t w = r.begin(); w != r.end(); ++w) {
          const std::size_t b = phase[w];
          GatherHalo(b, h.data());
          const std::array<int, 3> c = BrickCoords(b);
          const BrickBox box = Box(c[0], c[1], c[2]);
          bool converged = true;
          before = h;
          const bool changed = RelaxHalo(h.data(), box.n, converged);
          float* v = Stored(slots_[b]);
          if (changed) {
            std::array<bool, 6> face_changed{};
            for (int a = 0; a < box.n[0]; ++a)
              for (int bb = 0; bb < box.n[1]; ++bb)
                for (int cc = 0; cc < box.n[2]; ++cc) {
                  const float x = h.data()[H(a, bb, cc)];
                  if (x == before.data()[H(a, bb, cc)]) continue;
                  v[L(a, bb, cc)] = x;
                  ++local;
                  face_changed[0] = face_changed[0] || a == 0;
                  face_changed[1] = face_changed[1] || a == kB - 1;
                  face_changed[2] = face_changed[2] || bb == 0;
                  face_changed[3] = face_changed[3] || bb == kB - 1;
                  face_changed[4] = face_changed[4] || cc == 0;
                  face_changed[5] = face_changed[5] || cc == kB - 1;
                }
            for (int f = 0; f < 6; ++f) {
              std::size_t nb = 0;
              if (face_changed[static_cast<std::size_t>(f)] && neighbour(c, f, nb) && slots_[nb] >= 0)
                revisit[nb].store(1, std::memory_order_relaxed);
            }
          }
          if (!converged) revisit[b].store(1, std::memory_order_relaxed);
          flag_uniform_faces(b, v, nullptr);
        }
      });
    }
    st.node_updates += updates.combine(std::plus<>());
    std::vector<std::size_t> next = allocate_flagged();
    for (std::size_t b = 0; b < n_bricks; ++b)
      if (revisit[b].exchange(0, std::memory_order_relaxed) != 0) next.push_back(b);
    std::sort(next.begin(), next.end());
    next.erase(std::unique(next.begin(), next.end()), next.end());
    work.swap(next);
  }
  return st;
}

}  // namespace palpa::field
