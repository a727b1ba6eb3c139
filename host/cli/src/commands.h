// Subcommands of the `palpa` host tool. Each returns the process exit code:
// 0 success, 2 bad input or arguments (message on stderr naming file, line or byte), 1 I/O failure.
#pragma once

#include <array>
#include <optional>
#include <string>

namespace palpa::cli {

inline constexpr int kExitOk = 0;
inline constexpr int kExitIo = 1;
inline constexpr int kExitBadInput = 2;

struct BuildArgs {
  std::string points;                ///< .xyz / .pwn
  std::string output;                ///< FIELD.palpa
  double fit_m = 0.06;               ///< longest bbox side → this many metres, centred at origin
  std::optional<double> scale;       ///< instead of fit: device = scale·model + offset
  std::array<double, 3> offset_m{};  ///< with scale
  int cells = 300;                   ///< nodes along the longest axis
  double voxel_m = 0;                ///< > 0: node spacing instead of cells
  int band_voxels = 6;               ///< narrow band half-width
  std::string method = "erosion";
  int threads = 0;  ///< 0: all cores
  bool quiet = false;
};
int RunBuild(const BuildArgs& args);

int RunInfo(const std::string& field, bool json);
int RunExport(const std::string& field, const std::string& npy);

struct TraceSynthArgs {
  std::string field;
  std::string kind = "stroke";  ///< stroke | poke
  std::string output;
  double depth_m = 0.002;   ///< push-in depth below the surface
  double stroke_m = 0.02;   ///< slide length along the surface (stroke)
  double speed_m_s = 0.02;  ///< peak sliding speed
  double rate_hz = 1000;    ///< samples per second
  unsigned seed = 1;        ///< picks the touch direction
};
int RunTraceSynth(const TraceSynthArgs& args);

}  // namespace palpa::cli
