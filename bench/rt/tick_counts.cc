// Callgrind driver: runs every benchmark scenario tick by tick and, under
//   valgrind --tool=callgrind --collect-atstart=no --combine-dumps=yes
// collects only inside proxy::ProxyTick and dumps the count after each tick, labelled
// "SCENARIO STEADY" (bench/rt/callgrind_ticks parses them). Outside valgrind the client requests
// are no-ops and it just runs the ticks. Scenarios: the kitten strokes of palpa_rt_bench (free,
// shallow, deep), the 2 mm sliding stroke on the 8 mm analytic sphere, and 2-voxel plate passes at
// 0.5 and 2 m/s.
//
//   palpa_rt_ticks --field=build/kitten.palpa [--profile] [--only=SCENARIO] [--reference]

#include <valgrind/callgrind.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "float64_proxy.h"
#include "scenarios.h"

namespace {

bool g_dump = true;        // --profile: one total (for callgrind_annotate) instead of a dump per tick
std::string g_only;        // --only=SCENARIO: run just that one
bool g_reference = false;  // --reference: count the float64 reference tick instead

void Run(const palpa::bench::Field& f, const palpa::bench::Scenario& s) {
  if (!g_only.empty() && s.name != g_only) return;
  const auto params = palpa::proxy::MakeProxyParams({}, f.view.voxel_m).value();
  const palpa::bench::Float64Field ref(f.Stored(), *f.sampler);  // the storage the fixed tick reads
  const palpa::bench::Float64Params ref_params = palpa::bench::Float64Params::Of(params);
  palpa::proxy::ProxyState state;
  palpa::bench::Float64State ref_state;
  char label[96];
  long contact = 0;
  for (const auto& t : s.ticks) {
    if (t.reset) {
      state = {};
      ref_state = {};
    }
    bool in_contact = false;
    if (g_reference) {
      const palpa::bench::Vec3d hip = {t.hip.x / 65536.0, t.hip.y / 65536.0, t.hip.z / 65536.0};
      CALLGRIND_TOGGLE_COLLECT;
      const auto r = palpa::bench::Float64Tick(ref, ref_params, ref_state, hip);
      CALLGRIND_TOGGLE_COLLECT;
      in_contact = r.contact;
    } else {
      // The typed tick, as the servo loop runs it after choosing the storage (one branch a tick,
      // outside ProxyTick: proxy.h).
      f.sampler->Visit([&](const auto& typed) {
        CALLGRIND_TOGGLE_COLLECT;
        const auto r = palpa::proxy::ProxyTick(typed, params, state, t.hip);
        CALLGRIND_TOGGLE_COLLECT;
        in_contact = r.contact;
      });
    }
    std::snprintf(label, sizeof label, "%s %d %d", s.name.c_str(), t.steady ? 1 : 0, in_contact ? 1 : 0);
    if (g_dump) CALLGRIND_DUMP_STATS_AT(label);
    contact += in_contact ? 1 : 0;
  }
  std::printf("%-14s %6zu ticks, %6ld in contact\n", s.name.c_str(), s.ticks.size(), contact);
}

}  // namespace

int main(int argc, char** argv) {
  std::string field_path;
  for (int i = 1; i < argc; ++i) {
    if (std::strncmp(argv[i], "--field=", 8) == 0) field_path = argv[i] + 8;
    if (std::strcmp(argv[i], "--profile") == 0) g_dump = false;
    if (std::strcmp(argv[i], "--reference") == 0) g_reference = true;
    if (std::strncmp(argv[i], "--only=", 7) == 0) g_only = argv[i] + 7;
  }
  if (field_path.empty()) {
    std::fprintf(stderr, "usage: palpa_rt_ticks --field=FIELD.palpa\n");
    return 2;
  }
  // Calibration: the cost of the toggles and the dump with nothing between them.
  for (int i = 0; i < 3; ++i) {
    CALLGRIND_TOGGLE_COLLECT;
    CALLGRIND_TOGGLE_COLLECT;
    CALLGRIND_DUMP_STATS_AT("calibration 0 0");
  }
  // The sphere and the plates are stored like the field under test (bench/rt/run passes a v2 and
  // a v1 blob), so bounded work is measured on the storage palpad samples.
  auto storage = palpa::bench::Storage::kV1;
  {
    const auto kitten = palpa::bench::LoadField(field_path);
    if (kitten->stored) storage = palpa::bench::Storage::kV2;
    for (const auto& [name, depth] :
         {std::pair{"free", -1e-3}, std::pair{"shallow", 0.2e-3}, std::pair{"deep", 2e-3}}) {
      Run(*kitten, palpa::bench::SurfaceStrokes(*kitten, name, depth, 0.05, 8, 250, 1));
    }
  }
  {
    const auto sphere = palpa::bench::SphereField(100, 0.0002, 40, storage);
    Run(*sphere, palpa::bench::SphereStroke(*sphere, 40, 2e-3, 0.1));
  }
  const std::array<std::array<double, 3>, 3> normals = {
      std::array<double, 3>{0, 0, 1}, {0.3, 0.4, std::sqrt(0.75)}, {-0.5, 0.5, std::sqrt(0.5)}};
  for (std::size_t n = 0; n < normals.size(); ++n) {
    const auto plate = palpa::bench::PlateField(64, 0.0002, normals[n], 0.25 * static_cast<double>(n), storage);
    for (const double speed : {0.5, 2.0}) {
      Run(*plate, palpa::bench::PlatePasses(*plate, normals[n], 0.25 * static_cast<double>(n), speed, 20,
                                            static_cast<std::uint32_t>(n + 1)));
    }
  }
  return 0;
}
