// palpa eval: scores a field against the true signed distance of a closed mesh or a sphere
// (issue 5), in voxels over the band |true| ≤ 3 voxels.
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <memory>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include <fmt/core.h>
#include <nlohmann/json.hpp>

#include "commands.h"
#include "palpa/field/transform.h"
#include "palpa/io/atomic_file.h"
#include "palpa/mesh/eval.h"
#include "palpa/mesh/field_file.h"
#include "palpa/mesh/triangle_mesh.h"

namespace palpa::cli {
namespace {

nlohmann::ordered_json FarJson(const mesh::FarWrong& f) {
  return {{"nodes", f.nodes},
          {"deepest_voxels", f.deepest_voxels},
          {"deepest_at_m", {f.deepest_at_m.x(), f.deepest_at_m.y(), f.deepest_at_m.z()}}};
}

std::string FarLine(const mesh::FarWrong& f) {
  if (f.nodes == 0) return "0 nodes";
  return fmt::format("{} nodes, deepest {:.1f} voxels at ({:.6f}, {:.6f}, {:.6f}) m", f.nodes, f.deepest_voxels,
                     f.deepest_at_m.x(), f.deepest_at_m.y(), f.deepest_at_m.z());
}

// Every EvalResult field, keys as the member names (units in the name: *_error in voxels,
// max_error_at_m in metres, *_percent in %).
nlohmann::ordered_json ScoreJson(const mesh::EvalResult& r) {
  return {{"nodes", r.nodes},
          {"band_nodes", r.band_nodes},
          {"mean_abs_error", r.mean_abs_error},
          {"p99_abs_error", r.p99_abs_error},
          {"max_abs_error", r.max_abs_error},
          {"mean_signed_error", r.mean_signed_error},
          {"max_error_at_m", {r.max_error_at_m.x(), r.max_error_at_m.y(), r.max_error_at_m.z()}},
          {"wrong_sign_in_band", r.wrong_sign_in_band},
          {"wrong_sign_in_band_percent", r.wrong_sign_in_band_percent},
          {"on_surface_nodes", r.on_surface_nodes},
          {"gross_wrong_sign", r.gross_wrong_sign},
          {"gross_wrong_sign_percent", r.gross_wrong_sign_percent},
          {"far_wrong", r.far_wrong()},
          {"phantom_solid", FarJson(r.phantom_solid)},
          {"holes", FarJson(r.holes)}};
}

// --far-out's lines: each far wrong-sign node in model units (the inverse of the field's fit),
// its |true| in voxels and its kind, phantoms first; a comment line heads them.
std::string FarNodesText(const mesh::EvalResult& r, const blob::FieldView& v, double far_beyond_voxels) {
  std::string text = fmt::format(
      "# far wrong-sign nodes (|true| > {:g} voxels): x y z (model units) depth (voxels) kind; {} phantom, {} hole\n",
      far_beyond_voxels, r.phantom_solid.nodes, r.holes.nodes);
  const field::Transform to_model = mesh::ModelToDevice(v).Inverse();
  for (const auto& [far, kind] : {std::pair{&r.phantom_solid, "phantom"}, std::pair{&r.holes, "hole"}})
    for (const mesh::FarWrong::Node& node : far->listed) {
      const Eigen::Vector3d p = to_model.Apply(node.at_m);
      text += fmt::format("{:.9g} {:.9g} {:.9g} {:.3f} {}\n", p.x(), p.y(), p.z(), node.depth_voxels, kind);
    }
  return text;
}

double Seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

}  // namespace

int RunEval(const EvalArgs& args) {
  std::unique_ptr<tbb::global_control> threads;
  if (args.threads > 0)
    threads = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                    static_cast<std::size_t>(args.threads));
  if (!args.far_out.empty()) {
    std::vector<std::string> inputs = {args.field};
    for (const std::string& m : {args.mesh, args.candidate_mesh})
      if (!m.empty()) inputs.push_back(m);
    if (const int refused = CheckOutput("eval", args.far_out, inputs); refused != kExitOk) return refused;
  }
  if (args.mesh.empty() == !args.sphere_radius) {
    fmt::print(stderr, "palpa eval: give exactly one truth, --mesh MESH.off or --sphere R\n");
    return kExitBadInput;
  }
  // As stored: Evaluate reads v2 in place and knows its two bands (a dense copy would not).
  auto field = mesh::LoadField(args.field);
  if (!field) {
    fmt::print(stderr, "palpa eval: {}\n", field.error().message);
    return kExitBadInput;
  }
  const blob::FieldView& v = field->view();

  mesh::Truth truth;
  std::string truth_name;
  if (args.sphere_radius) {
    if (!(*args.sphere_radius > 0)) {
      fmt::print(stderr, "palpa eval: --sphere expects a positive radius, got {}\n", *args.sphere_radius);
      return kExitBadInput;
    }
    truth = mesh::Truth::Sphere(*args.sphere_radius);
    truth_name = fmt::format("sphere r={:g} (model units) at the model origin", *args.sphere_radius);
  } else {
    auto m = mesh::ReadClosedMesh(args.mesh);
    if (!m) {
      fmt::print(stderr, "palpa eval: {}\n", m.error().message);
      return kExitBadInput;
    }
    truth = mesh::Truth::Mesh(std::move(*m));
    truth_name = args.mesh;
  }

  // Stored φ is exact only within both bands (v2: 6 inside, 2 outside by default); beyond, it is
  // the clamp, and scoring there would measure the clamp. The default band (3) shrinks to fit.
  mesh::EvalOptions options;
  options.on_surface_voxels = args.on_surface_voxels;
  // (Evaluate refuses a wider band too; here it is refused before the truth is computed.)
  // A candidate mesh has an exact distance everywhere: FIELD lends it only its grid.
  const bool candidate = !args.candidate_mesh.empty();
  bool candidate_open = false;
  const double exact = candidate ? args.band_voxels : mesh::ExactBandVoxels(v);
  options.band_voxels = args.band_given ? args.band_voxels : std::min(args.band_voxels, exact);
  if (options.band_voxels > exact) {
    fmt::print(stderr,
               "palpa eval: {}: --band {} exceeds the field's narrow band ({} voxels inside, {} outside); "
               "rebuild with a wider --band / --band-outside or score a narrower band\n",
               args.field, options.band_voxels, v.band_voxels, v.band_outside);
    return kExitBadInput;
  }
  const auto t0 = std::chrono::steady_clock::now();
  auto grid = mesh::TrueDistances(v, truth, std::max(1.0, options.band_voxels));
  if (!grid) {
    fmt::print(stderr, "palpa eval: {}: {}\n", truth_name, grid.error().message);
    return kExitBadInput;
  }
  const double seconds_truth = Seconds(t0);
  options.list_far_nodes = !args.far_out.empty();
  const auto t1 = std::chrono::steady_clock::now();
  std::expected<mesh::EvalResult, mesh::Error> score;
  if (candidate) {
    // An open or non-manifold candidate (screened Poisson on an open scan or on noise) is scored
    // too, signed by its winding number; the closed path is unchanged.
    auto m = mesh::ReadClosedMesh(args.candidate_mesh);
    if (!m) {
      auto any = mesh::ReadOff(args.candidate_mesh);
      if (!any || any->faces.empty()) {
        fmt::print(stderr, "palpa eval: {}\n", any ? m.error().message : any.error().message);
        return kExitBadInput;
      }
      fmt::print(stderr,
                 "palpa eval: note: {} is not a closed, consistently oriented mesh ({}): signed by its generalized "
                 "winding number\n",
                 args.candidate_mesh, m.error().message);
      candidate_open = true;
      m = std::move(any);
    }
    auto c =
        mesh::TrueDistances(v, candidate_open ? mesh::Truth::OpenMesh(std::move(*m)) : mesh::Truth::Mesh(std::move(*m)),
                            std::max(1.0, options.band_voxels));
    if (!c) {
      fmt::print(stderr, "palpa eval: {}: {}\n", args.candidate_mesh, c.error().message);
      return kExitBadInput;
    }
    score = mesh::EvaluateCandidate(*c, *grid, options);
  } else {
    score = mesh::Evaluate(v, *grid, options);
  }
  const std::string& scored = candidate ? args.candidate_mesh : args.field;
  if (!score) {
    fmt::print(stderr, "palpa eval: {}: {}\n", scored, score.error().message);
    return kExitBadInput;
  }
  const double seconds_score = Seconds(t1);
  const mesh::EvalResult& r = *score;
  if (!args.far_out.empty()) {
    const std::string text = FarNodesText(r, v, options.far_beyond_voxels);
    if (auto w = io::WriteFileAtomically(args.far_out, std::as_bytes(std::span(text)), {.inputs = {args.field}}); !w) {
      fmt::print(stderr, "palpa eval: {}\n", w.error());
      return kExitIo;
    }
  }

  if (args.json) {
    const nlohmann::ordered_json out = {{"field", args.field},
                                        {"candidate_mesh", args.candidate_mesh},
                                        {"candidate_open", candidate_open},
                                        {"truth", truth_name},
                                        {"dims", {v.dims[0], v.dims[1], v.dims[2]}},
                                        {"voxel", v.voxel_m},
                                        {"band_voxels", options.band_voxels},
                                        {"seconds_truth", seconds_truth},
                                        {"seconds_score", seconds_score},
                                        {"score", ScoreJson(r)}};
    // Bytes of a path that are not UTF-8 become U+FFFD rather than an exception.
    fmt::print("{}\n", out.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace));
    return kExitOk;
  }
  fmt::print("{} against {}{}\n", scored, truth_name, candidate ? fmt::format(" on the grid of {}", args.field) : "");
  fmt::print("  grid                {} x {} x {} nodes, voxel {:.6f} mm\n", v.dims[0], v.dims[1], v.dims[2],
             v.voxel_m * 1e3);
  fmt::print("  band                |true| <= {:g} voxels: {} nodes\n", options.band_voxels, r.band_nodes);
  fmt::print("  mean |error|        {:.4f} voxels\n", r.mean_abs_error);
  fmt::print("  p99 |error|         {:.4f} voxels\n", r.p99_abs_error);
  fmt::print("  max |error|         {:.4f} voxels at ({:.6f}, {:.6f}, {:.6f}) m\n", r.max_abs_error,
             r.max_error_at_m.x(), r.max_error_at_m.y(), r.max_error_at_m.z());
  fmt::print("  mean signed error   {:+.4f} voxels\n", r.mean_signed_error);
  fmt::print("  wrong sign in band  {:.3f} % ({} nodes; {} on the surface, |true| <= {:g} voxels, not scored)\n",
             r.wrong_sign_in_band_percent, r.wrong_sign_in_band, r.on_surface_nodes, options.on_surface_voxels);
  fmt::print("  gross wrong sign    {:.4f} % of all {} nodes ({} nodes with |true| > 1 voxel)\n",
             r.gross_wrong_sign_percent, r.nodes, r.gross_wrong_sign);
  fmt::print("  far wrong sign      {} nodes with |true| > {:g} voxels\n", r.far_wrong(), options.far_beyond_voxels);
  fmt::print("    phantom solid     {}\n", FarLine(r.phantom_solid));
  fmt::print("    holes             {}\n", FarLine(r.holes));
  fmt::print("  time                truth {:.3f} s, score {:.3f} s\n", seconds_truth, seconds_score);
  return kExitOk;
}

}  // namespace palpa::cli
