// The HTTP API of `shadeform app` (all under /api), typed with the generated schema.
//
// Every error body is {"detail": "<one line>"}; ApiError carries that line and the status so
// the UI can show it as it is and react to 404 (the server forgot an image) specially. Every
// request goes through connection.send (the results the mesh worker fetches tell the connection
// how they went, by answered and unreachable): one that cannot reach the server is a
// NetworkError, and the connection says so and waits for the server to come back. ApiError,
// base64 and the meshes' decoding are decode.ts's (the mesh worker's too), re-exported here.
import type {
  AutoMaskRequest,
  BoxMaskRequest,
  FuseRequest,
  FuseResult,
  ImageInfo,
  MapsResult,
  MaskResult,
  Options,
  PhotoSetInfo,
  ReconstructParams,
  ReconstructRequest,
  ReconstructResult,
  ReliefParams,
  ReliefRequest,
  ReliefResult,
  SeedMaskRequest,
  SolveJob,
  StereoReliefRequest,
  StereoRequest,
  StereoResult,
  ViewSetInfo,
} from './api.gen';
import { answered, send, unreachable } from './connection';
import { ApiError, bytesToBase64, errorLine, type DecodedMesh } from './decode';
import type { DecodeReply, DecodeRequest, MeshBounds } from './meshWorker';

// the decoding the page shares with the mesh worker, for the page's modules as api.*
export { ApiError, base64ToBytes, bytesToBase64, decodeMesh, errorLine, type DecodedMesh } from './decode';

export type StereoRequestBody = StereoRequest;

export type FilterSpec = ReconstructParams['filter'];

async function failure(response: Response): Promise<ApiError> {
  const body = await response.text().catch(() => '');
  return new ApiError(response.status, errorLine(response, body), response.headers);
}

async function json<T>(response: Promise<Response>): Promise<T> {
  const done = await response;
  if (!done.ok) throw await failure(done);
  return (await done.json()) as T;
}

function postJson(url: string, body: unknown, signal?: AbortSignal): Promise<Response> {
  return send(url, {
    method: 'POST',
    headers: { 'Content-Type': 'application/json' },
    body: JSON.stringify(body),
    signal,
  });
}

export function getOptions(): Promise<Options> {
  return json<Options>(send('/api/options'));
}

/** Upload a photo; with ``fit``, one over the pixel limit is downsampled to fit (the server's offer). */
export function uploadImage(file: Blob, name: string, { fit = false } = {}): Promise<ImageInfo> {
  const form = new FormData();
  form.append('file', file, name);
  return json<ImageInfo>(send(`/api/images${fit ? '?fit=true' : ''}`, { method: 'POST', body: form }));
}

export function openExample(name: string): Promise<ImageInfo> {
  return json<ImageInfo>(send(`/api/examples/${encodeURIComponent(name)}`, { method: 'POST' }));
}

export function photoUrl(imageId: string): string {
  return `/api/images/${encodeURIComponent(imageId)}/photo.png`;
}

/** The filter in the server's text form: "none" or "kind:size". */
export function filterText(filter: FilterSpec): string {
  return filter.kind === 'none' ? 'none' : `${filter.kind}:${filter.size}`;
}

export function channelUrl(imageId: string, channel: string, filter: FilterSpec): string {
  const query = new URLSearchParams({ channel, filter: filterText(filter) });
  return `/api/images/${encodeURIComponent(imageId)}/channel.png?${query}`;
}

/** Whether the server still holds the image (it keeps a bounded number, and forgets on restart). */
export async function imageKnown(imageId: string): Promise<boolean> {
  const response = await send(photoUrl(imageId), { method: 'GET', cache: 'no-store' });
  if (response.status === 404) return false;
  if (!response.ok) throw await failure(response);
  return true;
}

export function reconstruct(request: ReconstructRequest, signal?: AbortSignal): Promise<ReconstructResult> {
  return json<ReconstructResult>(postJson('/api/reconstruct', request, signal));
}

/** A reconstruct result and its mesh, fetched and decoded in the mesh worker (its ``mesh`` strings emptied). */
export interface Decoded {
  result: ReconstructResult;
  mesh: DecodedMesh;
  bounds: MeshBounds;
  /** A copy of the mesh's arrays for the 3D view's renderer to take (Viewer.setMesh). */
  spare: DecodedMesh;
  /** Milliseconds the worker took to parse and decode it. */
  decodeMs: number;
}

let worker: Worker | null = null;
let decodeCounter = 0;
const decoding = new Map<number, { resolve: (d: Decoded) => void; reject: (e: Error) => void }>();

function meshWorker(): Worker {
  if (worker) return worker;
  worker = new Worker(new URL('./meshWorker.ts', import.meta.url), { type: 'module' });
  worker.onmessage = (event: MessageEvent<DecodeReply>) => {
    const reply = event.data;
    const waiting = decoding.get(reply.id);
    decoding.delete(reply.id);
    if (!waiting) return;
    if (reply.ok) {
      answered();
      waiting.resolve({ result: reply.result, mesh: reply.mesh, bounds: reply.bounds, spare: reply.spare, decodeMs: reply.decodeMs });
    } else if (reply.status === 0) {
      waiting.reject(unreachable());
    } else {
      answered();
      waiting.reject(new ApiError(reply.status, reply.message));
    }
  };
  return worker;
}

/**
 * A result fetched, parsed and its mesh decoded in the mesh worker: the page's thread never reads
 * its bytes (``body``: a JSON request's, sent with POST). ``signal`` cancels the worker's request.
 */
function decodedResult(url: string, body: unknown, signal?: AbortSignal): Promise<Decoded> {
  signal?.throwIfAborted();
  const id = ++decodeCounter;
  return new Promise<Decoded>((resolve, reject) => {
    decoding.set(id, { resolve, reject });
    const request: DecodeRequest =
      body === undefined ? { id, url, method: 'GET' } : { id, url, method: 'POST', body: JSON.stringify(body) };
    meshWorker().postMessage(request);
    // an aborted request never resolves (its reply, if the worker had it already, is dropped)
    const abort = () => {
      if (!decoding.delete(id)) return;
      meshWorker().postMessage({ cancel: id } satisfies DecodeRequest);
      reject(new DOMException('The request was cancelled', 'AbortError'));
    };
    signal?.addEventListener('abort', abort, { once: true });
  });
}

/** ``reconstruct``, fetched and decoded in the mesh worker. */
export function reconstructDecoded(request: ReconstructRequest, signal?: AbortSignal): Promise<Decoded> {
  return decodedResult('/api/reconstruct', request, signal);
}

// ------------------------------------------------------------- background full solves

/** Start the full-resolution solve in the background (a large photo's): its job, to poll. */
export function startSolve(request: ReconstructRequest, signal?: AbortSignal): Promise<SolveJob> {
  return json<SolveJob>(postJson('/api/solves', request, signal));
}

export function solveProgress(jobId: string, signal?: AbortSignal): Promise<SolveJob> {
  return json<SolveJob>(send(`/api/solves/${encodeURIComponent(jobId)}`, { cache: 'no-store', signal }));
}

export function solveResult(jobId: string, signal?: AbortSignal): Promise<Decoded> {
  return decodedResult(`/api/solves/${encodeURIComponent(jobId)}/result`, undefined, signal);
}

export function cancelSolve(jobId: string): Promise<SolveJob> {
  return json<SolveJob>(send(`/api/solves/${encodeURIComponent(jobId)}`, { method: 'DELETE' }));
}

function maskUrl(imageId: string, what: 'auto' | 'seeds' | 'box' | 'file'): string {
  return `/api/images/${encodeURIComponent(imageId)}/mask/${what}`;
}

/** The automatic mask, or a threshold's (``request.threshold``). */
export function autoMask(imageId: string, request: AutoMaskRequest, signal?: AbortSignal): Promise<MaskResult> {
  return json<MaskResult>(postJson(maskUrl(imageId, 'auto'), request, signal));
}

/** The object under the user's clicks. */
export function seedMask(imageId: string, request: SeedMaskRequest): Promise<MaskResult> {
  return json<MaskResult>(postJson(maskUrl(imageId, 'seeds'), request));
}

/** The object inside a box drawn round it. */
export function boxMask(imageId: string, request: BoxMaskRequest): Promise<MaskResult> {
  return json<MaskResult>(postJson(maskUrl(imageId, 'box'), request));
}

/** A mask file checked against the image (size, not empty) and made the app's PNG. */
export async function maskFile(imageId: string, file: Blob): Promise<MaskResult> {
  const data = bytesToBase64(new Uint8Array(await file.arrayBuffer()));
  return json<MaskResult>(postJson(maskUrl(imageId, 'file'), { data }));
}

/** The exported file and the name the server gave it (Content-Disposition); ``closed``: the
 *  closed model, its back the front mirrored (a guess). */
export function exportMesh(
  request: ReconstructRequest,
  suffix: string,
  signal?: AbortSignal,
  { closed = false } = {},
): Promise<{ blob: Blob; filename: string }> {
  const query = `format=${encodeURIComponent(suffix)}${closed ? '&closed=true' : ''}`;
  return downloaded(postJson(`/api/export?${query}`, request, signal), suffix);
}

// ------------------------------------------------------------------------- photo sets

/** Upload three or more photos, with their light file, strengths and mask when there are. */
export function uploadPhotoSet(
  photos: File[],
  extra: { lights: File | null; intensities: File | null; mask: File | null },
): Promise<PhotoSetInfo> {
  const form = new FormData();
  // the photos' folder where the browser knows it (a folder chosen or dropped): the exports' name
  for (const photo of photos) form.append('photos', photo, photo.webkitRelativePath || photo.name);
  for (const [field, file] of Object.entries(extra)) if (file) form.append(field, file, file.name);
  return json<PhotoSetInfo>(send('/api/photosets', { method: 'POST', body: form }));
}

export function openPhotoSetExample(name: string): Promise<PhotoSetInfo> {
  return json<PhotoSetInfo>(send(`/api/photosets/examples/${encodeURIComponent(name)}`, { method: 'POST' }));
}

export function photoSetPhotoUrl(photosetId: string, index: number): string {
  return `/api/photosets/${encodeURIComponent(photosetId)}/photos/${index}.png`;
}

export function stereo(request: StereoRequest, signal?: AbortSignal): Promise<StereoResult> {
  return json<StereoResult>(postJson('/api/stereo', request, signal));
}

export function exportStereo(request: StereoRequest, suffix: string): Promise<{ blob: Blob; filename: string }> {
  return downloaded(postJson(`/api/stereo/export?format=${encodeURIComponent(suffix)}`, request), suffix);
}

// ------------------------------------------------------------------------------ views

export function openViewSetExample(name: string): Promise<ViewSetInfo> {
  return json<ViewSetInfo>(send(`/api/viewsets/examples/${encodeURIComponent(name)}`, { method: 'POST' }));
}

export function fuse(request: FuseRequest, signal?: AbortSignal): Promise<FuseResult> {
  return json<FuseResult>(postJson('/api/fuse', request, signal));
}

export function exportFused(request: FuseRequest, suffix: string): Promise<{ blob: Blob; filename: string }> {
  return downloaded(postJson(`/api/fuse/export?format=${encodeURIComponent(suffix)}`, request), suffix);
}

// ------------------------------------------------------------------- prints and maps

/**
 * What a print and the maps are made of: the open photo's model (its reconstruction request) or
 * the open photo set's photometric stereo (its stereo request); each has its own routes.
 */
export type ModelSource = { kind: 'photo'; request: ReconstructRequest } | { kind: 'set'; request: StereoRequest };

/** The request of a print of ``source`` with these options. */
export function reliefRequest(source: ModelSource, relief: ReliefParams, request_id: number): ReliefRequest | StereoReliefRequest {
  return source.kind === 'photo'
    ? { image_id: source.request.image_id, params: source.request.params, relief, request_id }
    : { photoset_id: source.request.photoset_id, params: source.request.params, relief, request_id };
}

function printRoute(request: ReliefRequest | StereoReliefRequest | ReconstructRequest | StereoRequest, route: string): string {
  return 'photoset_id' in request ? `/api/stereo/${route}` : `/api/${route}`;
}

export function relief(request: ReliefRequest | StereoReliefRequest, signal?: AbortSignal): Promise<ReliefResult> {
  return json<ReliefResult>(postJson(printRoute(request, 'relief'), request, signal));
}

export function exportRelief(request: ReliefRequest | StereoReliefRequest, suffix: string): Promise<{ blob: Blob; filename: string }> {
  return downloaded(postJson(`${printRoute(request, 'relief/export')}?format=${encodeURIComponent(suffix)}`, request), suffix);
}

export function maps(request: ReconstructRequest | StereoRequest, signal?: AbortSignal): Promise<MapsResult> {
  return json<MapsResult>(postJson(printRoute(request, 'maps'), request, signal));
}

export function mapsZip(request: ReconstructRequest | StereoRequest): Promise<{ blob: Blob; filename: string }> {
  return downloaded(postJson(printRoute(request, 'maps/zip'), request), '.zip');
}

async function downloaded(pending: Promise<Response>, suffix: string): Promise<{ blob: Blob; filename: string }> {
  const response = await pending;
  if (!response.ok) throw await failure(response);
  const disposition = response.headers.get('Content-Disposition') ?? '';
  const named = /filename="?([^";]+)"?/i.exec(disposition);
  return { blob: await response.blob(), filename: named ? named[1] : `model${suffix}` };
}
