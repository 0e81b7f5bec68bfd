import { defineConfig } from "vite";

// Static files for `edrnr serve`: relative asset paths and no source maps, so
// the same sources and package-lock.json give the same files (asset names
// carry a hash of their content only).
export default defineConfig({
  base: "./",
  build: {
    outDir: "dist",
    emptyOutDir: true,
    sourcemap: false,
    target: "es2020",
    chunkSizeWarningLimit: 1024,
  },
  server: {
    // `npm exec vite` during development forwards the API to a running `edrnr serve`.
    proxy: { "/api": "http://127.0.0.1:8080" },
  },
});
