// palpa: the host tool. Builds signed distance fields from oriented points (paper §3.1-3.2),
// inspects and exports them, and synthesises HIP traces for the controller.
#include <fmt/core.h>
#include <CLI/CLI.hpp>

#include <sstream>

#include "commands.h"
#include "palpa/field/samples.h"
#include "palpa/io/escape.h"

int main(int argc, char** argv) {
  using namespace palpa::cli;
  CLI::App app{"palpa: distance-field haptic rendering of scattered oriented points (host tool)"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "palpa 0.1.0 (blob v1)");

  BuildArgs b;
  auto* build = app.add_subcommand("build", "Build a signed distance field blob from oriented points");
  build
      ->add_option("points", b.points,
                   "Oriented points: .xyz or .pwn (x y z nx ny nz per line), or .ply (vertex x y z nx ny nz)")
      ->required();
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
  build->add_option("--band", b.band_voxels, "Narrow band half-width in voxels (paper: 5-6); v2: inside the object")
      ->capture_default_str()
      ->check(CLI::Range(1, 64));
  build->add_option("--band-outside", b.band_outside, "v2: band outside the object in voxels (docs/blob-format.md)")
      ->capture_default_str()
      ->check(CLI::Range(1, 64));
  build->add_option("--format", b.format, "Blob version: 2 (narrow-band bricks) or 1 (dense, for older palpad)")
      ->capture_default_str()
      ->check(CLI::Range(1, 2));
  b.method = "hermite";  // the default (docs/field-methods.md)
  build
      ->add_option("--method", b.method,
                   "Distance method: hermite (sub-voxel, default), edt (signed EDT of the packing), erosion "
                   "(paper eq. 4)")
      ->capture_default_str()
      ->check(CLI::IsMember({"hermite", "edt", "erosion"}));
  build->add_option("--threads", b.threads, "Worker threads (0: all cores)")
      ->capture_default_str()
      ->check(CLI::Range(0, 256));
  build->add_flag("-q,--quiet", b.quiet, "No report on stdout");
  build
      ->add_option("--normals", b.normals,
                   "keep: the file's normals (default); orient: re-choose their signs (Hoppe MST, outward from the "
                   "divergence or the file's majority); estimate: new normals from a jet fit, then orient. A file "
                   "without normals (x y z lines, PLY without nx ny nz) is always estimated")
      ->capture_default_str()
      ->check(CLI::IsMember({"keep", "orient", "estimate"}));
  build
      ->add_option(
          "--denoise", b.denoise,
          fmt::format("auto: when the samples' position noise exceeds a quarter voxel RMS, move each "
                      "along its normal towards the surface its {}-{} nearest samples agree on ({} passes; along "
                      "estimated normals, no more than their fit used, and not where the neighbours' offsets scatter "
                      "beyond the noise), then filter the field once over 3x3x3 nodes; "
                      "estimated normals whose moves exceed 1.4x the noise RMS leave the samples in place and only "
                      "filter (default); off: never",
                      palpa::field::kMoveFewestNeighbours, palpa::field::kMoveMostNeighbours,
                      palpa::field::kMovePasses))
      ->capture_default_str()
      ->check(CLI::IsMember({"auto", "off"}));
  build->add_option("--points-out", b.points_out,
                    "Also write the oriented points the field was built from, in model units, as x y z nx ny nz "
                    "lines: the normals --normals estimated or oriented, without the samples dropped or ignored, "
                    "after --denoise moved them (written only when the build succeeds)");
  build->add_flag("--strict", b.strict,
                  "Refuse a point file with any zero-length or non-finite normal or exact duplicate (default: "
                  "drop them and say so)");

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
  synth
      ->add_option(
          "--kind", t.kind,
          "stroke | poke | strokes (ellipses, two-thirds power law) | poke-grid | taps | pass-through | free | "
          "excursion (docs/trace-format.md)")
      ->capture_default_str()
      ->check(CLI::IsMember({"stroke", "poke", "strokes", "poke-grid", "taps", "pass-through", "free", "excursion"}));
  synth->add_option("-o,--output", t.output, "Output trace: .ptb binary v2, else text v2 (CSV)")->required();
  synth->add_option("--depths", t.depths, "strokes: one lap per depth, m (comma-separated)")
      ->delimiter(',')
      ->check(CLI::Range(0.0, 0.02));
  synth->add_option("--speeds", t.speeds, "taps, pass-through: peak speeds, m/s (comma-separated)")
      ->delimiter(',')
      ->check(CLI::Range(1e-3, 2.0));
  synth->add_option("--count", t.count, "poke-grid pokes; taps/attempts without --speeds; free waypoints")
      ->capture_default_str()
      ->check(CLI::Range(1, 400));
  synth
      ->add_option("--button", t.button_window,
                   "START,END: hold button --button-bit over [START, END) s (e-stop cases)")
      ->expected(2)
      ->delimiter(',')
      ->check(CLI::Range(0.0, 1e6));
  synth->add_option("--button-bit", t.button_bit, "Button bit for --button (Falcon grip: 0-3)")
      ->check(CLI::Range(0, 7));
  synth->add_option("--tremor", t.tremor_m, "RMS of an added 8-12 Hz tremor, m (sub-millimetre)")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 0.001));
  synth->add_option("--force", t.force_n, "Force-constant stroking: depth = force / k, N")
      ->check(CLI::Range(0.0, 100.0));
  synth->add_option("--k", t.k_n_per_m, "Stiffness for --force, N/m")
      ->capture_default_str()
      ->check(CLI::Range(1.0, 1e5));
  synth->add_option("--through", t.through_m, "pass-through: distance past the far side, m")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 0.03));
  synth->add_option("--depth", t.depth_m, "Push-in depth below the surface, m")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 0.05));
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
  TraceImportArgs ti;
  auto* import = trace->add_subcommand("import", "A recorded t_s,x_m,y_m,z_m CSV, scaled into the workspace");
  import->add_option("input", ti.input, "Recording, CSV with header t_s,x_m,y_m,z_m")->required();
  import->add_option("-o,--output", ti.output, "Output trace: .ptb binary v2, else text v2")->required();
  import->add_option("--scale", ti.scale, "Uniform scale about the bounding-box centre")->check(CLI::PositiveNumber);
  import->add_option("--offset", ti.offset_m, "x,y,z metres for the box centre")->delimiter(',')->expected(3);
  import->add_option("--from", ti.from_s, "Window start, s")->check(CLI::NonNegativeNumber);
  import->add_option("--duration", ti.duration_s, "Window length, s (0: to the end)")->check(CLI::NonNegativeNumber);
  import->add_option("--note", ti.note, "Provenance kept in the trace's comment");

  HilArgs hil_args;
  std::string hil_emulator;
  bool hil_fast = false, hil_realtime = false;
  auto* hil = app.add_subcommand("hil", "Hardware-in-the-loop replay of hil/traces through palpad (docs/hil.md)");
  hil->require_subcommand(1);
  auto* hil_run = hil->add_subcommand("run", "Replay the cases: --fast against the goldens, --realtime paced");
  auto* hil_bless = hil->add_subcommand("bless", "Rewrite goldens from a fast replay and print what changed");
  auto* hil_report = hil->add_subcommand("report", "Replay, then write HTML pages with plots and a JSON summary");
  for (auto* sub : {hil_run, hil_bless, hil_report}) {
    sub->add_option("--cases", hil_args.cases, "Case list (default: hil/cases.toml above the current directory)");
    sub->add_option("--work", hil_args.work, "Fields and results directory (default <repo>/build/hil-work)");
    sub->add_option("--goldens", hil_args.goldens, "Golden directory (default hil/goldens)");
    sub->add_option("--palpad", hil_args.palpad, "palpad binary (default: the build tree's)");
  }
  for (auto* sub : {hil_run, hil_report}) {
    auto* f = sub->add_flag("--fast", hil_fast, "Lockstep replay, compared with the goldens (default)");
    sub->add_flag("--realtime", hil_realtime, "Paced on the wall clock: invariants and latency, no goldens")
        ->excludes(f);
    sub->add_option("--filter", hil_args.filter, "Only cases whose name contains NAME (comma-separated)");
    sub->add_option("--device", hil_args.device, "Only cases on this device")
        ->check(CLI::IsMember({"sim", "virtual-falcon"}));
    sub->add_option("--k", hil_args.k, "Override stiffness k, N/m")->check(CLI::Range(1.0, 1e5));
    sub->add_option("--max-force", hil_args.max_force, "Override the force clamp, N")->check(CLI::Range(0.01, 100.0));
    sub->add_option("--rate", hil_args.rate, "Override the tick rate, Hz")->check(CLI::Range(1.0, 10000.0));
  }
  hil_run->add_option("--emulator", hil_emulator, "Run palpad under this prefix, e.g. 'qemu-aarch64 -L /'");
  hil_bless->add_option("names", hil_args.names, "Cases to bless");
  hil_bless->add_flag("--all", hil_args.all, "Bless every case");
  hil_report->add_option("-o,--output", hil_args.report_dir, "Report directory (index.html, one page per case)")
      ->required();

  BenchLatencyArgs bench_args;
  bool bench_no_cyclictest = false;
  auto* bench = app.add_subcommand("bench", "Measurements of the runtime (docs/runtime.md)");
  bench->require_subcommand(1);
  auto* bench_latency =
      bench->add_subcommand("latency", "palpad's servo-loop wake-up latency next to cyclictest's, in one run");
  bench_latency->add_option("--seconds", bench_args.seconds, "Measuring time of each tool (split into the rounds), s")
      ->capture_default_str()
      ->check(CLI::Range(0.1, 3600.0));
  bench_latency->add_option("--rate", bench_args.rate_hz, "Tick rate, Hz")
      ->capture_default_str()
      ->check(CLI::Range(1.0, 10000.0));
  bench_latency->add_option("--priority", bench_args.priority, "SCHED_FIFO priority of both")
      ->capture_default_str()
      ->check(CLI::Range(1, 99));
  bench_latency->add_option("--cpu", bench_args.cpu, "Pin both to this CPU")->check(CLI::Range(0, 1023));
  bench_latency->add_option("--palpad", bench_args.palpad,
                            "palpad binary (default: next to palpa or the build tree's)");
  bench_latency->add_flag("--no-cyclictest", bench_no_cyclictest, "Skip the cyclictest anchor");
  bench_latency->add_flag("--with-viewer", bench_args.with_viewer,
                          "Also run palpad with palpa view --connect polling its status channel; both rows");
  bench_latency->add_option("--rounds", bench_args.rounds, "Alternate palpad and cyclictest in this many segments")
      ->capture_default_str()
      ->check(CLI::Range(1, 100));

  std::string falcon_ik_xyz, falcon_fk_enc;
  auto* falcon = app.add_subcommand("falcon", "Novint Falcon kinematics for bring-up (docs/falcon.md)");
  falcon->require_subcommand(1);
  auto* falcon_ik = falcon->add_subcommand("ik", "Joint angles and encoder counts for a grip position");
  falcon_ik->add_option("position", falcon_ik_xyz, "X,Y,Z in metres, Falcon frame (grip at z 0.075..0.175)")
      ->required();
  auto* falcon_fk = falcon->add_subcommand("fk", "Grip position for encoder counts (homed)");
  falcon_fk->add_option("encoders", falcon_fk_enc, "E1,E2,E3 encoder counts")->required();

  SampleArgs sa;
  auto* sample = app.add_subcommand("sample", "Area-uniform oriented points from a closed triangle mesh (.off)");
  sample->add_option("mesh", sa.mesh, "Closed triangle mesh, OFF")->required();
  sample->add_option("-n,--count", sa.count, "Number of points")->required()->check(CLI::Range(1, 10000000));
  sample->add_option("-o,--output", sa.output, "Output POINTS.xyz (x y z nx ny nz), written atomically")->required();
  sample->add_option("--seed", sa.seed, "Random seed: the same seed gives the same points")->capture_default_str();
  auto* views = sample
                    ->add_option("--views", sa.views,
                                 "A virtual range scan instead: cameras on the upper hemisphere, first hits only, "
                                 "an open scan of at most -n points (docs/tools.md)")
                    ->check(CLI::Range(1, 1000));
  sample->add_option("--range-noise", sa.range_noise, "With --views: Gaussian noise along each ray, model units")
      ->check(CLI::NonNegativeNumber)
      ->needs(views);
  sample->add_flag("-q,--quiet", sa.quiet, "No report on stdout");

  EvalArgs ea;
  auto* eval = app.add_subcommand("eval", "Score a field against the true signed distance of a mesh or a sphere");
  eval->add_option("field", ea.field, "FIELD.palpa")->required();
  auto* eval_mesh = eval->add_option("--mesh", ea.mesh, "Truth: closed triangle mesh (.off) in model units");
  eval->add_option("--sphere", ea.sphere_radius, "Truth: sphere of radius R (model units) at the model origin")
      ->excludes(eval_mesh);
  eval->add_flag("--json", ea.json, "Machine-readable output");
  eval->add_option("--candidate-mesh", ea.candidate_mesh,
                   "Score this closed triangle mesh (.off, model units; e.g. screened Poisson's) on FIELD's "
                   "grid instead of FIELD");
  auto* eval_band = eval->add_option("--band", ea.band_voxels,
                                     "Score nodes with |true| <= this many voxels (default 3, or the field's "
                                     "smaller band, e.g. a v2 field's outside band of 2)")
                        ->capture_default_str()
                        ->check(CLI::Range(0.5, 64.0));
  eval->add_option("--on-surface", ea.on_surface_voxels,
                   "Nodes with |true| <= this many voxels are on the surface: their sign is not scored "
                   "(default 1/1024: a face on a node plane leaves the sign to the points' rounding)")
      ->check(CLI::Range(0.0, 0.5));
  eval->add_option("--far-out", ea.far_out,
                   "Also write every far wrong-sign node (|true| > 3 voxels) as 'x y z depth kind' lines: model "
                   "units, depth |true| in voxels, kind phantom (inside where the truth is outside) or hole");
  eval->add_option("--threads", ea.threads, "Worker threads (0: all cores)")
      ->capture_default_str()
      ->check(CLI::Range(0, 256));

  MeshArgs ma;
  auto* mesh_cmd = app.add_subcommand("mesh", "Write the zero iso-surface of a field as a triangle mesh");
  mesh_cmd->add_option("field", ma.field, "FIELD.palpa")->required();
  mesh_cmd->add_option("-o,--output", ma.output, "SURFACE.ply or SURFACE.obj (device metres), written atomically")
      ->required();
  mesh_cmd->add_flag("-q,--quiet", ma.quiet, "No report on stdout");

  SliceArgs sl;
  std::string slice_axis = "z";
  auto* slice = app.add_subcommand("slice", "Write a colour-mapped cross-section of a field as a PNG");
  slice->add_option("field", sl.field, "FIELD.palpa")->required();
  slice->add_option("--axis", slice_axis, "Normal of the slice plane: x, y or z")
      ->capture_default_str()
      ->check(CLI::IsMember({"x", "y", "z"}));
  slice->add_option("--at", sl.at_m, "Coordinate of the plane along --axis, device metres")->required();
  slice->add_option("-o,--output", sl.output, "SLICE.png, written atomically")->required();
  slice->add_option("--scale", sl.pixels_per_voxel, "Pixels per voxel (0: panel at least 600 pixels)")
      ->capture_default_str()
      ->check(CLI::Range(0, 64));
  slice->add_flag("-q,--quiet", sl.quiet, "No report on stdout");

  ViewArgs va;
  auto* view_cmd = app.add_subcommand("view", "Serve the browser view: iso-surface, replay, live (docs/view.md)");
  view_cmd->add_option("field", va.field, "FIELD.palpa")->required();
  view_cmd->add_option("--trace", va.trace, "Replay: palpad output CSV or a HIL result directory");
  auto* view_connect = view_cmd->add_option("--connect", va.connect, "Live: palpad --listen HOST:PORT");
  view_cmd->add_option("--key-file", va.key_file, "Live: the status channel key (palpa keygen)")->needs(view_connect);
  view_cmd->add_option("--bind", va.bind, "HOST:PORT to serve on (loopback unless asked; port 0: any free)")
      ->capture_default_str();
  view_cmd->add_option("--assets", va.assets, "The page's asset directory (default: installed or build tree)");

  std::string keygen_out;
  bool keygen_force = false;
  auto* keygen = app.add_subcommand("keygen", "Write a new 32-byte shared key for palpad --listen (mode 0600)");
  keygen->add_option("-o,--output", keygen_out, "Key file to create")->required();
  keygen->add_flag("--force", keygen_force, "Replace an existing key file");
  UploadArgs up;
  auto* upload = app.add_subcommand("upload", "Verify a field blob and send it to a running palpad (docs/upload.md)");
  upload->add_option("field", up.field, "FIELD.palpa")->required();
  upload->add_option("--to", up.to, "HOST:PORT of palpad --listen")->required();
  upload->add_option("--key-file", up.key_file, "Shared key (palpa keygen), mode 0600")->required();
  upload->add_option("--timeout-ms", up.timeout_ms, "Longest wait for the controller, ms")
      ->check(CLI::Range(10, 600000));
  upload->add_flag("--no-verify", up.skip_verify, "Send without verifying locally (testing the controller)")->group("");
  StatusArgs st;
  auto* status = app.add_subcommand("status", "A running palpad's field, counters and latest sample");
  status->add_option("--to", st.to, "HOST:PORT of palpad --listen")->required();
  status->add_option("--key-file", st.key_file, "Shared key (palpa keygen), mode 0600")->required();
  status->add_flag("--json", st.json, "One JSON object");
  status->add_option("--timeout-ms", st.timeout_ms, "Longest wait, ms")->check(CLI::Range(10, 600000));
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    if (e.get_exit_code() == 0) return app.exit(e);  // --help
    // CLI11 quotes the offending argument as given: escaped and cut here (issue 18, finding 8).
    fmt::print(stderr, "{}\nRun with --help for more information.\n", palpa::io::Escape(e.what(), 512));
    return kExitBadInput;
  }

  if (*build) {
    if (!offset.empty()) {
      if (std::sscanf(offset.c_str(), "%lf,%lf,%lf", &b.offset_m[0], &b.offset_m[1], &b.offset_m[2]) != 3) {
        fmt::print(stderr, "palpa build: --offset expects x,y,z in metres, got '{}'\n", palpa::io::Escape(offset));
        return kExitBadInput;
      }
    }
    if (voxel->count() > 0) b.cells = 0;
    return RunBuild(b);
  }
  if (*keygen) return RunKeygen(keygen_out, keygen_force);
  if (*upload) return RunUpload(up);
  if (*status) return RunStatus(st);
  if (*info) return RunInfo(info_field, info_json);
  if (*exp) return RunExport(export_field, export_npy);
  if (*synth) return RunTraceSynth(t);
  if (*import) return RunTraceImport(ti);
  if (*hil) {
    hil_args.mode = hil_realtime ? "realtime" : "fast";
    std::istringstream words(hil_emulator);
    for (std::string w; words >> w;) hil_args.emulator.push_back(w);
    if (*hil_run) return RunHil(hil_args, "run");
    if (*hil_bless) return RunHil(hil_args, "bless");
    return RunHil(hil_args, "report");
  }
  if (*bench_latency) {
    bench_args.cyclictest = !bench_no_cyclictest;
    return RunBenchLatency(bench_args);
  }
  if (*falcon_ik) return RunFalconIk(falcon_ik_xyz);
  if (*falcon_fk) return RunFalconFk(falcon_fk_enc);
  if (*sample) return RunSample(sa);
  if (*eval) {
    ea.band_given = eval_band->count() > 0;
    return RunEval(ea);
  }
  if (*mesh_cmd) return RunMesh(ma);
  if (*view_cmd) return RunView(va);
  if (*slice) {
    sl.axis = slice_axis[0];
    return RunSlice(sl);
  }
  return kExitBadInput;
}
