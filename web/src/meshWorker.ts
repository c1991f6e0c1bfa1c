// A Web Worker that fetches a reconstruct result and turns its JSON into what the 3D view draws,
// off the page's thread: the response's bytes, JSON parsing, base64 to typed arrays, the bounding
// box and sphere. A 12 Mpx photo's full-resolution mesh is up to 300,000 vertices (the server's
// VIEW_VERTICES), about 20 MB of JSON: parsed on the page it blocked it for hundreds of
// milliseconds, and its bytes read there (fetched by the page) took 10-29 ms of the page's thread
// a chunk (Chromium traces of bench_app_large.py). The arrays come back transferred (no copy);
// the result comes back without its mesh strings.
import type { ReconstructResult } from './api.gen';
import { decodeMesh, errorLine, type DecodedMesh } from './decode';

/** Fetch ``url`` and decode its result (``id`` names the reply), or cancel request ``cancel``. */
export type DecodeRequest =
  | { id: number; url: string; method: 'GET' | 'POST'; body?: string }
  | { cancel: number };

/** Axis-aligned box (min x, y, z, max x, y, z) and bounding sphere (centre x, y, z, radius). */
export interface MeshBounds {
  box: [number, number, number, number, number, number];
  sphere: [number, number, number, number];
}

/** The decoded result; or why not: the server's answer (``status`` and its one line), a request
 * that never reached it or was cancelled (``status`` 0; the page drops a cancelled one's reply),
 * or bytes that did not decode (500). */
export type DecodeReply =
  | { id: number; ok: true; result: ReconstructResult; mesh: DecodedMesh; bounds: MeshBounds; spare: DecodedMesh; decodeMs: number }
  | { id: number; ok: false; status: number; message: string };

/** The box and a sphere round it (its centre, the farthest vertex from it), as three.js finds them. */
export function meshBounds(positions: Float32Array): MeshBounds {
  let [x0, y0, z0, x1, y1, z1] = [Infinity, Infinity, Infinity, -Infinity, -Infinity, -Infinity];
  for (let i = 0; i < positions.length; i += 3) {
    const x = positions[i];
    const y = positions[i + 1];
    const z = positions[i + 2];
    if (x < x0) x0 = x;
    if (x > x1) x1 = x;
    if (y < y0) y0 = y;
    if (y > y1) y1 = y;
    if (z < z0) z0 = z;
    if (z > z1) z1 = z;
  }
  const [cx, cy, cz] = [(x0 + x1) / 2, (y0 + y1) / 2, (z0 + z1) / 2];
  let far = 0;
  for (let i = 0; i < positions.length; i += 3) {
    const d = (positions[i] - cx) ** 2 + (positions[i + 1] - cy) ** 2 + (positions[i + 2] - cz) ** 2;
    if (d > far) far = d;
  }
  return { box: [x0, y0, z0, x1, y1, z1], sphere: [cx, cy, cz, Math.sqrt(far)] };
}

/** The worker's work, a plain function (the JS unit tests call it without a worker). */
export function decodeResult(bytes: ArrayBuffer): { result: ReconstructResult; mesh: DecodedMesh; bounds: MeshBounds } {
  const result = JSON.parse(new TextDecoder().decode(bytes)) as ReconstructResult;
  const mesh = decodeMesh(result.mesh);
  result.mesh = { ...result.mesh, positions: '', normals: '', uvs: '', indices: '' };
  return { result, mesh, bounds: meshBounds(mesh.positions) };
}

/** A mesh's arrays copied, each into its own buffer (one to move to another thread). */
export function meshCopy(mesh: DecodedMesh): DecodedMesh {
  const { positions, normals, uvs, indices } = mesh;
  return { ...mesh, positions: positions.slice(), normals: normals.slice(), uvs: uvs ? uvs.slice() : null, indices: indices.slice() };
}

/** The buffers of a mesh's arrays, to transfer. */
export function meshBuffers(mesh: DecodedMesh): ArrayBuffer[] {
  const arrays = [mesh.positions, mesh.normals, mesh.indices, ...(mesh.uvs ? [mesh.uvs] : [])];
  return [...new Set(arrays.map((array) => array.buffer as ArrayBuffer))];
}

// in a worker (not when imported by a test or the page)
const scope = globalThis as unknown as { document?: unknown; onmessage: unknown; postMessage: (m: unknown, t: Transferable[]) => void; numberFormat?: string };
if (typeof scope.document === 'undefined' && typeof (globalThis as { WorkerGlobalScope?: unknown }).WorkerGlobalScope !== 'undefined') {
  // The page's first number formatted for its locale (toLocaleString: the first mesh's counts)
  // set up number formatting, 11-18 ms of the page's thread on a loaded 2-core machine. Chromium
  // keeps that set-up (ICU's locale data) for the whole renderer process, this worker's thread
  // included: done here, before the first result is decoded, the page's first call then takes
  // under 1 ms (measured in headless Chromium). Kept on the scope: a bundler drops an unused call.
  scope.numberFormat = (0).toLocaleString();
  const requests = new Map<number, AbortController>();
  const reply = (message: DecodeReply, transfer: Transferable[] = []) => scope.postMessage(message, transfer);
  scope.onmessage = async (event: MessageEvent<DecodeRequest>) => {
    const request = event.data;
    if ('cancel' in request) {
      requests.get(request.cancel)?.abort();
      return;
    }
    const { id, url, method, body } = request;
    const controller = new AbortController();
    requests.set(id, controller);
    try {
      let response: Response;
      let bytes: ArrayBuffer;
      try {
        const headers = body === undefined ? undefined : { 'Content-Type': 'application/json' };
        response = await fetch(url, { method, body, headers, cache: 'no-store', signal: controller.signal });
        bytes = await response.arrayBuffer();
      } catch {
        reply({ id, ok: false, status: 0, message: 'the server is not reachable' });
        return;
      }
      if (!response.ok) {
        reply({ id, ok: false, status: response.status, message: errorLine(response, new TextDecoder().decode(bytes)) });
        return;
      }
      const start = performance.now();
      try {
        const { result, mesh, bounds } = decodeResult(bytes);
        const decodeMs = performance.now() - start;
        // the 3D view's renderer takes a copy of the arrays (the page keeps the mesh): made here, as
        // copied on the page a 273k-vertex mesh's 15 MB blocked it for 30-40 ms
        const spare = meshCopy(mesh);
        reply({ id, ok: true, result, mesh, bounds, spare, decodeMs }, [...meshBuffers(mesh), ...meshBuffers(spare)]);
      } catch (err) {
        reply({ id, ok: false, status: 500, message: `the model could not be read: ${(err as Error).message}` });
      }
    } finally {
      requests.delete(id);
    }
  };
}
