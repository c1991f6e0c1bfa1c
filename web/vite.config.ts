// Build the client into the Python package, where `shadeform app` serves it from.
// `npm run dev` serves it with hot reload and forwards /api to a server started with
// `shadeform app --no-browser --port 8765`.
import { fileURLToPath } from 'node:url';
import { defineConfig } from 'vite';

export default defineConfig({
  // relative asset paths: the page works whatever prefix the server mounts it under
  base: './',
  build: {
    outDir: fileURLToPath(new URL('../src/shadeform/app/static', import.meta.url)),
    emptyOutDir: true,
    // three.js alone is ~600 kB minified; one file loaded from loopback is fine
    chunkSizeWarningLimit: 1200,
  },
  server: {
    proxy: { '/api': 'http://127.0.0.1:8765' },
  },
});
