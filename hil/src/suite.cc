#include "palpa/hil/suite.h"

#include <algorithm>
#include <utility>

#include <fmt/core.h>
#include <toml++/toml.h>

#include "text.h"

namespace palpa::hil {

namespace fs = std::filesystem;

std::expected<Suite, std::string> LoadSuite(const fs::path& cases_path) {
  Suite s;
  s.cases_path = fs::absolute(cases_path);
  s.hil_dir = s.cases_path.parent_path();
  s.root = s.hil_dir.parent_path();
  toml::table t;
  try {
    t = toml::parse_file(s.cases_path.string());
  } catch (const toml::parse_error& e) {
    return std::unexpected(fmt::format("{}:{}:{}: {}", s.cases_path.string(), e.source().begin.line,
                                       e.source().begin.column, e.description()));
  }
  auto where = [&](const toml::node& n) { return fmt::format("{}:{}", s.cases_path.string(), n.source().begin.line); };
  if (auto* d = t["defaults"].as_table()) {
    s.settings.rate_hz = (*d)["rate_hz"].value_or(s.settings.rate_hz);
    s.settings.k_n_per_m = (*d)["k_n_per_m"].value_or(s.settings.k_n_per_m);
    s.settings.max_force_n = (*d)["max_force_n"].value_or(s.settings.max_force_n);
    s.limits.phi_tolerance_voxels = (*d)["phi_tolerance_voxels"].value_or(s.limits.phi_tolerance_voxels);
    s.limits.slope_factor = (*d)["slope_factor"].value_or(s.limits.slope_factor);
    s.limits.slope_floor_n = (*d)["slope_floor_n"].value_or(s.limits.slope_floor_n);
    s.limits.energy_tolerance_j = (*d)["energy_tolerance_j"].value_or(s.limits.energy_tolerance_j);
  }
  auto* fields = t["fields"].as_table();
  if (fields == nullptr) return std::unexpected(s.cases_path.string() + ": no [fields] table");
  for (auto&& [key, node] : *fields) {
    auto* ft = node.as_table();
    if (ft == nullptr) return std::unexpected(where(node) + ": fields." + std::string(key.str()) + " is not a table");
    FieldSpec f;
    auto build = (*ft)["build"].value<std::string>();
    auto blob = (*ft)["blob"].value<std::string>();
    if (blob && !build) {
      f.blob = *blob;  // a field palpa build can no longer make (e.g. one cut by its grid)
    } else if (!build || !build->starts_with("build ") || blob) {
      return std::unexpected(where(node) + ": fields." + std::string(key.str()) +
                             " needs either build = 'build POINTS ...' or blob = 'PATH'");
    } else {
      f.build = *build;
    }
    if (auto* prep = (*ft)["prepare"].as_array())
      for (auto&& p : *prep)
        if (auto v = p.value<std::string>()) f.prepare.push_back(*v);
    s.fields[std::string(key.str())] = f;
  }
  auto* cases = t["case"].as_array();
  if (cases == nullptr) return std::unexpected(s.cases_path.string() + ": no [[case]] entries");
  for (auto&& node : *cases) {
    auto* ct = node.as_table();
    if (ct == nullptr) return std::unexpected(where(node) + ": [[case]] is not a table");
    Case c;
    c.name = (*ct)["name"].value_or(std::string());
    c.trace = (*ct)["trace"].value_or(std::string());
    c.field = (*ct)["field"].value_or(std::string());
    c.device = (*ct)["device"].value_or(std::string("sim"));
    c.why = (*ct)["why"].value_or(std::string());
    c.expect_exit = (*ct)["expect_exit"].value_or(0);
    c.realtime = (*ct)["realtime"].value_or(true);
    c.swap_field = (*ct)["swap_field"].value_or(std::string());
    c.swap_at = (*ct)["swap_at"].value_or(std::int64_t{-1});
    c.output = (*ct)["output"].value_or(std::string());
    if (c.name.empty() || c.trace.empty() || c.field.empty())
      return std::unexpected(where(node) + ": a case needs name, trace and field");
    // Errors about a key name the key's own line.
    auto at = [&](const char* key) {
      const toml::node* n = ct->get(key);
      return where(n != nullptr ? *n : node);
    };
    if (!s.fields.contains(c.field)) return std::unexpected(at("field") + ": unknown field '" + c.field + "'");
    if (!c.swap_field.empty() && !s.fields.contains(c.swap_field))
      return std::unexpected(at("swap_field") + ": unknown field '" + c.swap_field + "'");
    if (c.swap_field.empty() != (c.swap_at < 0))
      return std::unexpected(where(node) + ": swap_field and swap_at (a tick ≥ 0) go together");
    if (c.device != "sim" && c.device != "virtual-falcon")
      return std::unexpected(at("device") + ": device must be sim or virtual-falcon");
    if (c.why.empty()) return std::unexpected(where(node) + ": case " + c.name + " must say why (its device choice)");
    if (auto* xf = (*ct)["xfail"].as_array())
      for (auto&& a : *xf)
        if (auto v = a.value<std::string>()) c.xfail.push_back(*v);
    if (auto* args = (*ct)["palpad"].as_array())
      for (auto&& a : *args)
        if (auto v = a.value<std::string>()) c.palpad.push_back(*v);
    if (auto* sph = (*ct)["sphere"].as_table()) {
      auto* centre = (*sph)["centre_m"].as_array();
      if (centre == nullptr || centre->size() != 3)
        return std::unexpected(where(node) + ": sphere.centre_m needs 3 numbers");
      c.sphere_centre_m =
          std::array<double, 3>{(*centre)[0].value_or(0.0), (*centre)[1].value_or(0.0), (*centre)[2].value_or(0.0)};
      c.sphere_radius_m = (*sph)["radius_m"].value_or(0.0);
      if (auto v = (*sph)["validate_rms_pct"].value<double>()) c.validate_rms_pct = *v;
      if (auto v = (*sph)["validate_angle_deg"].value<double>()) c.validate_angle_deg = *v;
    }
    for (const auto& other : s.cases)
      if (other.name == c.name) return std::unexpected(where(node) + ": duplicate case name " + c.name);
    s.cases.push_back(std::move(c));
  }
  return s;
}

std::optional<fs::path> FindCases(const std::vector<fs::path>& starts) {
  for (fs::path dir : starts) {
    for (; !dir.empty(); dir = dir.parent_path()) {
      if (fs::exists(dir / "hil" / "cases.toml")) return dir / "hil" / "cases.toml";
      if (dir == dir.root_path()) break;
    }
  }
  return std::nullopt;
}

std::vector<const Case*> SelectCases(const Suite& suite, const Selection& sel) {
  std::vector<const Case*> selected;
  for (const Case& c : suite.cases) {
    bool match = sel.filter.empty();
    if (!sel.names.empty())
      match = std::find(sel.names.begin(), sel.names.end(), c.name) != sel.names.end();
    else if (!sel.filter.empty())
      for (const auto& f : detail::SplitWords(detail::Replace(sel.filter, ",", " ")))
        match = match || c.name.find(f) != std::string::npos;
    if (sel.realtime && !c.realtime) match = false;
    if (!sel.device.empty() && c.device != sel.device) match = false;
    if (match) selected.push_back(&c);
  }
  return selected;
}

}  // namespace palpa::hil
