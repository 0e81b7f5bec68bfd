#pragma once
// The HTTP server behind `edrnr serve`: a JSON API (docs/web.md) and the
// built web front end as static files. Renders go through the engine
// registry (engines.h), one at a time with all cores; simulations run on
// SimQueue's worker. Every refused request gets a 4xx with a JSON body
// {"error", "status", "field"}.
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "serve_catalog.h"

namespace edrnr::serve {

struct ServerOptions {
  CatalogOptions catalog;
  std::vector<std::filesystem::path> chip_preset_dirs;
  std::vector<std::filesystem::path> dram_preset_dirs;
  std::filesystem::path web_dir;  // index.html and its assets; empty: API only
  std::string host = "127.0.0.1";
  int port = 8080;                  // 0: any free port (see port())
  std::string engine;               // empty: "fast" if registered, else "reference"
  int render_threads = 0;           // 0: all cores
  size_t max_waiting_renders = 32;  // more waiting: 503
  size_t http_threads = 48;         // connections served at once
};

class Server {
 public:
  // Scans the folders and registers the routes. Throws Error for a missing
  // folder or an unknown engine.
  explicit Server(ServerOptions options);
  ~Server();
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  // Binds host:port. Throws Error naming the address if it cannot.
  void bind();
  // The bound port (after bind()).
  int port() const;
  // Serves requests until stop() is called (from another thread or a signal).
  void serve();
  void stop();

  // The engine that renders ("fast" or "reference" unless one was named).
  std::string engine_name() const;
  const Catalog& catalog() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace edrnr::serve
