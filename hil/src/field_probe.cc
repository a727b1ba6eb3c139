// The one place the harness holds a verified blob: bytes and the view on them, sampled by the
// host's FieldSampler (host/cli). Kept apart so that a change of the blob's types touches only this.
#include "palpa/hil/field_probe.h"

#include <optional>
#include <utility>
#include <vector>

#include "field_sampler.h"
#include "palpa/blob/blob.h"

namespace palpa::hil {

struct FieldProbes::Loaded final : PhiField {
  explicit Loaded(std::vector<std::byte> b) : bytes(std::move(b)) {}
  double Phi(const Eigen::Vector3d& x_m) const override { return sampler->Phi(x_m); }
  double voxel_m() const override { return sampler->voxel_m(); }

  std::vector<std::byte> bytes;
  blob::FieldView view;  // into `bytes`, whose heap buffer stays put
  std::optional<cli::FieldSampler> sampler;
};

FieldProbes::FieldProbes() = default;
FieldProbes::~FieldProbes() = default;

std::expected<const PhiField*, std::string> FieldProbes::Get(const std::string& name,
                                                             const std::filesystem::path& path) {
  auto& loaded = loaded_[name];
  if (loaded) return loaded.get();
  auto blob_bytes = blob::ReadFile(path.c_str(), blob::Load::kAsStored);  // v2 sampled in place
  if (!blob_bytes) return std::unexpected(std::string(blob_bytes.error().what()));
  loaded = std::make_unique<Loaded>(std::move(*blob_bytes));
  auto view = blob::Verify(loaded->bytes);
  if (!view) {
    loaded.reset();
    return std::unexpected(path.string() + ": " + view.error().what());
  }
  loaded->view = *view;
  loaded->sampler.emplace(loaded->view);
  return loaded.get();
}

}  // namespace palpa::hil
