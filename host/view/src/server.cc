// palpa view's HTTP server. One pre-routing handler answers every request from in-memory data, so
// no request path is matched by std::regex (whose recursion a long path could exhaust) and none
// reaches the file system.
#include "palpa/view/server.h"

#include <httplib.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstring>
#include <limits>
#include <mutex>

#include <fmt/core.h>
#include <nlohmann/json.hpp>

#include "palpa/mesh/slice.h"

namespace palpa::view {
namespace {

using Json = nlohmann::json;
constexpr std::size_t kMaxPayloadBytes = 64 * 1024;

using blob::MethodName;

template <typename T>
void Append(std::vector<std::byte>& out, const T& value) {
  const auto* p = reinterpret_cast<const std::byte*>(&value);
  out.insert(out.end(), p, p + sizeof(T));
}

std::string InfoJson(const ViewContent& c) {
  const blob::FieldView& f = c.field.view;
  Json j;
  j["field"] = c.field_path;
  j["dims"] = f.dims;
  j["origin_m"] = f.origin_m;
  j["voxel_m"] = f.voxel_m;
  j["band_voxels"] = f.band_voxels;
  j["method"] = MethodName(f.method);
  j["point_count"] = f.point_count;
  j["crc32c"] = fmt::format("{:08x}", f.crc32c);
  j["blob_bytes"] = c.field.bytes.size();
  // The bounding box as the page will see it: of the float32 positions /api/mesh sends.
  std::array<float, 3> lo{std::numeric_limits<float>::infinity(), std::numeric_limits<float>::infinity(),
                          std::numeric_limits<float>::infinity()};
  std::array<float, 3> hi{-lo[0], -lo[1], -lo[2]};
  for (const auto& v : c.surface.vertices)
    for (int a = 0; a < 3; ++a) {
      const auto x = static_cast<float>(v[a]);
      lo[static_cast<std::size_t>(a)] = std::min(lo[static_cast<std::size_t>(a)], x);
      hi[static_cast<std::size_t>(a)] = std::max(hi[static_cast<std::size_t>(a)], x);
    }
  j["mesh"] = {{"vertices", c.surface.vertices.size()},
               {"triangles", c.surface.faces.size()},
               {"bbox_min_m", lo},
               {"bbox_max_m", hi}};
  if (c.trace) {
    j["trace"] = {{"rows", c.trace->t_s.size()},
                  {"source", c.trace->source},
                  {"t0_s", c.trace->t_s.front()},
                  {"t1_s", c.trace->t_s.back()}};
  } else {
    j["trace"] = nullptr;
  }
  j["live"] = {{"available", LiveAvailable() && c.live != nullptr},
               {"endpoint", c.live_endpoint},
               {"reason", c.live_endpoint.empty() ? "" : LiveUnavailableReason()}};
  return j.dump();
}

void Text(httplib::Response& res, int status, const std::string& message) {
  res.status = status;
  res.set_content(message + "\n", "text/plain; charset=utf-8");
}

}  // namespace

std::vector<std::byte> EncodeMesh(const mesh::TriangleMesh& surface) {
  const bool normals = surface.normals.size() == surface.vertices.size() && !surface.vertices.empty();
  std::vector<std::byte> out;
  out.reserve(16 + surface.vertices.size() * 24 + surface.faces.size() * 12);
  for (const char ch : {'P', 'V', 'M', '1'}) out.push_back(static_cast<std::byte>(ch));
  Append(out, static_cast<std::uint32_t>(surface.vertices.size()));
  Append(out, static_cast<std::uint32_t>(surface.faces.size()));
  Append(out, static_cast<std::uint32_t>(normals ? 1 : 0));
  for (const auto& v : surface.vertices)
    for (int a = 0; a < 3; ++a) Append(out, static_cast<float>(v[a]));
  if (normals)
    for (const auto& n : surface.normals)
      for (int a = 0; a < 3; ++a) Append(out, static_cast<float>(n[a]));
  for (const auto& f : surface.faces)
    for (const int i : f) Append(out, static_cast<std::uint32_t>(i));
  return out;
}

struct ViewServer::Impl {
  ViewContent content;
  AssetSet assets;
  std::string info_json;
  std::string mesh_bytes;
  std::string trace_json;
  std::mutex slice_mutex;  // one slice render at a time: bounds the CPU a client can take
  httplib::Server server;

  void Slice(const httplib::Request& req, httplib::Response& res) {
    const std::string axis = req.get_param_value("axis");
    const std::string at = req.get_param_value("at");
    if (axis.size() != 1 || axis[0] < 'x' || axis[0] > 'z')
      return Text(res, 400, fmt::format("axis must be x, y or z, got '{}'", axis.substr(0, 16)));
    double at_m = 0;
    const auto [ptr, ec] = std::from_chars(at.data(), at.data() + at.size(), at_m);
    if (at.empty() || ec != std::errc{} || ptr != at.data() + at.size() || !std::isfinite(at_m))
      return Text(res, 400, fmt::format("at must be a coordinate in metres, got '{}'", at.substr(0, 32)));
    std::lock_guard lock(slice_mutex);
    auto image = mesh::RenderSlice(content.field.view, axis[0] - 'x', at_m, 0);
    if (!image) return Text(res, 400, image.error().message);
    // The panel only: the page lays it on the plane itself, with its own colour bar.
    mesh::SliceImage panel = *image;
    const auto& p = image->panel;
    panel.width = p.w;
    panel.height = p.h;
    panel.rgb.assign(static_cast<std::size_t>(p.w) * static_cast<std::size_t>(p.h) * 3, 0);
    for (int r = 0; r < p.h; ++r)
      std::memcpy(panel.rgb.data() + static_cast<std::size_t>(r) * static_cast<std::size_t>(p.w) * 3,
                  image->rgb.data() + 3 * (static_cast<std::size_t>(p.y + r) * static_cast<std::size_t>(image->width) +
                                           static_cast<std::size_t>(p.x)),
                  static_cast<std::size_t>(p.w) * 3);
    const std::vector<std::byte> png = mesh::EncodePng(panel);
    res.set_content(std::string(reinterpret_cast<const char*>(png.data()), png.size()), "image/png");
    res.set_header("X-Slice-Pixels-Per-Voxel", std::to_string(image->pixels_per_voxel));
  }

  httplib::Server::HandlerResponse Route(const httplib::Request& req, httplib::Response& res) {
    res.set_header("Cache-Control", "no-store");
    res.set_header("X-Content-Type-Options", "nosniff");
    // The page loads nothing from elsewhere; the browser is told so too.
    res.set_header("Content-Security-Policy",
                   "default-src 'self'; script-src 'self' 'unsafe-inline'; style-src 'self' 'unsafe-inline'; "
                   "img-src 'self' blob: data:; connect-src 'self'");
    if (req.method != "GET" && req.method != "HEAD") {
      res.set_header("Allow", "GET, HEAD");
      res.set_header("Connection", "close");
      Text(res, 405, "only GET and HEAD");
      return httplib::Server::HandlerResponse::Handled;
    }
    const std::string& path = req.path;
    if (path == "/api/info") {
      res.set_content(info_json, "application/json");
    } else if (path == "/api/mesh") {
      res.set_content(mesh_bytes, "application/octet-stream");
    } else if (path == "/api/slice") {
      Slice(req, res);
    } else if (path == "/api/trace") {
      if (trace_json.empty())
        Text(res, 404, "no replay: start palpa view with --trace");
      else
        res.set_content(trace_json, "application/json");
    } else if (path == "/api/live") {
      if (content.live == nullptr) {
        const Json j = {{"error", content.live_endpoint.empty() ? "no live session: start palpa view with --connect"
                                                                : LiveUnavailableReason()}};
        res.status = 404;
        res.set_content(j.dump(), "application/json");
      } else {
        res.set_content(content.live->LatestJson(), "application/json");
      }
    } else if (const auto it = assets.find(path); it != assets.end()) {
      res.set_content(it->second.bytes, it->second.content_type);
    } else {
      Text(res, 404, "not found");
    }
    return httplib::Server::HandlerResponse::Handled;
  }
};

ViewServer::ViewServer(ViewContent content, AssetSet assets) : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.content = std::move(content);
  m.assets = std::move(assets);
  m.info_json = InfoJson(m.content);
  const std::vector<std::byte> mesh = EncodeMesh(m.content.surface);
  m.mesh_bytes.assign(reinterpret_cast<const char*>(mesh.data()), mesh.size());
  if (m.content.trace) m.trace_json = TraceToJson(*m.content.trace);

  m.server.set_payload_max_length(kMaxPayloadBytes);
  m.server.set_read_timeout(5, 0);
  m.server.set_write_timeout(5, 0);
  m.server.set_pre_routing_handler(
      [&m](const httplib::Request& req, httplib::Response& res) { return m.Route(req, res); });
  m.server.set_error_handler([](const httplib::Request&, httplib::Response& res) {
    if (res.body.empty()) res.set_content(fmt::format("HTTP {}\n", res.status), "text/plain; charset=utf-8");
  });
  m.server.set_exception_handler([](const httplib::Request&, httplib::Response& res, std::exception_ptr ep) {
    std::string what = "internal error";
    try {
      if (ep) std::rethrow_exception(ep);
    } catch (const std::exception& e) {
      what = e.what();
    } catch (...) {
    }
    Text(res, 500, what);
  });
}

ViewServer::~ViewServer() = default;

std::expected<int, Error> ViewServer::Bind(const std::string& host, int port) {
  if (port == 0) {
    const int bound = impl_->server.bind_to_any_port(host);
    if (bound > 0) return bound;
  } else if (impl_->server.bind_to_port(host, port)) {
    return port;
  }
  return std::unexpected(Error{
      fmt::format("cannot listen on {}:{}: {}", host, port, errno != 0 ? std::strerror(errno) : "address not usable")});
}

bool ViewServer::Run() { return impl_->server.listen_after_bind(); }

void ViewServer::Stop() { impl_->server.stop(); }

}  // namespace palpa::view
