// What survives a page reload, the project file, and the projects the server keeps.
//
// localStorage holds the small part (image info, parameters with the regions, view toggles, the
// photo set and the views with their settings);
// IndexedDB holds the image's original bytes, so that an image the server has forgotten (it
// keeps a bounded number, and none across a restart) can be uploaded again. A project file is
// the same session as one JSON document with the image inline as base64.
//
// The server keeps projects too (/api/projects, in its session store): the work open is
// autosaved there (ProjectAutosave) as the same document with the images named by their ids in
// the server's store, so that it outlives a server restart, cleared storage and another browser.
// localStorage keeps which server project this page works on, one per kind.
import { ApiError, base64ToBytes, bytesToBase64 } from './api';
import type {
  ImageInfo,
  PhotoSetInfo,
  Project,
  ProjectDocument,
  ProjectInfo,
  ProjectList,
  ProjectSource,
  StereoParams,
} from './api.gen';
import { NetworkError, onReconnect, send } from './connection';
import type { ImageSource, Params, Region, ViewsSaved } from './sessionTypes';

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
  /** The photo set open (photometric stereo) and its settings, when one is; how it was viewed
   * (relightModes.ts RelightSettings, checked as it is read back: restoreSettings). */
  photoSet?: { info: PhotoSetInfo; params: StereoParams; viewing?: unknown } | null;
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

/** Whether this browser kept a session for the app (false: a first visit, or storage cleared). */
export function hasSavedSession(): boolean {
  try {
    return localStorage.getItem(SESSION_KEY) !== null;
  } catch {
    return false;
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

// ------------------------------------------------------------------ the server's projects

export type ProjectKind = ProjectInfo['kind'];

/** What the page has open, as a server project: null when nothing is (or nothing worth keeping). */
export interface ProjectSnapshot {
  kind: ProjectKind;
  document: ProjectDocument;
}

/** The server project this page works on, per kind: opening a photo does not end the views' one. */
export type ProjectIds = Record<ProjectKind, string | null>;

const PROJECT_IDS_KEY = 'shadeform.projects.v1';
const AUTOSAVE_MS = 1000;
// a save sent as the page goes away must fit the browser's keepalive budget (64 KiB)
const KEEPALIVE_BYTES = 60_000;

/** A new project id: random, so that it is this project's on every browser and server. */
export function newProjectId(): string {
  // getRandomValues works where randomUUID does not (a page served over plain http to another machine)
  const bytes = crypto.getRandomValues(new Uint8Array(16));
  return Array.from(bytes, (b) => b.toString(16).padStart(2, '0')).join('');
}

export function toProjectSource(source: ImageSource): ProjectSource {
  return {
    kind: source.kind,
    name: source.name,
    type: source.kind === 'upload' ? source.type : null,
    index: source.kind === 'viewset' ? source.index : null,
  };
}

export function fromProjectSource(source: ProjectSource): ImageSource {
  if (source.kind === 'upload') return { kind: 'upload', name: source.name, type: source.type ?? '' };
  if (source.kind === 'viewset') return { kind: 'viewset', name: source.name, index: source.index ?? 0 };
  if (source.kind === 'photoset') return { kind: 'photoset', name: source.name };
  return { kind: source.kind, name: source.name };
}

async function answer<T>(response: Response): Promise<T> {
  if (!response.ok) {
    let detail = `${response.status} ${response.statusText}`.trim();
    try {
      const body = await response.json();
      if (body && typeof body.detail === 'string') detail = body.detail;
    } catch {
      // not JSON: keep the status line
    }
    throw new ApiError(response.status, detail);
  }
  return response.status === 204 ? (undefined as T) : ((await response.json()) as T);
}

function projectUrl(id: string): string {
  return `/api/projects/${encodeURIComponent(id)}`;
}

/** The server's projects, newest first; null when the server keeps none (--no-sessions, or older). */
export async function listProjects(): Promise<ProjectInfo[] | null> {
  try {
    return (await answer<ProjectList>(await send('/api/projects', { cache: 'no-store' }))).projects;
  } catch (err) {
    if (err instanceof ApiError && (err.status === 404 || err.status === 405)) return null;
    throw err;
  }
}

export async function fetchProject(id: string): Promise<Project> {
  return answer<Project>(await send(projectUrl(id), { cache: 'no-store' }));
}

export async function deleteProject(id: string): Promise<void> {
  await answer<void>(await send(projectUrl(id), { method: 'DELETE' }));
}

async function putProject(id: string, document: ProjectDocument): Promise<ProjectInfo> {
  const init = { method: 'PUT', headers: { 'Content-Type': 'application/json' }, body: JSON.stringify(document) };
  return answer<ProjectInfo>(await send(projectUrl(id), init));
}

/**
 * Saves what the page has open to the server, 1 s after the last change, one request at a time
 * (what changes while one is out goes once it is answered, the newest state per project).
 * Failures are silent: a server that is away is the connection's message (connection.ts) and the
 * save goes again once it answers; a server that keeps no projects ends the autosaving for this
 * page.
 */
export class ProjectAutosave {
  private ids: ProjectIds;
  private timer = 0;
  /** Documents to send, per project id, oldest first. */
  private readonly queue = new Map<string, ProjectDocument>();
  private sending = false;
  private off = false;
  private saves = 0;
  private error: string | null = null;

  constructor(private readonly snapshot: () => ProjectSnapshot | null) {
    this.ids = loadProjectIds();
    onReconnect(() => void this.pump());
    // a change made just before the page goes away: sent with the page's last breath, if small
    window.addEventListener('pagehide', () => this.flush());
  }

  /** New work of ``kind`` begins (a photo, a photo set, views opened): a new project. */
  begin(kind: ProjectKind): void {
    this.use(kind, newProjectId());
  }

  /** Work on project ``id`` (opened from the server's list) from now on. */
  use(kind: ProjectKind, id: string): void {
    this.settle(); // the work open until now keeps its last change, under its own id
    this.ids = { ...this.ids, [kind]: id };
    saveProjectIds(this.ids);
  }

  /** Something changed: save in a second unless another change comes first. */
  changed(): void {
    if (this.off) return;
    clearTimeout(this.timer);
    this.timer = window.setTimeout(() => this.settle(), AUTOSAVE_MS);
  }

  /** A save that is due goes now (before other work replaces what the page shows). */
  settle(): void {
    if (!this.timer) return;
    clearTimeout(this.timer);
    this.timer = 0;
    const now = this.current();
    if (!now) return;
    this.queue.delete(now.id); // re-queued as the newest
    this.queue.set(now.id, now.document);
    void this.pump();
  }

  /** For the test hook: the ids, how many saves the server took, whether one is due, the last failure. */
  state() {
    const pending = this.timer !== 0 || this.queue.size > 0 || this.sending;
    return { ids: { ...this.ids }, saves: this.saves, pending, error: this.error, off: this.off };
  }

  private current(): { id: string; document: ProjectDocument } | null {
    const now = this.snapshot();
    if (!now) return null;
    if (!this.ids[now.kind]) {
      this.ids = { ...this.ids, [now.kind]: newProjectId() };
      saveProjectIds(this.ids);
    }
    return { id: this.ids[now.kind]!, document: now.document };
  }

  private async pump(): Promise<void> {
    if (this.sending) return;
    this.sending = true;
    try {
      while (this.queue.size && !this.off) {
        const [id, document] = this.queue.entries().next().value!;
        this.queue.delete(id);
        try {
          await putProject(id, document);
          this.saves += 1;
          this.error = null;
        } catch (err) {
          this.error = (err as Error).message;
          if (err instanceof NetworkError) {
            // kept (unless a newer one came meanwhile) and sent once the server answers
            if (!this.queue.has(id)) this.queue.set(id, document);
            break;
          }
          // a server that keeps no projects (409), or an older one without them: stop asking
          if (err instanceof ApiError && [404, 405, 409].includes(err.status)) this.off = true;
        }
      }
    } finally {
      this.sending = false;
    }
  }

  private flush(): void {
    if (this.off || !this.timer) return;
    clearTimeout(this.timer);
    this.timer = 0;
    const now = this.current();
    if (!now) return;
    const body = JSON.stringify(now.document);
    if (body.length > KEEPALIVE_BYTES) return;
    // not through the connection: a page going away has no one to tell
    fetch(projectUrl(now.id), { method: 'PUT', headers: { 'Content-Type': 'application/json' }, body, keepalive: true }).catch(
      () => undefined,
    );
  }
}

function loadProjectIds(): ProjectIds {
  const none: ProjectIds = { photo: null, photo_set: null, views: null };
  try {
    const saved = JSON.parse(localStorage.getItem(PROJECT_IDS_KEY) ?? 'null') as Partial<ProjectIds> | null;
    return { ...none, ...(saved ?? {}) };
  } catch {
    return none;
  }
}

function saveProjectIds(ids: ProjectIds): void {
  try {
    localStorage.setItem(PROJECT_IDS_KEY, JSON.stringify(ids));
  } catch {
    // storage disabled: the ids last as long as the page
  }
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
