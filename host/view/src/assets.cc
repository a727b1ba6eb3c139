// Loading the page's assets into memory.
#include "palpa/view/assets.h"

#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>

#include <fmt/core.h>

namespace palpa::view {
namespace {

namespace fs = std::filesystem;
constexpr std::uintmax_t kMaxTotalBytes = 64u << 20;

std::string ContentType(const fs::path& p) {
  const std::string e = p.extension().string();
  if (e == ".html") return "text/html; charset=utf-8";
  if (e == ".js" || e == ".mjs") return "text/javascript; charset=utf-8";
  if (e == ".css") return "text/css; charset=utf-8";
  if (e == ".json" || e == ".map") return "application/json";
  if (e == ".png") return "image/png";
  if (e == ".svg") return "image/svg+xml";
  if (e == ".txt" || e == ".md") return "text/plain; charset=utf-8";
  return "application/octet-stream";
}

bool HasIndex(const fs::path& dir) {
  std::error_code ec;
  return fs::is_regular_file(dir / "index.html", ec);
}

}  // namespace

std::expected<std::string, Error> FindAssetDir(const std::string& explicit_dir) {
  if (!explicit_dir.empty()) {
    if (HasIndex(explicit_dir)) return explicit_dir;
    return std::unexpected(Error{fmt::format("{}: no index.html: not a palpa view asset directory", explicit_dir)});
  }
  std::vector<fs::path> tried;
  if (const char* env = std::getenv("PALPA_VIEW_ASSETS"); env != nullptr && *env != '\0') tried.emplace_back(env);
  char self[4096];
  const ssize_t n = readlink("/proc/self/exe", self, sizeof self - 1);
  if (n > 0) {
    self[n] = '\0';
    const fs::path bin = fs::path(self).parent_path();
    tried.push_back(bin / "../share/palpa/view");
    tried.push_back(bin / "../view/assets");
  }
  std::string names;
  for (const fs::path& d : tried) {
    if (HasIndex(d)) return fs::weakly_canonical(d).string();
    names += (names.empty() ? "" : ", ") + d.lexically_normal().string();
  }
  return std::unexpected(Error{fmt::format(
      "the page's assets are not found (tried {}); build palpa with web/node_modules present (scripts/install-deps "
      "runs npm ci) or pass --assets DIR",
      names.empty() ? "nothing" : names)});
}

std::expected<AssetSet, Error> LoadAssets(const std::string& dir) {
  AssetSet set;
  std::error_code ec;
  std::uintmax_t total = 0;
  fs::recursive_directory_iterator it(dir, fs::directory_options::none, ec);
  if (ec) return std::unexpected(Error{fmt::format("{}: cannot list: {}", dir, ec.message())});
  for (const fs::recursive_directory_iterator end; it != end; it.increment(ec)) {
    if (ec) return std::unexpected(Error{fmt::format("{}: cannot list: {}", dir, ec.message())});
    if (it->is_symlink(ec) || !it->is_regular_file(ec)) continue;
    const fs::path rel = fs::relative(it->path(), dir, ec);
    std::ifstream in(it->path(), std::ios::binary);
    std::ostringstream ss;
    ss << in.rdbuf();
    if (!in.good() && !in.eof()) return std::unexpected(Error{fmt::format("{}: cannot read", it->path().string())});
    Asset a{ContentType(it->path()), ss.str()};
    total += a.bytes.size();
    if (total > kMaxTotalBytes)
      return std::unexpected(Error{fmt::format("{}: assets exceed {} MiB", dir, kMaxTotalBytes >> 20)});
    set["/assets/" + rel.generic_string()] = std::move(a);
  }
  const auto index = set.find("/assets/index.html");
  if (index == set.end()) return std::unexpected(Error{fmt::format("{}: no index.html", dir)});
  set["/"] = index->second;
  return set;
}

}  // namespace palpa::view
