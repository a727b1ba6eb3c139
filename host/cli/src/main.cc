// palpa: the host tool. Builds signed distance fields from oriented points (paper §3.1-3.2),
// inspects and exports them, and synthesises HIP traces for the controller.
#include <fmt/core.h>
#include <CLI/CLI.hpp>

#include "commands.h"

int main(int argc, char** argv) {
  using namespace palpa::cli;
  CLI::App app{"palpa: distance-field haptic rendering of scattered oriented points (host tool)"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "palpa 0.1.0 (blob v1)");

  BuildArgs b;
  auto* build = app.add_subcommand("build", "Build a signed distance field blob from oriented points");
  build->add_option("points", b.points, "Oriented points: .xyz or .pwn (x y z nx ny nz per line)")->required();
  build->add_option("-o,--output", b.output, "Output blob (FIELD.palpa), written atomically")->required();
  auto* fit =
      build->add_option("--fit", b.fit_m, "Longest bounding-box side in metres, centred at the workspace origin")
          ->capture_default_str()
          ->check(CLI::Range(1e-4, 1.0));
  auto* scale =
      build->add_option("--scale", b.scale, "Model units → metres (instead of --fit)")->check(CLI::PositiveNumber);
  std::string offset;
  auto* off = build->add_option("--offset", offset, "x,y,z metres added after --scale")->needs(scale);
  fit->excludes(scale);
  (void)off;
  auto* cells = build->add_option("--cells", b.cells, "Grid nodes along the longest axis (paper: 300)")
                    ->capture_default_str()
                    ->check(CLI::Range(16, 4096));
  auto* voxel = build->add_option("--voxel", b.voxel_m, "Node spacing in metres (instead of --cells)")
                    ->check(CLI::PositiveNumber);
  cells->excludes(voxel);
  build->add_option("--band", b.band_voxels, "Narrow band half-width in voxels (paper: 5-6)")
      ->capture_default_str()
      ->check(CLI::Range(1, 64));
  build->add_option("--method", b.method, "Distance method: erosion (paper eq. 4)")
      ->capture_default_str()
      ->check(CLI::IsMember({"erosion"}));
  build->add_option("--threads", b.threads, "Worker threads (0: all cores)")
      ->capture_default_str()
      ->check(CLI::Range(0, 256));
  build->add_flag("-q,--quiet", b.quiet, "No report on stdout");

  std::string info_field;
  bool info_json = false;
  auto* info = app.add_subcommand("info", "Verify a blob and print its header");
  info->add_option("field", info_field, "FIELD.palpa")->required();
  info->add_flag("--json", info_json, "Machine-readable output");

  std::string export_field, export_npy;
  auto* exp = app.add_subcommand("export", "Write the field as float32 metres to a .npy file, shape (nx, ny, nz)");
  exp->add_option("field", export_field, "FIELD.palpa")->required();
  exp->add_option("--npy", export_npy, "Output .npy")->required();

  TraceSynthArgs t;
  auto* trace = app.add_subcommand("trace", "HIP traces");
  trace->require_subcommand(1);
  auto* synth = trace->add_subcommand("synth", "Synthesise a minimum-jerk HIP trace over a field's surface");
  synth->add_option("--field", t.field, "FIELD.palpa")->required();
  synth->add_option("--kind", t.kind, "stroke | poke")->capture_default_str()->check(CLI::IsMember({"stroke", "poke"}));
  synth->add_option("-o,--output", t.output, "Output trace CSV")->required();
  synth->add_option("--depth", t.depth_m, "Push-in depth below the surface, m")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 0.02));
  synth->add_option("--length", t.stroke_m, "Stroke length along the surface, m")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 0.2));
  synth->add_option("--speed", t.speed_m_s, "Peak sliding speed, m/s")
      ->capture_default_str()
      ->check(CLI::Range(1e-4, 2.0));
  synth->add_option("--rate", t.rate_hz, "Samples per second")
      ->capture_default_str()
      ->check(CLI::Range(10.0, 100000.0));
  synth->add_option("--seed", t.seed, "Chooses the touch direction")->capture_default_str();

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);
    return code == 0 ? 0 : kExitBadInput;
  }

  if (*build) {
    if (!offset.empty()) {
      if (std::sscanf(offset.c_str(), "%lf,%lf,%lf", &b.offset_m[0], &b.offset_m[1], &b.offset_m[2]) != 3) {
        fmt::print(stderr, "palpa build: --offset expects x,y,z in metres, got '{}'\n", offset);
        return kExitBadInput;
      }
    }
    if (voxel->count() > 0) b.cells = 0;
    return RunBuild(b);
  }
  if (*info) return RunInfo(info_field, info_json);
  if (*exp) return RunExport(export_field, export_npy);
  if (*synth) return RunTraceSynth(t);
  return kExitBadInput;
}
