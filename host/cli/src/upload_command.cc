// palpa upload (issue 7; docs/upload.md): verify a blob locally, send it to a running palpad,
// print its answer.
#include <fmt/core.h>

#include "commands.h"
#include "palpa/blob/blob.h"
#include "palpa/net/client.h"

namespace palpa::cli {

int RunUpload(const UploadArgs& a) {
  auto to = net::ParseEndpoint(a.to);
  if (!to) {
    fmt::print(stderr, "palpa upload: --to {}\n", to.error().message);
    return kExitBadInput;
  }
  auto key = net::ReadKeyFile(a.key_file);
  if (!key) {
    fmt::print(stderr, "palpa upload: --key-file {}\n", key.error().message);
    return kExitBadInput;
  }
  // Verify first: a blob the controller would refuse never leaves this machine.
  auto blob = blob::ReadFile(a.field.c_str());
  if (!blob) {
    fmt::print(stderr, "palpa upload: {}: {}\n", a.field, blob.error().what());
    return kExitBadInput;
  }
  if (!a.skip_verify) {
    if (const auto view = blob::Verify(*blob); !view) {
      fmt::print(stderr, "palpa upload: {}: {}\n", a.field, view.error().what());
      return kExitBadInput;
    }
  }
  const auto answer = net::Upload(*to, *key, *blob, std::chrono::milliseconds(a.timeout_ms));
  if (!answer) {
    const net::NetError& e = answer.error();
    if (e.code == net::NetErrorCode::kRefused) {
      fmt::print(stderr, "palpa upload: refused by {}: {}\n", a.to, e.message);
    } else {
      fmt::print(stderr, "palpa upload: {}\n", e.message);
    }
    return kExitIo;
  }
  fmt::print("accepted by {}: field crc32c 0x{:08x}, dims {}x{}x{}, voxel {:.6g} mm, {} bytes, swap {}\n", a.to,
             answer->field_crc32c, answer->dims[0], answer->dims[1], answer->dims[2], answer->voxel_m * 1e3,
             blob->size(), answer->swaps);
  return kExitOk;
}

}  // namespace palpa::cli
