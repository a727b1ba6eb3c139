// Narrow-band signed distance field stored as 8x8x8 bricks: only bricks that hold band values
// are allocated; every other brick is uniformly outside (+band) or inside (-band). Memory and
// work follow the surface, not the volume (issue 5). Non-RT, host only.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <new>
#include <optional>
#include <span>
#include <vector>

#include "palpa/field/grid.h"

namespace palpa::field {

class SparseField {
 public:
  static constexpr int kBrickLog2 = 3;
  static constexpr int kBrick = 1 << kBrickLog2;  // nodes per brick edge
  static constexpr int kBrickNodes = kBrick * kBrick * kBrick;
  static constexpr std::int32_t kUniformOutside = -1;  // brick slot: all nodes +band
  static constexpr std::int32_t kUniformInside = -2;   // brick slot: all nodes -band

  SparseField() = default;
  // All bricks uniformly outside.
  explicit SparseField(const GridSpec& grid);

  // Keeps the bricks of a dense field (grid.NodeCount() values, C order, voxels) that hold any
  // |phi| < band; the others become uniform with their sign. Values are clamped to +-band.
  static SparseField FromDense(const GridSpec& grid, std::span<const float> phi_voxels);

  const GridSpec& grid() const { return grid_; }
  const std::array<int, 3>& brick_dims() const { return brick_dims_; }
  std::size_t BrickIndex(int bi, int bj, int bk) const {
    return (static_cast<std::size_t>(bi) * static_cast<std::size_t>(brick_dims_[1]) + static_cast<std::size_t>(bj)) *
               static_cast<std::size_t>(brick_dims_[2]) +
           static_cast<std::size_t>(bk);
  }
  // (bi, bj, bk) of brick index `brick`: the inverse of BrickIndex.
  std::array<int, 3> BrickCoords(std::size_t brick) const;
  std::int32_t Slot(std::size_t brick) const { return slots_[brick]; }
  void SetUniform(std::size_t brick, bool inside) { slots_[brick] = inside ? kUniformInside : kUniformOutside; }
  // Allocates (if needed) the brick's values and returns them: kBrickNodes floats, local index
  // (a*kBrick + b)*kBrick + c for node (bi*8 + a, bj*8 + b, bk*8 + c). A new brick holds its
  // former uniform value (+band outside, -band inside). Earlier BrickValues pointers stay valid
  // (bricks live in pages of kPageBricks, never moved: a growing field is never copied whole).
  float* Allocate(std::size_t brick);
  // Allocates every brick flagged in `active` (one flag per brick), in brick order.
  void AllocateAll(const std::vector<std::uint8_t>& active);
  float* BrickValues(std::size_t brick) { return slots_[brick] >= 0 ? Stored(slots_[brick]) : nullptr; }
  const float* BrickValues(std::size_t brick) const { return slots_[brick] >= 0 ? Stored(slots_[brick]) : nullptr; }

  // phi at node (i, j, k) in voxels, in [-band, +band].
  float Value(int i, int j, int k) const;

  // The 27 bricks about one brick, each looked up once, for reading its nodes and a one-node halo
  // round them (SmoothBand, the closure vote): a Value call per halo node was most of those passes'
  // time. Holds pointers into the field: valid until a brick is allocated or made uniform.
  class Neighbourhood {
   public:
    // phi at node (i, j, k) in voxels, as Value: (i, j, k) must be a grid node within one brick of
    // the centre brick along each axis (unchecked).
    float Value(int i, int j, int k) const {
      const auto n =
          static_cast<std::size_t>((((i >> kBrickLog2) - centre_[0] + 1) * 3 + (j >> kBrickLog2) - centre_[1] + 1) * 3 +
                                   (k >> kBrickLog2) - centre_[2] + 1);
      const float* v = values_[n];
      return v != nullptr ? v[((i & (kBrick - 1)) * kBrick + (j & (kBrick - 1))) * kBrick + (k & (kBrick - 1))]
                          : uniform_[n];
    }

    // The kBrick values of row (i, j) (a grid row within one brick of the centre brick) in the
    // brick `dk` (-1, 0, 1) bricks from the centre along k, local index k & (kBrick - 1); null
    // where that brick is uniform, its value then in *uniform.
    const float* Row(int i, int j, int dk, float* uniform) const {
      const auto n = static_cast<std::size_t>(
          (((i >> kBrickLog2) - centre_[0] + 1) * 3 + (j >> kBrickLog2) - centre_[1] + 1) * 3 + dk + 1);
      *uniform = uniform_[n];
      const float* v = values_[n];
      return v != nullptr ? v + ((i & (kBrick - 1)) * kBrick + (j & (kBrick - 1))) * kBrick : nullptr;
    }

   private:
    friend class SparseField;
    std::array<int, 3> centre_{};
    std::array<const float*, 27> values_{};  // (di * 3 + dj) * 3 + dk for offsets -1..1; null: uniform
    std::array<float, 27> uniform_{};        // +-band of a uniform brick (0 past the grid's edge)
  };
  // The neighbourhood of brick (bi, bj, bk) = `bc`.
  Neighbourhood Neighbours(const std::array<int, 3>& bc) const;
  std::size_t AllocatedBricks() const { return stored_; }
  // Nodes with phi <= 0 (parallel; deterministic). Uniform bricks count without a per-node scan.
  std::size_t CountInside() const;

  // Labels every unallocated brick inside (-band) or outside (+band): each 6-connected component
  // of unallocated bricks takes the majority sign of the allocated grid nodes that face it across
  // a brick face (the nodes just outside the component). In an exact distance field those nodes
  // all share the component's sign: no node of the component is within band of the surface, so
  // no path through it crosses the surface. A component that no allocated node faces is outside.
  // Unlike a flood fill from the grid boundary this is right for enclosed outside pockets
  // (cavities, closed handles) and for inside regions that a gap in the band connects to the
  // boundary. Returns the minority votes summed over components (0 for a consistent field).
  std::size_t LabelUnallocatedBricks();

  struct LipschitzStats {
    std::size_t sign_conflict_nodes = 0;  // allocated nodes facing a uniform brick of the other sign
    std::size_t interface_nodes_scaled = 0;
    std::size_t node_updates = 0;      // lowerings by the same-sign pass (a node may count twice)
    std::size_t bricks_allocated = 0;  // uniform bricks that had to take values
    int sweeps = 0;
  };
  // Lipschitz projection: afterwards every pair of axis-neighbour grid nodes differs by at most
  // kLipschitzStep < 1 voxel, so each trilinear cell has |grad phi| <= sqrt(3) voxel/voxel, as the
  // proxy's sphere tracing needs (docs/realtime-core.md), and the Q16.16 payload (WriteQ16) keeps
  // every axis difference <= 65536 (1 voxel) despite rounding. It only ever lowers |phi| and
  // never changes a sign (phi <= 0 stays inside), so it never overstates a distance:
  //  1. Interface: a node with an axis neighbour of the other sign is scaled by
  //     min(1, step / (|phi| + |phi_nb|)) over those neighbours (from the input values), so every
  //     such pair gets |a| + |b| <= step; an edge whose ends have no other such neighbour keeps
  //     its linear zero crossing.
  //  2. Same sign: |phi(x)| <- min(|phi(x)|, |phi(y)| + step) over same-sign axis neighbours y,
  //     to the fixed point: the greatest field below the input with that property. That is a
  //     shortest-path problem, so any relaxation order reaches the same values (deterministic
  //     for any thread count); bricks relax in parallel in 8 colour phases, Gauss-Seidel,
  //     revisited while a face changes.
  // A uniform brick that must take values (an allocated node of the other sign faces it, or a
  // same-sign node below band - step) is allocated with its uniform value and follows the rules.
  static constexpr float kLipschitzStep = 1.0f - 1.0f / 32768.0f;

  // Position noise (issue 20): one pass of the binomial filter [1 2 1] / 4 along each axis (the
  // 3x3x3 kernel, variance 1/2 voxel^2 per axis) over every node of the allocated bricks, reading
  // uniform bricks as +-band and a node past the grid's edge as its edge neighbour, clamped to
  // +-band. A surface's noise at the node scale is averaged over 27 nodes (independent node noise:
  // RMS x 0.23); a linear field is unchanged, and a curved surface moves inward by (k1 + k2) / 4
  // voxels for principal curvatures k1, k2 in 1/voxel (the heat equation for t = 1/4: 0.05 voxel
  // on a sphere of radius 10). A convex combination of translates, it keeps every axis-neighbour
  // difference within kLipschitzStep (up to rounding; ProjectLipschitz then makes it exact). Uniform
  // bricks stay uniform, and the grid's face nodes keep their values (HermiteField leaves each at
  // least half a voxel outside; an average with inside neighbours could put one inside).
  // O(allocated bricks); parallel, deterministic.
  void SmoothBand();
  LipschitzStats ProjectLipschitz();
  // Writes phi as Q16.16 voxels for every node into `dense` (NodeCount() values, C order), in
  // parallel over i-planes: nearest, but phi > 0 to 1 at least (outside stays outside, never the
  // surface's 0). This is the blob v1 payload.
  void WriteQ16(std::span<std::int32_t> dense) const;
  // phi at node (i, j, k) as WriteQ16 writes it: Q16.16 voxels, nearest, within +-band.
  std::int32_t ValueQ16(int i, int j, int k) const;
  // Brick `brick` as WriteQ16 writes its nodes, for a brick-wise blob encoder (blob::BrickSource):
  // a uniform brick returns its one Q16.16 value and leaves `q16` alone; an allocated one writes
  // its kBrickNodes values (local index as BrickValues, nodes past the grid's edge included) and
  // returns nullopt. O(brick), no dense array.
  std::optional<std::int32_t> BrickQ16(std::size_t brick, std::span<std::int32_t, kBrickNodes> q16) const;
  // The dense float field (tests and references only: O(volume) memory).
  std::vector<float> ToDense() const;

 private:
  // Grid nodes per axis inside brick (bi, bj, bk): 8, or fewer in the last brick of an axis.
  struct BrickBox {
    std::array<int, 3> n{};
    std::size_t NodeCount() const {
      return static_cast<std::size_t>(n[0]) * static_cast<std::size_t>(n[1]) * static_cast<std::size_t>(n[2]);
    }
  };
  BrickBox Box(int bi, int bj, int bk) const;
  // 10^3 halo of a brick's nodes and its 6 face neighbours (NaN where there is no grid node).
  void GatherHalo(std::size_t brick, float* halo) const;

  // The values of stored brick `slot` (slot >= 0).
  float* Stored(std::int32_t slot) {
    const auto s = static_cast<std::size_t>(slot);
    return pages_[s / kPageBricks].data() + (s % kPageBricks) * kBrickNodes;
  }
  const float* Stored(std::int32_t slot) const {
    const auto s = static_cast<std::size_t>(slot);
    return pages_[s / kPageBricks].data() + (s % kPageBricks) * kBrickNodes;
  }

  // Bricks per page of values (128 KiB): a vector that grew by doubling held the old and the new
  // copy at once (the kitten at 1,200 cells: 246 MB of bricks, a 492 MB peak).
  static constexpr std::size_t kPageBricks = 64;
  GridSpec grid_;
  std::array<int, 3> brick_dims_{};
  std::vector<std::int32_t> slots_;
  // Pages are not zeroed: every brick handed out is filled first, and its first touch, page
  // fault by page fault, is most of the cost of allocating (AllocateAll does it in parallel).
  template <class T>
  struct NoInit : std::allocator<T> {
    template <class U>
    struct rebind {
      using other = NoInit<U>;
    };
    template <class U>
    void construct(U* p) {
      ::new (static_cast<void*>(p)) U;
    }
  };
  std::vector<std::vector<float, NoInit<float>>> pages_;
  std::size_t stored_ = 0;  // bricks with values: slots 0 .. stored_ - 1
};

}  // namespace palpa::field
