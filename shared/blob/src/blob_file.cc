// blob::ReadFile, apart from blob.cc so that the in-memory format (Encode, Verify, DenseV1) builds
// without shared/io: the clang libFuzzer build of blob.cc (fuzz/) has no file to read.
#include <cstddef>
#include <cstdio>
#include <cstring>
#include <utility>

#include "palpa/blob/blob.h"
#include "palpa/io/file_safety.h"

namespace palpa::blob {

std::expected<std::vector<std::byte>, BlobError> ReadFile(const char* path, Load load) {
  // A regular file within kMaxFileBytes (a FIFO or /dev/zero is refused before any read).
  auto read = io::ReadBounded(path, kMaxFileBytes, "blob file");
  if (!read) {
    BlobError e;
    e.field = "file";
    std::snprintf(e.message.data(), e.message.size(), "file at byte 0: %s", read.error().message.c_str());
    return std::unexpected(e);
  }
  std::vector<std::byte> data = std::move(*read);
  std::uint16_t version = 0;
  if (load == Load::kAsStored || data.size() < kHeaderSizeV2 ||
      std::memcmp(data.data(), kMagic.data(), kMagic.size()) != 0)
    return data;
  std::memcpy(&version, data.data() + offsetof(HeaderV1, version), sizeof version);
  if (version != kVersion2) return data;
  const auto view = Verify(data);
  if (!view) return std::unexpected(view.error());
  return DenseV1(*view);
}

std::expected<VerifiedField, BlobError> LoadFile(const char* path) {
  auto bytes = ReadFile(path, Load::kAsStored);
  if (!bytes) return std::unexpected(bytes.error());
  return VerifyOwned(std::move(*bytes));
}

}  // namespace palpa::blob
