// `palpa view`'s HTTP server (cpp-httplib): one page and a small JSON/binary API for it.
//
//   GET /                 index.html
//   GET /assets/<path>    the fixed asset set (assets.h); nothing else on disk is reachable
//   GET /api/info         field header: dims, origin_m, voxel_m, band_voxels, method, crc32c,
//                         point_count, mesh {vertices, triangles, bbox_min_m, bbox_max_m},
//                         trace {rows, source, t0_s, t1_s} | null, live {available, endpoint, reason}
//   GET /api/mesh         the zero iso-surface (ExtractZeroSurface), application/octet-stream,
//                         little-endian: char[4] "PVM1", u32 vertices V, u32 triangles T,
//                         u32 flags (1: normals), f32 positions[3V] (device m), f32 normals[3V],
//                         u32 indices[3T] (counter-clockwise seen from outside)
//   GET /api/slice?axis=x|y|z&at=METRES
//                         the field panel of RenderSlice (palpa slice's colours) as PNG; panel
//                         pixel columns span node u −½ … n_u − ½ (likewise rows, v upwards)
//   GET /api/trace        TraceToJson of the --trace run (404 without --trace)
//   GET /api/live         LiveFeed::LatestJson (404 without --connect)
//
// Every other method or path gets 404/405; malformed queries 400; an exception in a handler 500.
// Request lines over 8 KiB get 414 and bodies over 64 KiB 413 (httplib's limits). Non-RT.
#pragma once

#include <cstddef>
#include <expected>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "palpa/mesh/field_file.h"
#include "palpa/mesh/triangle_mesh.h"
#include "palpa/view/assets.h"
#include "palpa/view/live.h"
#include "palpa/view/trace_series.h"

namespace palpa::view {

/// What the server shows. It owns all of it; handlers only read (the live feed is thread-safe).
struct ViewContent {
  std::string field_path;
  std::optional<blob::VerifiedField> field;  ///< set before the server starts
  mesh::TriangleMesh surface;                ///< ExtractZeroSurface(field->view())
  std::optional<TraceSeries> trace;          ///< --trace
  std::unique_ptr<LiveFeed> live;            ///< --connect
  std::string live_endpoint;                 ///< as given to --connect (even when live is unavailable)
};

/// The /api/mesh bytes for `surface` (layout above).
std::vector<std::byte> EncodeMesh(const mesh::TriangleMesh& surface);

class ViewServer {
 public:
  ViewServer(ViewContent content, AssetSet assets);
  ~ViewServer();
  ViewServer(const ViewServer&) = delete;
  ViewServer& operator=(const ViewServer&) = delete;

  /// Binds HOST:PORT (port 0: any free port). Returns the bound port.
  /// Error: the address cannot be bound (in use, not local, permission).
  std::expected<int, Error> Bind(const std::string& host, int port);
  /// Serves until Stop(); returns false if the listener failed.
  bool Run();
  /// Thread-safe; makes Run() return.
  void Stop();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace palpa::view
