#include "palpa/hil/run.h"

#include <fcntl.h>
#include <spawn.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <sstream>

#include <fmt/core.h>

#include "palpa/record/run_record.h"
#include "palpa/trace/trace.h"
#include "text.h"

extern char** environ;

namespace palpa::hil {

namespace fs = std::filesystem;
using detail::Join;
using detail::Slurp;

int Spawn(const std::vector<std::string>& argv, const fs::path& out, const fs::path& err, const fs::path& cwd) {
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, 1, out.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_addopen(&fa, 2, err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_addchdir_np(&fa, cwd.c_str());
  std::vector<char*> args;
  for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  pid_t pid = 0;
  const int rc = posix_spawnp(&pid, args[0], &fa, nullptr, args.data(), environ);
  posix_spawn_file_actions_destroy(&fa);
  if (rc != 0) return -1;
  int status = 0;
  while (waitpid(pid, &status, 0) < 0) {
    if (errno != EINTR) return -1;
  }
  if (WIFEXITED(status)) return WEXITSTATUS(status);
  if (WIFSIGNALED(status)) return 128 + WTERMSIG(status);
  return -1;
}

fs::path SelfExe() {
  std::error_code ec;
  auto p = fs::read_symlink("/proc/self/exe", ec);
  return ec ? fs::path() : p;
}

namespace {

// Size and modification time: a rebuilt palpa may build fields differently.
std::string FileStamp(const fs::path& p) {
  struct stat st {};
  if (stat(p.c_str(), &st) != 0) return "missing";
  return fmt::format("{}:{}.{}", st.st_size, st.st_mtim.tv_sec, st.st_mtim.tv_nsec);
}

}  // namespace

std::expected<fs::path, std::string> EnsureField(const Harness& h, const std::string& name) {
  const FieldSpec& spec = h.suite.fields.at(name);
  if (!spec.blob.empty()) return h.suite.root / spec.blob;
  const fs::path dir = h.work / "fields";
  fs::create_directories(dir);
  const fs::path blob = dir / (name + ".palpa");
  const std::string work = h.work.string();
  std::vector<std::vector<std::string>> commands;
  for (const auto& p : spec.prepare) commands.push_back(detail::SplitWords(detail::Replace(p, "{work}", work)));
  auto build = detail::SplitWords(detail::Replace(spec.build, "{work}", work));
  build.insert(build.end(), {"-o", blob.string(), "-q"});
  commands.push_back(build);
  std::string stamp = "palpa " + FileStamp(h.palpa) + "\n";
  for (const auto& c : commands) stamp += Join(c) + "\n";
  const fs::path stamp_path = dir / (name + ".stamp");
  if (fs::exists(blob) && Slurp(stamp_path) == stamp) return blob;
  for (auto c : commands) {
    c.insert(c.begin(), h.palpa.string());
    const int rc = Spawn(c, dir / (name + ".log"), dir / (name + ".err"), h.suite.root);
    if (rc != 0)
      return std::unexpected(
          fmt::format("field {}: `{}` failed (exit {}): {}", name, Join(c), rc, Slurp(dir / (name + ".err"))));
  }
  if (auto w = h.write_text(stamp_path, stamp); !w) return std::unexpected(w.error());
  return blob;
}

std::vector<std::string> PalpadArgv(const Harness& h, const Case& c, const fs::path& field, const fs::path& out,
                                    const fs::path& summary, bool fast) {
  std::vector<std::string> argv = h.emulator;
  argv.push_back(h.palpad.string());
  const std::vector<std::string> rest = {"--device",
                                         c.device,
                                         "--field",
                                         field.string(),
                                         "--trace",
                                         (h.suite.hil_dir / c.trace).string(),
                                         "--out",
                                         out.string(),
                                         "--summary-json",
                                         summary.string(),
                                         "--rate",
                                         fmt::format("{}", h.settings.rate_hz),
                                         "--k",
                                         fmt::format("{}", h.settings.k_n_per_m),
                                         "--max-force",
                                         fmt::format("{}", h.settings.max_force_n)};
  argv.insert(argv.end(), rest.begin(), rest.end());
  if (fast) argv.push_back("--fast");
  // Per-tick timing (and, paced, the HIP recording) leave palpad through its telemetry ring.
  argv.insert(argv.end(), {"--record-timing", (out.parent_path() / "timing.csv").string()});
  if (!fast) argv.insert(argv.end(), {"--record", (out.parent_path() / "recorded.ptb").string()});
  argv.insert(argv.end(), c.palpad.begin(), c.palpad.end());
  return argv;
}

namespace {

// WORK/results/MODE/NAME, emptied of a previous run's outputs.
fs::path ResultDir(const Harness& h, const Case& c, bool fast) {
  const fs::path dir = h.work / "results" / (fast ? "fast" : "realtime") / c.name;
  fs::create_directories(dir);
  for (const char* f : {"out.csv", "summary.json", "timing.csv", "recorded.ptb"}) fs::remove(dir / f);
  return dir;
}

}  // namespace

std::expected<Replay, std::string> RunReplay(const Harness& h, const Case& c, const fs::path& field, bool fast) {
  Replay r;
  r.dir = ResultDir(h, c, fast);
  const auto argv = PalpadArgv(h, c, field, r.dir / "out.csv", r.dir / "summary.json", fast);
  if (auto w = h.write_text(r.dir / "command.txt", Join(argv) + "\n"); !w) return std::unexpected(w.error());
  const auto t0 = std::chrono::steady_clock::now();
  r.exit_code = Spawn(argv, r.dir / "stdout.txt", r.dir / "stderr.txt", h.suite.root);
  r.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (r.exit_code < 0) return std::unexpected("cannot start " + argv.front());
  r.csv = Slurp(r.dir / "out.csv");
  r.summary_json = Slurp(r.dir / "summary.json");
  r.stderr_text = Slurp(r.dir / "stderr.txt");
  // The Falcon driver's end-of-run counters run on the virtual Falcon's simulated clock: part of
  // the deterministic output.
  std::istringstream lines(r.stderr_text);
  for (std::string line; std::getline(lines, line);)
    if (line.starts_with("palpad: falcon:") || line.starts_with("palpad: virtual falcon:") ||
        line.find("Falcon") != std::string::npos)
      r.device_report += line + "\n";
  auto ticks = ParseOutput(r.csv, (r.dir / "out.csv").string());
  if (!ticks) return std::unexpected(ticks.error());
  r.ticks = std::move(*ticks);
  return r;
}

std::expected<Replay, std::string> ReadOutput(const Harness& h, const Case& c, bool fast) {
  Replay r;
  r.dir = ResultDir(h, c, fast);
  const fs::path path = h.suite.hil_dir / c.output;
  if (!fs::is_regular_file(path)) return std::unexpected(path.string() + ": no such output file");
  r.csv = Slurp(path);
  r.exit_code = c.expect_exit;
  auto ticks = ParseOutput(r.csv, path.string());
  if (!ticks) return std::unexpected(ticks.error());
  r.ticks = std::move(*ticks);
  return r;
}

std::expected<CaseResult, std::string> ReplayCase(const Harness& h, const Case& c, bool fast, FieldProbes& probes) {
  auto field = EnsureField(h, c.field);
  if (!field) return std::unexpected(field.error());
  const fs::path trace_path = h.suite.hil_dir / c.trace;
  if (auto tr = trace::ReadTraceFile(trace_path.string()); !tr)
    return std::unexpected(fmt::format("case {}: {}", c.name, tr.error().message));
  // A swap case replays with --swap-at TICK:PATH; the goldens keep the case's own arguments
  // (the path depends on the work directory).
  Case with_swap = c;
  fs::path swap_path;
  if (!c.swap_field.empty()) {
    auto swap = EnsureField(h, c.swap_field);
    if (!swap) return std::unexpected(swap.error());
    swap_path = *swap;
    with_swap.palpad.insert(with_swap.palpad.end(), {"--swap-at", fmt::format("{}:{}", c.swap_at, swap->string())});
  }
  auto replay = c.output.empty() ? RunReplay(h, with_swap, *field, fast) : ReadOutput(h, c, fast);
  if (!replay) return std::unexpected(fmt::format("case {}: {}", c.name, replay.error()));
  CaseResult res;
  res.replay = std::move(*replay);
  auto first = probes.Get(c.field, *field);
  if (!first) return std::unexpected(first.error());
  res.field = *first;
  const PhiField* swapped = nullptr;
  if (!c.swap_field.empty()) {
    auto s = probes.Get(c.swap_field, swap_path);
    if (!s) return std::unexpected(s.error());
    swapped = *s;
  }
  // Timing and telemetry flags from palpad --record-timing (both modes).
  const auto timing = ReadTiming(res.replay.dir / "timing.csv");
  auto& ticks = res.replay.ticks;
  for (std::size_t i = 0; i < timing.size() && i < ticks.size(); ++i)
    ticks[i].flags = static_cast<std::uint8_t>(timing[i].flags & record::kDeterministicFlags);
  res.metrics = Measure(ticks, c, *res.field, swapped, h.settings.k_n_per_m, h.settings.max_force_n, h.suite.limits);
  res.estop_ticks = CheckRun(res.replay, timing, c, res.metrics);
  res.latency = Latency::Of(timing);
  // --record (paced runs): the recording must read and hold the HIP the loop saw, tick by tick.
  if (!fast) res.recorded_note = CheckRecording(res.replay, res.replay.dir / "recorded.ptb", res.metrics);
  res.known = SetAsideKnown(c, res.metrics);
  return res;
}

}  // namespace palpa::hil
