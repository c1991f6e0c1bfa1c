// What survives a page reload, and the project file.
//
// localStorage holds the small part (image info, parameters with the regions, view toggles, the
// photo set and the views with their settings);
// IndexedDB holds the image's original bytes, so that an image the server has forgotten (it
// keeps a bounded number, and none across a restart) can be uploaded again. A project file is
// the same session as one JSON document with the image inline as base64.
import { base64ToBytes, bytesToBase64 } from './api';
import type { ImageInfo, PhotoSetInfo, ReconstructParams, StereoParams } from './api.gen';
import type { ViewsSaved } from './views';

export type Params = ReconstructParams;
export type Region = Params['concave']['regions'][number];
export type Axis = Region['axis'];

/** Where the current image came from: a shipped example is reopened by name, an upload re-sent. */
export type ImageSource =
  | { kind: 'example'; name: string }
  | { kind: 'upload'; name: string; type: string }
  | { kind: 'initial'; name: string } // the image `shadeform app IMAGE` was started with
  | { kind: 'viewset'; name: string; index: number }; // a photo of a shipped view set

export interface ViewSettings {
  wireframe: boolean;
  normalColours: boolean;
  texture: boolean;
  maskOverlay: boolean;
  lightArrow: boolean;
}

export interface Session {
  image: ImageInfo | null;
  source: ImageSource | null;
  params: Params | null;
  view: ViewSettings;
  /** The server's start-up image last shown: a server started anew with an image shows it. */
  initialId: string | null;
  /** The photo set open (photometric stereo) and its settings, when one is. */
  photoSet?: { info: PhotoSetInfo; params: StereoParams } | null;
  /** The views (photos of one object from several sides) and the fusion's settings. */
  views?: ViewsSaved | null;
  /** Whether the Views panel was open. */
  viewsOpen?: boolean;
}

export const DEFAULT_VIEW: ViewSettings = {
  wireframe: false,
  normalColours: false,
  texture: false,
  maskOverlay: true,
  lightArrow: true,
};

const SESSION_KEY = 'shadeform.session.v1';
const DB_NAME = 'shadeform';
const STORE = 'images';
const IMAGE_KEY = 'current';

export function loadSession(): Session {
  const empty: Session = { image: null, source: null, params: null, view: { ...DEFAULT_VIEW }, initialId: null };
  try {
    const text = localStorage.getItem(SESSION_KEY);
    if (!text) return empty;
    const saved = JSON.parse(text) as Partial<Session>;
    return {
      image: saved.image ?? null,
      source: saved.source ?? null,
      params: saved.params ?? null,
      view: { ...DEFAULT_VIEW, ...(saved.view ?? {}) },
      initialId: saved.initialId ?? null,
      photoSet: saved.photoSet ?? null,
      views: saved.views ?? null,
      viewsOpen: saved.viewsOpen ?? false,
    };
  } catch {
    return empty; // storage disabled or a corrupt entry: start afresh
  }
}

export function saveSession(session: Session): void {
  try {
    localStorage.setItem(SESSION_KEY, JSON.stringify(session));
  } catch {
    // private mode or quota: the session just won't survive a reload
  }
}

function openDb(): Promise<IDBDatabase> {
  return new Promise((resolve, reject) => {
    const request = indexedDB.open(DB_NAME, 1);
    request.onupgradeneeded = () => request.result.createObjectStore(STORE);
    request.onsuccess = () => resolve(request.result);
    request.onerror = () => reject(request.error);
  });
}

async function withStore<T>(mode: IDBTransactionMode, act: (store: IDBObjectStore) => IDBRequest<T>): Promise<T> {
  const db = await openDb();
  try {
    return await new Promise<T>((resolve, reject) => {
      const request = act(db.transaction(STORE, mode).objectStore(STORE));
      request.onsuccess = () => resolve(request.result);
      request.onerror = () => reject(request.error);
    });
  } finally {
    db.close();
  }
}

/** Keep the uploaded image's bytes for a later re-upload; null forgets them (examples). */
export async function storeImageBytes(blob: Blob | null): Promise<void> {
  try {
    await withStore<unknown>('readwrite', (store) => (blob ? store.put(blob, IMAGE_KEY) : store.delete(IMAGE_KEY)) as IDBRequest<unknown>);
  } catch {
    // no IndexedDB: a reload then needs the image opened again
  }
}

export async function loadImageBytes(): Promise<Blob | null> {
  try {
    const found = await withStore<unknown>('readonly', (store) => store.get(IMAGE_KEY));
    return found instanceof Blob ? found : null;
  } catch {
    return null;
  }
}

// ------------------------------------------------------------------------------ project file

export const PROJECT_FORMAT = 'shadeform-project';
export const PROJECT_VERSION = 1;

export interface ProjectFile {
  format: typeof PROJECT_FORMAT;
  version: number;
  image: { name: string; type: string; data: string; example?: string };
  params: Params;
  view: ViewSettings;
}

export async function projectDocument(
  source: ImageSource,
  bytes: Blob,
  params: Params,
  view: ViewSettings,
): Promise<ProjectFile> {
  const data = bytesToBase64(new Uint8Array(await bytes.arrayBuffer()));
  const image: ProjectFile['image'] = { name: source.name, type: bytes.type || 'image/png', data };
  // an example is reopened by name (full precision, its true mask); the bytes are the fallback
  if (source.kind === 'example') image.example = source.name;
  return { format: PROJECT_FORMAT, version: PROJECT_VERSION, image, params, view };
}

/** Check a parsed project document; the message says what is wrong with the file. */
export function readProject(document: unknown): { project: ProjectFile; bytes: Blob } {
  const doc = document as Partial<ProjectFile> | null;
  if (!doc || typeof doc !== 'object' || doc.format !== PROJECT_FORMAT) {
    throw new Error('not a shadeform project file (its "format" must be "shadeform-project")');
  }
  if (typeof doc.version !== 'number' || doc.version > PROJECT_VERSION) {
    throw new Error(`project file version ${String(doc.version)} is newer than this app reads (${PROJECT_VERSION})`);
  }
  const image = doc.image;
  if (!image || typeof image.data !== 'string' || typeof image.name !== 'string') {
    throw new Error('project file has no image; save the project again from the app');
  }
  if (!doc.params || typeof doc.params !== 'object') {
    throw new Error('project file has no parameters; save the project again from the app');
  }
  const bytes = new Blob([base64ToBytes(image.data) as Uint8Array<ArrayBuffer>], { type: image.type || 'image/png' });
  return { project: doc as ProjectFile, bytes };
}

// ------------------------------------------------------------------------- regions JSON

/** The CLI's regions document (docs/conventions.md), checked enough to give a clear message. */
export function readRegions(document: unknown): Region[] {
  const regions = (document as { regions?: unknown } | null)?.regions;
  if (!Array.isArray(regions)) {
    throw new Error('not a regions file: expected {"regions": [{"polygon": [[x, y], ...], "axis": "x" | "y" | "both"}]}');
  }
  return regions.map((entry, index) => {
    const polygon = (entry as Region)?.polygon;
    const axis = (entry as Region)?.axis;
    const ok =
      Array.isArray(polygon) &&
      polygon.length >= 3 &&
      polygon.every((p) => Array.isArray(p) && p.length === 2 && p.every((v) => typeof v === 'number' && Number.isFinite(v)));
    if (!ok) throw new Error(`region ${index + 1}: "polygon" must be 3 or more [x, y] number pairs`);
    if (axis !== 'x' && axis !== 'y' && axis !== 'both') throw new Error(`region ${index + 1}: "axis" must be "x", "y" or "both"`);
    return { polygon: polygon.map(([x, y]): [number, number] => [x, y]), axis };
  });
}

export function regionsDocument(regions: Region[]): { regions: Region[] } {
  return { regions: regions.map((r) => ({ polygon: r.polygon.map(([x, y]): [number, number] => [x, y]), axis: r.axis })) };
}

/** Offer a blob as a download under ``filename``. */
export function download(blob: Blob, filename: string): void {
  const url = URL.createObjectURL(blob);
  const link = document.createElement('a');
  link.href = url;
  link.download = filename;
  document.body.append(link);
  link.click();
  link.remove();
  setTimeout(() => URL.revokeObjectURL(url), 10_000);
}

/** Read a user-chosen file as JSON, with a message that names the file when it is not JSON. */
export async function readJsonFile(file: File): Promise<unknown> {
  try {
    return JSON.parse(await file.text());
  } catch (err) {
    throw new Error(`${file.name} is not valid JSON (${(err as Error).message})`);
  }
}
