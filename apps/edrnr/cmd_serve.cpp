// edrnr serve: a local web app. It lists the models and datasets it finds,
// renders views on demand as the user orbits, shows the ground-truth test view
// beside the render with its PSNR, and runs cycle simulations of the current
// view in the background, showing their reports as charts (docs/web.md).
#include <fmt/format.h>

#include <csignal>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "commands.h"
#include "core/error.h"
#include "core/limits.h"
#include "search_paths.h"
#include "serve_server.h"

namespace edrnr::cli {
namespace {

namespace fs = std::filesystem;

struct ServeOptions {
  std::string models, data, host = "127.0.0.1", web, engine;
  int port = 8080, threads = 0;
  bool no_procedural = false;
  CLI::Option *models_opt, *data_opt, *web_opt;
};

serve::Server* g_server = nullptr;

void on_signal(int) {
  if (g_server) g_server->stop();
}

// The first existing folder among `candidates` (relative ones against the working directory).
std::optional<fs::path> first_dir(const std::vector<fs::path>& candidates) {
  std::error_code ec;
  for (const fs::path& c : candidates)
    if (fs::is_directory(c, ec)) return c;
  return std::nullopt;
}

std::string joined(const std::vector<fs::path>& paths) {
  std::string s;
  for (const fs::path& p : paths) s += "\n  " + p.string();
  return s;
}

// --models: given, or assets/ here, beside the executable or in the source tree.
fs::path models_dir(const ServeOptions& o) {
  if (o.models_opt->count()) return o.models;
  std::vector<fs::path> candidates = {"assets"};
  if (const fs::path d = executable_dir(); !d.empty()) {
    candidates.push_back(d.parent_path() / "assets");
    candidates.push_back(d.parent_path() / "share" / "edrnr" / "assets");
  }
  if (const fs::path root = source_tree(); !root.empty()) candidates.push_back(root / "assets");
  if (auto d = first_dir(candidates)) return *d;
  fail("no models folder found (looked in:{}); give one with --models", joined(candidates));
}

// --data: given, or the Synthetic-NeRF data beside a checkout (as edrnr reproduce finds it); none is fine.
fs::path data_dir(const ServeOptions& o) {
  if (o.data_opt->count()) return o.data;
  std::vector<fs::path> candidates = {"../shared/data/nerf_synthetic"};
  if (const fs::path root = source_tree(); !root.empty()) candidates.push_back(root / "../shared/data/nerf_synthetic");
  if (auto d = first_dir(candidates)) return fs::path(*d).lexically_normal();
  return {};
}

// --web: given, or the built front end (web/dist) in the source tree, beside the executable or installed.
fs::path web_dir(const ServeOptions& o) {
  if (o.web_opt->count()) {
    std::error_code ec;
    if (!fs::is_regular_file(fs::path(o.web) / "index.html", ec))
      fail("--web '{}': no index.html there (build the front end with scripts/build-web.sh)", o.web);
    return o.web;
  }
  if (auto index = find_shipped_file("web/dist/index.html")) return index->parent_path();
  if (auto index = find_shipped_file("share/edrnr/web/index.html")) return index->parent_path();
  fail(
      "the web front end is not built (no web/dist/index.html in the source tree or beside the executable); "
      "run scripts/build-web.sh, or give the folder with --web");
}

void run_serve(const ServeOptions& o) {
  if (o.port < 0 || o.port > 65535) fail("--port {}: must be 0 (any free port) up to 65535", o.port);
  limits::check_threads(o.threads);
  serve::ServerOptions so;
  so.catalog.models_dir = models_dir(o);
  so.catalog.data_dir = data_dir(o);
  so.catalog.procedural = !o.no_procedural;
  so.chip_preset_dirs = preset_dirs("chip");
  so.dram_preset_dirs = preset_dirs("dram");
  so.web_dir = web_dir(o);
  so.host = o.host;
  so.port = o.port;
  so.engine = o.engine;
  so.render_threads = o.threads;
  serve::Server server(so);
  for (const std::string& s : server.catalog().skipped()) fmt::print("serve: skipped {}\n", s);
  server.bind();
  fmt::print("serve: {} models from {}, {} datasets from {}, {} chip presets; renderer '{}'\n",
             server.catalog().models().size(), so.catalog.models_dir.string(), server.catalog().datasets().size(),
             so.catalog.data_dir.empty() ? "(none found)" : so.catalog.data_dir.string(),
             server.catalog().presets().size(), server.engine_name());
  fmt::print("serve: listening on http://{}:{}/ (Ctrl-C stops)\n", o.host, server.port());
  std::fflush(stdout);
  g_server = &server;
  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);
  server.serve();
  g_server = nullptr;
  fmt::print("serve: stopped\n");
}

void register_serve_cmd(CLI::App& app) {
  auto o = std::make_shared<ServeOptions>();
  CLI::App* cmd =
      app.add_subcommand("serve", "A local web app: orbit models, compare with ground truth, run simulations");
  o->models_opt = cmd->add_option("--models", o->models, "folder of .edrnr models (default: assets/)");
  o->data_opt = cmd->add_option("--data", o->data,
                                "folder of NeRF datasets, one sub-folder each (default: ../shared/data/nerf_synthetic "
                                "here or beside the source tree)");
  cmd->add_option("--port", o->port, "TCP port (0: any free port, printed)")->capture_default_str();
  cmd->add_option("--host", o->host, "address to listen on (loopback by default)")->capture_default_str();
  o->web_opt = cmd->add_option("--web", o->web, "folder of the built front end (default: web/dist)");
  cmd->add_option("--engine", o->engine, "renderer (default: fast if available, else reference)");
  cmd->add_option("--threads", o->threads, "render threads (0: all cores)")->capture_default_str();
  cmd->add_flag("--no-procedural", o->no_procedural, "do not offer the procedural scenes");
  cmd->callback([o] { run_serve(*o); });
}

Registrar reg{90, register_serve_cmd};

}  // namespace
}  // namespace edrnr::cli
