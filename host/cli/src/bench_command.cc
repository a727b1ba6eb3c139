// palpa bench latency (issue 9, docs/runtime.md): the servo loop's wake-up latency next to
// cyclictest's, measured in one run, at the same SCHED_FIFO priority, rate and CPU.
//
// Why palpa runs palpad rather than linking the loop: the figure people need is that of the
// binary that runs on the board — palpad's own real-time set-up, its telemetry drain and watchdog
// threads included. palpad writes its wake-up histogram in cyclictest's histogram file layout
// (--latency-histogram), so one parser and one percentile definition (palpa/record/latency_histogram.h)
// read both sides. On a board, where palpa is not installed, the same two commands can be run by hand.
//
// The load: a sphere field (R = 10 mm, 0.5 mm voxels, built here) and a HIP that presses 1 mm in
// and slides around it, so most ticks are contact ticks with a full proxy update.

#include <fmt/core.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <numbers>
#include <sstream>
#include <string>
#include <vector>

#include "commands.h"
#include "palpa/blob/blob.h"
#include "palpa/record/latency_histogram.h"
#include "palpa/trace/trace.h"

namespace palpa::cli {
namespace {

constexpr int kHistogramUs = 20000;  // bins tracked by both tools (palpad's WakeLatencyHistogram range)

std::string Trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t");
  const auto e = s.find_last_not_of(" \t\r");
  return b == std::string::npos ? "" : s.substr(b, e - b + 1);
}

// Starts argv with stdout and stderr to files; the child's pid, or -1.
pid_t SpawnProcess(const std::vector<std::string>& argv, const std::string& out_path, const std::string& err_path) {
  std::fflush(nullptr);
  const pid_t pid = fork();
  if (pid == 0) {
    if (!std::freopen(out_path.c_str(), "w", stdout) || !std::freopen(err_path.c_str(), "w", stderr)) _exit(127);
    std::vector<char*> args;
    for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
    args.push_back(nullptr);
    execvp(args[0], args.data());
    std::fprintf(stderr, "cannot run %s: %s\n", args[0], std::strerror(errno));
    _exit(127);
  }
  return pid;
}

// Waits for a spawned child: its exit code, 128 + signal, or 127 if it never started.
int WaitProcess(pid_t pid) {
  if (pid < 0) return 127;
  int status = 0;
  while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + (WIFSIGNALED(status) ? WTERMSIG(status) : 0);
}

// Runs argv with stdout and stderr to files; the exit code, or 127 if it could not be started.
int RunProcess(const std::vector<std::string>& argv, const std::string& out_path, const std::string& err_path) {
  return WaitProcess(SpawnProcess(argv, out_path, err_path));
}

std::string ReadText(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// --with-viewer (issue 11): one palpad segment with `palpa view --connect` polling its status
// channel (~40 Hz) from palpad's first listening moment to its end.
struct ViewerSegment {
  std::string error;  // empty: ran
  std::uint64_t polls = 0, failed = 0;
  double seconds = 0;
  std::string last_failure;  // the viewer's last failed poll, if any
};
ViewerSegment RunWithViewer(const std::vector<std::string>& pa, const std::string& self, const std::string& field,
                            const std::string& key, const std::string& dir) {
  ViewerSegment seg;
  const std::string perr = dir + "/palpad-viewer.err", verr = dir + "/viewer.err";
  std::remove(perr.c_str());  // else the previous round's port could be read before the child truncates it
  const pid_t pd = SpawnProcess(pa, dir + "/palpad-viewer.out", perr);
  std::string endpoint;
  for (int i = 0; i < 400 && endpoint.empty(); ++i) {  // palpad prints its port at start-up
    const std::string err = ReadText(perr);
    if (const auto at = err.find("listening on "); at != std::string::npos) {
      const auto end = err.find_first_of(" \n", at + 13);
      endpoint = err.substr(at + 13, end == std::string::npos ? std::string::npos : end - at - 13);
    } else {
      usleep(5000);
    }
  }
  if (endpoint.empty()) {
    kill(pd, SIGTERM);
    WaitProcess(pd);
    seg.error = "palpad --listen did not report its port: " + Trim(ReadText(perr));
    return seg;
  }
  const pid_t view =
      SpawnProcess({self, "view", field, "--connect", endpoint, "--key-file", key, "--bind", "127.0.0.1:0"},
                   dir + "/viewer.out", verr);
  const int pc = WaitProcess(pd);
  kill(view, SIGTERM);
  const int vc = WaitProcess(view);
  const std::string vtext = ReadText(verr);
  const auto at = vtext.find("live: ");
  if (pc != 0) {
    seg.error = fmt::format("palpad failed (exit {}): {}", pc, Trim(ReadText(perr)));
  } else if (vc != 0 || at == std::string::npos ||
             std::sscanf(vtext.c_str() + at, "live: %lu status polls (%lu failed) in %lf s", &seg.polls, &seg.failed,
                         &seg.seconds) != 3) {
    seg.error = fmt::format("palpa view --connect failed (exit {}): {}", vc, Trim(vtext));
  }
  if (const auto f = vtext.find("last failure: "); f != std::string::npos)
    seg.last_failure = Trim(vtext.substr(f + 14, vtext.find('\n', f) - f - 14));
  return seg;
}

bool IsExecutable(const std::string& path) { return access(path.c_str(), X_OK) == 0; }

// palpad next to this palpa (installed: /usr/bin), in the build tree (build/X/host/cli/palpa →
// build/X/firmware/palpad), else on PATH.
std::string FindPalpad() {
  char self[4096];
  const ssize_t n = readlink("/proc/self/exe", self, sizeof self - 1);
  if (n > 0) {
    self[n] = '\0';
    std::string dir(self);
    dir = dir.substr(0, dir.rfind('/'));
    for (const std::string& candidate : {dir + "/palpad", dir + "/../../firmware/palpad"})
      if (IsExecutable(candidate)) return candidate;
  }
  return "palpad";
}

// A sphere of radius 10 mm (20 voxels of 0.5 mm) on a 64³ grid, φ clamped to the 6-voxel band.
std::vector<std::byte> SphereBlob(std::array<double, 3>& center_m) {
  constexpr int kN = 64;
  constexpr double kVoxel = 0.5e-3, kRadiusVox = 20, kBand = 6;
  const std::array<double, 3> c_vox = {32.3, 31.6, 32.1};
  blob::BlobMeta meta;
  meta.dims = {kN, kN, kN};
  meta.origin_m = {-0.016, -0.016, -0.016};
  meta.voxel_m = kVoxel;
  meta.band_voxels = static_cast<std::uint32_t>(kBand);
  meta.point_count = 1;
  std::vector<std::int32_t> phi(static_cast<std::size_t>(kN) * kN * kN);
  std::size_t idx = 0;
  for (int i = 0; i < kN; ++i)
    for (int j = 0; j < kN; ++j)
      for (int k = 0; k < kN; ++k) {
        const double dx = i - c_vox[0], dy = j - c_vox[1], dz = k - c_vox[2];
        const double d = std::clamp(std::sqrt(dx * dx + dy * dy + dz * dz) - kRadiusVox, -kBand, kBand);
        phi[idx++] = static_cast<std::int32_t>(std::lround(d * 65536.0));
      }
  for (std::size_t a = 0; a < 3; ++a) center_m[a] = meta.origin_m[a] + c_vox[a] * kVoxel;
  return blob::Encode(meta, phi);
}

// 0.2 s pressing from 3 mm outside to 1 mm inside, then sliding around the equator every 2 s.
std::vector<trace::TraceSample> SlideTrace(const std::array<double, 3>& c, double seconds) {
  constexpr double kR = 10e-3, kDt = 0.005;
  std::vector<trace::TraceSample> out;
  for (double t = 0; t <= seconds + 1e-9; t += kDt) {
    const double r = t < 0.2 ? kR + 3e-3 - 4e-3 * (t / 0.2) : kR - 1e-3;
    const double a = t < 0.2 ? 0.0 : 2 * std::numbers::pi * (t - 0.2) / 2.0;
    out.push_back({t, {c[0] + r * std::cos(a), c[1] + r * std::sin(a), c[2]}, 0});
  }
  return out;
}

// Display buckets, µs: fine where the mass is, coarse in the tail.
constexpr std::array<int, 17> kEdgesUs = {0,   10,  20,  30,   40,   50,   75,    100,         150,
                                          200, 300, 500, 1000, 2000, 5000, 10000, kHistogramUs};

using record::LatencyHistogram;

std::uint64_t CountIn(const LatencyHistogram& h, int lo, int hi) {
  std::uint64_t n = 0;
  for (int i = lo; i < hi && i < static_cast<int>(h.bins.size()); ++i) n += h.bins[static_cast<std::size_t>(i)];
  return n;
}

void PrintRow(const char* name, const LatencyHistogram& h) {
  fmt::print("  {:<22}{:>9}{:>8}{:>8}{:>8}{:>8}{:>9}{:>11}\n", name, h.count, h.MinNs() / 1000,
             h.PercentileNs(0.5) / 1000, h.PercentileNs(0.99) / 1000, h.PercentileNs(0.999) / 1000, h.max_ns / 1000,
             h.overflow);
}

}  // namespace

int RunBenchLatency(const BenchLatencyArgs& args) {
  char dir_template[] = "/tmp/palpa-bench-XXXXXX";
  if (mkdtemp(dir_template) == nullptr) {
    fmt::print(stderr, "palpa bench latency: cannot create a temporary directory: {}\n", std::strerror(errno));
    return kExitIo;
  }
  const std::string dir = dir_template;
  const auto path = [&](const char* name) { return dir + "/" + name; };
  struct Cleanup {
    std::string dir;
    ~Cleanup() {
      for (const char* f : {"field.palpa", "trace.csv", "palpad.hist", "palpad.out", "palpad.err", "cyclictest.hist",
                            "cyclictest.out", "cyclictest.err", "status.key", "palpad-viewer.hist", "palpad-viewer.out",
                            "palpad-viewer.err", "viewer.out", "viewer.err"})
        std::remove((dir + "/" + f).c_str());
      rmdir(dir.c_str());
    }
  } cleanup{dir};

  // The two tools alternate in `rounds` segments, so that a load change on a shared machine falls
  // on both alike rather than on whichever ran second.
  const int rounds = std::max(1, args.rounds);
  const double segment_s = args.seconds / rounds;
  std::array<double, 3> center{};
  {
    const std::vector<std::byte> blob = SphereBlob(center);
    std::ofstream f(path("field.palpa"), std::ios::binary);
    f.write(reinterpret_cast<const char*>(blob.data()), static_cast<std::streamsize>(blob.size()));
    std::ofstream(path("trace.csv")) << trace::FormatTrace(SlideTrace(center, segment_s), "palpa bench latency");
  }
  const std::string palpad = args.palpad.empty() ? FindPalpad() : args.palpad;
  const std::string cpu = args.cpu >= 0 ? std::to_string(args.cpu) : "";
  fmt::print(
      "palpa bench latency: {} s each at {} Hz in {} alternating rounds, SCHED_FIFO priority {}, {}; simulated "
      "device (sphere, 1 mm deep slide)\n",
      args.seconds, args.rate_hz, rounds, args.priority, cpu.empty() ? "CPU not pinned" : "CPU " + cpu);

  // palpad: no overrun fault (the bench counts overruns instead of stopping).
  std::vector<std::string> pa = {palpad,
                                 "--device",
                                 "sim",
                                 "--field",
                                 path("field.palpa"),
                                 "--trace",
                                 path("trace.csv"),
                                 "--out",
                                 "/dev/null",
                                 "--rate",
                                 fmt::format("{}", args.rate_hz),
                                 "--priority",
                                 std::to_string(args.priority),
                                 "--overrun-limit",
                                 "0",
                                 "--latency-histogram",
                                 path("palpad.hist")};
  if (!cpu.empty()) pa.insert(pa.end(), {"--cpu", cpu});
  // --with-viewer: palpad listens in every segment, so the two rows differ only by the viewer.
  std::vector<std::string> pa_viewer;
  std::string self;
  if (args.with_viewer) {
    char exe[4096];
    const ssize_t n = readlink("/proc/self/exe", exe, sizeof exe - 1);
    self = n > 0 ? std::string(exe, static_cast<std::size_t>(n)) : "palpa";
    if (const int kc = RunProcess({self, "keygen", "-o", path("status.key")}, path("viewer.out"), path("viewer.err"));
        kc != 0) {
      fmt::print(stderr, "palpa bench latency: palpa keygen failed (exit {}): {}\n", kc, ReadText(path("viewer.err")));
      return kExitIo;
    }
    pa.insert(pa.end(), {"--listen", "127.0.0.1:0", "--key-file", path("status.key")});
    pa_viewer = pa;
    std::replace(pa_viewer.begin(), pa_viewer.end(), path("palpad.hist"), path("palpad-viewer.hist"));
  }
  // cyclictest: the same priority, interval, CPU and sample count, its histogram in the same layout.
  const auto interval_us = static_cast<long>(std::lround(1e6 / args.rate_hz));
  const auto loops = static_cast<long>(std::llround(segment_s * args.rate_hz));
  std::vector<std::string> ca = {"cyclictest",
                                 "-m",
                                 "-q",
                                 "-p",
                                 std::to_string(args.priority),
                                 "-i",
                                 std::to_string(interval_us),
                                 "-l",
                                 std::to_string(loops),
                                 "-h",
                                 std::to_string(kHistogramUs),
                                 "--histfile=" + path("cyclictest.hist")};
  if (!cpu.empty()) ca.insert(ca.end(), {"-a", cpu});

  LatencyHistogram loop, anchor, viewed;  // viewed: palpad with palpa view --connect attached
  long long viewed_overruns = 0;
  std::uint64_t viewer_polls = 0, viewer_failed = 0;
  double viewer_seconds = 0;
  std::string viewer_failure;
  bool have_anchor = args.cyclictest;
  std::string anchor_note = args.cyclictest ? "" : "cyclictest not run (--no-cyclictest)";
  std::string palpad_err;
  std::array<long long, 4> compute{};  // worst round's p50, p99, p99.9, max (ns)
  long long overruns = 0, longest = 0, dropped = 0;
  for (int r = 0; r < rounds; ++r) {
    const int pc = RunProcess(pa, path("palpad.out"), path("palpad.err"));
    const std::string err = ReadText(path("palpad.err"));
    if (pc != 0) {
      fmt::print(stderr, "palpa bench latency: {} failed (exit {}):\n{}", palpad, pc, err);
      return kExitIo;
    }
    if (r == 0) palpad_err = err;
    const auto h = record::ReadLatencyHistogram(path("palpad.hist"));
    if (!h) {
      fmt::print(stderr, "palpa bench latency: {}\n", h.error());
      return kExitIo;
    }
    if (r == 0) loop.palpad = h->palpad;
    loop.Merge(*h);
    std::istringstream ss(h->Palpad("compute_ns"));
    for (long long& c : compute) {
      long long v = 0;
      ss >> v;
      c = std::max(c, v);
    }
    overruns += std::atoll(h->Palpad("overruns").c_str());
    longest = std::max(longest, std::atoll(h->Palpad("max_consecutive_overruns").c_str()));
    dropped += std::atoll(h->Palpad("dropped_rows").c_str());

    if (args.with_viewer) {
      const ViewerSegment seg = RunWithViewer(pa_viewer, self, path("field.palpa"), path("status.key"), dir);
      if (!seg.error.empty()) {
        fmt::print(stderr, "palpa bench latency --with-viewer: {}\n", seg.error);
        return kExitIo;
      }
      const auto hv = record::ReadLatencyHistogram(path("palpad-viewer.hist"));
      if (!hv) {
        fmt::print(stderr, "palpa bench latency: {}\n", hv.error());
        return kExitIo;
      }
      viewed.Merge(*hv);
      viewed_overruns += std::atoll(hv->Palpad("overruns").c_str());
      viewer_polls += seg.polls;
      viewer_failed += seg.failed;
      viewer_seconds += seg.seconds;
      if (!seg.last_failure.empty()) viewer_failure = seg.last_failure;
    }

    if (!have_anchor) continue;
    const int cc = RunProcess(ca, path("cyclictest.out"), path("cyclictest.err"));
    if (cc == 127) {
      anchor_note = "cyclictest not found (Debian: apt-get install rt-tests): no anchor";
      have_anchor = false;
    } else if (cc != 0) {
      anchor_note = fmt::format("cyclictest failed (exit {}): {}", cc, Trim(ReadText(path("cyclictest.err"))));
      have_anchor = false;
    } else if (const auto c = record::ReadLatencyHistogram(path("cyclictest.hist"))) {
      anchor.Merge(*c);
    } else {
      anchor_note = c.error();
      have_anchor = false;
    }
  }

  const std::string realtime = loop.Palpad("realtime");
  fmt::print("real-time set-up (palpad): {}{}\n", realtime,
             realtime == "yes" ? "" : " (refused: " + loop.Palpad("rt_refused") + ")");
  if (!palpad_err.empty()) fmt::print("palpad said:\n{}", palpad_err);
  fmt::print("\nwake-up latency, us (nearest rank; 1 us bins, truncated, as cyclictest):\n");
  fmt::print("  {:<22}{:>9}{:>8}{:>8}{:>8}{:>8}{:>9}{:>11}\n", "", "samples", "min", "p50", "p99", "p99.9", "max",
             "overflows");
  PrintRow(args.with_viewer ? "palpad, no viewer" : "palpad servo loop", loop);
  if (args.with_viewer) PrintRow("palpad + palpa view", viewed);
  if (have_anchor) {
    PrintRow("cyclictest (anchor)", anchor);
    const std::int64_t a99 = anchor.PercentileNs(0.99) / 1000, l99 = loop.PercentileNs(0.99) / 1000;
    if (a99 > 0) {
      fmt::print("  p99 ratio loop / cyclictest: {:.2f} (goal <= 1.5)\n",
                 static_cast<double>(l99) / static_cast<double>(a99));
    } else {
      fmt::print("  p99 ratio loop / cyclictest: cyclictest p99 is 0 us\n");
    }
    if (1e6 / static_cast<double>(interval_us) != args.rate_hz)
      fmt::print("  (cyclictest's interval is whole microseconds: {} us = {:.3f} Hz)\n", interval_us,
                 1e6 / static_cast<double>(interval_us));
  } else {
    fmt::print("  {}\n", anchor_note);
  }
  fmt::print(
      "\npalpad compute time per tick, us (worst of {} rounds): p50 {:.1f}, p99 {:.1f}, p99.9 {:.1f}, max {:.1f}\n",
      rounds, static_cast<double>(compute[0]) / 1e3, static_cast<double>(compute[1]) / 1e3,
      static_cast<double>(compute[2]) / 1e3, static_cast<double>(compute[3]) / 1e3);
  fmt::print("palpad overruns: {} (longest run {}), telemetry samples dropped: {}\n", overruns, longest, dropped);
  if (args.with_viewer) {
    fmt::print(
        "viewer: palpa view --connect made {} status requests ({} failed) in {:.1f} s, {:.1f} per second; palpad "
        "--listen in both rows; overruns with the viewer: {}\n",
        viewer_polls, viewer_failed, viewer_seconds, static_cast<double>(viewer_polls) / std::max(viewer_seconds, 1e-9),
        viewed_overruns);
    if (!viewer_failure.empty())
      fmt::print("  the viewer's last failed status request (one as palpad exits is expected): {}\n", viewer_failure);
    const auto p = [](const LatencyHistogram& h, double q) { return static_cast<double>(h.PercentileNs(q) / 1000); };
    fmt::print("  with / without viewer: p50 {:.2f}, p99 {:.2f}, max {:.2f}\n",
               p(viewed, 0.5) / std::max(p(loop, 0.5), 1.0), p(viewed, 0.99) / std::max(p(loop, 0.99), 1.0),
               static_cast<double>(viewed.max_ns) / std::max(static_cast<double>(loop.max_ns), 1.0));
  }

  fmt::print("\nhistogram, wake-up latency (count per bucket):\n  {:>15}{:>12}{:>12}\n", "us", "palpad",
             have_anchor ? "cyclictest" : "");
  for (std::size_t b = 0; b + 1 < kEdgesUs.size(); ++b) {
    const std::uint64_t l = CountIn(loop, kEdgesUs[b], kEdgesUs[b + 1]);
    const std::uint64_t a = have_anchor ? CountIn(anchor, kEdgesUs[b], kEdgesUs[b + 1]) : 0;
    if (l == 0 && a == 0) continue;
    fmt::print("  {:>15}{:>12}{:>12}\n", fmt::format("{}..{}", kEdgesUs[b], kEdgesUs[b + 1] - 1), l,
               have_anchor ? std::to_string(a) : "");
  }
  if (loop.overflow != 0 || (have_anchor && anchor.overflow != 0))
    fmt::print("  {:>15}{:>12}{:>12}\n", fmt::format(">= {}", kHistogramUs), loop.overflow,
               have_anchor ? std::to_string(anchor.overflow) : "");
  return kExitOk;
}

}  // namespace palpa::cli
