// Running a case: the fields built with `palpa build` (reused while the command lines and the
// palpa binary are unchanged), palpad spawned on the trace with its outputs in
// WORK/results/MODE/NAME/, then the replay measured (invariants.h). Both modes: fast (lockstep,
// `palpad --fast`, compared with the goldens by the caller) and realtime (paced on the wall clock,
// with --record). Non-RT host code; POSIX processes.
#pragma once

#include <cstddef>
#include <expected>
#include <filesystem>
#include <functional>
#include <string>
#include <string_view>
#include <vector>

#include "palpa/hil/field_probe.h"
#include "palpa/hil/invariants.h"
#include "palpa/hil/replay.h"
#include "palpa/hil/suite.h"
#include "palpa/hil/timing.h"

namespace palpa::hil {

/// Writes a whole text file (the host tool's atomic writer). Error: a sentence naming the path.
using TextWriter = std::function<std::expected<void, std::string>(const std::filesystem::path&, std::string_view)>;

/// What every replay of one `palpa hil` command shares. Paths absolute.
struct Harness {
  Suite suite;
  std::filesystem::path palpa;        ///< the palpa binary: builds the fields, stamps them
  std::filesystem::path palpad;       ///< the palpad binary replayed
  std::vector<std::string> emulator;  ///< prefix for palpad, e.g. {"qemu-aarch64", "-L", "/"}
  std::filesystem::path work;         ///< fields/ and results/ (docs/hil.md § Layout)
  std::filesystem::path goldens;      ///< NAME.toml, NAME.ticks.gz
  Settings settings;                  ///< the suite's, with the command's overrides
  TextWriter write_text;              ///< for the field stamps and command.txt
};

/// Runs argv (argv[0] looked up on PATH) in `cwd` with stdout and stderr to files; waits. Returns
/// the exit status, 128 + signal if killed, −1 if it could not be started.
int Spawn(const std::vector<std::string>& argv, const std::filesystem::path& out, const std::filesystem::path& err,
          const std::filesystem::path& cwd);

/// This process's binary (/proc/self/exe); empty if unknown.
[[nodiscard]] std::filesystem::path SelfExe();

/// The blob of field `name`: a committed blob's path, or WORK/fields/NAME.palpa built by running
/// the field's prepare and build command lines through h.palpa in the suite's root — unless
/// NAME.stamp shows the same command lines and the same palpa binary (size and mtime). Error:
/// "field NAME: `COMMAND` failed (exit N): its stderr", or the stamp's write error.
[[nodiscard]] std::expected<std::filesystem::path, std::string> EnsureField(const Harness& h, const std::string& name);

/// palpad's command line for case `c` on `field`: the emulator prefix, device, field, trace,
/// outputs (out.csv and summary beside timing.csv; recorded.ptb when paced), settings, --fast,
/// then the case's own arguments.
[[nodiscard]] std::vector<std::string> PalpadArgv(const Harness& h, const Case& c, const std::filesystem::path& field,
                                                  const std::filesystem::path& out,
                                                  const std::filesystem::path& summary, bool fast);

/// Replays case `c` on `field` into WORK/results/MODE/NAME/ (its old outputs removed first;
/// command.txt holds the command line). Error: the command line could not be written or run, or
/// out.csv does not parse ("PATH:LINE: why").
[[nodiscard]] std::expected<Replay, std::string> RunReplay(const Harness& h, const Case& c,
                                                           const std::filesystem::path& field, bool fast);

/// A case's `output` (relative to the case list) read as if replayed, with the exit code the case
/// expects. Error: "PATH: no such output file" or its parse error.
[[nodiscard]] std::expected<Replay, std::string> ReadOutput(const Harness& h, const Case& c, bool fast);

/// One case replayed (or its `output` read) and measured.
struct CaseResult {
  Replay replay;    ///< ticks with their flags from the timing record
  Metrics metrics;  ///< failures: all the checks of invariants.h, the known ones set aside
  KnownFailures known;
  Latency latency;  ///< from palpad's timing record
  std::size_t estop_ticks = 0;
  std::string recorded_note;        ///< paced: how much of the HIP the recording kept
  const PhiField* field = nullptr;  ///< the field the replay starts on (in the FieldProbes given)
};

/// Everything `palpa hil` does for a case short of the golden: fields ensured, the trace read,
/// the replay run, the fields loaded through `probes`, the timing record's flags applied, Measure,
/// CheckRun, CheckRecording (paced), SetAsideKnown. Error: bad input, a sentence naming the field
/// or the case and the file ("case NAME: ..."): the command stops there.
[[nodiscard]] std::expected<CaseResult, std::string> ReplayCase(const Harness& h, const Case& c, bool fast,
                                                                FieldProbes& probes);

}  // namespace palpa::hil
