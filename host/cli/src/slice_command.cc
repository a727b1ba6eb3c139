// palpa slice: a colour-mapped cross-section of a field as a PNG.
#include <fmt/core.h>

#include "commands.h"
#include "palpa/io/atomic_file.h"
#include "palpa/mesh/field_file.h"
#include "palpa/mesh/slice.h"

namespace palpa::cli {

int RunSlice(const SliceArgs& args) {
  if (const int refused = CheckOutput("slice", args.output, {args.field}); refused != kExitOk) return refused;
  auto field = mesh::LoadField(args.field);  // v2 read in place
  if (!field) {
    fmt::print(stderr, "palpa slice: {}\n", field.error().message);
    return kExitBadInput;
  }
  const int axis = args.axis - 'x';
  auto image = mesh::RenderSlice(field->view(), axis, args.at_m, args.pixels_per_voxel);
  if (!image) {
    fmt::print(stderr, "palpa slice: {}: {}\n", args.field, image.error().message);
    return kExitBadInput;
  }
  if (auto w = io::WriteFileAtomically(args.output, mesh::EncodePng(*image), {.inputs = {args.field}}); !w) {
    fmt::print(stderr, "palpa slice: {}\n", w.error());
    return kExitIo;
  }
  if (!args.quiet)
    fmt::print("{}: slice {} = {:.3f} mm, {} x {} pixels ({} per voxel) -> {}\n", args.field, args.axis,
               args.at_m * 1e3, image->width, image->height, image->pixels_per_voxel, args.output);
  return kExitOk;
}

}  // namespace palpa::cli
