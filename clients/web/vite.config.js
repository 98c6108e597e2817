// The bundle the gateway serves at "/" (BUILD/web): everything from npm, nothing from a CDN.
import { defineConfig } from "vite";

export default defineConfig({
  base: "./",
  build: {
    outDir: process.env.INSTASCENE_WEB_OUT || "dist",
    emptyOutDir: true,
    chunkSizeWarningLimit: 4096, // three.js + Spark's splat worker are large by nature
    sourcemap: false,
  },
  worker: { format: "es" },
});
