// palpa status (issue 7; docs/upload.md): the controller's field, counters and latest sample.
#include <fmt/core.h>

#include "commands.h"
#include "palpa/net/client.h"

namespace palpa::cli {

int RunStatus(const StatusArgs& a) {
  auto to = net::ParseEndpoint(a.to);
  if (!to) {
    fmt::print(stderr, "palpa status: --to {}\n", to.error().message);
    return kExitBadInput;
  }
  auto key = net::ReadKeyFile(a.key_file);
  if (!key) {
    fmt::print(stderr, "palpa status: --key-file {}\n", key.error().message);
    return kExitBadInput;
  }
  const auto s = net::FetchStatus(*to, *key, std::chrono::milliseconds(a.timeout_ms));
  if (!s) {
    fmt::print(stderr, "palpa status: {}\n", s.error().message);
    return kExitIo;
  }
  if (a.json) {
    fmt::print("{}\n", net::ToJson(*s));
    return kExitOk;
  }
  fmt::print("controller     {} ({}, {:g} Hz)\n", a.to, s->running ? "running" : "loop ended", s->rate_hz);
  fmt::print("field          crc32c 0x{:08x}, dims {}x{}x{}, voxel {:.6g} mm, {} bytes, {} swaps{}\n", s->field_crc32c,
             s->dims[0], s->dims[1], s->dims[2], s->voxel_m * 1e3, s->field_bytes, s->swaps,
             s->swap_ramp ? " (force ramping in)" : "");
  fmt::print(
      "ticks          {} ({} in contact), overruns {}, max tick {:.1f} us, force clamps {}, e-stops {}, "
      "dropped {}\n",
      s->ticks, s->contact_ticks, s->overruns, static_cast<double>(s->max_tick_ns) / 1e3, s->force_clamps, s->estops,
      s->dropped);
  fmt::print("uploads        {} accepted, {} refused\n", s->uploads_accepted, s->uploads_refused);
  fmt::print(
      "latest tick    {} at t = {:.3f} s: HIP ({:.6f}, {:.6f}, {:.6f}) m, proxy ({:.6f}, {:.6f}, {:.6f}) m, "
      "force ({:.3f}, {:.3f}, {:.3f}) N, {}\n",
      s->last_tick, s->t_s, s->hip_m[0], s->hip_m[1], s->hip_m[2], s->proxy_m[0], s->proxy_m[1], s->proxy_m[2],
      s->force_n[0], s->force_n[1], s->force_n[2], s->contact ? "contact" : "free");
  return kExitOk;
}

}  // namespace palpa::cli
