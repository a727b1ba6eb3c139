// Subcommands of the `palpa` host tool. Each returns the process exit code:
// 0 success, 2 bad input or arguments (message on stderr naming file, line or byte), 1 I/O failure.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace palpa::cli {

inline constexpr int kExitOk = 0;
inline constexpr int kExitIo = 1;
inline constexpr int kExitBadInput = 2;

/// io::CheckOutputTarget for a command, run before any work: prints "palpa COMMAND: <why>" to
/// stderr and returns the exit code (2: a device, FIFO, socket, directory or an input; 1: the
/// target cannot be checked), or 0 when `path` may be written. Outputs are then written with
/// io::AtomicFile or io::WriteFileAtomically (palpa/io/atomic_file.h), which check it again.
[[nodiscard]] int CheckOutput(const char* command, const std::string& path,
                              const std::vector<std::string>& inputs = {});

/// Whether two paths name one file, existing or not (./x, a/../x, a link to the directory): equal
/// as given, or their absolute, lexically normal, link-resolved forms (std::filesystem::
/// weakly_canonical) are equal. A path that cannot be resolved is compared as given only.
[[nodiscard]] bool SamePath(const std::string& a, const std::string& b);

struct BuildArgs {
  std::string points;                ///< .xyz / .pwn / .ply
  std::string output;                ///< FIELD.palpa
  double fit_m = 0.06;               ///< longest bbox side → this many metres, centred at origin
  std::optional<double> scale;       ///< instead of fit: device = scale·model + offset
  std::array<double, 3> offset_m{};  ///< with scale
  int cells = 300;                   ///< nodes along the longest axis
  double voxel_m = 0;                ///< > 0: node spacing instead of cells
  int band_voxels = 6;               ///< narrow band half-width (v2: the inside band)
  int band_outside = 2;              ///< v2: outside band, voxels (docs/blob-format.md)
  int format = 2;                    ///< blob version written: 2 (bricks, default) or 1 (dense)
  std::string method = "erosion";
  int threads = 0;  ///< 0: all cores
  bool quiet = false;
  bool strict = false;           ///< refuse degenerate samples instead of dropping them (issue 20)
  std::string normals = "keep";  ///< keep | orient | estimate (field::NormalsMode, issue 20)
  std::string denoise = "auto";  ///< auto | off (field::SmoothNoisyPositions, issue 20)
  /// Non-empty: also write the samples the field was built from (model units, x y z nx ny nz).
  std::string points_out;
};
int RunBuild(const BuildArgs& args);

int RunInfo(const std::string& field, bool json);
int RunExport(const std::string& field, const std::string& npy);

struct TraceSynthArgs {
  std::string field;
  std::string kind = "stroke";        ///< stroke | poke | strokes | poke-grid | taps | pass-through | free | excursion
  std::string output;                 ///< .ptb: binary v2, else text v2 (docs/trace-format.md)
  double depth_m = 0.002;             ///< push-in depth below the surface
  double stroke_m = 0.02;             ///< slide length along the surface (stroke); ellipse major axis (strokes)
  double speed_m_s = 0.02;            ///< peak sliding / travel speed
  double rate_hz = 1000;              ///< samples per second
  unsigned seed = 1;                  ///< picks the touch direction
  std::vector<double> depths;         ///< strokes: one lap per depth, m (empty: --depth)
  std::vector<double> speeds;         ///< taps, pass-through: peak speed per tap/attempt, m/s (empty: 0.1..0.5)
  int count = 5;                      ///< poke-grid pokes, taps / attempts (without --speeds), free waypoints
  double tremor_m = 0;                ///< RMS of the added 8–12 Hz tremor, m (0: none)
  std::optional<double> force_n;      ///< force-constant stroking: depth = force / k
  double k_n_per_m = 800;             ///< with --force
  double through_m = 0.005;           ///< pass-through: how far past the far side, m
  std::vector<double> button_window;  ///< [start, end) s with button `button_bit` held (empty: no buttons column)
  int button_bit = 0;                 ///< 0..7 (Falcon grip: 0-3)
};
int RunTraceSynth(const TraceSynthArgs& args);

/// `palpa trace import`: a recorded `t_s,x_m,y_m,z_m` CSV (third-party recordings, any extent)
/// scaled uniformly about its bounding-box centre into the device workspace, as a v2 trace.
struct TraceImportArgs {
  std::string input;             ///< CSV: header line `t_s,x_m,y_m,z_m`, then rows, s and m
  std::string output;            ///< .ptb: binary v2, else text v2
  double scale = 1;              ///< uniform factor applied about the window's bounding-box centre
  std::vector<double> offset_m;  ///< x,y,z added after scaling (default 0,0,0: the box centre at the origin)
  double from_s = 0;             ///< window start, s of the recording
  double duration_s = 0;         ///< window length, s (0: to the end)
  std::string note;              ///< provenance line(s) kept in the trace's comment
};
int RunTraceImport(const TraceImportArgs& args);

// Tools for seeing and scoring a field (issue 5; library: host/mesh, docs/tools.md).
struct SampleArgs {
  std::string mesh;        ///< closed triangle mesh, .off
  std::size_t count = 0;   ///< points to draw
  std::string output;      ///< POINTS.xyz, written atomically
  std::uint64_t seed = 1;  ///< same seed, same points
  bool quiet = false;
  int views = 0;             ///< > 0: a virtual range scan from this many viewpoints (mesh::RangeScan)
  double range_noise = 0.0;  ///< with views: Gaussian range noise, model units
};
int RunSample(const SampleArgs& args);

struct EvalArgs {
  std::string field;                    ///< FIELD.palpa
  std::string mesh;                     ///< truth: closed .off mesh in model units, or
  std::optional<double> sphere_radius;  ///< truth: sphere of this radius (model units) at the model origin
  bool json = false;
  double band_voxels = 3;                 ///< score nodes with |true| ≤ this
  bool band_given = false;                ///< --band on the command line (else 3, or less to fit the field's bands)
  double on_surface_voxels = 1.0 / 1024;  ///< |true| ≤ this: sign not scored (EvalOptions::on_surface_voxels)
  int threads = 0;                        ///< 0: all cores
  std::string candidate_mesh;  ///< score this closed .off mesh (model units) on FIELD's grid instead of FIELD
  std::string far_out;         ///< FAR.xyz: every far wrong-sign node (model units), written atomically
};
int RunEval(const EvalArgs& args);

struct MeshArgs {
  std::string field;   ///< FIELD.palpa
  std::string output;  ///< SURFACE.ply | SURFACE.obj, written atomically
  bool quiet = false;
};
int RunMesh(const MeshArgs& args);

struct SliceArgs {
  std::string field;         ///< FIELD.palpa
  char axis = 'z';           ///< x | y | z: the slice is normal to this axis
  double at_m = 0;           ///< device-frame coordinate of the slice plane, m
  std::string output;        ///< SLICE.png, written atomically
  int pixels_per_voxel = 0;  ///< 0: the panel's longer side becomes at least 600 pixels
  bool quiet = false;
};
int RunSlice(const SliceArgs& args);

// Hardware-in-the-loop replay (issue 10; docs/hil.md): palpa hil run | bless | report.
struct HilArgs {
  std::string mode = "fast";                 ///< fast (lockstep, goldens) | realtime (paced, invariants, latency)
  std::string filter;                        ///< run/report: cases whose name contains any of these (comma-separated)
  std::string device;                        ///< run/report: only cases on this device (sim | virtual-falcon)
  std::vector<std::string> names;            ///< bless: the cases to bless
  bool all = false;                          ///< bless: every case
  std::string cases;                         ///< hil/cases.toml (default: found above the current directory)
  std::string work;                          ///< fields and results (default <repo>/build/hil-work)
  std::string goldens;                       ///< golden directory (default hil/goldens)
  std::string palpad;                        ///< palpad binary (default: next to palpa in the build tree)
  std::vector<std::string> emulator;         ///< prefix for palpad, e.g. qemu-aarch64 -L /
  std::optional<double> k, max_force, rate;  ///< overrides of the cases' settings
  std::string report_dir;                    ///< report: output directory
};
/// `action`: run | bless | report. Exit 0 all pass, 1 a mismatch or a broken invariant, 2 bad input.
int RunHil(const HilArgs& args, const std::string& action);

// Novint Falcon kinematics for bring-up (issue 8; docs/falcon.md): joint angles and encoder
// counts for a grip position (Falcon frame, m), and the grip position for encoder counts.
int RunFalconIk(const std::string& position_xyz);
int RunFalconFk(const std::string& encoders);

// Servo loop latency next to cyclictest's (issue 9; docs/runtime.md): runs palpad paced on the
// simulated device, then cyclictest at the same priority, rate and CPU, and prints both.
struct BenchLatencyArgs {
  double seconds = 10;    ///< each of the two runs
  double rate_hz = 1000;  ///< 1..10000
  int priority = 80;      ///< SCHED_FIFO, 1..99
  int cpu = -1;           ///< pin both to this CPU; -1: not pinned
  std::string palpad;     ///< palpad binary (default: next to palpa, the build tree's, or PATH)
  bool cyclictest = true;
  int rounds = 5;            ///< the two alternate in this many segments of seconds/rounds each
  bool with_viewer = false;  ///< also run each segment with `palpa view --connect` attached (issue 11)
};
/// Exit 0 (the figures are reported, not judged), 1 if palpad could not run.
int RunBenchLatency(const BenchLatencyArgs& args);

// The browser view (issue 11; library: host/view, docs/view.md): the zero iso-surface, a replay
// of a palpad run, or a running palpad through its status channel.
struct ViewArgs {
  std::string field;                    ///< FIELD.palpa
  std::string trace;                    ///< palpad output CSV or a HIL result directory ("" none)
  std::string connect;                  ///< HOST:PORT of palpad --listen ("" none)
  std::string key_file;                 ///< with connect: the key from palpa keygen
  std::string bind = "127.0.0.1:8080";  ///< HOST:PORT to serve on (port 0: any free port)
  std::string assets;                   ///< asset directory override ("" the installed/build-tree one)
};
/// Serves until SIGINT/SIGTERM: exit 0; 2 bad input; 1 cannot listen or no assets.
int RunView(const ViewArgs& args);

// Upload to a running controller (issue 7; docs/upload.md). Exit 0 accepted / answered, 1 the
// controller refused or could not be reached, 2 bad input (endpoint, key file, blob).
int RunKeygen(const std::string& output, bool force);
struct UploadArgs {
  std::string field;         ///< FIELD.palpa, verified locally before it is sent
  std::string to;            ///< HOST:PORT of palpad --listen
  std::string key_file;      ///< shared key, mode 0600
  int timeout_ms = 10000;    ///< per wait for the controller (connect, each send, the answer)
  bool skip_verify = false;  ///< tests only (hidden): send a blob that fails Verify
};
int RunUpload(const UploadArgs& args);
struct StatusArgs {
  std::string to;
  std::string key_file;
  bool json = false;
  int timeout_ms = 2000;
};
int RunStatus(const StatusArgs& args);

}  // namespace palpa::cli
