// palpa view's HTTP server. One pre-routing handler answers every request from in-memory data, so
// no request path is matched by std::regex (whose recursion a long path could exhaust) and none
// reaches the file system.
#include "palpa/view/server.h"

#include <httplib.h>

#include <pthread.h>
#include <sys/socket.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <condition_variable>
#include <cstring>
#include <functional>
#include <limits>
#include <mutex>

#include <fmt/core.h>
#include <nlohmann/json.hpp>

#include "palpa/mesh/slice.h"

namespace palpa::view {
namespace {

using Json = nlohmann::json;
constexpr std::size_t kMaxPayloadBytes = 64 * 1024;

// Connections: each gets its own thread, at most kMaxConnections at once (more wait in the kernel's
// listen queue, kListenBacklog long, until one ends). httplib's own pool has max(8, cores − 1)
// threads, and every idle connection held one for the keep-alive timeout: 500 idle connections
// delayed a GET by 30-60 s. A connection without a request for kIdleSeconds is closed, as is a
// request stalled kReadSeconds without a byte. One request per connection: httplib reads each
// request through a fresh buffer, so the bytes of a pipelined second request were read and
// dropped, and the client waited for an answer that never came; now the first answer says
// "Connection: close" and the connection closes, which tells the client to send the rest again.
constexpr std::size_t kMaxConnections = 1024;
constexpr int kListenBacklog = 1024;                // httplib's 5 dropped SYNs (1 s client retries) under load
constexpr std::size_t kThreadStackBytes = 1 << 20;  // handlers keep their data on the heap
constexpr time_t kIdleSeconds = 5;
constexpr time_t kReadSeconds = 5;

// httplib::Server with the listen backlog raised after binding (httplib listens with 5).
class Server : public httplib::Server {
 public:
  void RaiseBacklog(int backlog) {
    if (svr_sock_ != INVALID_SOCKET) ::listen(svr_sock_, backlog);  // Linux updates the backlog in place
  }
};

// httplib::TaskQueue with a thread per task (a connection), at most `max` running; enqueue waits
// (so the accept loop stops accepting) while `max` run. shutdown waits for all of them.
class ConnectionThreads : public httplib::TaskQueue {
 public:
  explicit ConnectionThreads(std::size_t max) : max_(max) {}
  ~ConnectionThreads() override { shutdown(); }

  void enqueue(std::function<void()> fn) override {
    std::unique_lock lock(mutex_);
    changed_.wait(lock, [&] { return running_ < max_; });
    auto* task = new Task{this, std::move(fn)};
    pthread_attr_t attr;
    pthread_attr_init(&attr);
    pthread_attr_setstacksize(&attr, kThreadStackBytes);
    pthread_attr_setdetachstate(&attr, PTHREAD_CREATE_DETACHED);
    pthread_t thread;
    const bool started = pthread_create(&thread, &attr, &Run, task) == 0;
    pthread_attr_destroy(&attr);
    if (started) {
      ++running_;
      return;
    }
    // No thread to be had: serve it on this one (the accept loop waits meanwhile).
    lock.unlock();
    task->fn();
    delete task;
  }

  void shutdown() override {
    std::unique_lock lock(mutex_);
    changed_.wait(lock, [&] { return running_ == 0; });
  }

 private:
  struct Task {
    ConnectionThreads* owner;
    std::function<void()> fn;
  };
  static void* Run(void* arg) {
    auto* task = static_cast<Task*>(arg);
    task->fn();
    ConnectionThreads* owner = task->owner;
    delete task;
    std::lock_guard lock(owner->mutex_);
    --owner->running_;
    owner->changed_.notify_all();
    return nullptr;
  }

  const std::size_t max_;
  std::mutex mutex_;
  std::condition_variable changed_;
  std::size_t running_ = 0;
};

using blob::MethodName;

template <typename T>
void Append(std::vector<std::byte>& out, const T& value) {
  const auto* p = reinterpret_cast<const std::byte*>(&value);
  out.insert(out.end(), p, p + sizeof(T));
}

std::string InfoJson(const ViewContent& c) {
  const blob::FieldView& f = c.field->view();
  Json j;
  j["field"] = c.field_path;
  j["dims"] = f.dims;
  j["origin_m"] = f.origin_m;
  j["voxel_m"] = f.voxel_m;
  j["band_voxels"] = std::max(f.band_voxels, f.band_outside);  // the dense equivalent's (docs/blob-format.md)
  j["method"] = MethodName(f.method);
  j["point_count"] = f.point_count;
  // The file's, as palpad reports them for the field it renders.
  j["crc32c"] = fmt::format("{:08x}", f.crc32c);
  j["blob_bytes"] = f.blob_size;
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
  Server server;

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
    auto image = mesh::RenderSlice(content.field->view(), axis[0] - 'x', at_m, 0);
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
    if (req.ranges.size() > 1) {
      // Several ranges would each be a copy of the body (100 ranges of the mesh: over 240 MB).
      // The request object is httplib's own non-const local; clearing its ranges keeps httplib
      // from applying them to this answer.
      const_cast<httplib::Request&>(req).ranges.clear();
      res.set_header("Connection", "close");
      Text(res, 416, "one byte range per request");
      return httplib::Server::HandlerResponse::Handled;
    }
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
  m.server.set_read_timeout(kReadSeconds, 0);
  m.server.set_write_timeout(5, 0);
  m.server.set_keep_alive_timeout(kIdleSeconds);
  m.server.set_keep_alive_max_count(1);
  m.server.new_task_queue = [] { return new ConnectionThreads(kMaxConnections); };
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
    if (bound > 0) {
      impl_->server.RaiseBacklog(kListenBacklog);
      return bound;
    }
  } else if (impl_->server.bind_to_port(host, port)) {
    impl_->server.RaiseBacklog(kListenBacklog);
    return port;
  }
  return std::unexpected(Error{
      fmt::format("cannot listen on {}:{}: {}", host, port, errno != 0 ? std::strerror(errno) : "address not usable")});
}

bool ViewServer::Run() { return impl_->server.listen_after_bind(); }

void ViewServer::Stop() { impl_->server.stop(); }

}  // namespace palpa::view
