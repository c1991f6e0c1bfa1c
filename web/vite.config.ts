// Build the client into the Python package, where `shadeform app` serves it from.
// `npm run dev` serves it with hot reload and forwards /api to a server started with
// `shadeform app --no-browser --port 8765`.
import { fileURLToPath } from 'node:url';
import { defineConfig, type Plugin } from 'vite';

// three.js's core (maths, cameras, scene objects): the module three.module.js builds on
const THREE_CORE = fileURLToPath(new URL('./node_modules/three/build/three.core.js', import.meta.url));
// the modules that draw (WebGLRenderer): the render worker's, and the page's only in the chunk
// loaded for a browser without OffscreenCanvas (viewer.ts)
const DRAWS = /\/src\/(renderScene|gizmo)\.ts$/;

/**
 * The page's own modules (the camera and its OrbitControls, the print's guides) use three.js's
 * core only: their ``three`` is three.core.js, tree-shaken to what they use. The modules that
 * draw get three.js from its sources (``three/src/Three.js``), modules the page's shares none of:
 * so the renderer, its shaders and the core it needs are all in the chunk that only a browser
 * without OffscreenCanvas loads (that browser then holds two copies of the maths). The page's
 * first task (its bundle evaluated) held and ran them all before: 50 ms median, 26 ms without
 * them, on the 2-core machine at a load of 2-3 (Chromium traces of bench_app_large.py's page).
 * A page module that needs the renderer fails the build (not exported by three.core.js): import
 * it from renderScene.ts. The render worker's bundle is built apart (worker.plugins), from
 * three.module.js as before.
 */
function threeCoreOnThePage(): Plugin {
  return {
    name: 'three-core-on-the-page',
    enforce: 'pre',
    async resolveId(source, importer) {
      if (source !== 'three' || !importer) return null;
      if (!DRAWS.test(importer)) return THREE_CORE;
      return this.resolve('three/src/Three.js', importer, { skipSelf: true });
    },
  };
}

export default defineConfig({
  // relative asset paths: the page works whatever prefix the server mounts it under
  base: './',
  plugins: [threeCoreOnThePage()],
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
