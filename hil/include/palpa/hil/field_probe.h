// The fields a run samples on the host, in double (the invariants, the report's per-tick series):
// φ in metres at device points, the way the servo's sampler extends it beyond the grid. Each blob
// is read (v2 in place) and verified once per run and kept for it: the sphere's is 108 MB.
#pragma once

#include <expected>
#include <filesystem>
#include <map>
#include <memory>
#include <string>

#include <Eigen/Core>

namespace palpa::hil {

/// What the invariants read of a field. Tests implement it analytically.
class PhiField {
 public:
  virtual ~PhiField() = default;
  /// φ in metres at a device point (negative inside; outside the grid: the boundary value
  /// extended outward, as sampler::TrilinearSampler).
  [[nodiscard]] virtual double Phi(const Eigen::Vector3d& x_m) const = 0;
  /// Node spacing, m: the invariants' unit of depth.
  [[nodiscard]] virtual double voxel_m() const = 0;
};

/// The blobs of one run, by field name.
class FieldProbes {
 public:
  FieldProbes();
  ~FieldProbes();
  FieldProbes(const FieldProbes&) = delete;
  FieldProbes& operator=(const FieldProbes&) = delete;

  /// Field `name` (its blob at `path`), read and verified on first use; the same object after.
  /// Error: the blob reader's message (it names the file and byte), or "PATH: the verifier's".
  [[nodiscard]] std::expected<const PhiField*, std::string> Get(const std::string& name,
                                                                const std::filesystem::path& path);

 private:
  struct Loaded;
  std::map<std::string, std::unique_ptr<Loaded>> loaded_;
};

}  // namespace palpa::hil
