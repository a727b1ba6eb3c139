// palpa as a user runs it: exit codes, messages, no partial outputs, and outputs checked against
// independent truths (the blob's own bytes for export, the analytic sphere for trace synth).
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <numbers>
#include <random>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include "palpa/blob/blob.h"
#include "palpa/trace/trace.h"
#include "process.h"

namespace {

namespace fs = std::filesystem;

using palpa::test_support::Outcome;

Outcome Palpa(const std::string& args) { return palpa::test_support::Run(std::string(PALPA_BIN) + " " + args); }

using Cli = palpa::test_support::TempDirTest;

// The whole file at `path`, bytes as stored ("" when it cannot be read).
std::string ReadBytes(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), {});
}

// Shortest text that reads back as the same double.
std::string fmt(double x) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.17g", x);
  return buf;
}

constexpr const char* kFourPoints = "0 0 0 0 0 -1\n1 0 0 1 0 0\n0 1 0 0 1 0\n0 0 1 0 0 1\n";

// OpenVDB binds ~69,000 symbols at load (60 ms, 8 % of a kitten build): palpa loads it only for
// the zero iso-surface (palpa_vdb.so), and a command that meshes still finds it and meshes.
TEST_F(Cli, OpenVdbIsLoadedOnlyByTheCommandsThatMesh) {
  const Outcome version = palpa::test_support::Run("LD_DEBUG=files " + std::string(PALPA_BIN) + " --version");
  ASSERT_EQ(version.code, 0) << version.out;
  EXPECT_NE(version.out.find("libc.so"), std::string::npos) << "LD_DEBUG printed nothing: " << version.out;
  EXPECT_EQ(version.out.find("libopenvdb"), std::string::npos) << version.out;
  const std::string points = std::string(PALPA_DATA_DIR) + "/sphere926.pwn";
  ASSERT_EQ(Palpa("build " + points + " --cells 40 -o " + Path("s.palpa") + " -q").code, 0);
  const Outcome mesh = palpa::test_support::Run("LD_DEBUG=files " + std::string(PALPA_BIN) + " mesh " +
                                                Path("s.palpa") + " -o " + Path("s.ply"));
  EXPECT_EQ(mesh.code, 0) << mesh.out;
  EXPECT_NE(mesh.out.find("libopenvdb"), std::string::npos) << mesh.out;
  EXPECT_NE(mesh.out.find("closed"), std::string::npos) << mesh.out;
  EXPECT_TRUE(fs::exists(Path("s.ply")));
}

TEST_F(Cli, BadPointFilesExitTwoAndWriteNothing) {
  struct Case {
    std::string name, text, expect;
  };
  const Case cases[] = {
      {"malformed.xyz", std::string(kFourPoints) + "1 2 3 4\n", "malformed.xyz:5"},
      {"nan.xyz", std::string(kFourPoints) + "nan 0 0 0 0 1\n", "nan.xyz:5"},
      // A zero normal is dropped (issue 20); refused only when fewer than 4 usable samples remain.
      {"zero.xyz", "0 0 0 0 0 -1\n1 0 0 1 0 0\n0 1 0 0 1 0\n0.5 0.5 0.5 0 0 0\n", "zero.xyz:4"},
      {"few.xyz", "0 0 0 0 0 1\n1 0 0 1 0 0\n0 1 0 0 1 0\n", "few.xyz"},
  };
  for (const Case& c : cases) {
    const std::string in = Write(c.name, c.text);
    const Outcome r = Palpa("build " + in + " -o " + Path("out.palpa") + " --cells 32");
    EXPECT_EQ(r.code, 2) << c.name << ": " << r.out;
    EXPECT_NE(r.out.find(c.expect), std::string::npos) << c.name << ": " << r.out;
    EXPECT_FALSE(fs::exists(Path("out.palpa"))) << c.name;
  }
  const Outcome missing = Palpa("build " + Path("missing.xyz") + " -o " + Path("out.palpa"));
  EXPECT_EQ(missing.code, 2);
  EXPECT_NE(missing.out.find("missing.xyz"), std::string::npos) << missing.out;
  EXPECT_FALSE(fs::exists(Path("out.palpa")));
  // Nothing else (no temporary) is left in the directory.
  for (const auto& e : fs::directory_iterator(dir_)) EXPECT_EQ(e.path().extension(), ".xyz") << e.path();
}

// Issue 20: a real scan with a few zero or non-finite normals and exact duplicates is not refused
// whole: those samples are dropped, counted and the first of each named by its line; the field is
// the one of the file without them (compared through palpa export). --strict refuses the file.
TEST_F(Cli, DegenerateSamplesAreDroppedAndNamed) {
  std::ifstream in(std::string(PALPA_DATA_DIR) + "/sphere926.pwn");
  std::vector<std::string> lines;
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  ASSERT_EQ(lines.size(), 926u);
  std::string clean;
  for (const std::string& l : lines) clean += l + "\n";
  std::string dirty;
  for (std::size_t i = 0; i < lines.size(); ++i) {
    if (i == 100) dirty += "1 2 3 0 0 0\n";    // line 101: zero-length normal
    if (i == 500) dirty += "1 2 4 nan 0 1\n";  // line 502: non-finite normal
    dirty += lines[i] + "\n";
  }
  dirty += lines[7] + "\n";  // line 929: the position of line 8 (an exact duplicate)
  const std::string clean_in = Write("clean.xyz", clean);
  const std::string dirty_in = Write("dirty.xyz", dirty);
  const Outcome a = Palpa("build " + clean_in + " -o " + Path("clean.palpa") + " --cells 48 -q");
  ASSERT_EQ(a.code, 0) << a.out;
  const Outcome b = Palpa("build " + dirty_in + " -o " + Path("dirty.palpa") + " --cells 48 -q");
  ASSERT_EQ(b.code, 0) << b.out;
  EXPECT_NE(b.out.find("dropped 2 samples with a zero-length or non-finite normal (first: " + dirty_in +
                       ":101) and 1 exact duplicate (first: " + dirty_in + ":929, the position of " + dirty_in +
                       ":8); 926 samples remain"),
            std::string::npos)
      << b.out;
  ASSERT_EQ(Palpa("export " + Path("clean.palpa") + " --npy " + Path("clean.npy")).code, 0);
  ASSERT_EQ(Palpa("export " + Path("dirty.palpa") + " --npy " + Path("dirty.npy")).code, 0);
  EXPECT_EQ(ReadBytes(Path("clean.npy")), ReadBytes(Path("dirty.npy")));
  const Outcome info = Palpa("info --json " + Path("dirty.palpa"));
  EXPECT_NE(info.out.find("\"point_count\": 926"), std::string::npos) << info.out;

  const Outcome strict = Palpa("build " + dirty_in + " -o " + Path("strict.palpa") + " --cells 48 --strict");
  EXPECT_EQ(strict.code, 2) << strict.out;
  EXPECT_NE(
      strict.out.find("--strict: 2 samples with a zero-length or non-finite normal (first: " + dirty_in + ":101)"),
      std::string::npos)
      << strict.out;
  EXPECT_FALSE(fs::exists(Path("strict.palpa")));
  // A non-finite position stays an error.
  const std::string nan_pos = Write("nanpos.xyz", clean + "nan 0 0 0 0 1\n");
  const Outcome n = Palpa("build " + nan_pos + " -o " + Path("n.palpa") + " --cells 48");
  EXPECT_EQ(n.code, 2) << n.out;
  EXPECT_NE(n.out.find("nanpos.xyz:927: position is not finite"), std::string::npos) << n.out;
}

// Issue 20: a scanner's bare positions (three numbers a line) are built with estimated, oriented
// normals and the build says so; a file whose normals are all inward is refused nothing but warned
// with the remedy, and --normals orient repairs it: the field equals the outward file's (the sign
// of every normal is recovered exactly, so the samples are the same bit for bit).
TEST_F(Cli, BarePositionsAreEstimatedAndFlippedNormalsAreReoriented) {
  std::ifstream in(std::string(PALPA_DATA_DIR) + "/sphere926.pwn");
  std::string bare, inward, outward;
  for (std::string line; std::getline(in, line);) {
    std::istringstream values(line);
    std::array<double, 6> v{};
    for (double& x : v) values >> x;
    bare += fmt(v[0]) + " " + fmt(v[1]) + " " + fmt(v[2]) + "\n";
    outward += line + "\n";
    inward +=
        fmt(v[0]) + " " + fmt(v[1]) + " " + fmt(v[2]) + " " + fmt(-v[3]) + " " + fmt(-v[4]) + " " + fmt(-v[5]) + "\n";
  }
  const std::string bare_in = Write("bare.xyz", bare);
  const Outcome b = Palpa("build " + bare_in + " -o " + Path("bare.palpa") + " --cells 48");
  ASSERT_EQ(b.code, 0) << b.out;
  EXPECT_NE(b.out.find("926 normals estimated (jet fit, 10 neighbours: the samples are clean) and oriented: 1 piece "
                       "(1 closed, 0 open) (the file has no normals)"),
            std::string::npos)
      << b.out;
  EXPECT_EQ(b.out.find("not consistently oriented"), std::string::npos) << b.out;
  // Every normal 0 0 0 (what tools write where they have none): the same build as bare positions,
  // not a refusal for 926 degenerate normals; --strict still refuses it.
  std::string zeros;
  std::istringstream bare_lines(bare);
  for (std::string line; std::getline(bare_lines, line);) zeros += line + " 0 0 0\n";
  const std::string zeros_in = Write("zeros.xyz", zeros);
  const Outcome z = Palpa("build " + zeros_in + " -o " + Path("zeros.palpa") + " --cells 48");
  ASSERT_EQ(z.code, 0) << z.out;
  EXPECT_NE(z.out.find("926 normals estimated (jet fit, 10 neighbours: the samples are clean) and oriented: 1 piece "
                       "(1 closed, 0 open) (every normal in the file is zero or not finite)"),
            std::string::npos)
      << z.out;
  ASSERT_EQ(Palpa("export " + Path("bare.palpa") + " --npy " + Path("bare.npy")).code, 0);
  ASSERT_EQ(Palpa("export " + Path("zeros.palpa") + " --npy " + Path("zeros.npy")).code, 0);
  EXPECT_EQ(ReadBytes(Path("bare.npy")), ReadBytes(Path("zeros.npy")));
  const Outcome zs = Palpa("build " + zeros_in + " -o " + Path("zeros_strict.palpa") + " --cells 48 --strict");
  EXPECT_EQ(zs.code, 2) << zs.out;
  EXPECT_NE(zs.out.find("--strict: 926 samples with a zero-length or non-finite normal"), std::string::npos) << zs.out;
  EXPECT_FALSE(fs::exists(Path("zeros_strict.palpa")));

  const std::string inward_in = Write("inward.xyz", inward);
  const Outcome keep = Palpa("build " + inward_in + " -o " + Path("keep.palpa") + " --cells 48 -q");
  ASSERT_EQ(keep.code, 0) << keep.out;
  EXPECT_NE(keep.out.find("Rerun with --normals orient"), std::string::npos) << keep.out;
  const Outcome orient = Palpa("build " + inward_in + " -o " + Path("orient.palpa") + " --cells 48 --normals orient");
  ASSERT_EQ(orient.code, 0) << orient.out;
  EXPECT_NE(orient.out.find("normals oriented, 926 signs changed"), std::string::npos) << orient.out;
  const std::string outward_in = Write("outward.xyz", outward);
  ASSERT_EQ(Palpa("build " + outward_in + " -o " + Path("outward.palpa") + " --cells 48 -q").code, 0);
  ASSERT_EQ(Palpa("export " + Path("orient.palpa") + " --npy " + Path("orient.npy")).code, 0);
  ASSERT_EQ(Palpa("export " + Path("outward.palpa") + " --npy " + Path("outward.npy")).code, 0);
  EXPECT_EQ(ReadBytes(Path("orient.npy")), ReadBytes(Path("outward.npy")));
  const Outcome bad = Palpa("build " + outward_in + " -o " + Path("x.palpa") + " --normals guess");
  EXPECT_NE(bad.code, 0);
  EXPECT_FALSE(fs::exists(Path("x.palpa")));
}

// --points-out writes the samples the field was built from: for bare positions, the same
// positions (model units) with the estimated, oriented normals, which on a sphere point away from
// its centre (within 10 degrees: a jet fit of 10 neighbours on 926 samples). It is written only
// when the build succeeds, and never onto the blob's own path.
TEST_F(Cli, PointsOutHoldsTheEstimatedNormalsTheFieldWasBuiltFrom) {
  std::ifstream in(std::string(PALPA_DATA_DIR) + "/sphere926.pwn");
  std::vector<std::array<double, 3>> given;
  std::string bare;
  for (std::string line; std::getline(in, line);) {
    std::istringstream values(line);
    std::array<double, 3> p{};
    for (double& x : p) values >> x;
    given.push_back(p);
    bare += fmt(p[0]) + " " + fmt(p[1]) + " " + fmt(p[2]) + "\n";
  }
  const std::string bare_in = Write("bare.xyz", bare);
  const Outcome b =
      Palpa("build " + bare_in + " -o " + Path("bare.palpa") + " --cells 48 -q --points-out " + Path("built.xyz"));
  ASSERT_EQ(b.code, 0) << b.out;
  std::ifstream written(Path("built.xyz"));
  std::size_t count = 0;
  double worst_position = 0.0, worst_length = 0.0, worst_degrees = 0.0;
  for (std::string line; std::getline(written, line); ++count) {
    std::istringstream values(line);
    std::array<double, 6> v{};
    for (double& x : v) values >> x;
    ASSERT_FALSE(values.fail()) << line;
    ASSERT_LT(count, given.size());
    const std::array<double, 3>& p = given[count];  // the input's order is kept
    const double radius = std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
    double dot = 0.0, length2 = 0.0;
    for (std::size_t a = 0; a < 3; ++a) {
      worst_position = std::max(worst_position, std::abs(v[a] - p[a]) / radius);
      dot += v[3 + a] * p[a] / radius;
      length2 += v[3 + a] * v[3 + a];
    }
    worst_length = std::max(worst_length, std::abs(std::sqrt(length2) - 1.0));
    worst_degrees = std::max(worst_degrees, std::acos(std::clamp(dot, -1.0, 1.0)) * 180.0 / std::numbers::pi);
  }
  EXPECT_EQ(count, given.size());
  EXPECT_LT(worst_position, 1e-6);
  EXPECT_LT(worst_length, 1e-6);
  EXPECT_LT(worst_degrees, 10.0);

  const Outcome same = Palpa("build " + bare_in + " -o " + Path("x.palpa") + " --points-out " + Path("x.palpa"));
  EXPECT_EQ(same.code, 2) << same.out;
  EXPECT_NE(same.out.find("the same path as -o"), std::string::npos) << same.out;
  EXPECT_FALSE(fs::exists(Path("x.palpa")));
  // The same file spelt another way, before either exists.
  const Outcome spelt = Palpa("build " + bare_in + " -o " + Path("x.palpa") + " --points-out " + Path("./x.palpa"));
  EXPECT_EQ(spelt.code, 2) << spelt.out;
  EXPECT_NE(spelt.out.find("the same path as -o"), std::string::npos) << spelt.out;
  EXPECT_FALSE(fs::exists(Path("x.palpa")));
  // ... and through a link to its directory.
  fs::create_directory(Path("dir"));
  fs::create_directory_symlink(Path("dir"), Path("link"));
  const Outcome linked =
      Palpa("build " + bare_in + " -o " + Path("dir/x.palpa") + " --points-out " + Path("link/x.palpa"));
  EXPECT_EQ(linked.code, 2) << linked.out;
  EXPECT_NE(linked.out.find("the same path as -o"), std::string::npos) << linked.out;
  EXPECT_FALSE(fs::exists(Path("dir/x.palpa")));
  const std::string bad = Write("bad.xyz", "1 2 3\n");
  EXPECT_EQ(Palpa("build " + bad + " -o " + Path("y.palpa") + " --points-out " + Path("y.xyz")).code, 2);
  EXPECT_FALSE(fs::exists(Path("y.xyz")));
  EXPECT_FALSE(fs::exists(Path("y.palpa")));
}

// The number right after `key` in `palpa eval --json`'s output (e.g. "\"far_wrong\":"); NaN, which
// fails every comparison, when the key is missing.
double EvalFigure(const Outcome& e, const std::string& key) {
  const auto at = e.out.find(key);
  return at == std::string::npos ? std::numeric_limits<double>::quiet_NaN() : std::stod(e.out.substr(at + key.size()));
}

// `palpa eval --json`'s verdict: no far wrong sign, and mean |error| in the band below `max_mean`
// voxels.
void ExpectNoFarWrongAndMeanBelow(const Outcome& e, double max_mean) {
  ASSERT_EQ(e.code, 0) << e.out;
  EXPECT_EQ(EvalFigure(e, "\"far_wrong\":"), 0.0) << e.out;
  EXPECT_LT(EvalFigure(e, "\"mean_abs_error\":"), max_mean) << e.out;
}

// `palpa sample MESH -n COUNT --seed SEED`, `palpa build` with defaults at 150 cells, then
// `palpa eval --json` of the field against MESH (a bundled mesh's file name); the files are
// STEM.xyz and STEM.palpa. Eval's outcome, or the first step's that failed.
Outcome SampleBuildEval(const std::string& mesh_file, int count, int seed, const std::string& stem) {
  const std::string mesh = std::string(PALPA_DATA_DIR) + "/" + mesh_file;
  const std::string points = stem + ".xyz", field = stem + ".palpa";
  const Outcome s = Palpa("sample " + mesh + " -n " + std::to_string(count) + " --seed " + std::to_string(seed) +
                          " -o " + points + " -q");
  if (s.code != 0) return s;
  const Outcome b = Palpa("build " + points + " -o " + field + " --cells 150 -q");
  if (b.code != 0) return b;
  return Palpa("eval " + field + " --mesh " + mesh + " --json");
}

// Issue 20: samples denser than the grid are averaged per cell before the build, and the build
// says so; the field stays within a tenth of a voxel of the true sphere (palpa eval), with no far
// wrong sign. 60,000 samples on a 48-cell grid: ~25 samples a cell.
TEST_F(Cli, DenseScansAreThinnedToTheGridAndSaySo) {
  const std::string mesh = std::string(PALPA_DATA_DIR) + "/sphere.off";
  ASSERT_EQ(Palpa("sample " + mesh + " -n 60000 -o " + Path("dense.xyz") + " -q").code, 0);
  const Outcome b = Palpa("build " + Path("dense.xyz") + " -o " + Path("dense.palpa") + " --cells 48 --format 1");
  ASSERT_EQ(b.code, 0) << b.out;
  EXPECT_NE(b.out.find("60000 samples thinned to "), std::string::npos) << b.out;
  EXPECT_NE(b.out.find("samples are denser than the grid: averaged per cell of 1.5 voxels"), std::string::npos)
      << b.out;
  EXPECT_NE(b.out.find("60000 oriented points ("), std::string::npos) << b.out;
  ExpectNoFarWrongAndMeanBelow(Palpa("eval " + Path("dense.palpa") + " --mesh " + mesh + " --json"), 0.1);
}

// Issue 20, clean samples: no wrong sign beyond 3 voxels, through `palpa build` defaults. CGAL's
// couplingdown with 5,000 samples (seed 2) had a hole 3.6 voxels inside a thick part, 5.8 voxels
// from every sample, where the estimate's patches meet at a concave edge and w is 0.77. The far
// pass's cheap filter, w interpolated from the brick's corners, read 0.30 there: one corner lay
// beside a sample, where the dipole sum reads -2.36, and the filter skipped the node. The corners
// are now clamped to [0, 1]. Since the stray test keeps the narrow side of a thin wall
// (FindStraySamples), one sample at the foot of a fin, 0.4 voxel above the floor, is kept, and its
// plane, carried past the concave edge by the blend, left one node 3.4 voxels under the floor
// (4.4 voxels from every sample) outside: w is 0.71 there, but the corners of its brick, outside
// the fin, interpolate to 0.46. The filter now passes a node held outside whose interpolated w
// is under 1/2 by less than kFilterMargin.
// docs/field-methods.md § The far pass's filter near 1/2 and CAD parts' rims.
TEST_F(Cli, CleanCouplingHasNoWrongSignFarFromTheSurface) {
  ExpectNoFarWrongAndMeanBelow(SampleBuildEval("couplingdown.off", 5000, 2, Path("c")), 0.1);
}

// Issue 20, clean samples: the spool's flange is 1.5 voxels thick and its narrow top face has most
// of its 16 nearest samples on the wide chamfer below. The stray test took 51 of those top
// samples (seed 2) for flipped normals, and the chamfer's inner balls, no longer stopped by the
// top face's discs, filled the concave corner above the flange: 2 phantom nodes 3.1 voxels out.
// The other side of a thin wall now supports a sample (FindStraySamples).
TEST_F(Cli, CleanSpoolKeepsItsThinFlangesNarrowFace) {
  ExpectNoFarWrongAndMeanBelow(SampleBuildEval("spool.off", 5000, 2, Path("spool")), 0.1);
}

// Issue 20, clean samples: CGAL's joint (bundled), seed 1, had 4 phantom nodes 3.5-3.8 voxels
// beneath a convex edge, 6.4 voxels from every sample: the nearest sample lay on the other face,
// and its plane held the node inside. w there is 0.30, unclear, and its level surface too near to
// overrule the estimate; the planes of the node's two nearest faces prove it outside (EdgeSide).
TEST_F(Cli, CleanJointHasNoPhantomBeneathItsConvexEdges) {
  for (const int seed : {1, 2})
    ExpectNoFarWrongAndMeanBelow(SampleBuildEval("joint.off", 5000, seed, Path("joint" + std::to_string(seed))), 0.1);
}

// Issue 20, parts that touch: the cow's tail lies on its rump. With 1,000 samples (seeds 3 and 4)
// the nearest samples of nodes up to 4.4 voxels inside the rump were the tail's, facing them: the
// local estimate, blending the tail's patches, put the nodes outside (6 and 2 hole nodes), and w
// there, 0.59-0.67, was too near 1/2 to overrule it. In front of the tail's sample but behind a
// rump sample among the 8 nearest that faces it (normals opposed), with w at least 0.55, they are
// inside (BehindTouchingPart; docs/field-methods.md § Parts that touch).
TEST_F(Cli, CowsTailOnItsRumpLeavesNoHole) {
  for (const int seed : {3, 4})
    ExpectNoFarWrongAndMeanBelow(SampleBuildEval("cow.off", 1000, seed, Path("cow" + std::to_string(seed))), 0.3);
}

// Issue 20, sparse samples through `palpa build` defaults: the cow with 500 samples (seed 2) had 55
// phantom nodes beyond 3 voxels, 4-7 voxels from every sample (spacing ~9 voxels), where the
// samples' winding number w reads 0.3-0.6: a point dipole's 1/r^2 overstates a sparse sample's
// share that close to it. With the nearest samples' dipoles spread over their discs, w reads below
// 0.2 there and the far pass puts the node outside (LabelByWinding, kDiscOutside): 18 left.
// Since the stray test keeps the narrow side of a thin wall (FindStraySamples), two true samples
// of this draw are kept (a leg's, line 100, dropped as stray before, and line 141, then a
// winding outlier), and their patches and balls make 95 more phantom nodes 4-6 voxels out:
// 137 without the disc rule, 113 with it (docs/field-methods.md § Thin walls' narrow sides).
// Since one agreeing neighbour of its own side is enough with the wall's (FindStraySamples: a
// sparse face's sample at a convex corner), line 426 is kept too. It lies on a sheet of the cow
// mesh that runs inside the mesh's own solid (the mesh's winding number is 1 on both sides of
// it), which the points present as a surface like any other: its patch cuts 10 hole nodes, at
// most 3.6 voxels deep, into the solid in front of it (docs/field-methods.md § A sparse face's
// sample at a convex corner).
TEST_F(Cli, SparseCowPhantomsGoWhereTheDiscSpreadWindingNumberIsClearlyOutside) {
  const Outcome e = SampleBuildEval("cow.off", 500, 2, Path("cow"));
  ASSERT_EQ(e.code, 0) << e.out;
  EXPECT_LE(EvalFigure(e, "\"phantom_solid\":{\"nodes\":"), 120.0) << e.out;
  EXPECT_LE(EvalFigure(e, "\"holes\":{\"nodes\":"), 12.0) << e.out;
  const auto holes = e.out.find("\"holes\":{");
  ASSERT_NE(holes, std::string::npos) << e.out;
  EXPECT_LT(EvalFigure({e.code, e.out.substr(holes)}, "\"deepest_voxels\":"), 4.0) << e.out;
}

// Issue 20: the cow with 500 samples (seed 6) has no sample on two hooves' soles; the nearest
// samples carried those legs on below them (140 phantom nodes, 6.2 voxels deep). The nodes held
// inside more than max(3 voxels, 0.3 spacings) outside the samples' convex hull are set outside,
// and the build says how many and how far out.
TEST_F(Cli, SparseCowsLegsAreCutAtTheSamplesHullAndTheBuildSaysSo) {
  const Outcome e = SampleBuildEval("cow.off", 500, 6, Path("cow"));
  ASSERT_EQ(e.code, 0) << e.out;
  EXPECT_LE(EvalFigure(e, "\"far_wrong\":"), 5.0) << e.out;
  const Outcome b = Palpa("build " + Path("cow.xyz") + " -o " + Path("again.palpa") + " --cells 150");
  ASSERT_EQ(b.code, 0) << b.out;
  EXPECT_NE(b.out.find("mm outside the samples' convex hull (a part carried on past its last samples"),
            std::string::npos)
      << b.out;
}

// The positions of `palpa sample`'s output `xyz` (x y z nx ny nz lines).
std::vector<std::array<double, 3>> SampledPositions(const std::string& xyz) {
  std::ifstream in(xyz);
  std::vector<std::array<double, 3>> points;
  for (double x, y, z, nx, ny, nz; in >> x >> y >> z >> nx >> ny >> nz;) points.push_back({x, y, z});
  return points;
}

// About the voxel of `palpa build --cells 150` on `points`: the bounding box's largest side over
// the 150 nodes less 1 and the default band's 8-node margin on each side (GridMarginNodes).
double VoxelAt150Cells(const std::vector<std::array<double, 3>>& points) {
  std::array<double, 3> lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
  for (const auto& p : points)
    for (std::size_t a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], p[a]);
      hi[a] = std::max(hi[a], p[a]);
    }
  return std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]}) / (150 - 1 - 16);
}

// `points` as bare x y z lines (a scan without normals), each coordinate moved by Gaussian noise
// of standard deviation `sigma` (model units; none when 0) drawn in order from mt19937_64(seed).
std::string BareText(const std::vector<std::array<double, 3>>& points, double sigma, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> gauss(0.0, sigma > 0 ? sigma : 1.0);
  const auto jitter = [&] { return sigma > 0 ? gauss(rng) : 0.0; };
  std::ostringstream bare;
  for (const auto& p : points) {
    const double x = p[0] + jitter(), y = p[1] + jitter(), z = p[2] + jitter();
    bare << x << ' ' << y << ' ' << z << '\n';
  }
  return bare.str();
}

// The same dense sphere without normals: thinned by position before its normals are estimated
// (the estimate over 2,000,000 points took a minute), with the oriented set's accuracy.
TEST_F(Cli, DenseBarePositionsAreThinnedBeforeTheirNormalsAreEstimated) {
  const std::string mesh = std::string(PALPA_DATA_DIR) + "/sphere.off";
  ASSERT_EQ(Palpa("sample " + mesh + " -n 60000 -o " + Path("dense.xyz") + " -q").code, 0);
  const std::string input = Write("bare.xyz", BareText(SampledPositions(Path("dense.xyz")), 0.0, 0));
  const Outcome b = Palpa("build " + input + " -o " + Path("bare.palpa") + " --cells 48 --format 1");
  ASSERT_EQ(b.code, 0) << b.out;
  const auto thinned = b.out.find("60000 samples thinned to ");
  ASSERT_NE(thinned, std::string::npos) << b.out;
  EXPECT_LT(thinned, b.out.find("normals estimated")) << b.out;
  EXPECT_EQ(b.out.find("60000 normals estimated"), std::string::npos) << b.out;
  ExpectNoFarWrongAndMeanBelow(Palpa("eval " + Path("bare.palpa") + " --mesh " + mesh + " --json"), 0.1);
}

// Issue 20: the same dense sphere with noise of about a voxel per axis spreads over a shell that
// half-voxel cells do not halve; cells of the grid's 1.5 voxels do, and their averages carry
// normals the jet fit can find (mean |error| 0.097 voxel; fitted on every sample instead: 1.43
// voxels and 6,598 far-wrong nodes).
TEST_F(Cli, NoisyDenseBarePositionsAreThinnedToTheGridBeforeTheirNormalsAreEstimated) {
  const std::string mesh = std::string(PALPA_DATA_DIR) + "/sphere.off";
  ASSERT_EQ(Palpa("sample " + mesh + " -n 60000 -o " + Path("dense.xyz") + " -q").code, 0);
  const std::vector<std::array<double, 3>> points = SampledPositions(Path("dense.xyz"));
  double lo = 1e300, hi = -1e300;
  for (const auto& p : points) {
    lo = std::min({lo, p[0], p[1], p[2]});
    hi = std::max({hi, p[0], p[1], p[2]});
  }
  const std::string input = Write("noisy_bare.xyz", BareText(points, (hi - lo) / 48, 3));  // ~1 voxel at 48 cells
  const Outcome b = Palpa("build " + input + " -o " + Path("noisy_bare.palpa") + " --cells 48 --format 1");
  ASSERT_EQ(b.code, 0) << b.out;
  EXPECT_NE(b.out.find("60000 samples thinned to "), std::string::npos) << b.out;
  EXPECT_NE(b.out.find("(1.5 voxels, by position) before their normals were estimated"), std::string::npos) << b.out;
  ExpectNoFarWrongAndMeanBelow(Palpa("eval " + Path("noisy_bare.palpa") + " --mesh " + mesh + " --json"), 0.2);
}

// 5,000 samples of `mesh` (`palpa sample --seed 3`, written to `sampled`) as a bare scan: no
// normals, and Gaussian noise of 0.3 voxel at 150 cells per axis (BareText, seed 3).
std::string NoisyBareText(const std::string& mesh, const std::string& sampled) {
  EXPECT_EQ(Palpa("sample " + mesh + " -n 5000 --seed 3 -o " + sampled + " -q").code, 0);
  const std::vector<std::array<double, 3>> points = SampledPositions(sampled);
  return BareText(points, 0.3 * VoxelAt150Cells(points), 3);
}

// Cli with one bundled mesh's NoisyBareText built at 150 cells and scored against the mesh.
class NoisyBareCli : public Cli {
 protected:
  struct Scored {
    Outcome build;
    Outcome eval;  // `palpa eval --json`, run only when the build exited 0
  };
  // data/`name`.off as NoisyBareText (written to noisy_`name`.xyz), built to noisy_`name`.palpa
  // with `--cells 150` and `options`.
  Scored BuildAndScore(const std::string& name, const std::string& options = "") {
    const std::string mesh = std::string(PALPA_DATA_DIR) + "/" + name + ".off";
    const std::string input = Write("noisy_" + name + ".xyz", NoisyBareText(mesh, Path(name + ".xyz")));
    const std::string field = Path("noisy_" + name + ".palpa");
    Scored out{Palpa("build " + input + " -o " + field + " --cells 150" + options), {}};
    if (out.build.code == 0) out.eval = Palpa("eval " + field + " --mesh " + mesh + " --json");
    return out;
  }
};

// Issue 20: bare samples of a part with blades thinner than the spacing and a little position
// noise are called noisy (the two sides no longer fit two clean sheets), and the spanning tree
// alone oriented them across the blades: CGAL's rotor, 5,000 samples with 0.3 voxels of noise,
// 31 % of the band wrong and ~148,000 far-wrong nodes. The sheet pass now runs on such mildly
// noisy sets too (normals.cc, kSheetPassNoise).
TEST_F(NoisyBareCli, MildlyNoisyBareSamplesOfThinBladesAreNotOrientedAcrossThem) {
  const auto [b, e] = BuildAndScore("rotor");
  ASSERT_EQ(b.code, 0) << b.out;
  EXPECT_NE(b.out.find("jet fit, 18 neighbours)"), std::string::npos) << b.out;  // called noisy
  ASSERT_EQ(e.code, 0) << e.out;
  EXPECT_LT(EvalFigure(e, "\"far_wrong\":"), 10000.0) << e.out;
  EXPECT_LT(EvalFigure(e, "\"wrong_sign_in_band_percent\":"), 20.0) << e.out;
}

// Issue 20: bare samples whose noise is small for their spacing (the normals' clean fit, 10
// neighbours) but over a quarter voxel for the grid: the denoiser moves them along their lines, and
// the 10-sample lines carried the noise into the moves. Their normals are fitted again as noisy
// ones (18 neighbours and up); --denoise off keeps the clean fit. The joint, 5,000 samples, 0.3
// voxel of noise per axis: band mean 0.251 -> 0.157 voxel, wrong sign 3.82 -> 3.02 %.
TEST_F(NoisyBareCli, BareSamplesNoisyForTheGridButNotTheirSpacingTakeTheNoisyFit) {
  const auto [b, e] = BuildAndScore("joint", " --format 1");
  ASSERT_EQ(b.code, 0) << b.out;
  EXPECT_NE(b.out.find("their normals were fitted again as noisy ones, to the 18 nearest"), std::string::npos) << b.out;
  EXPECT_NE(b.out.find("jet fit, 18 neighbours)"), std::string::npos) << b.out;
  ASSERT_EQ(e.code, 0) << e.out;
  EXPECT_LT(EvalFigure(e, "\"mean_abs_error\":"), 0.19) << e.out;
  EXPECT_LT(EvalFigure(e, "\"wrong_sign_in_band_percent\":"), 3.6) << e.out;
  EXPECT_LT(EvalFigure(e, "\"far_wrong\":"), 100.0) << e.out;
  const Outcome off =
      Palpa("build " + Path("noisy_joint.xyz") + " -o " + Path("off.palpa") + " --cells 150 --format 1 --denoise off");
  ASSERT_EQ(off.code, 0) << off.out;
  EXPECT_NE(off.out.find("jet fit, 10 neighbours"), std::string::npos) << off.out;
  EXPECT_EQ(off.out.find("fitted again"), std::string::npos) << off.out;
}

// Issue 20: bare noisy samples of a part whose creases and teeth are as fine as the normals' fit
// (the pinion, 5,000 samples, 0.3 voxel of noise per axis): the bisector moves followed lines that
// do not carry the shape, 1.6 x the noise RMS, and left the samples farther from the surface. The
// moves are undone and only the field is filtered: band mean 0.349 -> 0.236 voxel, wrong sign
// 5.57 -> 3.89 %, no far-wrong node either way.
TEST_F(NoisyBareCli, BareNoisySamplesAreNotMovedFartherThanTheirNoise) {
  const auto [b, e] = BuildAndScore("pinion", " --format 1");
  ASSERT_EQ(b.code, 0) << b.out;
  EXPECT_NE(b.out.find("more than that noise explains"), std::string::npos) << b.out;
  EXPECT_NE(b.out.find("the samples were kept in place and only the field filtered"), std::string::npos) << b.out;
  EXPECT_EQ(b.out.find("samples moved along their normals"), std::string::npos) << b.out;
  ASSERT_EQ(e.code, 0) << e.out;
  EXPECT_LT(EvalFigure(e, "\"mean_abs_error\":"), 0.28) << e.out;
  EXPECT_LT(EvalFigure(e, "\"far_wrong\":"), 100.0) << e.out;
}

// Issue 20, position noise: a sphere926 with Gaussian noise of ~0.75 voxel per axis is denoised by
// default, says so with the noise it measured, and scores better against the true sphere than
// with --denoise off (which leaves the samples as they are and says nothing).
TEST_F(Cli, NoisyScansAreDenoisedAndSaySo) {
  std::ifstream in(std::string(PALPA_DATA_DIR) + "/sphere926.pwn");
  std::ostringstream noisy;
  std::mt19937_64 rng(7);
  std::normal_distribution<double> gauss(0.0, 0.3);  // radius 10; 64 cells: a voxel is ~0.37
  for (double x, y, z, nx, ny, nz; in >> x >> y >> z >> nx >> ny >> nz;)
    noisy << x + gauss(rng) << ' ' << y + gauss(rng) << ' ' << z + gauss(rng) << ' ' << nx << ' ' << ny << ' ' << nz
          << '\n';
  const std::string input = Write("noisy.xyz", noisy.str());
  const auto mean_error = [&](const std::string& blob) {
    const Outcome e = Palpa("eval " + blob + " --sphere 10 --json");
    EXPECT_EQ(e.code, 0) << e.out;
    const auto at = e.out.find("\"mean_abs_error\":");
    return at == std::string::npos ? 1e9 : std::stod(e.out.substr(at + 17));
  };
  const Outcome on = Palpa("build " + input + " -o " + Path("on.palpa") + " --cells 64");
  ASSERT_EQ(on.code, 0) << on.out;
  EXPECT_NE(on.out.find("position noise "), std::string::npos) << on.out;
  EXPECT_NE(on.out.find("(--denoise off keeps them)"), std::string::npos) << on.out;
  EXPECT_NE(on.out.find("the field filtered once over 3x3x3 nodes"), std::string::npos) << on.out;
  const Outcome off = Palpa("build " + input + " -o " + Path("off.palpa") + " --cells 64 --denoise off");
  ASSERT_EQ(off.code, 0) << off.out;
  EXPECT_EQ(off.out.find("position noise "), std::string::npos) << off.out;
  const double denoised = mean_error(Path("on.palpa")), raw = mean_error(Path("off.palpa"));
  EXPECT_LT(denoised, 0.7 * raw) << denoised << " vs " << raw;
}

// Issue 20: a stray sample off the surface and a point at 1e30 are ignored, counted and named
// (the farthest); the field is that of the file without them (compared through palpa export),
// so neither makes solid of its own nor collapses --fit (the 1e30 point used to turn the grid
// into 300 x 17 x 17 nodes, exit 0).
TEST_F(Cli, StraySamplesAreIgnoredAndNamed) {
  std::ifstream in(std::string(PALPA_DATA_DIR) + "/sphere926.pwn");
  std::string clean((std::istreambuf_iterator<char>(in)), {});
  // sphere926 is radius 10 with ~1.2 between samples: 13 is 3 units off the surface, outward.
  const std::string stray_in = Write("stray.xyz", clean + "13 0 0 1 0 0\n");
  const std::string far_in = Write("far.xyz", clean + "1e30 1e30 1e30 0 0 1\n");
  const std::string clean_in = Write("clean.xyz", clean);
  ASSERT_EQ(Palpa("build " + clean_in + " -o " + Path("clean.palpa") + " --cells 48 -q").code, 0);
  ASSERT_EQ(Palpa("export " + Path("clean.palpa") + " --npy " + Path("clean.npy")).code, 0);
  for (const std::string& input : {stray_in, far_in}) {
    const Outcome b = Palpa("build " + input + " -o " + Path("x.palpa") + " --cells 48 -q");
    ASSERT_EQ(b.code, 0) << b.out;
    EXPECT_NE(b.out.find("ignored 1 sample that its neighbours do not support (off their surface or isolated); "
                         "the farthest: " +
                         input + ":927"),
              std::string::npos)
        << b.out;
    ASSERT_EQ(Palpa("export " + Path("x.palpa") + " --npy " + Path("x.npy")).code, 0);
    EXPECT_EQ(ReadBytes(Path("x.npy")), ReadBytes(Path("clean.npy"))) << input;
  }
  // The clean file has none.
  const Outcome c = Palpa("build " + clean_in + " -o " + Path("c.palpa") + " --cells 48 -q");
  EXPECT_EQ(c.out.find("ignored"), std::string::npos) << c.out;
}

// Issue 20: a closed set sampled sparsely is reported as such, not as an open scan. CGAL's spool
// and couplingdown with 500 samples (`palpa sample` seeds 3 and 4) and the rotor's (seed 7) had
// their fields' inside reach a grid face, or span gaps far from every sample, and were called
// open scans; the open-scan test's tighter bound on flipped pairs then blamed their exact normals.
// Only samples that show an open side themselves (normals' flux >= 0.1 of their area, or many rim
// samples: HermiteStats::samples_open) make an open scan; the open scans' tests below still hold.
// The spool's and the rotor's fields have surface far from every sample, and the note says so;
// couplingdown's no longer has (since the closing balls must continue the surface, 86 mm^2 -> none
// over the note's threshold; far-wrong nodes 7,452 -> 6,826), so only the first two hold for it.
TEST_F(Cli, SparseClosedSetsAreNotCalledOpenScans) {
  for (const auto& [mesh, seed, sparse_note] :
       {std::tuple{"spool.off", 3, true}, {"couplingdown.off", 4, false}, {"rotor.off", 7, true}}) {
    const std::string points = Path(std::string(mesh) + ".xyz");
    ASSERT_EQ(Palpa("sample " + std::string(PALPA_DATA_DIR) + "/" + mesh + " -n 500 --seed " + std::to_string(seed) +
                    " -o " + points + " -q")
                  .code,
              0);
    const Outcome b = Palpa("build " + points + " -o " + Path("sparse.palpa") + " --cells 150");
    ASSERT_EQ(b.code, 0) << b.out;
    EXPECT_EQ(b.out.find("the scan is open"), std::string::npos) << mesh << b.out;
    EXPECT_EQ(b.out.find("not consistently oriented"), std::string::npos) << mesh << b.out;
    if (sparse_note) {
      EXPECT_NE(b.out.find("the samples make a closed surface, sparsely"), std::string::npos) << mesh << b.out;
    }
  }
}

// A build of an open scan: it succeeded and said the scan is open, without blaming the normals.
void ExpectReportedOpen(const Outcome& build) {
  ASSERT_EQ(build.code, 0) << build.out;
  EXPECT_NE(build.out.find("the scan is open (the normals are not to blame)"), std::string::npos) << build.out;
  EXPECT_EQ(build.out.find("not consistently oriented"), std::string::npos) << build.out;
}

// Issue 20: an open scan is reported open (with the area the field closed), a closed one is not.
// Issue 21: trace synth samples a v2 blob in place. Its traces are those of the blob::DenseV1
// file of the same field, byte for byte, for a stroke and a poke grid.
TEST_F(Cli, TraceSynthSamplesV2InPlaceAsItsDenseEquivalent) {
  const std::string v2 = Path("s.palpa");
  ASSERT_EQ(Palpa("build " + std::string(PALPA_DATA_DIR) + "/sphere926.pwn -o " + v2 + " --cells 80 -q").code, 0);
  auto stored = palpa::blob::ReadFile(v2.c_str());
  ASSERT_TRUE(stored.has_value());
  const auto view = palpa::blob::Verify(*stored);
  ASSERT_TRUE(view.has_value()) << view.error().what();
  ASSERT_EQ(view->version, palpa::blob::kVersion2);
  const std::vector<std::byte> dense = palpa::blob::DenseV1(*view);
  const std::string v1 = Path("dense.palpa");
  std::ofstream(v1, std::ios::binary)
      .write(reinterpret_cast<const char*>(dense.data()), static_cast<std::streamsize>(dense.size()));
  // The traces without their "# field NAME" comment line (the files' names differ).
  const auto read = [](const std::string& path) {
    std::ifstream in(path);
    std::string text;
    for (std::string line; std::getline(in, line);)
      if (line.rfind("# field ", 0) != 0) text += line + "\n";
    return text;
  };
  for (const char* kind : {"stroke", "poke"}) {
    const std::string a = Path(std::string(kind) + "-v2.csv"), b = Path(std::string(kind) + "-v1.csv");
    ASSERT_EQ(Palpa("trace synth --field " + v2 + " --kind " + kind + " -o " + a).code, 0) << kind;
    ASSERT_EQ(Palpa("trace synth --field " + v1 + " --kind " + kind + " -o " + b).code, 0) << kind;
    const std::string ta = read(a), tb = read(b);
    EXPECT_GT(ta.size(), 1000u) << kind;
    EXPECT_TRUE(ta == tb) << kind;
  }
}

TEST_F(Cli, OpenScanIsReportedOpen) {
  std::ifstream in(std::string(PALPA_DATA_DIR) + "/sphere926.pwn");
  std::string cap;
  for (std::string line; std::getline(in, line);) {
    double x = 0, y = 0, z = 0;
    if (std::sscanf(line.c_str(), "%lf %lf %lf", &x, &y, &z) == 3 && z > 0) cap += line + "\n";
  }
  const std::string cap_in = Write("cap.xyz", cap);
  ExpectReportedOpen(Palpa("build " + cap_in + " -o " + Path("cap.palpa") + " --cells 64 -q"));
  // The area it closed, with the equator's samples kept (z >= 0: the closure is then round): the
  // sphere's (r = 10) lower half beyond the cover distance d of the equator's samples,
  // 2 pi r^2 (1 - sin(2 asin(d / 2r))) (tests/host/coverage_test.cc), at any resolution (the
  // brick count it replaced gave 409.5 model units^2 at 64 cells, fewer finer).
  std::ifstream again(std::string(PALPA_DATA_DIR) + "/sphere926.pwn");
  std::string half;
  for (std::string line; std::getline(again, line);) {
    double x = 0, y = 0, z = 0;
    if (std::sscanf(line.c_str(), "%lf %lf %lf", &x, &y, &z) == 3 && z >= 0) half += line + "\n";
  }
  const std::string half_in = Write("half.xyz", half);
  for (const int cells : {64, 128}) {
    const Outcome open = Palpa("build " + half_in + " -o " + Path("half.palpa") + " --cells " + std::to_string(cells));
    double mm2 = 0, units2 = 0, d_mm = 0;
    const std::size_t at = open.out.find(") over ");
    ASSERT_NE(at, std::string::npos) << open.out;
    ASSERT_EQ(std::sscanf(open.out.c_str() + at, ") over %lf mm^2 (%lf model units^2) more than %lf mm", &mm2, &units2,
                          &d_mm),
              3)
        << open.out;
    const double d = d_mm / std::sqrt(mm2 / units2);  // model units
    const double expected = 2 * std::numbers::pi * 100 * (1 - std::sin(2 * std::asin(d / 20)));
    EXPECT_NEAR(units2, expected, 0.06 * expected) << cells << " cells: " << open.out;
  }
  const Outcome closed =
      Palpa("build " + std::string(PALPA_DATA_DIR) + "/sphere926.pwn -o " + Path("s.palpa") + " --cells 64 -q");
  ASSERT_EQ(closed.code, 0) << closed.out;
  EXPECT_EQ(closed.out.find("open"), std::string::npos) << closed.out;
}

// Issue 20: a range scan from one view (exact normals) is open, and its points farthest from the
// scanner face it, which the closed-surface support test read as inward normals (knot1: 4 of 26
// directions, cow: 9). It is reported open, not inconsistent; cube.pwn, whose normals really are
// half inward (all along +x, +y or +z), still is.
TEST_F(Cli, OneViewRangeScanIsOpenNotInconsistent) {
  const std::string mesh = std::string(PALPA_DATA_DIR) + "/knot1.off";
  ASSERT_EQ(Palpa("sample " + mesh + " -n 5000 --seed 1 --views 1 -o " + Path("view.xyz") + " -q").code, 0);
  const Outcome view = Palpa("build " + Path("view.xyz") + " -o " + Path("view.palpa") + " --cells 150 -q");
  ExpectReportedOpen(view);
  // The closure beyond the samples was smoothed (HermiteOptions::smooth_closure), and the note says
  // by how many side changes: one view leaves most of the knot unscanned.
  const std::size_t smoothed = view.out.find("; then smoothed by ");
  ASSERT_NE(smoothed, std::string::npos) << view.out;
  long changes = 0;
  ASSERT_EQ(std::sscanf(view.out.c_str() + smoothed, "; then smoothed by %ld side changes", &changes), 1) << view.out;
  EXPECT_GT(changes, 0) << view.out;
  const Outcome cube =
      Palpa("build " + std::string(PALPA_DATA_DIR) + "/cube.pwn -o " + Path("cube.palpa") + " --cells 100 -q");
  ASSERT_EQ(cube.code, 0) << cube.out;
  EXPECT_NE(cube.out.find("not consistently oriented"), std::string::npos) << cube.out;
  EXPECT_NE(cube.out.find("Rerun with --normals orient"), std::string::npos) << cube.out;
}

TEST_F(Cli, FailedBuildKeepsThePreviousOutput) {
  const std::string out = Path("field.palpa");
  ASSERT_EQ(Palpa("build " + std::string(PALPA_DATA_DIR) + "/sphere926.pwn -o " + out + " --cells 40 -q").code, 0);
  const auto before = fs::file_size(out);
  const std::string bad = Write("bad.xyz", "1 2 3\n");
  EXPECT_EQ(Palpa("build " + bad + " -o " + out).code, 2);
  ASSERT_TRUE(fs::exists(out));
  EXPECT_EQ(fs::file_size(out), before);
  EXPECT_EQ(Palpa("info " + out).code, 0);
}

TEST_F(Cli, InfoExportAndTraceSynthOnSphere926) {
  const std::string field = Path("sphere.palpa");
  const Outcome b = Palpa("build " + std::string(PALPA_DATA_DIR) + "/sphere926.pwn -o " + field + " --cells 100");
  ASSERT_EQ(b.code, 0) << b.out;

  const Outcome info = Palpa("info --json " + field);
  ASSERT_EQ(info.code, 0) << info.out;
  EXPECT_NE(info.out.find("\"method\": \"hermite\""), std::string::npos) << info.out;  // the default method
  EXPECT_NE(info.out.find("\"point_count\": 926"), std::string::npos) << info.out;
  EXPECT_NE(info.out.find("\"checksum\": \"ok\""), std::string::npos) << info.out;

  // export: NPY v1.0, '<f4', C order, shape (nx, ny, nz), values = blob Q16.16 · voxel.
  const std::string npy = Path("sphere.npy");
  ASSERT_EQ(Palpa("export " + field + " --npy " + npy).code, 0);
  // The dense equivalent, whose values export writes (docs/blob-format.md § Tools and v2).
  const auto dense =
      palpa::blob::VerifyOwned(palpa::blob::DenseV1(palpa::blob::LoadFile(field.c_str())->view())).value();
  const palpa::blob::FieldView& view = dense.view();
  std::ifstream f(npy, std::ios::binary);
  std::string data((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  ASSERT_EQ(data.compare(0, 6, "\x93NUMPY"), 0);
  std::uint16_t hlen = 0;
  std::memcpy(&hlen, data.data() + 8, 2);
  EXPECT_EQ((10 + hlen) % 64, 0);
  const std::string header = data.substr(10, hlen);
  const std::string shape = "'shape': (" + std::to_string(view.dims[0]) + ", " + std::to_string(view.dims[1]) + ", " +
                            std::to_string(view.dims[2]) + ")";
  EXPECT_NE(header.find(shape), std::string::npos) << header;
  EXPECT_NE(header.find("'<f4'"), std::string::npos);
  const std::size_t count = static_cast<std::size_t>(view.dims[0] * view.dims[1] * view.dims[2]);
  ASSERT_EQ(data.size(), 10 + hlen + 4 * count);
  for (std::size_t n = 0; n < count; n += 97) {
    float v = 0;
    std::memcpy(&v, data.data() + 10 + hlen + 4 * n, 4);
    EXPECT_FLOAT_EQ(v, static_cast<float>(view.dense()->data()[n] / 65536.0 * view.voxel_m)) << n;
  }

  // trace synth poke 1 mm deep: the deepest HIP lies 1 mm inside the analytic sphere
  // (radius 10 model units → 0.03 m at --fit 0.06), within the erosion field's surface error.
  const std::string poke = Path("poke.csv");
  const Outcome t = Palpa("trace synth --field " + field + " --kind poke --depth 0.001 -o " + poke);
  ASSERT_EQ(t.code, 0) << t.out;
  auto samples = palpa::trace::ReadTrace(poke);
  ASSERT_TRUE(samples.has_value()) << samples.error().message;
  double min_r = 1, first_r = 0;
  for (const auto& s : *samples) {
    const double dx = s.hip_m[0] - view.fit_offset_m[0], dy = s.hip_m[1] - view.fit_offset_m[1],
                 dz = s.hip_m[2] - view.fit_offset_m[2];
    const double r = std::sqrt(dx * dx + dy * dy + dz * dz);
    if (&s == &samples->front()) first_r = r;
    min_r = std::min(min_r, r);
  }
  const double radius = 10 * view.fit_scale;
  EXPECT_NEAR(first_r, radius + 0.010, 2 * view.voxel_m);  // starts 10 mm off the surface
  EXPECT_NEAR(min_r, radius - 0.001, 2 * view.voxel_m);    // erosion surface within ~1.5 voxels
  // Minimum-jerk at 1 kHz: no jump between samples larger than 0.1 mm.
  for (std::size_t i = 1; i < samples->size(); ++i) {
    const auto& a = (*samples)[i - 1].hip_m;
    const auto& c = (*samples)[i].hip_m;
    EXPECT_LT(std::hypot(c[0] - a[0], c[1] - a[1], c[2] - a[2]), 1e-4) << i;
  }
}

TEST_F(Cli, UsageErrorsExitTwo) {
  EXPECT_EQ(Palpa("build").code, 2);
  EXPECT_EQ(Palpa("build x.xyz -o y.palpa --method nonsense").code, 2);
  EXPECT_EQ(Palpa("frobnicate").code, 2);
  EXPECT_EQ(Palpa("info " + Path("missing.palpa")).code, 2);
}

}  // namespace
