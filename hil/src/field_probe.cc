// The one place the harness holds a verified blob (blob::VerifiedField, read once per run), sampled
// by the host's float64 FieldSampler (palpa/mesh/field_sampler.h).
#include "palpa/hil/field_probe.h"

#include <utility>
#include <vector>

#include "palpa/blob/blob.h"
#include "palpa/mesh/field_file.h"
#include "palpa/mesh/field_sampler.h"

namespace palpa::hil {

struct FieldProbes::Loaded final : PhiField {
  explicit Loaded(blob::VerifiedField f) : field(std::move(f)), sampler(field.view()) {}
  double Phi(const Eigen::Vector3d& x_m) const override { return sampler.Phi(x_m); }
  double voxel_m() const override { return sampler.voxel_m(); }

  blob::VerifiedField field;
  mesh::FieldSampler sampler;
};

FieldProbes::FieldProbes() = default;
FieldProbes::~FieldProbes() = default;

std::expected<const PhiField*, std::string> FieldProbes::Get(const std::string& name,
                                                             const std::filesystem::path& path) {
  auto& loaded = loaded_[name];
  if (loaded) return loaded.get();
  auto field = mesh::LoadField(path.string());  // v2 sampled in place
  if (!field) return std::unexpected(field.error().message);
  loaded = std::make_unique<Loaded>(std::move(*field));
  return loaded.get();
}

}  // namespace palpa::hil
