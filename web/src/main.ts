// The app's controller: owns the session (image, parameters, regions, mask, view), talks to the
// server, and wires the image pane, the side panel, the mask tool and the 3D view together. The
// photo-set mode (stereo.ts) and the Views panel (views.ts) own their sessions; the controller
// switches modes and lends them the 3D view.
//
// Requests: every edit sends one reconstruct request (slider drags debounced briefly, one at a
// time); a quick look solved at the mesh's grid (or a coarser one) comes first where the image
// is large enough for it to pay, then the full solve under the same id. A newer request aborts
// the one in flight, and a response whose request_id is not the newest is dropped, so a stale
// model never arrives last. A large photo (more than Options.limits.large_pixels: a 12 Mpx phone
// photo) gets its quick look from a downsampled copy, then its full solve runs in the background
// (/api/solves): a progress bar with Cancel, which stops it and leaves the quick look shown.
// Results are parsed and their meshes decoded in a Web Worker (meshWorker.ts), so that the page
// never blocks on a large one.
//
// What the model on screen is (up to date, computing, out of date, failed) is each session's
// ModelState (modelState.ts); the badge by the 3D view, the export menu and the dimming are drawn
// from the shown session's state and nothing else.
//
// A server that stops answering (connection.ts) fails the open mode's model with UNREACHABLE;
// when it answers again, that mode's solve is sent again (reconnected()).
//
// The work open (one photo, a photo set or the views) is autosaved to the server as a project
// (state.ts, ProjectAutosave); Project ▸ Open recent… lists the server's projects to reopen one,
// and a page whose storage is empty offers the newest.
import './style.css';
import * as api from './api';
import type { ExampleInfo, ImageInfo, Options, ProjectInfo, ReconstructRequest, ReconstructResult, SolveJob } from './api.gen';
import { connectionState, NetworkError, onReconnect, send, UNREACHABLE } from './connection';
import { Panel, type Urgency } from './controls';
import { ImagePane, readUnsure, type Display, type Tool, type Unsure } from './imagePane';
import { MaskTool } from './maskTool';
import { ModelState, statusText, type ModelStateView } from './modelState';
import {
  deleteProject,
  download,
  fetchProject,
  fromProjectSource,
  hasSavedSession,
  listProjects,
  loadImageBytes,
  loadSession,
  PROJECT_FORMAT,
  PROJECT_VERSION,
  ProjectAutosave,
  projectDocument,
  readJsonFile,
  readProject,
  readRegions,
  regionsDocument,
  saveSession,
  storeImageBytes,
  toProjectSource,
  type Axis,
  type ImageSource,
  type Params,
  type ProjectSnapshot,
  type Region,
  type ViewSettings,
} from './state';
import { StereoSession } from './stereo';
import { bindToasts, toast, toasts } from './toast';
import { PART_COLOURS, ViewsSession } from './views';
import { MapsPanel } from './mapsPanel';
import { PrintPanel } from './print';
import { Viewer } from './viewer';
import type { MeshBounds } from './meshWorker';

const DRAG_DEBOUNCE_MS = 40;
/** How often a background solve's progress is asked for. */
const PROGRESS_POLL_MS = 250;
const $ = <T extends HTMLElement>(id: string) => document.getElementById(id) as T;

/** Timestamps (performance.now()) of the last applied result: where the time went. */
interface Timeline {
  requestId: number;
  changed: number;
  sent: number;
  received: number;
  decoded: number;
  rendered: number;
  /** When the first model of this request was drawn (the preview's, if one came). */
  firstRendered: number;
  /** Whether the last model drawn is the quick look (the full one still to come). */
  preview: boolean;
  serverTimings: Record<string, number>;
}

class App {
  private image: ImageInfo | null = null;
  private source: ImageSource | null = null;
  private imageBytes: Blob | null = null; // an upload's original bytes (for re-upload and projects)
  private params: Params;
  private view: ViewSettings;
  private requestCounter = 0;
  private latestSent = 0;
  private inFlight: AbortController | null = null;
  private debounce = 0;
  private changedAt: number | null = null;
  private refitNext = true;
  private result: ReconstructResult | null = null;
  private failureShown: (() => void) | null = null; // takes the last solve failure's message away
  private mesh: api.DecodedMesh | null = null;
  /** A large photo's mask tool is still to ask what its automatic mask is (after the first view). */
  private describeMask = false;
  /** The background full solve running now (a large photo's), to cancel. */
  private job: string | null = null;
  /** A photo refused for its size, offered downsampled (the offer that stays over the image pane). */
  private fitOffer: { file: File; factor: number } | null = null;
  private appliedCount = 0;
  private timeline: Timeline | null = null;
  private saveTimer = 0;
  private solving = false;
  private dragWaiting = false; // a drag moved on while a request was out
  private readonly tasks: string[] = [];
  private initialId: string | null = null;
  /** The one photo's model (the photo set's and the views' are theirs). */
  private readonly model = new ModelState(() => this.showModelState());
  private readonly pane: ImagePane;
  private readonly viewer: Viewer;
  private readonly maskTool: MaskTool;
  // built in a task after the constructor's (App.create)
  private panel!: Panel;
  private stereo!: StereoSession;
  private views!: ViewsSession;
  /** The Print and Maps panels: the one photo's model as a solid in mm, and as texture maps. */
  private print!: PrintPanel;
  private maps!: MapsPanel;
  /** The work open, saved to the server as a project. */
  private readonly projects: ProjectAutosave;
  /**
   * ``freshStorage``: nothing was kept in this browser (a first visit, storage cleared), so the
   * newest server project is offered.
   */
  constructor(
    private readonly options: Options,
    private readonly freshStorage: boolean,
  ) {
    const session = loadSession();
    this.projects = new ProjectAutosave(() => this.projectSnapshot());
    this.params = structuredClone(options.defaults);
    this.view = session.view;
    this.pane = new ImagePane($('image-host'), {
      regions: (regions, final) => this.regionsEdited(regions, final),
      references: (refs) => this.change({ references: refs }, 'now'),
      selection: () => this.showRegions(),
      hover: (pixel) => ($('pixel').textContent = pixel ? `row ${pixel.row}, col ${pixel.col}` : ''),
      hint: (text) => ($('hint').textContent = text),
      notice: (text) => this.notice(text),
    });
    this.viewer = new Viewer($('view-host'));
    this.maskTool = new MaskTool({
      image: () => this.image && { id: this.image.image_id, width: this.image.width, height: this.image.height, channel: this.params.channel },
      changed: (png, refit) => {
        this.refitNext ||= refit;
        this.change({ mask: png }, 'now');
      },
      cleared: () => this.model.changed('the mask was cleared: paint or outline the object'),
      show: (mask, dirty) => this.pane.setMask(mask, dirty),
      redraw: () => this.pane.redraw(),
      hint: (text) => {
        if (this.pane.tool === 'mask') $('hint').textContent = text;
      },
      download: (blob, filename) => download(blob, filename),
      stem: () => this.stem(),
      notice: (text) => this.notice(text),
    });
    this.pane.maskEditor = this.maskTool;
  }

  /**
   * The app, built in three tasks: the image pane, the 3D view and the mask tool; the panels and
   * the other modes' sessions; the menus, the bindings and what the panel shows. Built in one
   * task it held the page 13 ms of thread time, 26-35 ms of wall time on a loaded 2-core
   * machine (Chromium traces of bench_app_large.py's page).
   */
  static async create(options: Options, freshStorage: boolean): Promise<App> {
    const app = new App(options, freshStorage);
    await nextTask();
    app.buildPanels(options);
    await nextTask();
    app.bind();
    return app;
  }

  private buildPanels(options: Options): void {
    this.stereo = new StereoSession(options, {
      showMesh: (result, mesh, refit) => {
        this.mesh = mesh;
        this.viewer.setMesh(mesh, { refit });
        this.viewer.setLight(result.light);
        this.viewer.setPhoto(`data:image/png;base64,${result.albedo_png}`);
        this.modelShown();
        const [low, high] = result.depth_range;
        $('mesh-info').textContent =
          `${mesh.vertexCount.toLocaleString()} vertices · ${mesh.triangleCount.toLocaleString()} triangles · ` +
          `depth ${low.toFixed(1)} … ${high.toFixed(1)} px`;
        $('timing').textContent = `server ${((result.timings.total ?? 0) * 1000).toFixed(0)} ms${result.info.cached ? ' (cached solve)' : ''}`;
      },
      busy: (text, work) => this.busy(text, work),
      solving: (on) => this.setSolving(on),
      toast: (message, kind) => this.toast(message, kind),
      changed: () => this.persist(),
      modelChanged: () => this.showModelState(),
    });
    this.views = new ViewsSession(options, {
      showFused: (result, fused, parts, refit) => {
        this.mesh = fused;
        this.viewer.setMesh(fused, { refit });
        this.viewer.setParts(parts, PART_COLOURS);
        this.viewer.setPartsVisible(this.views.showParts);
        this.viewer.setLight(result.views[0].light); // the object frame is the first view's camera frame
        this.modelShown();
        $('mesh-info').textContent =
          `${fused.vertexCount.toLocaleString()} vertices · ${fused.triangleCount.toLocaleString()} triangles · ` +
          `fused from ${result.views.length} views${result.watertight ? '' : ' · NOT closed'}`;
        $('timing').textContent = `server ${((result.timings.total ?? 0) * 1000).toFixed(0)} ms${result.info.cached ? ' (fused model reused)' : ''}`;
      },
      showParts: (on) => this.viewer.setPartsVisible(on),
      edit: (index) => this.editView(index),
      // an upload's bytes kept for a reload are the open photo's, not a view's: never re-sent for one
      reopen: (source) => (source.kind === 'upload' ? Promise.resolve(null) : this.reopen(source)),
      busy: (text, work) => this.busy(text, work),
      solving: (on) => this.setSolving(on),
      toast: (message, kind) => this.toast(message, kind),
      changed: () => {
        if (document.body.classList.contains('views-mode')) this.showViewsTitle();
        this.persist();
      },
      modelChanged: () => this.showModelState(),
    });
    const modelRequest = () => (this.image ? this.request(0) : null);
    this.print = new PrintPanel(options.relief_defaults, this.viewer, {
      request: modelRequest,
      showModel: () => this.result && this.mesh && this.applyResult(this.result, this.mesh),
      shown: () => this.modelShown(),
      busy: (text, work) => this.busy(text, work),
      toast: (message, kind) => this.toast(message, kind),
    });
    this.maps = new MapsPanel({ request: modelRequest, busy: (text, work) => this.busy(text, work), toast: (message, kind) => this.toast(message, kind) });
    this.panel = new Panel(options, {
      change: (patch, urgency) => this.change(patch, urgency),
      axis: (axis) => this.setAxis(axis),
      selectRegion: (i) => this.pane.select(i),
      removeRegion: (i) => this.pane.removeRegion(i),
      removeReference: (i) => this.change({ references: this.params.references.filter((_, k) => k !== i) }, 'now'),
      clearReferences: () => this.change({ references: [] }, 'now'),
      drawRegion: () => this.setTool('polygon'),
      editReferences: () => this.setTool('reference'),
      editMask: () => this.setTool('mask'),
      loadRegions: () => $<HTMLInputElement>('file-regions').click(),
      saveRegions: () => this.saveRegions(),
      clearRegions: () => this.regionsEdited([], true),
      markUnsure: (i) => this.markUnsure(i),
    });
  }

  private bind(): void {
    this.buildMenus();
    bindToasts();
    $('solve-cancel').addEventListener('click', () => void this.cancelJob());
    $('solve-again').addEventListener('click', () => {
      $('solve-progress').hidden = true;
      this.solve();
    });
    $('fit-accept').addEventListener('click', () => {
      const offer = this.fitOffer;
      if (offer) void this.openFile(offer.file);
    });
    $('fit-dismiss').addEventListener('click', () => this.showFitOffer(null));
    onReconnect(() => this.reconnected());
    // a change made just before a reload is reopened by it, not lost with the pending save
    window.addEventListener('pagehide', () => {
      if (this.saveTimer !== 0) this.saveNow();
    });
    this.bindToolbar();
    this.bindFiles();
    this.bindKeys();
    this.applyView();
    this.setTool('select');
    this.panel.show(this.params);
    this.showReferences();
    this.showRegions();
    this.showEditing();
    this.showModelState();
  }

  /** Reopen what the last visit had open: the server may have forgotten the image. */
  async restore(): Promise<void> {
    const session = loadSession();
    const initial = this.options.initial_image;
    this.initialId = session.initialId;
    if (session.views) this.views.restore(session.views);
    if (initial && initial.image_id !== session.initialId) {
      this.initialId = initial.image_id;
      this.views.editing = null;
      this.projects.begin('photo');
      return this.showImage(initial, { kind: 'initial', name: initial.name }, null);
    }
    if (this.freshStorage) void this.offerNewest(); // not awaited: the page is ready without it
    if (session.viewsOpen) return this.setViewsMode(true);
    if (session.photoSet) {
      this.stereo.reopen(session.photoSet.info, session.photoSet.params);
      this.setStereoMode(true);
      return;
    }
    if (!session.image || !session.source) return;
    try {
      let info = session.image;
      if (!(await api.imageKnown(info.image_id))) {
        const reopened = await this.reopen(session.source);
        if (!reopened) return this.toast(`${forgotten(session.image.name)}; this page has no copy to send again: open it again`, 'info');
        this.toast(`${forgotten(session.image.name)}: ${session.source.kind === 'upload' ? 'sent it again' : 'opened it again'}`, 'info');
        info = reopened;
      } else if (session.source.kind === 'upload') {
        this.imageBytes = await loadImageBytes();
      }
      // defaults first: a session saved by an older client may lack newer fields
      this.showImage(info, session.source, session.params ? { ...this.options.defaults, ...session.params } : null);
    } catch (err) {
      this.toast(`Could not reopen the last image: ${(err as Error).message}`);
    }
  }

  /** A fresh id for the same image: by example name, or by re-sending the stored bytes. */
  private async reopen(source: ImageSource): Promise<ImageInfo | null> {
    if (source.kind === 'example') return api.openExample(source.name);
    if (source.kind === 'initial') return (await api.getOptions()).initial_image;
    if (source.kind === 'viewset') return (await api.openViewSetExample(source.name)).images[source.index] ?? null;
    const bytes = this.imageBytes ?? (await loadImageBytes());
    if (!bytes) return null;
    this.imageBytes = bytes;
    return api.uploadImage(bytes, source.name);
  }

  // ------------------------------------------------------------------------- opening

  async openFile(file: File): Promise<void> {
    if (file.name.toLowerCase().endsWith('.json') || file.type === 'application/json') return this.openJson(file);
    const limit = this.options.limits.max_upload_bytes;
    if (file.size > limit) {
      this.toast(`${file.name} is ${(file.size / 1e6).toFixed(1)} MB; the limit is ${(limit / 1e6).toFixed(1)} MB — use a smaller image`);
      return;
    }
    await this.busy('Uploading…', async () => {
      let info: ImageInfo;
      try {
        info = await api.uploadImage(file, file.name, { fit: this.fitOffer?.file === file });
      } catch (err) {
        if (err instanceof api.ApiError && err.status === 413 && err.headers?.has('X-Shadeform-Fit')) {
          return this.offerFit(file, err);
        }
        throw err;
      }
      this.showFitOffer(null);
      this.views.editing = null;
      this.imageBytes = file;
      await storeImageBytes(file);
      this.projects.begin('photo');
      this.showImage(info, { kind: 'upload', name: file.name, type: file.type }, null);
    });
  }

  /**
   * A photo over the server's pixel limit: an offer that stays over the image pane, in the
   * server's words (its size, the limit, the CLI's tiled command for the full resolution), with
   * one button that opens it downsampled to fit (where it is at most Limits.fit_factor times over).
   */
  private offerFit(file: File, err: api.ApiError): void {
    const fit = err.headers?.get('X-Shadeform-Fit') ?? 'none';
    this.showFitOffer(fit === 'none' ? null : { file, factor: Number(fit) }, err.message);
  }

  private showFitOffer(offer: { file: File; factor: number } | null, message: string | null = null): void {
    this.fitOffer = offer;
    const box = $('fit-offer');
    box.hidden = message === null;
    if (message === null) return;
    const text = $('fit-offer-text');
    text.textContent = '';
    // the command in the message (between backquotes) as code, to copy
    message.split('`').forEach((part, i) => {
      if (i % 2) {
        const code = document.createElement('code');
        code.textContent = part;
        text.append(code);
      } else text.append(part);
    });
    const button = $<HTMLButtonElement>('fit-accept');
    button.hidden = offer === null;
    button.textContent = offer ? `Downsample ${offer.factor}× and open` : '';
  }

  async openExample(name: string): Promise<void> {
    await this.busy('Opening example…', async () => {
      const info = await api.openExample(name);
      this.imageBytes = null;
      await storeImageBytes(null);
      this.views.editing = null;
      this.projects.begin('photo');
      this.showImage(info, { kind: 'example', name }, null);
    });
  }

  /** A JSON file: a project or a regions file, told apart by their content. */
  private async openJson(file: File): Promise<void> {
    try {
      const document = await readJsonFile(file);
      if ((document as { format?: string })?.format === 'shadeform-project') return await this.openProject(document);
      this.loadRegions(readRegions(document));
    } catch (err) {
      this.toast((err as Error).message);
    }
  }

  private async openProject(document: unknown): Promise<void> {
    const { project, bytes } = readProject(document);
    await this.busy('Opening project…', async () => {
      const example = project.image.example;
      let info: ImageInfo;
      let source: ImageSource;
      if (example && this.options.examples.some((e) => e.name === example)) {
        info = await api.openExample(example);
        source = { kind: 'example', name: example };
        this.imageBytes = null;
        await storeImageBytes(null);
      } else {
        info = await api.uploadImage(bytes, project.image.name);
        source = { kind: 'upload', name: project.image.name, type: bytes.type };
        this.imageBytes = bytes;
        await storeImageBytes(bytes);
      }
      this.projects.begin('photo');
      this.view = { ...this.view, ...project.view };
      this.applyView();
      this.views.editing = null;
      this.showImage(info, source, { ...this.options.defaults, ...project.params });
    });
  }

  // ---------------------------------------------------------------- the server's projects

  /** What is open, as the server keeps it: the project file's document, images by their ids. */
  private projectSnapshot(): ProjectSnapshot | null {
    const base = {
      format: PROJECT_FORMAT, version: PROJECT_VERSION, name: null, view: { ...this.view },
      image: null, params: null, photo_set: null, views: null,
    } as const;
    const body = document.body.classList;
    // a view being edited in single-photo mode is the views' work
    if (body.contains('views-mode') || this.views.editing !== null) {
      const saved = this.views.session();
      if (!saved.views.length) return null;
      const views = saved.views.map((view) => ({ ...view, source: toProjectSource(view.source) }));
      return { kind: 'views', document: { ...base, views: { ...saved, views } } };
    }
    if (body.contains('stereo-mode')) {
      const set = this.stereo.session();
      return set && { kind: 'photo_set', document: { ...base, photo_set: set } };
    }
    if (!this.image || !this.source) return null;
    const source = this.source;
    const image = {
      name: source.name,
      type: source.kind === 'upload' ? source.type : '',
      data: null, // the server's session store has the bytes
      example: source.kind === 'example' ? source.name : null,
      source: toProjectSource(source),
      info: { ...this.image },
    };
    return { kind: 'photo', document: { ...base, image, params: structuredClone(this.params) } };
  }

  /** Reopen server project ``id``: its photo (by its id in the server's store, as a reload does),
   * photo set or views, with its settings; from now on the autosave goes to it. */
  private async openServerProject(id: string): Promise<void> {
    $<HTMLDialogElement>('recent-dialog').close();
    $('resume').hidden = true;
    await this.busy('Opening project…', async () => {
      const { document: doc } = await fetchProject(id);
      this.projects.settle(); // the work open now keeps its last change before this replaces it
      const showAsSaved = () => {
        this.view = { ...this.view, ...doc.view };
        this.applyView();
      };
      if (doc.photo_set) {
        showAsSaved();
        this.projects.use('photo_set', id);
        this.stereo.reopen(doc.photo_set.info, doc.photo_set.params);
        this.setStereoMode(true);
        return;
      }
      if (doc.views) {
        showAsSaved();
        this.projects.use('views', id);
        const views = doc.views.views.map((view) => ({ ...view, source: fromProjectSource(view.source) }));
        this.views.restore({ ...doc.views, views });
        const editing = this.views.editing;
        if (editing !== null) this.editView(editing);
        else this.setViewsMode(true);
        return;
      }
      const image = doc.image!;
      const source: ImageSource = image.source
        ? fromProjectSource(image.source)
        : image.example
          ? { kind: 'example', name: image.example }
          : { kind: 'upload', name: image.name, type: image.type };
      // this browser's copy of an upload is another image's: only the project's own bytes may be sent
      const bytes = image.data ? new Blob([api.base64ToBytes(image.data) as Uint8Array<ArrayBuffer>], { type: image.type || 'image/png' }) : null;
      let info: ImageInfo | null = null;
      if (image.info && (await api.imageKnown(image.info.image_id))) info = image.info;
      else if (source.kind === 'upload') info = bytes && (await api.uploadImage(bytes, source.name));
      else info = await this.reopen(source);
      if (!info) throw new Error(`${forgotten(image.name)}; the project has no copy of it: open the image again`);
      // only now that it opened: what is open until now keeps its copy if it did not
      this.imageBytes = bytes;
      await storeImageBytes(bytes);
      showAsSaved();
      this.projects.use('photo', id);
      this.views.editing = null;
      this.showImage(info, source, { ...this.options.defaults, ...doc.params });
    });
  }

  /** Project ▸ Open recent…: the server's projects, newest first, to reopen or forget. */
  private async showRecent(): Promise<void> {
    const dialog = $<HTMLDialogElement>('recent-dialog');
    const list = $('recent-list');
    list.replaceChildren();
    $('recent-note').textContent = 'Asking the server…';
    if (!dialog.open) dialog.showModal();
    let projects: ProjectInfo[] | null;
    try {
      projects = await listProjects();
    } catch (err) {
      $('recent-note').textContent = `Could not list the projects: ${(err as Error).message}`;
      return;
    }
    if (projects === null) {
      $('recent-note').textContent = 'This server keeps no projects; start it without --no-sessions.';
      return;
    }
    $('recent-note').textContent = projects.length
      ? 'Kept by the server as you work, newest first. Open one to go on with it.'
      : 'No projects yet: what you open is kept here as you work.';
    const open = new Set(Object.values(this.projects.state().ids));
    for (const project of projects) list.append(this.recentItem(project, open.has(project.id)));
  }

  private recentItem(project: ProjectInfo, open: boolean): HTMLElement {
    const item = document.createElement('li');
    item.dataset.project = project.id;
    const button = document.createElement('button');
    button.className = 'recent-open';
    button.title = `Open ${project.name}`;
    const name = document.createElement('b');
    name.textContent = project.name;
    const what = document.createElement('small');
    what.textContent = `${describe(project)}${open ? ' · open in this page' : ''}`;
    const when = document.createElement('time');
    when.dateTime = new Date(project.updated * 1000).toISOString();
    when.title = new Date(project.updated * 1000).toLocaleString();
    when.textContent = ago(project.updated);
    button.append(name, what, when);
    button.addEventListener('click', () => this.openServerProject(project.id));
    const forget = document.createElement('button');
    forget.className = 'recent-forget';
    forget.textContent = '×';
    forget.title = 'Forget this project (the server deletes it)';
    forget.setAttribute('aria-label', `Forget ${project.name}`);
    forget.addEventListener('click', async () => {
      try {
        await deleteProject(project.id);
        item.remove();
      } catch (err) {
        this.toast(`Could not forget ${project.name}: ${(err as Error).message}`);
      }
    });
    item.append(button, forget);
    return item;
  }

  /** A page without storage (first visit, cleared, another browser): offer the newest server
   * project on the empty image pane, without opening it. */
  private async offerNewest(): Promise<void> {
    let projects: ProjectInfo[] | null = null;
    try {
      projects = await listProjects();
    } catch {
      return; // the server away: the connection says so
    }
    const newest = projects?.[0];
    // something was opened meanwhile: the offer is moot
    if (!newest || $('image-empty').hidden || this.image || document.body.classList.contains('stereo-mode')) return;
    $('resume-name').textContent = newest.name;
    $('resume-detail').textContent = `${describe(newest)} · ${ago(newest.updated)}`;
    $('resume-open').onclick = () => this.openServerProject(newest.id);
    $('resume').hidden = false;
  }

  /** Make ``info`` the current image, with ``params`` or else its suggested settings. */
  private showImage(info: ImageInfo, source: ImageSource, params: Params | null): void {
    this.setStereoMode(false);
    this.setViewsMode(false);
    this.image = info;
    this.source = source;
    this.result = null;
    this.mesh = null;
    this.refitNext = true;
    this.model.changed('another image opened');
    this.outlived();
    this.params = structuredClone(params ?? { ...this.options.defaults, ...(info.suggested ?? {}) });
    $('image-empty').hidden = true;
    $('image-title').innerHTML = '';
    const name = document.createElement('b');
    name.textContent = info.name;
    $('image-title').append(name, ` ${info.width} × ${info.height} · ${info.channels === 1 ? 'grey' : `${info.channels} channels`}`);
    this.pane.setImage(info.width, info.height, this.sources());
    this.describeMask = this.large();
    this.maskTool.open(this.params.mask ?? null, !this.describeMask);
    this.pane.setRegions(this.params.concave.regions);
    this.viewer.setPhoto(api.photoUrl(info.image_id));
    this.panel.show(this.params);
    this.panel.showResult(null);
    this.showUnsure([]);
    this.showReferences();
    this.showRegions();
    this.showEditing();
    this.persist();
    this.solve();
  }

  /** Photo-set mode (photometric stereo) or one photo: the pane, the panel and exports follow. */
  private setStereoMode(on: boolean): void {
    if (on) this.setViewsMode(false);
    document.body.classList.toggle('stereo-mode', on);
    this.showModelState();
    if (!on) {
      this.stereo.close();
      return;
    }
    this.leaveImage();
    const info = this.stereo.info!;
    $('image-title').innerHTML = '';
    const name = document.createElement('b');
    name.textContent = info.name;
    $('image-title').append(name, ` ${info.count} photos · ${info.width} × ${info.height}`);
    this.persist();
  }

  /** The Views panel (several sides fused into one model) or not: the panes and exports follow. */
  private setViewsMode(on: boolean): void {
    const was = document.body.classList.contains('views-mode');
    if (on) this.setStereoMode(false);
    document.body.classList.toggle('views-mode', on);
    this.showModelState();
    if (!on) {
      if (was) {
        this.views.close();
        this.clearModel();
      }
      return;
    }
    this.leaveImage();
    this.showViewsTitle();
    this.views.show();
    this.persist();
  }

  private showViewsTitle(): void {
    const count = this.views.views.length;
    $('image-title').innerHTML = '';
    const name = document.createElement('b');
    name.textContent = 'Views';
    $('image-title').append(name, ` ${count} photo${count === 1 ? '' : 's'} of one object, fused into one closed model`);
  }

  /** No single photo is open any more (another mode takes the panes): nothing of it is solved or shown. */
  private leaveImage(): void {
    this.inFlight?.abort();
    this.image = null;
    this.source = null;
    this.result = null;
    this.model.reset();
    $('image-empty').hidden = true;
    this.clearModel();
  }

  /** No model on screen (a new mode's comes): the 3D view is empty, the exports off. */
  private clearModel(): void {
    this.mesh = null;
    this.viewer.clear();
    this.viewer.setParts([], PART_COLOURS);
    $('view-empty').hidden = false;
    $('view-host').classList.remove('has-model');
    $('mesh-info').textContent = '';
    $('timing').textContent = '';
    this.showModelState();
  }

  /** A model is on screen: the 3D view's controls are on (the exports follow the model's state). */
  private modelShown(): void {
    $('view-empty').hidden = true;
    $('view-host').classList.add('has-model');
  }

  /** The state of the model the 3D view shows: the mode's session's. */
  private shownModel(): ModelState {
    const body = document.body.classList;
    if (body.contains('stereo-mode')) return this.stereo.model;
    if (body.contains('views-mode')) return this.views.model;
    return this.model;
  }

  /**
   * Everything that tells what the model on screen is, from its ModelState alone: the badge,
   * the export menu (only a current model may be exported: the file would otherwise not be what
   * is shown, or the server would refuse it) and the dimming of a model that is not current.
   */
  private showModelState(): void {
    // called by the sessions' states, the first time before the sessions exist
    if (!this.stereo || !this.views) return;
    // every edit of the photo's inputs comes through here (its model goes stale): so do the panels'
    this.print?.sync();
    this.maps?.sync();
    const { status, message } = this.shownModel();
    const onScreen = $('view-host').classList.contains('has-model');
    const badge = $('model-badge');
    badge.hidden = status === 'none';
    badge.dataset.status = status;
    badge.textContent = statusText(status, message);
    const waiting = status === 'failed' && message === UNREACHABLE;
    badge.title = waiting
      ? 'The model shown is an older one: it is made again once the server answers'
      : status === 'failed' ? 'The model shown is an older one: change a setting to try again' : '';
    $('view-host').dataset.modelStatus = status;
    $('view-host').classList.toggle('outdated', onScreen && status !== 'current');
    const exportable = onScreen && status === 'current';
    const button = $<HTMLButtonElement>('export-button');
    button.disabled = !exportable;
    button.title = exportable
      ? 'Download the current mesh in one of the library\'s formats'
      : 'Export is off until the model on screen is up to date with the settings';
    if (!exportable) $('export-menu').classList.remove('open');
  }

  /**
   * The server answers again: the open mode's solve that failed for want of it goes again (the
   * server kept the session, or the 404 path reopens what it forgot), and previews that could
   * not load meanwhile are asked for again.
   */
  private reconnected(): void {
    this.pane.retryImages();
    const { status, message } = this.shownModel();
    if (status !== 'failed' || message !== UNREACHABLE) return;
    const body = document.body.classList;
    if (body.contains('stereo-mode')) this.stereo.solve();
    else if (body.contains('views-mode')) this.views.solve();
    else this.solve();
  }

  /** A message over the image about what its tool refused; null takes it away. */
  private notice(text: string | null): void {
    const box = $('image-notice');
    box.hidden = text === null;
    box.textContent = text ?? '';
  }

  // the work open keeps its last change (settle) before the other views replace what is shown
  async openViewPhotos(files: File[]): Promise<void> {
    this.projects.settle();
    if (await this.views.openFiles(files)) this.openedViews();
  }

  async openViewSetExample(name: string): Promise<void> {
    this.projects.settle();
    if (await this.views.openExample(name)) this.openedViews();
  }

  /** Other views replaced the list: new work, a new project. */
  private openedViews(): void {
    this.projects.begin('views');
    this.setViewsMode(true);
    this.persist(); // saved even when the panel was open already (no mode change to persist it)
  }

  /** The photo open now, with its settings, becomes one more view. */
  private addView(): void {
    if (!this.image || !this.source) return this.toast('Open a photo first, then add it as a view');
    const angle = this.views.nextAngle();
    const index = this.views.add({ image: this.image, source: this.source, angle, params: this.params });
    this.toast(`Added as view ${index + 1} at ${angle}° — Views fuses the views into one model`, 'info');
  }

  /** Open a view's photo in single-photo mode with its settings; what changes is kept in the view. */
  private editView(index: number): void {
    const view = this.views.views[index];
    if (!view) return;
    // the stored bytes are another photo's: a forgotten upload is then said, not replaced by them
    this.imageBytes = null;
    storeImageBytes(null);
    this.showImage(view.image, view.source, { ...this.options.defaults, ...view.params });
  }

  /** The single-photo panel says which view is being edited, and offers to go back. */
  private showEditing(): void {
    const index = this.views.editing;
    const view = index === null ? undefined : this.views.views[index];
    $('view-editing').hidden = !view;
    $('view-add-row').hidden = !!view;
    $('view-add-group').hidden = !this.image; // nothing to add or edit before a photo is open
    if (view) $('view-editing-name').textContent = `view ${index! + 1} (${view.image.name}, ${view.angle}°)`;
  }

  async openPhotos(files: File[]): Promise<void> {
    this.projects.settle();
    if (await this.stereo.openFiles(files)) this.openedPhotoSet();
  }

  async openPhotoSetExample(name: string): Promise<void> {
    this.projects.settle();
    if (await this.stereo.openExample(name)) this.openedPhotoSet();
  }

  private openedPhotoSet(): void {
    this.projects.begin('photo_set');
    this.setStereoMode(true);
  }

  private sources() {
    const id = this.image!.image_id;
    return {
      photo: api.photoUrl(id),
      before: api.channelUrl(id, this.params.channel, { kind: 'none', size: this.params.filter.size }),
      after: api.channelUrl(id, this.params.channel, this.params.filter),
    };
  }

  // ------------------------------------------------------------------------- editing

  private change(patch: Partial<Params>, urgency: Urgency): void {
    const before = this.params;
    this.params = { ...this.params, ...structuredClone(patch) };
    if (this.image) this.model.changed();
    this.panel.show(this.params);
    if ('references' in patch) this.showReferences();
    if (patch.channel !== undefined && patch.channel !== before.channel) this.maskTool.channelChanged();
    if (this.image && (patch.channel !== undefined || patch.filter !== undefined)) {
      if (patch.channel !== before.channel || JSON.stringify(patch.filter) !== JSON.stringify(before.filter)) {
        this.pane.setSources(this.sources());
      }
    }
    this.persist();
    this.schedule(urgency);
  }

  private regionsEdited(regions: Region[], final: boolean): void {
    this.params = { ...this.params, concave: { regions: structuredClone(regions) } };
    if (this.image) this.model.changed('regions changed');
    this.showRegions();
    if (final) {
      this.persist();
      this.schedule('now');
    }
  }

  /** Make the shown result's ``index``-th unsure area a concave region with its suggested axis. */
  private markUnsure(index: number): void {
    const area = this.pane.unsure[index];
    if (!area) return;
    const region: Region = { polygon: area.polygon.map(([x, y]): [number, number] => [x, y]), axis: area.axis };
    const regions = [...this.params.concave.regions, region];
    this.pane.setRegions(regions);
    this.regionsEdited(regions, true);
  }

  private showUnsure(areas: Unsure[]): void {
    this.pane.setUnsure(areas);
    this.panel.showUnsure(areas, this.params.concave.regions);
  }

  private loadRegions(regions: Region[]): void {
    this.pane.setRegions(regions);
    this.pane.select(null);
    this.regionsEdited(regions, true);
    this.toast(`Loaded ${regions.length} region${regions.length === 1 ? '' : 's'}`, 'info');
  }

  private setAxis(axis: Axis): void {
    this.pane.newAxis = axis;
    const selected = this.pane.selection;
    if (selected !== null) this.pane.setAxis(selected, axis);
    this.showRegions();
    this.pane.redraw();
  }

  private setTool(tool: Tool): void {
    this.pane.setTool(tool);
    for (const button of document.querySelectorAll<HTMLButtonElement>('#tools button')) {
      button.classList.toggle('on', button.dataset.tool === tool);
    }
  }

  private showRegions(): void {
    this.panel.showRegions(this.params.concave.regions, this.pane.selection, this.pane.newAxis);
    this.panel.showUnsure(this.pane.unsure, this.params.concave.regions);
  }

  private showReferences(): void {
    const used = this.result?.references ?? [];
    this.pane.setReferences(this.params.references, used);
    this.panel.showReferences(this.params.references, used);
  }

  // ------------------------------------------------------------------------- solving

  /**
   * Send the current parameters: at once for a click or a slider's release; during a drag after
   * a short pause, and not while a request is out (the server cannot stop a solve it started,
   * so aborting one per drag step would queue solves nobody waits for): the drag's newest state
   * goes as soon as the answer is in.
   */
  private schedule(urgency: Urgency): void {
    if (!this.image) return;
    this.changedAt ??= performance.now();
    clearTimeout(this.debounce);
    if (urgency === 'now') {
      this.dragWaiting = false;
      this.solve();
    } else if (this.solving) {
      this.dragWaiting = true;
    } else {
      this.debounce = window.setTimeout(() => this.solve(), DRAG_DEBOUNCE_MS);
    }
  }

  private request(requestId: number): ReconstructRequest {
    return {
      image_id: this.image!.image_id, params: structuredClone(this.params), request_id: requestId, preview: false,
    };
  }

  private async solve(retried = false): Promise<void> {
    if (!this.image) return;
    clearTimeout(this.debounce);
    this.inFlight?.abort();
    const controller = new AbortController();
    this.inFlight = controller;
    const id = ++this.requestCounter;
    this.latestSent = id;
    const changed = this.changedAt ?? performance.now();
    this.changedAt = null;
    const version = this.model.computing();
    this.setSolving(true);
    $('solve-progress').hidden = true; // a cancelled solve's note goes with the next request
    try {
      // ask for a quick look first (the server gives the full result instead where a quick look
      // would not pay), then the full solve; both under this request's id and abort signal
      let firstRendered: number | null = null;
      for (let preview = true; ; preview = false) {
        const sent = performance.now();
        const background = !preview && this.large();
        const answer = background
          ? await this.solveInBackground(id, controller.signal)
          : await api.reconstructDecoded({ ...this.request(id), preview }, controller.signal);
        if (answer === null) {
          // cancelled: the quick look stays, said to be one
          if (id === this.latestSent) this.model.changed('full resolution cancelled: the quick look is shown');
          return;
        }
        const { result, mesh, bounds, spare } = answer;
        // decoded in the worker: received is when it arrived there, decoded when it came back
        const decoded = performance.now();
        const received = decoded - answer.decodeMs;
        if (result.request_id !== this.latestSent) return; // superseded while on the wire
        this.applyResult(result, mesh, { bounds, spare });
        this.model.arrived(version, !result.preview);
        if (!result.preview) this.outlived();
        if (this.describeMask) {
          this.describeMask = false;
          void this.maskTool.describe();
        }
        const rendered = await this.viewer.rendered();
        if (id !== this.latestSent) return;
        this.appliedCount += 1;
        firstRendered ??= rendered;
        this.timeline = {
          requestId: id, changed, sent, received, decoded, rendered, firstRendered,
          preview: result.preview, serverTimings: result.timings,
        };
        $('timing').textContent = this.timingText(result, rendered - changed);
        // a drag that moved on wants its newest state, not this one at full resolution
        if (!result.preview || this.dragWaiting) break;
      }
    } catch (err) {
      if ((err as Error).name === 'AbortError' || id !== this.latestSent) return;
      if (err instanceof NetworkError) {
        // the connection's message says so; this solve goes again once the server answers
        this.model.failed(version, UNREACHABLE);
        return;
      }
      if (err instanceof api.ApiError && err.status === 404 && !retried && this.source) {
        // the server forgot the image (restarted without its sessions, or its store is full)
        const source = this.source;
        const name = this.image?.name ?? source.name;
        let info: ImageInfo | null = null;
        let why = 'this page has no copy to send again: open the image again';
        try {
          info = await this.reopen(source);
        } catch (reopenErr) {
          if (reopenErr instanceof NetworkError) return this.model.failed(version, UNREACHABLE); // away again
          why = `opening it again failed: ${(reopenErr as Error).message}`;
        }
        if (id !== this.latestSent) return;
        if (info) {
          this.image = info;
          this.pane.setSources(this.sources());
          this.persist();
          this.toast(`${forgotten(name)}: ${source.kind === 'upload' ? 'sent it again' : 'opened it again'}`, 'info');
          return this.solve(true);
        }
        this.model.failed(version, `${forgotten(name)}; ${why}`);
        this.failureShown = toast(`${forgotten(name)}; ${why}`);
        return;
      }
      // the old model stays on screen, dimmed and not exportable, until the next change; a model
      // of another image does not: a new image whose first solve failed shows none
      if (this.result === null) this.clearModel();
      this.model.failed(version, (err as Error).message);
      this.failureShown = toast((err as Error).message);
    } finally {
      if (id === this.latestSent) {
        this.setSolving(false);
        if (this.dragWaiting) {
          this.dragWaiting = false;
          this.solve();
        }
      }
    }
  }

  /** Whether the open photo is large: its full solve runs in the background, with progress. */
  private large(): boolean {
    return !!this.image && this.image.width * this.image.height > this.options.limits.large_pixels;
  }

  /**
   * The full solve of request ``id`` as a background job: its progress shown with Cancel, polled
   * until it ends; the result decoded in the worker, or null if it was cancelled. A newer request
   * (the signal aborted) cancels it on the server too.
   */
  private async solveInBackground(id: number, signal: AbortSignal): Promise<api.Decoded | null> {
    let job = await api.startSolve(this.request(id), signal);
    const jobId = job.job_id;
    const cancel = () => void api.cancelSolve(jobId).catch(() => undefined);
    signal.addEventListener('abort', cancel);
    this.job = jobId;
    try {
      this.showJob(job);
      while (job.state === 'running') {
        await new Promise((resolve) => window.setTimeout(resolve, PROGRESS_POLL_MS));
        signal.throwIfAborted();
        job = await api.solveProgress(jobId, signal);
        if (this.job === jobId) this.showJob(job);
      }
      if (job.state === 'cancelled') return null;
      if (job.state === 'failed') throw new api.ApiError(422, job.detail ?? 'the full-resolution solve failed');
      return await api.solveResult(jobId, signal);
    } finally {
      signal.removeEventListener('abort', cancel);
      if (this.job === jobId) {
        this.job = null;
        $('solve-progress').hidden = true;
      }
    }
  }

  /** The progress bar of the background solve: stage, share done, seconds so far. */
  private showJob(job: SolveJob): void {
    $('solve-progress').hidden = false;
    $('solve-again').hidden = true;
    $('solve-cancel').hidden = false;
    $('solve-bar').hidden = false;
    $('solve-stage').textContent = `Full resolution: ${job.stage_text}`;
    $<HTMLProgressElement>('solve-bar').value = job.fraction;
    $('solve-percent').textContent = `${Math.round(job.fraction * 100)} % · ${job.elapsed.toFixed(0)} s`;
  }

  /** Cancel: the background solve stops (its worker process ends) and the quick look stays. */
  private async cancelJob(): Promise<void> {
    const jobId = this.job;
    if (!jobId) return;
    this.job = null;
    try {
      await api.cancelSolve(jobId);
    } catch (err) {
      this.toast((err as Error).message);
    }
    $('solve-progress').hidden = false;
    $('solve-cancel').hidden = true;
    $('solve-bar').hidden = true;
    $('solve-again').hidden = false;
    $('solve-stage').textContent = 'Full resolution cancelled: the quick look is shown';
    $('solve-percent').textContent = '';
  }

  /** ``decoded``: what the mesh worker found with the mesh (its bounds, the renderer's copy). */
  private applyResult(result: ReconstructResult, mesh: api.DecodedMesh, decoded: { bounds?: MeshBounds; spare?: api.DecodedMesh } = {}): void {
    this.result = result;
    this.mesh = mesh;
    this.viewer.setMesh(mesh, { refit: this.refitNext, ...decoded });
    this.refitNext = false;
    this.viewer.setLight(result.light);
    this.modelShown();
    if (result.mask_png) this.maskTool.solvedWith(result.mask_png); // a large photo's quick look has none
    this.showReferences();
    this.panel.showResult(result);
    // a quick look may leave the areas out: keep the last ones until a result says
    if (!result.preview || 'unsure' in result.info) this.showUnsure(readUnsure(result.info));
    const [low, high] = result.depth_range;
    $('mesh-info').textContent =
      `${mesh.vertexCount.toLocaleString()} vertices · ${mesh.triangleCount.toLocaleString()} triangles · ` +
      `depth ${low.toFixed(1)} … ${high.toFixed(1)} px`;
  }

  private timingText(result: ReconstructResult, total: number): string {
    const server = (result.timings.total ?? 0) * 1000;
    const cached = result.info.cached ? ' (cached solve)' : '';
    if (result.preview && result.info.level) return `quick look (photo ÷ ${result.info.level}) in ${total.toFixed(0)} ms`;
    if (result.preview) return `quick look in ${total.toFixed(0)} ms · refining…`;
    return `server ${server.toFixed(0)} ms${cached} · shown in ${total.toFixed(0)} ms`;
  }

  // --------------------------------------------------------------------------- files

  private async exportFormat(suffix: string): Promise<void> {
    const { status, message } = this.shownModel();
    if (status !== 'current') {
      const now = status === 'none' ? 'no model yet' : statusText(status, message);
      return this.toast(`Nothing exported: the model on screen is not up to date (${now}); export once it is`);
    }
    if (document.body.classList.contains('views-mode')) {
      return this.busy(`Exporting ${suffix}…`, async () => {
        const { blob, filename } = await this.views.exportFormat(suffix);
        download(blob, filename);
      });
    }
    if (document.body.classList.contains('stereo-mode')) {
      return this.busy(`Exporting ${suffix}…`, async () => {
        const { blob, filename } = await this.stereo.exportFormat(suffix);
        download(blob, filename);
      });
    }
    if (!this.image) return this.toast('Open an image first, then export its model');
    await this.busy(`Exporting ${suffix}…`, async () => {
      const { blob, filename } = await api.exportMesh(this.request(++this.requestCounter), suffix);
      download(blob, filename);
    });
  }

  private stem(): string {
    const name = this.image?.name ?? 'shadeform';
    return name.replace(/\.[^.]+$/, '').replace(/[^\w.-]+/g, '_') || 'shadeform';
  }

  private async saveProject(): Promise<void> {
    if (!this.image || !this.source) return this.toast('Open an image first; a project holds the image with its settings');
    await this.busy('Saving project…', async () => {
      let bytes = this.imageBytes;
      if (!bytes) {
        const photo = await send(api.photoUrl(this.image!.image_id));
        if (!photo.ok) throw new Error('the server no longer has this image; open it again, then save');
        bytes = await photo.blob();
      }
      const project = await projectDocument(this.source!, bytes, this.params, this.view);
      download(new Blob([JSON.stringify(project)], { type: 'application/json' }), `${this.stem()}.shadeform.json`);
    });
  }

  private saveRegions(): void {
    const text = JSON.stringify(regionsDocument(this.params.concave.regions), null, 2);
    download(new Blob([text + '\n'], { type: 'application/json' }), `${this.stem()}.regions.json`);
  }

  // ---------------------------------------------------------------------- view, UI

  private applyView(): void {
    $<HTMLInputElement>('wire-toggle').checked = this.view.wireframe;
    $<HTMLInputElement>('normals-toggle').checked = this.view.normalColours;
    $<HTMLInputElement>('texture-toggle').checked = this.view.texture;
    $<HTMLInputElement>('arrow-toggle').checked = this.view.lightArrow;
    $<HTMLInputElement>('mask-toggle').checked = this.view.maskOverlay;
    this.viewer.setOptions(this.view);
    this.pane.showMask = this.view.maskOverlay;
    this.pane.redraw();
  }

  private toggleView(key: keyof ViewSettings): void {
    this.view = { ...this.view, [key]: !this.view[key] };
    this.applyView();
    this.persist();
  }

  private persist(): void {
    // a view being edited keeps what the user changes (its photo too: a forgotten one reopened)
    if (this.image && this.source && this.views.editing !== null) this.views.edited(this.image, this.source, this.params);
    this.projects.changed();
    clearTimeout(this.saveTimer);
    this.saveTimer = window.setTimeout(() => this.saveNow(), 150);
  }

  /** Store what a reload reopens (a change is stored a moment later, or at once when the page goes). */
  private saveNow(): void {
    clearTimeout(this.saveTimer);
    this.saveTimer = 0;
    saveSession({
      image: this.image,
      source: this.source,
      params: this.image ? this.params : null,
      view: this.view,
      initialId: this.initialId,
      photoSet: this.stereo.session(),
      views: this.views.session(),
      viewsOpen: document.body.classList.contains('views-mode'),
    });
  }

  /** The progress indicator: on while a solve or another task (upload, export, ...) runs. */
  private showProgress(): void {
    const on = this.solving || this.tasks.length > 0;
    $('busy').hidden = !on;
    $('progress').hidden = !on;
    $('busy-text').textContent = this.tasks.at(-1) ?? 'Solving…';
  }

  private setSolving(on: boolean): void {
    this.solving = on;
    this.showProgress();
  }

  private async busy(text: string, work: () => Promise<void>): Promise<void> {
    this.tasks.push(text);
    this.showProgress();
    try {
      await work();
    } catch (err) {
      this.toast((err as Error).message);
    } finally {
      this.tasks.splice(this.tasks.indexOf(text), 1);
      this.showProgress();
    }
  }

  toast(message: string, kind: 'error' | 'info' = 'error'): void {
    toast(message, kind);
  }

  /** The last solve's failure is outlived (a model for the current inputs is drawn, or another
   * image opened): its message goes; the badge said the same and now says what holds. */
  private outlived(): void {
    this.failureShown?.();
    this.failureShown = null;
  }

  private buildMenus(): void {
    const examples = $('examples-menu').querySelector('.menu-items')!;
    const photos = this.options.examples.filter((e) => !e.name.startsWith('synth:'));
    const synthetic = this.options.examples.filter((e) => e.name.startsWith('synth:'));
    // one heading per kind; each button names its entry in data-<kind> (data-example, ...)
    const group = (heading: string, entries: ExampleInfo[], kind: string, label: (name: string) => string, open: (name: string) => void) => {
      if (!entries.length) return;
      const title = document.createElement('div');
      title.className = 'heading';
      title.textContent = heading;
      examples.append(title);
      for (const example of entries) {
        const button = document.createElement('button');
        button.dataset[kind] = example.name;
        button.className = 'example';
        button.innerHTML = '<b></b><small></small>';
        button.querySelector('b')!.textContent = label(example.name);
        button.querySelector('small')!.textContent = example.title;
        button.addEventListener('click', () => open(example.name));
        examples.append(button);
      }
    };
    const image = (name: string) => this.openExample(name);
    group('Photographs', photos, 'example', (name) => name, image);
    group('Synthetic scenes (known shape)', synthetic, 'example', (name) => name.replace(/^synth:/, ''), image);
    group('Photo sets (several lights)', this.options.photo_set_examples, 'photoSet',
      (name) => name.replace(/^stereo:/, '') + ' (photo set)', (name) => this.openPhotoSetExample(name));
    group('View sets (several sides)', this.options.view_set_examples, 'viewSet',
      (name) => name.replace(/^views:/, '') + ' (views)', (name) => this.openViewSetExample(name));
    for (const example of this.options.examples) {
      const button = document.createElement('button');
      button.className = 'btn small';
      button.textContent = example.name.replace(/^synth:/, '');
      button.title = example.title;
      button.addEventListener('click', () => this.openExample(example.name));
      $('empty-examples').append(button);
    }

    const exports = $('export-menu').querySelector('.menu-items')!;
    for (const format of this.options.formats) {
      const button = document.createElement('button');
      button.dataset.format = format.suffix;
      button.title = `Download the mesh as ${format.suffix}`;
      button.innerHTML = `<span class="format"></span><span class="desc"></span>`;
      button.querySelector('.format')!.textContent = format.suffix;
      button.querySelector('.desc')!.textContent = format.description;
      button.addEventListener('click', () => this.exportFormat(format.suffix));
      exports.append(button);
    }

    for (const menu of document.querySelectorAll<HTMLElement>('.menu')) {
      menu.querySelector(':scope > button')!.addEventListener('click', (event) => {
        event.stopPropagation();
        const open = !menu.classList.contains('open');
        document.querySelectorAll('.menu.open').forEach((m) => m.classList.remove('open'));
        menu.classList.toggle('open', open);
      });
      menu.querySelector('.menu-items')!.addEventListener('click', () => menu.classList.remove('open'));
    }
    document.addEventListener('click', () => document.querySelectorAll('.menu.open').forEach((m) => m.classList.remove('open')));
  }

  private bindToolbar(): void {
    for (const button of document.querySelectorAll<HTMLButtonElement>('#tools button')) {
      button.addEventListener('click', () => this.setTool(button.dataset.tool as Tool));
    }
    $<HTMLSelectElement>('display').addEventListener('change', (event) => {
      this.pane.display = (event.target as HTMLSelectElement).value as Display;
      this.pane.redraw();
    });
    $('fit-image').addEventListener('click', () => this.pane.fit());
    const toggles: Array<[string, keyof ViewSettings]> = [
      ['wire-toggle', 'wireframe'],
      ['normals-toggle', 'normalColours'],
      ['texture-toggle', 'texture'],
      ['arrow-toggle', 'lightArrow'],
      ['mask-toggle', 'maskOverlay'],
    ];
    for (const [id, key] of toggles) $(id).addEventListener('change', () => this.toggleView(key));
    const nav: Record<string, () => void> = {
      left: () => this.viewer.rotate(-15, 0),
      right: () => this.viewer.rotate(15, 0),
      up: () => this.viewer.rotate(0, 10),
      down: () => this.viewer.rotate(0, -10),
      'zoom-in': () => this.viewer.zoom(1.2),
      'zoom-out': () => this.viewer.zoom(1 / 1.2),
      recenter: () => this.viewer.recenter(),
    };
    for (const button of document.querySelectorAll<HTMLButtonElement>('.nav button')) {
      button.addEventListener('click', () => nav[button.dataset.nav!]());
    }
    $('help').addEventListener('click', () => $<HTMLDialogElement>('help-dialog').showModal());
    $('resume-more').addEventListener('click', () => this.showRecent());
    $('project-menu').addEventListener('click', (event) => {
      const action = (event.target as HTMLElement).closest<HTMLElement>('[data-action]')?.dataset.action;
      if (action === 'save-project') this.saveProject();
      if (action === 'open-project') $<HTMLInputElement>('file-project').click();
      if (action === 'open-recent') this.showRecent();
      if (action === 'save-regions') this.saveRegions();
      if (action === 'load-regions') $<HTMLInputElement>('file-regions').click();
    });
  }

  private bindFiles(): void {
    const pickedAll = (id: string, use: (files: File[]) => void) => {
      const input = $<HTMLInputElement>(id);
      input.addEventListener('change', () => {
        const files = Array.from(input.files ?? []);
        input.value = ''; // choosing the same files again must fire again
        if (files.length) use(files);
      });
    };
    const picked = (id: string, use: (file: File) => void) => pickedAll(id, (files) => use(files[0]));
    $('open-image').addEventListener('click', () => $<HTMLInputElement>('file-image').click());
    picked('file-image', (file) => this.openFile(file));
    $('open-photos').addEventListener('click', () => $<HTMLInputElement>('file-photos').click());
    pickedAll('file-photos', (files) => this.openPhotos(files));
    $('open-views').addEventListener('click', () => this.setViewsMode(true));
    $('views-open').addEventListener('click', () => $<HTMLInputElement>('file-views').click());
    pickedAll('file-views', (files) => this.openViewPhotos(files));
    $('add-view').addEventListener('click', () => this.addView());
    $('view-back').addEventListener('click', () => this.setViewsMode(true));
    picked('file-project', (file) => this.openJson(file));
    picked('file-regions', (file) => this.openJson(file));

    // drag and drop anywhere on the window
    const overlay = $('drop-overlay');
    let depth = 0;
    const hasFiles = (event: DragEvent) => event.dataTransfer?.types.includes('Files') ?? false;
    window.addEventListener('dragenter', (event) => {
      if (!hasFiles(event)) return;
      depth += 1;
      overlay.hidden = false;
    });
    window.addEventListener('dragleave', () => {
      depth = Math.max(0, depth - 1);
      if (!depth) overlay.hidden = true;
    });
    window.addEventListener('dragover', (event) => hasFiles(event) && event.preventDefault());
    window.addEventListener('drop', (event) => {
      event.preventDefault();
      depth = 0;
      overlay.hidden = true;
      const files = Array.from(event.dataTransfer?.files ?? []);
      // several images at once are a photo set (views, in the Views panel); one file opens as before
      const several = files.filter((f) => f.type.startsWith('image/') || /\.tiff?$/i.test(f.name)).length > 1;
      if (several && document.body.classList.contains('views-mode')) this.openViewPhotos(files);
      else if (several) this.openPhotos(files);
      else if (files[0]) this.openFile(files[0]);
    });
  }

  /**
   * Shortcuts, at the document level, wherever the focus is: a clicked checkbox, button, select
   * or slider keeps focus but must not swallow them. Only typing is left alone (a text or number
   * field), and so are the keys a focused control uses itself (see ownKey).
   */
  private bindKeys(): void {
    document.addEventListener('keydown', (event) => {
      const target = event.target as HTMLElement;
      if ($<HTMLDialogElement>('help-dialog').open || $<HTMLDialogElement>('recent-dialog').open) return;
      if (typing(target) || ownKey(target, event.key)) return;
      const openMenus = document.querySelectorAll('.menu.open');
      if (event.key === 'Escape' && openMenus.length) {
        openMenus.forEach((menu) => menu.classList.remove('open'));
        return;
      }
      if ((event.ctrlKey || event.metaKey) && event.key.toLowerCase() === 's') {
        event.preventDefault();
        this.saveProject();
        return;
      }
      if (event.ctrlKey || event.metaKey || event.altKey) return;
      // the image pane's keys act on one photo only
      const photo = !document.body.classList.contains('stereo-mode') && !document.body.classList.contains('views-mode');
      if (photo && this.pane.key(event)) {
        event.preventDefault();
        return;
      }
      const actions: Record<string, () => void> = {
        o: () => $<HTMLInputElement>('file-image').click(),
        v: () => this.setTool('select'),
        p: () => this.setTool('polygon'),
        f: () => this.setTool('reference'),
        k: () => this.setTool('mask'),
        x: () => this.setAxis('x'),
        y: () => this.setAxis('y'),
        b: () => this.setAxis('both'),
        m: () => this.toggleView('maskOverlay'),
        w: () => this.toggleView('wireframe'),
        n: () => this.toggleView('normalColours'),
        t: () => this.toggleView('texture'),
        l: () => this.toggleView('lightArrow'),
        r: () => this.viewer.recenter(),
        ArrowLeft: () => this.viewer.rotate(-15, 0),
        ArrowRight: () => this.viewer.rotate(15, 0),
        ArrowUp: () => this.viewer.rotate(0, 10),
        ArrowDown: () => this.viewer.rotate(0, -10),
        '+': () => this.viewer.zoom(1.2),
        '=': () => this.viewer.zoom(1.2),
        '-': () => this.viewer.zoom(1 / 1.2),
        '?': () => $<HTMLDialogElement>('help-dialog').showModal(),
      };
      if (!photo) for (const key of 'vpfkxybm') delete actions[key];
      const act = event.key === 'O' ? () => $<HTMLInputElement>('file-photos').click() : (actions[event.key] ?? actions[event.key.toLowerCase()]);
      if (act) {
        event.preventDefault();
        act();
      }
    });
  }

  // ------------------------------------------------------------------ test hook

  /** Read-only views for the end-to-end tests and the benchmark (window.shadeform). */
  hook() {
    return {
      state: () => ({
        image: this.image ? { ...this.image } : null,
        params: structuredClone(this.params),
        view: { ...this.view },
        tool: this.pane.tool,
        selectedRegion: this.pane.selection,
        busy: !$('busy').hidden,
        /** The one photo's model: current, computing, stale, failed or none. */
        model: this.model.status,
      }),
      /** The one photo's model state (message, whether shown, the statuses so far). */
      modelState: (): ModelStateView => this.model.view(),
      /** The state of the model the 3D view shows now, whichever mode, as the badge says it. */
      shownModelState: () => ({ ...this.shownModel().view(), badge: $('model-badge').hidden ? null : $('model-badge').textContent }),
      /** Whether the session a reload reopens is stored (no change waits to be). */
      sessionSaved: () => this.saveTimer === 0,
      /** The messages at the bottom of the window, oldest first. */
      toasts: () => toasts(),
      /** The autosave to the server's projects: this page's project ids, saves taken, whether one is due. */
      projects: () => this.projects.state(),
      /** Whether the server answers: "online", or "lost" while it is polled for (connection.ts). */
      connection: () => connectionState(),
      /** The message over the image about what its tool refused, or null. */
      notice: () => ($('image-notice').hidden ? null : $('image-notice').textContent),
      lastResult: () => {
        const r = this.result;
        if (!r) return null;
        return {
          request_id: r.request_id,
          preview: r.preview,
          /** Whether its JSON was parsed and its mesh decoded in the mesh worker (the page kept no base64). */
          decodedInWorker: r.mesh.positions === '' && this.mesh !== null && this.mesh.vertexCount === r.mesh.vertex_count,
          vertex_count: r.mesh.vertex_count,
          triangle_count: r.mesh.triangle_count,
          light: r.light,
          references: r.references,
          depth_range: r.depth_range,
          timings: r.timings,
          info: r.info,
        };
      },
      /** The background full solve's progress bar (a large photo's): shown, its words, the share done. */
      solveProgress: () => ({
        shown: !$('solve-progress').hidden,
        job: this.job,
        text: $('solve-stage').textContent,
        fraction: $<HTMLProgressElement>('solve-bar').value,
        cancellable: !$('solve-cancel').hidden,
      }),
      /** The offer to downsample a photo over the pixel limit, or null. */
      fitOffer: () => ($('fit-offer').hidden ? null : { text: $('fit-offer-text').textContent, button: !$('fit-accept').hidden }),
      /** The id of the newest reconstruct request sent. */
      requests: () => this.latestSent,
      /** How many results have been drawn in the 3D view so far. */
      applied: () => this.appliedCount,
      timeline: () => (this.timeline ? { ...this.timeline } : null),
      depthAt: (row: number, col: number) => this.viewer.depthAt(row, col),
      cameraOffset: () => this.viewer.cameraOffset(),
      mesh: () =>
        this.mesh && {
          positions: Array.from(this.mesh.positions),
          normals: Array.from(this.mesh.normals),
          uvs: this.mesh.uvs ? Array.from(this.mesh.uvs) : [],
          indices: Array.from(this.mesh.indices),
        },
      pagePoint: (x: number, y: number) => this.pane.pagePoint(x, y),
      /** The unsure areas outlined on the image (the newest result's). */
      unsure: () => structuredClone(this.pane.unsure),
      /** The mask tool: whose mask is shown (user or automatic), its pixels, note, error. */
      mask: () => this.maskTool.state(),
      /** Whether pixel (row, col) is object in the mask the pane shows. */
      maskAt: (row: number, col: number) => this.maskTool.at(row, col),
      /** The photo set's session (photometric stereo): what it shows and found. */
      stereo: this.stereo.hook(),
      /** The views' session (several sides fused): the views, the fused model and what is drawn. */
      /** The Print panel's solid (print.ts) and the Maps panel's previews (mapsPanel.ts). */
      print: this.print.hook(),
      maps: this.maps.hook(),
      views: {
        ...this.views.hook(),
        open: () => document.body.classList.contains('views-mode'),
        shownVertexCount: () => this.viewer.vertexCount(),
        partsShown: () => this.viewer.partsShown(),
      },
    };
  }
}

type Hook = ReturnType<App['hook']>;

/**
 * The rest of the work in a later task, so that the page can draw and take input between: the
 * scheduler's yield where there is one (it keeps this work's priority), else a timer.
 */
function nextTask(): Promise<void> {
  const scheduler = (globalThis as { scheduler?: { yield?: () => Promise<void> } }).scheduler;
  if (scheduler?.yield) return scheduler.yield();
  return new Promise((resolve) => setTimeout(resolve, 0));
}

/** Why an image id stopped working, in the user's words. */
function forgotten(name: string): string {
  return `The server no longer had ${name} (it was restarted without its sessions, or let it go)`;
}

/** What a project of each kind is, in Open recent. */
const KIND_WORDS: Record<ProjectInfo['kind'], string> = { photo: 'photo', photo_set: 'photo set', views: 'views' };

/** What a project is (its kind, and what it is of unless its name says it). */
function describe(project: ProjectInfo): string {
  return project.image === project.name ? KIND_WORDS[project.kind] : `${KIND_WORDS[project.kind]} · ${project.image}`;
}

/** How long ago ``seconds`` (since the epoch) was, in a few words. */
function ago(seconds: number): string {
  const minutes = Math.round((Date.now() / 1000 - seconds) / 60);
  if (minutes < 1) return 'just now';
  if (minutes < 60) return `${minutes} min ago`;
  if (minutes < 24 * 60) return `${Math.round(minutes / 60)} h ago`;
  return new Date(seconds * 1000).toLocaleDateString();
}

/** Input types that take no typing: keys there are shortcuts. */
const NOT_TYPED = new Set(['checkbox', 'radio', 'range', 'button', 'submit', 'reset', 'color', 'file', 'image']);

/** Whether keys at ``target`` are text being typed (a text or number field, a text area). */
function typing(target: HTMLElement): boolean {
  if (target.isContentEditable || target instanceof HTMLTextAreaElement) return true;
  return target instanceof HTMLInputElement && !NOT_TYPED.has(target.type);
}

/**
 * Whether a focused control uses ``key`` itself: arrows (and Home, End, Page keys) move a slider
 * or a select's choice; Enter and Space press a button or tick a box. Other keys stay shortcuts
 * there (and are kept from a select's type-to-choose by the handler's preventDefault).
 */
function ownKey(target: HTMLElement, key: string): boolean {
  const slider = target instanceof HTMLInputElement && target.type === 'range';
  if ((slider || target instanceof HTMLSelectElement) && /^(Arrow|Page|Home$|End$)/.test(key)) return true;
  const pressable = target instanceof HTMLButtonElement || target instanceof HTMLSelectElement || target instanceof HTMLInputElement;
  return pressable && (key === 'Enter' || key === ' ');
}

declare global {
  interface Window {
    /** Read-only test hook; ``ready`` settles once the last session is restored. */
    shadeform?: Partial<Hook> & { ready: Promise<void> };
  }
}

async function start(): Promise<void> {
  let resolveReady!: () => void;
  let rejectReady!: (err: unknown) => void;
  const ready = new Promise<void>((resolve, reject) => {
    resolveReady = resolve;
    rejectReady = reject;
  });
  ready.catch(() => undefined); // reported on the page below; a test awaiting it sees the error
  const hook: Partial<Hook> & { ready: Promise<void> } = { ready };
  window.shadeform = hook; // at once, so a test can wait on ready before the options arrive
  try {
    const options = api.getOptions();
    options.catch(() => undefined); // awaited below, after a task
    // the page's first read of its storage loads it (synchronously: 1-20 ms on a loaded machine):
    // in a task of its own while the options are fetched, not in the one that builds the app
    await nextTask();
    const freshStorage = !hasSavedSession();
    const app = await App.create(await options, freshStorage);
    Object.assign(hook, app.hook());
    // the page between building the app and opening its image: one task for both blocked it for
    // 55 ms at start-up on a loaded 2-core machine (bench_app_large.py). The page's number
    // formatting (toLocaleString: the mesh's counts) is set up by the mesh worker, before the
    // first result (meshWorker.ts), no longer in a task of the page's here (11 ms of thread time)
    await nextTask();
    await app.restore();
    resolveReady();
  } catch (err) {
    if (err instanceof NetworkError) {
      // nothing was built without the options: start afresh once the server answers
      onReconnect(() => location.reload());
      toast('Cannot reach the shadeform server: start it with `shadeform app`; this page reloads once it answers.');
    } else {
      toast(`Cannot start the app: ${(err as Error).message}. Reload the page to try again.`);
    }
    rejectReady(err);
  }
}

start();
