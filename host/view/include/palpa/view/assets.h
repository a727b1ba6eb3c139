// The page's fixed asset set (index.html, its JS/CSS, three.js and uPlot from web/), read into
// memory once at start-up. The server answers only from this map: no request path ever reaches
// the file system, so `..`, symlinks or odd encodings cannot name a file outside the set. Non-RT.
#pragma once

#include <expected>
#include <map>
#include <string>

#include "palpa/field/error.h"

namespace palpa::view {

using Error = field::Error;

struct Asset {
  std::string content_type;  ///< from the extension: text/html, text/javascript, text/css, ...
  std::string bytes;
};

/// URL path ("/assets/three/three.module.js", "/" for index.html) → asset.
using AssetSet = std::map<std::string, Asset>;

/// Where the assets are, first match: `explicit_dir` if set; $PALPA_VIEW_ASSETS; next to the
/// installed binary (<bin>/../share/palpa/view); in the build tree (<build>/host/cli/palpa →
/// <build>/host/view/assets). Error: none of them holds index.html (the list names each tried).
std::expected<std::string, Error> FindAssetDir(const std::string& explicit_dir = "");

/// Reads every regular file under `dir` (symlinks and other types are skipped, at most 64 MiB in
/// all), keyed "/assets/<relative path>"; `index.html` is also served at "/".
/// Errors: unreadable directory or file; no index.html; over the size limit.
std::expected<AssetSet, Error> LoadAssets(const std::string& dir);

}  // namespace palpa::view
