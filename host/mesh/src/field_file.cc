#include "palpa/mesh/field_file.h"

namespace palpa::mesh {

std::expected<LoadedField, Error> LoadField(const std::string& path, blob::Load load) {
  auto bytes = blob::ReadFile(path.c_str(), blob::Load::kAsStored);
  if (!bytes) return std::unexpected(Error{bytes.error().what()});
  LoadedField out;
  out.bytes = std::move(*bytes);
  auto view = blob::Verify(out.bytes);
  if (!view) return std::unexpected(Error{path + ": " + view.error().what()});
  out.file_crc32c = view->crc32c;
  out.file_bytes = out.bytes.size();
  if (load == blob::Load::kDense && view->version == blob::kVersion2) {
    out.bytes = blob::DenseV1(*view);
    view = blob::Verify(out.bytes);
    if (!view) return std::unexpected(Error{path + ": " + view.error().what()});  // not reached: DenseV1 is valid
  }
  out.view = *view;
  return out;
}

}  // namespace palpa::mesh
