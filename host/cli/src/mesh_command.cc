// palpa mesh: the zero iso-surface of a field as a triangle mesh (.ply or .obj).
#include <algorithm>
#include <cctype>
#include <filesystem>

#include <fmt/core.h>
#include <malloc.h>

#include "commands.h"
#include "palpa/io/atomic_file.h"
#include "palpa/mesh/field_file.h"
#include "palpa/mesh/iso_surface.h"

namespace palpa::cli {

int RunMesh(const MeshArgs& args) {
  // One malloc arena for OpenVDB's TBB threads: with one per thread, the blocks they free stay
  // spread over the arenas and the peak RSS of a 1,200-cell kitten varies between 563 and 617 MB
  // from run to run; with one, 549 MB every time (issue 21's goal: output + 400 MB = 574 MB), for
  // ~0.2 s of 1.8.
  mallopt(M_ARENA_MAX, 1);
  if (const int refused = CheckOutput("mesh", args.output, {args.field}); refused != kExitOk) return refused;
  std::string ext = std::filesystem::path(args.output).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  if (ext != ".ply" && ext != ".obj") {
    fmt::print(stderr, "palpa mesh: {}: unknown extension '{}'; use .ply or .obj\n", args.output, ext);
    return kExitBadInput;
  }
  // The blob is released once meshed: not beside the output and the closedness check.
  std::expected<mesh::TriangleMesh, mesh::Error> surface;
  {
    auto field = mesh::LoadField(args.field);  // v2 meshed in place
    if (!field) {
      fmt::print(stderr, "palpa mesh: {}\n", field.error().message);
      return kExitBadInput;
    }
    surface = mesh::ExtractZeroSurface(field->view());
  }
  if (!surface) {
    fmt::print(stderr, "palpa mesh: {}: {}\n", args.field, surface.error().message);
    return kExitBadInput;
  }
  std::expected<void, std::string> written;
  if (ext == ".ply") {
    // Streamed: the output is never whole in memory (issue 21).
    auto out = io::AtomicFile::Create(args.output, {.inputs = {args.field}});
    if (!out) {
      written = std::unexpected(std::move(out.error()));
    } else {
      mesh::WritePly(*surface, [&](std::span<const std::byte> bytes) {
        written = out->Append(bytes);
        return written.has_value();
      });
      if (written) written = out->Commit();
    }
  } else {
    const std::string text = mesh::ToObj(*surface);
    written = io::WriteFileAtomically(args.output, std::as_bytes(std::span(text)), {.inputs = {args.field}});
  }
  if (!written) {
    fmt::print(stderr, "palpa mesh: {}\n", written.error());
    return kExitIo;
  }
  if (!args.quiet) {
    const bool closed = mesh::CheckClosedOriented(*surface, args.output).has_value();
    fmt::print("{}: zero iso-surface, {} vertices, {} triangles, {}, area {:.1f} mm^2, volume {:.1f} mm^3 -> {}\n",
               args.field, surface->vertices.size(), surface->faces.size(), closed ? "closed" : "NOT closed",
               mesh::SurfaceArea(*surface) * 1e6, mesh::SignedVolume(*surface) * 1e9, args.output);
  }
  return kExitOk;
}

}  // namespace palpa::cli
