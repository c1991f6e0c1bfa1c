// What the page (api.ts) and the mesh worker (meshWorker.ts) both read in the server's answers:
// an error answer's one line (ApiError), base64, and a mesh's arrays decoded into typed arrays.
// A module of its own so that the worker's bundle needs nothing of the page's (api.ts sends
// through the connection, and starts the worker).
import type { MeshData } from './api.gen';

export class ApiError extends Error {
  constructor(
    readonly status: number,
    message: string,
    /** The response's headers (a refused upload's offer to downsample: X-Shadeform-Fit). */
    readonly headers: Headers | null = null,
  ) {
    super(message);
    this.name = 'ApiError';
  }
}

/** A mesh with its arrays decoded from base64 into typed arrays (shared with WebGL as is). */
export interface DecodedMesh {
  vertexCount: number;
  triangleCount: number;
  positions: Float32Array;
  normals: Float32Array;
  /** Null for a mesh without texture coordinates (a fused model). */
  uvs: Float32Array | null;
  indices: Uint32Array;
}

/** An error answer's one line: its ``{"detail": ...}``, else its status line (a proxy's page). */
export function errorLine(response: Response, body: string): string {
  try {
    const parsed = JSON.parse(body);
    if (parsed && typeof parsed.detail === 'string') return parsed.detail;
  } catch {
    // not JSON: the status line
  }
  return `${response.status} ${response.statusText}`.trim();
}

// Chromium 140+ and Firefox 133+ decode base64 natively, several times faster than atob.
type Base64Decoder = (text: string) => Uint8Array;
const nativeFromBase64 = (Uint8Array as unknown as { fromBase64?: Base64Decoder }).fromBase64;

export function base64ToBytes(text: string): Uint8Array {
  if (nativeFromBase64) return nativeFromBase64(text);
  const binary = atob(text);
  const bytes = new Uint8Array(binary.length);
  for (let i = 0; i < binary.length; i++) bytes[i] = binary.charCodeAt(i);
  return bytes;
}

export function bytesToBase64(bytes: Uint8Array): string {
  const native = (bytes as unknown as { toBase64?: () => string }).toBase64;
  if (native) return native.call(bytes);
  let binary = '';
  const chunk = 0x8000; // String.fromCharCode takes its arguments on the stack
  for (let i = 0; i < bytes.length; i += chunk) {
    binary += String.fromCharCode(...bytes.subarray(i, i + chunk));
  }
  return btoa(binary);
}

// The server sends little-endian arrays; every platform a browser runs on is little-endian,
// so the bytes are viewed in place. A fresh Uint8Array from base64 is 0-offset, so aligned.
function floats(text: string, expected: number, what: string): Float32Array {
  const bytes = base64ToBytes(text);
  const values = new Float32Array(bytes.buffer, bytes.byteOffset, bytes.byteLength / 4);
  if (values.length !== expected) throw new ApiError(500, `mesh ${what}: expected ${expected} values, got ${values.length}`);
  return values;
}

export function decodeMesh(mesh: MeshData): DecodedMesh {
  const v = mesh.vertex_count;
  const t = mesh.triangle_count;
  const indexBytes = base64ToBytes(mesh.indices);
  const indices = new Uint32Array(indexBytes.buffer, indexBytes.byteOffset, indexBytes.byteLength / 4);
  if (indices.length !== 3 * t) throw new ApiError(500, `mesh indices: expected ${3 * t} values, got ${indices.length}`);
  return {
    vertexCount: v,
    triangleCount: t,
    positions: floats(mesh.positions, 3 * v, 'positions'),
    normals: floats(mesh.normals, 3 * v, 'normals'),
    uvs: mesh.uvs ? floats(mesh.uvs, 2 * v, 'uvs') : null,
    indices,
  };
}
