// The app's shell and the page's start. The App builds the panels and the other modes' sessions,
// switches between the three modes (one photo; a photo set: stereo.ts; the views: views.ts) and
// lends them the 3D view, keeps the session for a reload, runs the busy indicator and sets up the
// test hook. The panels are modules of their own, each with its wiring, handlers and rendering:
//
//   photo.ts          the one photo open: image, source, settings, last result, model state
//   photoPanel.ts     its image pane, mask tool, parameter panel and Add-as-view group
//   solvePanel.ts     its solves (quick look, full solve, a large photo's in the background)
//   viewerPanel.ts    the 3D view: the model shown, its badge, Export, the view's toggles
//   openPanel.ts      opening images, examples, files, photo sets, views; restoring a reload
//   projectsPanel.ts  the Project menu, the server's projects (Open recent…, the autosave's snapshot)
//   printPanel.ts, mapsPanel.ts   the Print and Maps panels
//   keys.ts           the keyboard shortcuts
//
// What the model on screen is (up to date, computing, out of date, failed) is each session's
// ModelState (modelState.ts); the badge by the 3D view, the export menu and the dimming are drawn
// from the shown session's state and nothing else.
//
// A server that stops answering (connection.ts) fails the open mode's model with UNREACHABLE;
// when it answers again, that mode's solve is sent again (reconnected()).
//
// The work open (one photo, a photo set or the views) is autosaved to the server as a project
// (state.ts, ProjectAutosave; projectsPanel.ts); Project ▸ Open recent… lists the server's
// projects to reopen one, and a page whose storage is empty offers the newest.
import './style.css';
import * as api from './api';
import type { ImageInfo, Options } from './api.gen';
import { connectionState, NetworkError, onReconnect, UNREACHABLE } from './connection';
import { $ } from './dom';
import { bindKeys } from './keys';
import { MapsPanel } from './mapsPanel';
import { statusText, type ModelState, type ModelStateView } from './modelState';
import { OpenPanel } from './openPanel';
import { Photo } from './photo';
import { PhotoPanel } from './photoPanel';
import { PrintPanel } from './printPanel';
import { ProjectsPanel } from './projectsPanel';
import type { ImageSource, Params } from './sessionTypes';
import { SolvePanel } from './solvePanel';
import { download, hasSavedSession, loadSession, ProjectAutosave, saveSession, storeImageBytes } from './state';
import { StereoSession } from './stereo';
import { bindToasts, toast, toasts } from './toast';
import { Viewer } from './viewer';
import { ViewerPanel } from './viewerPanel';
import { ViewsSession } from './views';

class App {
  /** The one photo (single-photo mode); the photo set's and the views' are their sessions'. */
  private readonly photo: Photo;
  private readonly photoPanel: PhotoPanel;
  private readonly viewerPanel: ViewerPanel;
  /** The work open, saved to the server as a project. */
  private readonly projects: ProjectAutosave;
  private saveTimer = 0;
  private solving = false;
  private readonly tasks: string[] = [];
  // built in a task after the constructor's (App.create)
  private stereo!: StereoSession;
  private views!: ViewsSession;
  private solver!: SolvePanel;
  private opener!: OpenPanel;
  private recent!: ProjectsPanel;
  /** The Print and Maps panels: the one photo's model as a solid in mm, and as texture maps. */
  private print!: PrintPanel;
  private maps!: MapsPanel;

  /**
   * ``freshStorage``: nothing was kept in this browser (a first visit, storage cleared), so the
   * newest server project is offered.
   */
  constructor(
    private readonly options: Options,
    private readonly freshStorage: boolean,
  ) {
    const session = loadSession();
    this.projects = new ProjectAutosave(() => this.recent.snapshot());
    this.photo = new Photo(options, () => this.showModelState());
    this.photoPanel = new PhotoPanel(this.photo, {
      schedule: (urgency) => this.solver.schedule(urgency),
      persist: () => this.persist(),
    });
    this.viewerPanel = new ViewerPanel(new Viewer($('view-host')), this.photoPanel.pane, session.view, this);
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
    const viewerPanel = this.viewerPanel;
    const busy = (text: string, work: () => Promise<void>) => this.busy(text, work);
    this.stereo = new StereoSession(options, {
      showMesh: (result, mesh, refit) => viewerPanel.showStereo(result, mesh, refit),
      busy,
      solving: (on) => this.setSolving(on),
      toast: (message, kind) => toast(message, kind),
      changed: () => this.persist(),
      viewingChanged: () => this.saveSoon(),
      modelChanged: () => this.showModelState(),
    });
    this.views = new ViewsSession(options, {
      showFused: (result, fused, parts, refit) => viewerPanel.showFused(result, fused, parts, refit, this.views.showParts),
      showParts: (on) => viewerPanel.viewer.setPartsVisible(on),
      edit: (index) => this.editView(index),
      // an upload's bytes kept for a reload are the open photo's, not a view's: never re-sent for one
      reopen: (source) => (source.kind === 'upload' ? Promise.resolve(null) : this.opener.reopen(source)),
      busy,
      solving: (on) => this.setSolving(on),
      toast: (message, kind) => toast(message, kind),
      changed: () => {
        if (document.body.classList.contains('views-mode')) this.showViewsTitle();
        this.persist();
      },
      modelChanged: () => this.showModelState(),
    });
    // the open photo set's model in its mode, else the open photo's
    const modelRequest = (): api.ModelSource | null => {
      if (document.body.classList.contains('stereo-mode')) {
        const request = this.stereo.current();
        return request ? { kind: 'set', request } : null;
      }
      return this.photo.image ? { kind: 'photo', request: this.photo.request(0) } : null;
    };
    this.print = new PrintPanel(options.relief_defaults, viewerPanel.viewer, {
      request: modelRequest,
      showModel: () => (document.body.classList.contains('stereo-mode') ? this.stereo.showModel() : this.solver.showModel()),
      shown: () => viewerPanel.modelShown(),
      busy,
      toast: (message, kind) => toast(message, kind),
    });
    this.maps = new MapsPanel({ request: modelRequest, busy, toast: (message, kind) => toast(message, kind) });
    this.photoPanel.buildControls(options, this.views);
    this.solver = new SolvePanel(this.photo, viewerPanel, this.photoPanel.pane, this.photoPanel.maskTool, {
      setSolving: (on) => this.setSolving(on),
      isSolving: () => this.solving,
      persist: () => this.persist(),
      reopen: (source) => this.opener.reopen(source),
      showResult: (result) => this.photoPanel.showResult(result),
    });
    // what opening and the server's projects ask of the shell
    const shell = {
      busy,
      showImage: (info: ImageInfo, source: ImageSource, params: Params | null) => this.showImage(info, source, params),
      setStereoMode: (on: boolean) => this.setStereoMode(on),
      setViewsMode: (on: boolean) => this.setViewsMode(on),
    };
    this.opener = new OpenPanel(options, this.photo, this.projects, this.stereo, this.views, this.photoPanel, viewerPanel, {
      ...shell,
      persist: () => this.persist(),
      offerNewest: () => this.recent.offerNewest(),
    });
    this.recent = new ProjectsPanel(options, this.photo, this.projects, this.stereo, this.views, this.photoPanel, viewerPanel, {
      ...shell,
      editView: (index) => this.editView(index),
      reopen: (source) => this.opener.reopen(source),
    });
  }

  private bind(): void {
    this.opener.bind(); // the Examples menu, the open buttons and files, the fit offer
    this.viewerPanel.bind(this.options); // the Export menu, the view's toggles and buttons
    bindMenus();
    bindToasts();
    onReconnect(() => this.reconnected());
    // a change made just before a reload is reopened by it, not lost with the pending save
    window.addEventListener('pagehide', () => {
      if (this.saveTimer !== 0) this.saveNow();
    });
    this.photoPanel.bind();
    $('help').addEventListener('click', () => $<HTMLDialogElement>('help-dialog').showModal());
    this.recent.bind();
    const { photoPanel, viewerPanel } = this;
    bindKeys({
      viewer: viewerPanel.viewer,
      saveProject: () => this.recent.saveProject(),
      paneKey: (event) => photoPanel.pane.key(event),
      setTool: (tool) => photoPanel.setTool(tool),
      setAxis: (axis) => photoPanel.setAxis(axis),
      toggleView: (key) => viewerPanel.toggleView(key),
    });
    viewerPanel.applyView();
    photoPanel.setTool('select');
    photoPanel.show(this.photo.params);
    photoPanel.showReferences();
    photoPanel.showRegions();
    photoPanel.showEditing();
    this.showModelState();
  }

  /** Reopen what the last visit had open: the server may have forgotten the image. */
  restore(): Promise<void> {
    return this.opener.restore(this.freshStorage);
  }

  // --------------------------------------------------------------------------- modes

  /** Make ``info`` the current image, with ``params`` or else its suggested settings. */
  private showImage(info: ImageInfo, source: ImageSource, params: Params | null): void {
    const { photo, photoPanel } = this;
    this.setStereoMode(false);
    this.setViewsMode(false);
    photo.image = info;
    photo.source = source;
    photo.result = null;
    this.viewerPanel.mesh = null;
    photo.refitNext = true;
    photo.model.changed('another image opened');
    this.solver.outlived();
    photo.params = structuredClone(params ?? { ...this.options.defaults, ...(info.suggested ?? {}) });
    $('image-empty').hidden = true;
    showTitle(info.name, ` ${info.width} × ${info.height} · ${info.channels === 1 ? 'grey' : `${info.channels} channels`}`);
    photoPanel.pane.setImage(info.width, info.height, photo.sources());
    this.solver.describeMask = photo.large();
    photoPanel.maskTool.open(photo.params.mask ?? null, !this.solver.describeMask);
    photoPanel.pane.setRegions(photo.params.concave.regions);
    this.viewerPanel.viewer.setPhoto(api.photoUrl(info.image_id));
    photoPanel.show(photo.params);
    photoPanel.showResult(null);
    photoPanel.showUnsure([]);
    photoPanel.showReferences();
    photoPanel.showRegions();
    photoPanel.showEditing();
    this.persist();
    this.solver.solve();
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
    showTitle(info.name, ` ${info.count} photos · ${info.width} × ${info.height}`);
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
        this.viewerPanel.clearModel();
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
    showTitle('Views', ` ${count} view${count === 1 ? '' : 's'} of one object, fused into one closed model`);
  }

  /** No single photo is open any more (another mode takes the panes): nothing of it is solved or shown. */
  private leaveImage(): void {
    this.solver.abort();
    this.photo.image = null;
    this.photo.source = null;
    this.photo.result = null;
    this.photo.model.reset();
    $('image-empty').hidden = true;
    this.viewerPanel.clearModel();
  }

  /** Open a view's photo in single-photo mode with its settings; what changes is kept in the view. */
  private editView(index: number): void {
    const view = this.views.views[index];
    if (!view || view.photo_set) return; // a photo set's view has nothing to edit in single-photo mode
    // the stored bytes are another photo's: a forgotten upload is then said, not replaced by them
    this.photo.imageBytes = null;
    storeImageBytes(null);
    this.showImage(view.image, view.source, { ...this.options.defaults, ...view.params });
  }

  /** The state of the model the 3D view shows: the mode's session's. */
  private shownModel(): ModelState {
    const body = document.body.classList;
    if (body.contains('stereo-mode')) return this.stereo.model;
    if (body.contains('views-mode')) return this.views.model;
    return this.photo.model;
  }

  /** The badge, the export menu and the dimming, from the shown model's state (viewerPanel.ts). */
  showModelState(): void {
    // called by the sessions' states, the first time before the sessions exist
    if (!this.stereo || !this.views) return;
    // every edit of the photo's inputs comes through here (its model goes stale): so do the panels'
    this.print?.sync();
    this.maps?.sync();
    this.viewerPanel.showState(this.shownModel());
  }

  /**
   * The server answers again: the open mode's solve that failed for want of it goes again (the
   * server kept the session, or the 404 path reopens what it forgot), and previews that could
   * not load meanwhile are asked for again.
   */
  private reconnected(): void {
    this.photoPanel.pane.retryImages();
    const { status, message } = this.shownModel();
    if (status !== 'failed' || message !== UNREACHABLE) return;
    const body = document.body.classList;
    if (body.contains('stereo-mode')) this.stereo.solve();
    else if (body.contains('views-mode')) this.views.solve();
    else this.solver.solve();
  }

  /** Export menu: the shown mode's model, downloaded as ``suffix``. */
  async exportFormat(suffix: string): Promise<void> {
    const { status, message } = this.shownModel();
    if (status !== 'current') {
      const now = status === 'none' ? 'no model yet' : statusText(status, message);
      return void toast(`Nothing exported: the model on screen is not up to date (${now}); export once it is`);
    }
    const exported = (file: () => Promise<{ blob: Blob; filename: string }>) =>
      this.busy(`Exporting ${suffix}…`, async () => {
        const { blob, filename } = await file();
        download(blob, filename);
      });
    if (document.body.classList.contains('views-mode')) return exported(() => this.views.exportFormat(suffix));
    if (document.body.classList.contains('stereo-mode')) return exported(() => this.stereo.exportFormat(suffix));
    if (!this.photo.image) return void toast('Open an image first, then export its model');
    const closed = $<HTMLInputElement>('export-closed').checked;
    await exported(async () => {
      const file = await api.exportMesh(this.photo.request(this.solver.nextId()), suffix, undefined, { closed });
      if (closed) toast('Exported a closed model: its back is the front mirrored, a guess the photo does not show', 'info');
      return file;
    });
  }

  // ------------------------------------------------------------------ session, progress

  persist(): void {
    const { image, source, params } = this.photo;
    // a view being edited keeps what the user changes (its photo too: a forgotten one reopened)
    if (image && source && this.views.editing !== null) this.views.edited(image, source, params);
    this.projects.changed();
    this.saveSoon();
  }

  /** Store what a reload reopens in a moment (the server's project is not told: only a reload
   * keeps what changed, e.g. how a photo set is viewed). */
  private saveSoon(): void {
    clearTimeout(this.saveTimer);
    this.saveTimer = window.setTimeout(() => this.saveNow(), 150);
  }

  /** Store what a reload reopens (a change is stored a moment later, or at once when the page goes). */
  private saveNow(): void {
    clearTimeout(this.saveTimer);
    this.saveTimer = 0;
    const photo = this.photo;
    saveSession({
      image: photo.image,
      source: photo.source,
      params: photo.image ? photo.params : null,
      view: this.viewerPanel.view,
      initialId: photo.initialId,
      photoSet: this.stereo.info ? { ...this.stereo.session()!, viewing: this.stereo.viewingSession() } : null,
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
      toast((err as Error).message);
    } finally {
      this.tasks.splice(this.tasks.indexOf(text), 1);
      this.showProgress();
    }
  }

  // ------------------------------------------------------------------ test hook

  /** Read-only views for the end-to-end tests and the benchmark (window.shadeform). */
  hook() {
    const { photo, photoPanel, viewerPanel } = this;
    return {
      state: () => ({
        image: photo.image ? { ...photo.image } : null,
        params: structuredClone(photo.params),
        view: { ...viewerPanel.view },
        tool: photoPanel.pane.tool,
        selectedRegion: photoPanel.pane.selection,
        busy: !$('busy').hidden,
        /** The one photo's model: current, computing, stale, failed or none. */
        model: photo.model.status,
      }),
      /** The one photo's model state (message, whether shown, the statuses so far). */
      modelState: (): ModelStateView => photo.model.view(),
      /** The state of the model the 3D view shows now, whichever mode, as the badge says it. */
      shownModelState: () => ({ ...this.shownModel().view(), badge: viewerPanel.badge() }),
      /** Whether the session a reload reopens is stored (no change waits to be). */
      sessionSaved: () => this.saveTimer === 0,
      /** The messages at the bottom of the window, oldest first. */
      toasts: () => toasts(),
      /** The autosave to the server's projects: this page's project ids, saves taken, whether one is due. */
      projects: () => this.projects.state(),
      /** Whether the server answers: "online", or "lost" while it is polled for (connection.ts). */
      connection: () => connectionState(),
      // the last result, the requests and the background solve's progress (solvePanel.ts); the
      // fit offer (openPanel.ts); the 3D view (viewerPanel.ts); the image pane and the mask tool
      ...this.solver.hook(),
      ...this.opener.hook(),
      ...viewerPanel.hook(),
      ...photoPanel.hook(),
      /** The photo set's session (photometric stereo): what it shows and found. */
      stereo: this.stereo.hook(),
      /** The Print panel's solid (printPanel.ts) and the Maps panel's previews (mapsPanel.ts). */
      print: this.print.hook(),
      maps: this.maps.hook(),
      /** The views' session (several sides fused): the views, the fused model and what is drawn. */
      views: {
        ...this.views.hook(),
        open: () => document.body.classList.contains('views-mode'),
        shownVertexCount: () => viewerPanel.viewer.vertexCount(),
        partsShown: () => viewerPanel.viewer.partsShown(),
      },
    };
  }
}

/** The image pane's title: ``name`` in bold, then ``rest``. */
function showTitle(name: string, rest: string): void {
  const title = $('image-title');
  title.innerHTML = '';
  const bold = document.createElement('b');
  bold.textContent = name;
  title.append(bold, rest);
}

/** The top bar's menus (Examples, Project, Export): a click opens one and closes the others. */
function bindMenus(): void {
  for (const menu of document.querySelectorAll<HTMLElement>('.menu')) {
    menu.querySelector(':scope > button')!.addEventListener('click', (event) => {
      event.stopPropagation();
      const open = !menu.classList.contains('open');
      document.querySelectorAll('.menu.open').forEach((m) => m.classList.remove('open'));
      menu.classList.toggle('open', open);
    });
    menu.querySelector('.menu-items')!.addEventListener('click', (event) => {
      // a toggle in a menu (Export's "Closed") is set, not chosen: the menu stays open
      if ((event.target as Element).closest('label.toggle')) return event.stopPropagation();
      menu.classList.remove('open');
    });
  }
  document.addEventListener('click', () => document.querySelectorAll('.menu.open').forEach((m) => m.classList.remove('open')));
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
