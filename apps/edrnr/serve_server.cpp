#include "serve_server.h"

#include <fmt/format.h>
#include <httplib.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <csignal>
#include <filesystem>
#include <list>
#include <map>
#include <mutex>

#include "core/error.h"
#include "core/file_io.h"
#include "core/metrics.h"
#include "engines.h"
#include "render/fast.h"
#include "serve_image.h"
#include "serve_sim.h"
#include "serve_validate.h"
#include "serve_view.h"

namespace edrnr::serve {

namespace {

const char* kJson = "application/json";
constexpr uint64_t kMaxStaticFileBytes = uint64_t{16} << 20;   // one file of the front end
constexpr uint64_t kMaxStaticTotalBytes = uint64_t{64} << 20;  // all of them (kept in memory)

void send_error(httplib::Response& res, int status, const std::string& field, const std::string& message) {
  res.status = status;
  res.set_header("Cache-Control", "no-store");
  res.set_content(error_json(status, field, message), kJson);
}

void send_json(httplib::Response& res, const nlohmann::json& j, int status = 200) {
  res.status = status;
  res.set_header("Cache-Control", "no-store");
  res.set_content(j.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace), kJson);
}

const cli::Engine& pick_engine(const std::string& wanted) {
  if (!wanted.empty()) return cli::find_engine(wanted);
  try {
    return cli::find_engine("fast");
  } catch (const Error&) {
    return cli::find_engine("reference");
  }
}

// The index in a path segment such as "/image/0": 0..15.
size_t parse_index(const std::string& text) {
  Params p = {{"index", text}};
  return size_t(int_param(p, "index", 0, 15));
}

}  // namespace

struct Server::Impl {
  ServerOptions options;
  Catalog catalog;
  const cli::Engine& engine;
  SimQueue sims;
  httplib::Server http;
  int port = 0;
  std::mutex render_mutex;
  // The fast engine packs a model before rendering it; an interactive client
  // asks for many frames of one model, so the packed form of the most recently
  // rendered models is kept (guarded by render_mutex).
  std::list<std::pair<std::shared_ptr<const SceneModel>, std::unique_ptr<FastRenderer>>> packed;
  std::atomic<size_t> waiting_renders{0};
  std::atomic<uint64_t> renders{0};

  explicit Impl(ServerOptions o)
      : options(std::move(o)),
        catalog(options.catalog, options.chip_preset_dirs),
        engine(pick_engine(options.engine)),
        sims(catalog, options.dram_preset_dirs) {
    routes();
  }

  // Runs `fn`, turning every exception into a JSON error response.
  template <class Fn>
  httplib::Server::Handler guarded(Fn fn) {
    return [fn](const httplib::Request& req, httplib::Response& res) {
      try {
        fn(req, res);
      } catch (const RequestError& e) {
        send_error(res, e.status(), e.field(), e.what());
      } catch (const Error& e) {
        send_error(res, 500, "", e.what());
      } catch (const std::exception& e) {
        send_error(res, 500, "", fmt::format("internal error: {}", e.what()));
      }
    };
  }

  std::string model_param(const Params& p) { return name_param(p, "model", catalog.model_names()); }

  void routes() {
    http.new_task_queue = [n = options.http_threads] { return new httplib::ThreadPool(n); };
    http.set_payload_max_length(kMaxBodyBytes);
    http.set_keep_alive_max_count(1000);
    http.set_read_timeout(10, 0);
    http.set_write_timeout(10, 0);
    http.set_error_handler([](const httplib::Request& req, httplib::Response& res) {
      if (!res.body.empty()) return;
      const std::string what = res.status == 404   ? "not found"
                               : res.status == 413 ? fmt::format("request too large (limit {} bytes)", kMaxBodyBytes)
                                                   : "refused";
      send_error(res, res.status, "", fmt::format("{} {}: {}", req.method, req.path.substr(0, 80), what));
    });
    http.set_exception_handler([](const httplib::Request&, httplib::Response& res, std::exception_ptr) {
      send_error(res, 500, "", "internal error");
    });

    http.Get("/api/health", guarded([](const httplib::Request& req, httplib::Response& res) {
               check_params(req.params, {});
               send_json(res, {{"ok", true}});
             }));

    http.Get("/api/catalog", guarded([this](const httplib::Request& req, httplib::Response& res) {
               check_params(req.params, {});
               nlohmann::json j = catalog.to_json();
               j["engine"] = engine.name;
               j["limits"] = {{"min_side", kMinRenderSide},  {"max_side", kMaxRenderSide},
                              {"max_sim_side", kMaxSimSide}, {"min_radius", kMinRadius},
                              {"max_radius", kMaxRadius},    {"min_fov_deg", kMinFovDeg},
                              {"max_fov_deg", kMaxFovDeg},   {"max_elevation_deg", kMaxElevationDeg}};
               send_json(res, j);
             }));

    http.Get("/api/render", guarded([this](const httplib::Request& req, httplib::Response& res) { render(req, res); }));

    http.Get("/api/groundtruth", guarded([this](const httplib::Request& req, httplib::Response& res) {
               check_params(req.params, {"dataset", "view", "w"});
               const std::string dataset = name_param(req.params, "dataset", catalog.dataset_names());
               // A test view of this dataset, through the same rules as a render.
               std::string model;
               for (const ModelEntry& m : catalog.models())
                 if (m.dataset == dataset) model = m.name;
               if (model.empty()) reject(404, "dataset", fmt::format("dataset '{}' has no model served", dataset));
               const ViewChoice v = parse_view(req.params, catalog, model, kMaxRenderSide);
               const std::shared_ptr<const Image> gt = catalog.ground_truth(v.dataset, v.view, v.factor);
               res.set_header("Cache-Control", "max-age=3600");
               res.set_content(encode_png(*gt), "image/png");
             }));

    http.Post("/api/sim",
              guarded([this](const httplib::Request& req, httplib::Response& res) { submit_sim(req, res); }));
    http.Get(R"(/api/sim/([^/]+))", guarded([this](const httplib::Request& req, httplib::Response& res) {
               check_params(req.params, {});
               send_json(res, sims.status(parse_job_id(req.matches[1].str())));
             }));
    http.Get(R"(/api/sim/([^/]+)/image/([^/]+))", guarded([this](const httplib::Request& req, httplib::Response& res) {
               check_params(req.params, {});
               res.set_content(sims.image_png(parse_job_id(req.matches[1].str()), parse_index(req.matches[2].str())),
                               "image/png");
             }));
    http.Get(R"(/api/sim/([^/]+)/trace/([^/]+))", guarded([this](const httplib::Request& req, httplib::Response& res) {
               check_params(req.params, {});
               const uint64_t id = parse_job_id(req.matches[1].str());
               const size_t index = parse_index(req.matches[2].str());
               res.set_content(sims.trace_json(id, index), kJson);
               res.set_header("Content-Disposition",
                              fmt::format("attachment; filename=\"edrnr-sim-{}-{}-trace.json\"", id, index));
             }));
    http.Delete(R"(/api/sim/([^/]+))", guarded([this](const httplib::Request& req, httplib::Response& res) {
                  check_params(req.params, {"client"});
                  const std::string client = find_param(req.params, "client").value_or("");
                  if (!is_client_id(client)) reject(400, "client", "parameter 'client': 8..64 of [A-Za-z0-9_-]");
                  sims.cancel(parse_job_id(req.matches[1].str()), client);
                  send_json(res, {{"cancelled", true}});
                }));

    // The front end: exactly the files of web_dir, read once at start (a
    // request names one of them or gets a 404; nothing else on disk is reachable).
    if (!options.web_dir.empty()) load_static_files();
    http.Get(".*", [this](const httplib::Request& req, httplib::Response& res) {
      const std::string path = req.path == "/" ? "/index.html" : req.path;
      auto it = static_files.find(path);
      if (it == static_files.end()) {
        send_error(res, 404, "", fmt::format("GET {}: not found", req.path.substr(0, 80)));
        return;
      }
      res.set_header("Cache-Control", path == "/index.html" ? "no-cache" : "max-age=86400");
      res.set_content(it->second.body, it->second.mime);
    });
  }

  struct StaticFile {
    std::string body;
    std::string mime;
  };
  std::map<std::string, StaticFile> static_files;  // by URL path ("/assets/index-x.js")

  void load_static_files() {
    namespace fs = std::filesystem;
    const std::map<std::string, std::string> mimes = {{".html", "text/html; charset=utf-8"},
                                                      {".js", "text/javascript"},
                                                      {".css", "text/css"},
                                                      {".svg", "image/svg+xml"},
                                                      {".png", "image/png"},
                                                      {".ico", "image/x-icon"},
                                                      {".json", "application/json"},
                                                      {".woff2", "font/woff2"},
                                                      {".txt", "text/plain"}};
    std::error_code ec;
    size_t total_bytes = 0;
    for (fs::recursive_directory_iterator it(options.web_dir, ec), end; !ec && it != end; it.increment(ec)) {
      if (!it->is_regular_file(ec)) continue;
      const std::string rel = fs::relative(it->path(), options.web_dir, ec).generic_string();
      const auto mime = mimes.find(it->path().extension().string());
      if (ec || mime == mimes.end() || !is_safe_name(it->path().filename().string())) continue;
      StaticFile f{read_file_text(it->path(), kMaxStaticFileBytes), mime->second};
      total_bytes += f.body.size();
      if (total_bytes > kMaxStaticTotalBytes)
        fail("web front end folder '{}': over {} MiB of files", options.web_dir.string(), kMaxStaticTotalBytes >> 20);
      static_files.emplace("/" + rel, std::move(f));
    }
    if (!static_files.count("/index.html")) fail("web front end folder '{}': no index.html", options.web_dir.string());
  }

  void render(const httplib::Request& req, httplib::Response& res) {
    std::vector<std::string_view> allowed = kViewParams;
    allowed.insert(allowed.end(), {"model", "format"});
    check_params(req.params, allowed);
    const std::string model_name = model_param(req.params);
    const std::string format = choice_param(req.params, "format", {"rgba", "png"}, "rgba");
    const ViewChoice v = parse_view(req.params, catalog, model_name, kMaxRenderSide);
    if (waiting_renders.load() >= options.max_waiting_renders)
      reject(503, "", fmt::format("{} renders are waiting; try again", waiting_renders.load()));
    const std::shared_ptr<const SceneModel> model = catalog.model(model_name);
    std::shared_ptr<const Image> gt;
    if (v.view >= 0) gt = catalog.ground_truth(v.dataset, v.view, v.factor);
    RenderSettings settings;
    settings.threads = options.render_threads;
    Image img;
    double ms = 0;
    {
      ++waiting_renders;
      std::lock_guard lock(render_mutex);
      --waiting_renders;
      const auto t0 = std::chrono::steady_clock::now();
      img = render_frame(model, v.camera, settings);
      ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    }
    ++renders;
    res.set_header("Cache-Control", "no-store");
    res.set_header("X-Render-Ms", fmt::format("{:.2f}", ms));
    res.set_header("X-Engine", engine.name);
    res.set_header("X-Width", std::to_string(img.width));
    res.set_header("X-Height", std::to_string(img.height));
    if (gt && gt->width == img.width && gt->height == img.height)
      res.set_header("X-PSNR-dB", fmt::format("{:.3f}", psnr(img, *gt)));
    if (format == "png")
      res.set_content(encode_png(img), "image/png");
    else
      res.set_content(to_rgba8(img), "application/octet-stream");
  }

  // engine.render(), through a kept FastRenderer for the fast engines. Caller holds render_mutex.
  Image render_frame(const std::shared_ptr<const SceneModel>& model, const Camera& camera,
                     const RenderSettings& settings) {
    const bool fast = engine.render == render_fast, fast_float = engine.render == render_fast_float;
    if (!fast && !fast_float) return engine.render(*model, camera, settings, nullptr);
    auto it = std::find_if(packed.begin(), packed.end(), [&](const auto& p) { return p.first == model; });
    if (it == packed.end()) {
      packed.emplace_front(
          model, std::make_unique<FastRenderer>(*model, settings.form, fast ? FastPath::Auto : FastPath::Float));
      while (packed.size() > 3) packed.pop_back();
    } else {
      packed.splice(packed.begin(), packed, it);
    }
    return packed.front().second->render(camera, settings);
  }

  void submit_sim(const httplib::Request& req, httplib::Response& res) {
    // The fields come from the JSON body only (a form-encoded body would also
    // show up in req.params; it fails to parse as JSON below).
    const Params p = params_from_json_body(req.body);
    std::vector<std::string_view> allowed = kViewParams;
    allowed.insert(allowed.end(), {"client", "model", "preset", "compare", "allow_over_budget"});
    check_params(p, allowed);
    SimRequest rq;
    rq.client = find_param(p, "client").value_or("");
    if (!is_client_id(rq.client))
      reject(400, "client", "field 'client': 8..64 characters of [A-Za-z0-9_-] (the page makes one)");
    rq.model = model_param(p);
    const std::vector<std::string> presets = catalog.preset_names();
    const std::string fallback = std::find(presets.begin(), presets.end(), "edr_nr_40nm") != presets.end()
                                     ? "edr_nr_40nm"
                                     : (presets.empty() ? "" : presets.front());
    rq.presets.push_back(name_param(p, "preset", presets, fallback.empty() ? std::nullopt : std::optional(fallback)));
    if (p.count("compare")) rq.presets.push_back(name_param(p, "compare", presets));
    rq.allow_over_budget = bool_param(p, "allow_over_budget", false);
    const ViewChoice v = parse_view(p, catalog, rq.model, kMaxSimSide);
    rq.camera = v.camera;
    rq.view = v.description;
    if (v.view >= 0) rq.ground_truth = catalog.ground_truth(v.dataset, v.view, v.factor);
    const uint64_t id = sims.submit(std::move(rq));
    send_json(res, {{"id", id}, {"status_url", fmt::format("/api/sim/{}", id)}}, 202);
  }
};

Server::Server(ServerOptions options) : impl_(std::make_unique<Impl>(std::move(options))) {}
Server::~Server() { stop(); }

void Server::bind() {
  // A client that goes away mid-response must not end the process.
  std::signal(SIGPIPE, SIG_IGN);
  const std::string& host = impl_->options.host;
  if (impl_->options.port == 0) {
    impl_->port = impl_->http.bind_to_any_port(host);
    if (impl_->port <= 0) fail("--host '{}': cannot listen on any port", host);
  } else {
    if (!impl_->http.bind_to_port(host, impl_->options.port))
      fail("--host '{}' --port {}: cannot listen there (in use, or not an address of this machine)", host,
           impl_->options.port);
    impl_->port = impl_->options.port;
  }
}

int Server::port() const { return impl_->port; }
void Server::serve() { impl_->http.listen_after_bind(); }
void Server::stop() {
  if (impl_->http.is_running()) impl_->http.stop();
}
std::string Server::engine_name() const { return impl_->engine.name; }
const Catalog& Server::catalog() const { return impl_->catalog; }

}  // namespace edrnr::serve
