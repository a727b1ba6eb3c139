// blob::ReadFile, apart from blob.cc so that the in-memory format (Encode, Verify, DenseV1) builds
// without shared/io: the clang libFuzzer build of blob.cc (fuzz/) has no file to read.
#include <cstddef>
#include <cstdio>
#include <cstring>
#include <utility>

#include "palpa/blob/blob.h"
#include "palpa/io/file_safety.h"

namespace palpa::blob {

std::expected<std::vector<std::byte>, BlobError> ReadFile(const char* path) {
  // A regular file within kMaxFileBytes (a FIFO or /dev/zero is refused before any read).
  auto read = io::ReadBounded(path, kMaxFileBytes, "blob file");
  if (!read) {
    BlobError e;
    e.field = "file";
    std::snprintf(e.message.data(), e.message.size(), "file at byte 0: %s", read.error().message.c_str());
    return std::unexpected(e);
  }
  return std::move(*read);
}

std::expected<VerifiedField, BlobError> LoadFile(const char* path) {
  auto bytes = ReadFile(path);
  if (!bytes) return std::unexpected(bytes.error());
  return VerifyOwned(std::move(*bytes));
}

}  // namespace palpa::blob
