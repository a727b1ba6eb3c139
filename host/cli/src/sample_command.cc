// palpa sample: area-uniform oriented points from a closed triangle mesh (a test case with a
// known surface for any field method).
#include <fmt/core.h>

#include "commands.h"
#include "palpa/io/atomic_file.h"
#include "palpa/mesh/sample.h"
#include "palpa/mesh/triangle_mesh.h"

namespace palpa::cli {

int RunSample(const SampleArgs& args) {
  if (const int refused = CheckOutput("sample", args.output, {args.mesh}); refused != kExitOk) return refused;
  bool flipped = false;
  auto mesh = mesh::ReadClosedMesh(args.mesh, &flipped);
  if (!mesh) {
    fmt::print(stderr, "palpa sample: {}\n", mesh.error().message);
    return kExitBadInput;
  }
  auto points = args.views > 0 ? mesh::RangeScan(*mesh, args.count, args.views, args.range_noise, args.seed, args.mesh)
                               : mesh::SampleSurface(*mesh, args.count, args.seed, args.mesh);
  if (!points) {
    fmt::print(stderr, "palpa sample: {}\n", points.error().message);
    return kExitBadInput;
  }
  const std::string text = mesh::ToXyzText(*points);
  if (auto w = io::WriteFileAtomically(args.output, std::as_bytes(std::span(text)), {.inputs = {args.mesh}}); !w) {
    fmt::print(stderr, "palpa sample: {}\n", w.error());
    return kExitIo;
  }
  if (!args.quiet)
    fmt::print("{}: {} vertices, {} faces, area {:.6g}, volume {:.6g}{}; wrote {} oriented points to {} (seed {})\n",
               args.mesh, mesh->vertices.size(), mesh->faces.size(), mesh::SurfaceArea(*mesh),
               mesh::SignedVolume(*mesh), flipped ? " (faces wound inward: normals flipped outward)" : "",
               points->positions.size(), args.output, args.seed);
  if (!args.quiet && args.views > 0)
    fmt::print("  range scan from {} view{} on the upper hemisphere, range noise {:.4g}: an open scan\n", args.views,
               args.views == 1 ? "" : "s", args.range_noise);
  return kExitOk;
}

}  // namespace palpa::cli
