#include "palpa/mesh/field_file.h"

namespace palpa::mesh {

std::expected<LoadedField, Error> LoadField(const std::string& path) {
  auto bytes = blob::ReadFile(path.c_str());
  if (!bytes) return std::unexpected(Error{bytes.error().what()});
  LoadedField out;
  out.bytes = std::move(*bytes);
  auto view = blob::Verify(out.bytes);
  if (!view) return std::unexpected(Error{path + ": " + view.error().what()});
  out.view = *view;
  return out;
}

}  // namespace palpa::mesh
