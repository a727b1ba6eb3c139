// HIP trajectories for the real-time core's benchmarks: strokes over a field's own surface (free
// space, shallow and deep contact), the sliding stroke on an analytic sphere and passes through a
// 2-voxel plate. Non-RT set-up code shared by the Google Benchmark target and the callgrind
// driver. Positions are grid Q16.16 (what ProxyTick takes).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "palpa/blob/blob.h"
#include "palpa/proxy/proxy.h"
#include "palpa/sampler/trilinear.h"

namespace palpa::bench {

/// A verified blob kept in place with its sampler. Not movable (the views refer to the fields).
/// `sampler` reads the blob as stored, as palpad does (a v2 blob's bricks in place); `view` is
/// the dense v1 form of the same values (identical for a v1 blob), which the float64 reference
/// and the scenario builders index directly.
struct Field {
  Field(blob::VerifiedField dense_form, std::optional<blob::VerifiedField> stored_form)
      : dense(std::move(dense_form)),
        stored(std::move(stored_form)),
        view(dense.view()),
        stored_view(stored ? stored->view() : dense.view()),
        sampler(std::make_unique<sampler::TrilinearSampler>(stored_view)) {}
  Field(const Field&) = delete;
  Field& operator=(const Field&) = delete;

  blob::VerifiedField dense;                           ///< the dense v1 form
  std::optional<blob::VerifiedField> stored;           ///< the stored form when it is not `dense` (v2)
  const blob::FieldView& view;                         ///< dense.view()
  const blob::FieldView& stored_view;                  ///< the blob as stored
  std::unique_ptr<sampler::TrilinearSampler> sampler;  ///< samples the stored form
  const blob::FieldView& Stored() const { return stored_view; }
};

/// Reads and verifies a .palpa blob; exits with a message naming the file on any error.
std::unique_ptr<Field> LoadField(const std::string& path);
/// How an analytic field is stored and sampled: a dense v1 blob (band 6), or blob v2 bricks with
/// palpa build's default bands (6 inside, 2 outside); `view` is the dense form either way.
enum class Storage { kV1, kV2 };
/// Sphere of radius `radius_vox` voxels at the centre of an n³ grid.
std::unique_ptr<Field> SphereField(std::uint32_t n, double voxel_m, double radius_vox, Storage storage = Storage::kV1);
/// Plate |n·x − c| ≤ 1 voxel through the centre of an n³ grid, normal `normal` (unit).
std::unique_ptr<Field> PlateField(std::uint32_t n, double voxel_m, const std::array<double, 3>& normal, double offset,
                                  Storage storage = Storage::kV1);

/// One tick's input and what the tick is for.
struct Tick {
  sampler::GridPos hip;
  bool reset = false;   ///< start a fresh proxy state before this tick (a new pass or stroke)
  bool steady = false;  ///< part of the stroke proper (not its approach)
};

struct Scenario {
  std::string name;
  std::vector<Tick> ticks;
};

/// Strokes over the field's zero level set at `speed_m_s`, the HIP `depth_m` below the walked
/// surface point (negative: outside, free space). Each stroke starts with a 20-tick approach from
/// 1 mm outside along the normal. Deterministic for a given seed.
Scenario SurfaceStrokes(const Field& f, const std::string& name, double depth_m, double speed_m_s, int strokes,
                        int ticks_per_stroke, std::uint32_t seed);

/// The sliding stroke of tests/shared/proxy_test.cc: 200 ms press to `depth_m`, then 1 s along a
/// great circle at `speed_m_s` (field from SphereField).
Scenario SphereStroke(const Field& f, double radius_vox, double depth_m, double speed_m_s);

/// Straight passes at `speed_m_s` from 2 mm above to 2 mm past a plate from PlateField, in random
/// directions within 60° of its normal.
Scenario PlatePasses(const Field& f, const std::array<double, 3>& normal, double offset, double speed_m_s, int passes,
                     std::uint32_t seed);

}  // namespace palpa::bench
