// Opening work: an image file (with the offer over the image pane to open a photo over the pixel
// limit downsampled), an example from the Examples menu or the empty pane, a project or regions
// file (JSON), a photo set or view photos; from the top bar's buttons, the file choosers or a drop
// anywhere on the window. Also reopening what the last visit had open (restore), and an image the
// server forgot (reopen: by example name, or by sending its bytes again).
import * as api from './api';
import type { ExampleInfo, ImageInfo, Options } from './api.gen';
import { $ } from './dom';
import { forgotten, type Photo } from './photo';
import type { PhotoPanel } from './photoPanel';
import type { ImageSource, Params } from './sessionTypes';
import { loadImageBytes, loadSession, readJsonFile, readProject, readRegions, storeImageBytes, type ProjectAutosave } from './state';
import type { StereoSession } from './stereo';
import { toast } from './toast';
import type { ViewerPanel } from './viewerPanel';
import type { ViewsSession } from './views';

export interface OpenHost {
  busy(text: string, work: () => Promise<void>): Promise<void>;
  /** Make ``info`` the photo open, with ``params`` or else its suggested settings. */
  showImage(info: ImageInfo, source: ImageSource, params: Params | null): void;
  setStereoMode(on: boolean): void;
  setViewsMode(on: boolean): void;
  /** Keep what is open for a reload. */
  persist(): void;
  /** Offer the server's newest project on the empty image pane (a page without storage). */
  offerNewest(): Promise<void>;
}

export class OpenPanel {
  /** A photo refused for its size, offered downsampled (the offer that stays over the image pane). */
  private fitOffer: { file: File; factor: number } | null = null;

  constructor(
    private readonly options: Options,
    private readonly photo: Photo,
    private readonly projects: ProjectAutosave,
    private readonly stereo: StereoSession,
    private readonly views: ViewsSession,
    private readonly photoPanel: PhotoPanel,
    private readonly viewerPanel: ViewerPanel,
    private readonly host: OpenHost,
  ) {}

  /** The examples (the menu and the empty pane's buttons), the open buttons, the file choosers,
   * the fit offer's buttons and the drop. */
  bind(): void {
    this.buildExamples();
    $('fit-accept').addEventListener('click', () => {
      const offer = this.fitOffer;
      if (offer) void this.openFile(offer.file);
    });
    $('fit-dismiss').addEventListener('click', () => this.showFitOffer(null));
    this.bindFiles();
  }

  /** Reopen what the last visit had open: the server may have forgotten the image. */
  async restore(freshStorage: boolean): Promise<void> {
    const session = loadSession();
    const initial = this.options.initial_image;
    this.photo.initialId = session.initialId;
    if (session.views) this.views.restore(session.views);
    if (initial && initial.image_id !== session.initialId) {
      this.photo.initialId = initial.image_id;
      this.views.editing = null;
      this.projects.begin('photo');
      return this.host.showImage(initial, { kind: 'initial', name: initial.name }, null);
    }
    if (freshStorage) void this.host.offerNewest(); // not awaited: the page is ready without it
    if (session.viewsOpen) return this.host.setViewsMode(true);
    if (session.photoSet) {
      this.stereo.reopen(session.photoSet.info, session.photoSet.params, session.photoSet.viewing);
      this.host.setStereoMode(true);
      return;
    }
    if (!session.image || !session.source) return;
    try {
      let info = session.image;
      if (!(await api.imageKnown(info.image_id))) {
        const reopened = await this.reopen(session.source);
        if (!reopened) return void toast(`${forgotten(session.image.name)}; this page has no copy to send again: open it again`, 'info');
        toast(`${forgotten(session.image.name)}: ${session.source.kind === 'upload' ? 'sent it again' : 'opened it again'}`, 'info');
        info = reopened;
      } else if (session.source.kind === 'upload') {
        this.photo.imageBytes = await loadImageBytes();
      }
      // defaults first: a session saved by an older client may lack newer fields
      this.host.showImage(info, session.source, session.params ? { ...this.options.defaults, ...session.params } : null);
    } catch (err) {
      toast(`Could not reopen the last image: ${(err as Error).message}`);
    }
  }

  /** A fresh id for the same image: by example name, or by re-sending the stored bytes. */
  async reopen(source: ImageSource): Promise<ImageInfo | null> {
    if (source.kind === 'photoset') return null; // a view's photo set is no photo to reopen
    if (source.kind === 'example') return api.openExample(source.name);
    if (source.kind === 'initial') return (await api.getOptions()).initial_image;
    if (source.kind === 'viewset') return (await api.openViewSetExample(source.name)).images[source.index] ?? null;
    const bytes = this.photo.imageBytes ?? (await loadImageBytes());
    if (!bytes) return null;
    this.photo.imageBytes = bytes;
    return api.uploadImage(bytes, source.name);
  }

  // ------------------------------------------------------------------------ one photo

  async openFile(file: File): Promise<void> {
    if (file.name.toLowerCase().endsWith('.json') || file.type === 'application/json') return this.openJson(file);
    const limit = this.options.limits.max_upload_bytes;
    if (file.size > limit) {
      toast(`${file.name} is ${(file.size / 1e6).toFixed(1)} MB; the limit is ${(limit / 1e6).toFixed(1)} MB — use a smaller image`);
      return;
    }
    await this.host.busy('Uploading…', async () => {
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
      this.photo.imageBytes = file;
      await storeImageBytes(file);
      this.projects.begin('photo');
      this.host.showImage(info, { kind: 'upload', name: file.name, type: file.type }, null);
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
    await this.host.busy('Opening example…', async () => {
      const info = await api.openExample(name);
      this.photo.imageBytes = null;
      await storeImageBytes(null);
      this.views.editing = null;
      this.projects.begin('photo');
      this.host.showImage(info, { kind: 'example', name }, null);
    });
  }

  /** A JSON file: a project or a regions file, told apart by their content. */
  private async openJson(file: File): Promise<void> {
    try {
      const document = await readJsonFile(file);
      if ((document as { format?: string })?.format === 'shadeform-project') return await this.openProject(document);
      this.photoPanel.loadRegions(readRegions(document));
    } catch (err) {
      toast((err as Error).message);
    }
  }

  private async openProject(document: unknown): Promise<void> {
    const { project, bytes } = readProject(document);
    await this.host.busy('Opening project…', async () => {
      const example = project.image.example;
      let info: ImageInfo;
      let source: ImageSource;
      if (example && this.options.examples.some((e) => e.name === example)) {
        info = await api.openExample(example);
        source = { kind: 'example', name: example };
        this.photo.imageBytes = null;
        await storeImageBytes(null);
      } else {
        info = await api.uploadImage(bytes, project.image.name);
        source = { kind: 'upload', name: project.image.name, type: bytes.type };
        this.photo.imageBytes = bytes;
        await storeImageBytes(bytes);
      }
      this.projects.begin('photo');
      this.viewerPanel.view = { ...this.viewerPanel.view, ...project.view };
      this.viewerPanel.applyView();
      this.views.editing = null;
      this.host.showImage(info, source, { ...this.options.defaults, ...project.params });
    });
  }

  // --------------------------------------------------------------- photo sets and views

  // the work open keeps its last change (settle) before the other views replace what is shown
  async openViewPhotos(files: File[]): Promise<void> {
    this.projects.settle();
    if (await this.views.openFiles(files)) this.openedViews();
  }

  async openViewSetExample(name: string): Promise<void> {
    this.projects.settle();
    if (await this.views.openExample(name)) this.openedViews();
  }

  /** The photo set open in its mode, with its settings, as one more view (its side under several lights). */
  private addSetView(): void {
    const set = this.stereo.session();
    if (!set) return void toast('Open a photo set first, then add it as a view');
    const index = this.views.addPhotoSet(set.info, set.params);
    toast(`Added as view ${index + 1} at ${this.views.views[index].angle}° — Views fuses the views into one model`, 'info');
  }

  /** Other views replaced the list: new work, a new project. */
  private openedViews(): void {
    this.projects.begin('views');
    this.host.setViewsMode(true);
    this.host.persist(); // saved even when the panel was open already (no mode change to persist it)
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
    this.host.setStereoMode(true);
  }

  /** The offer to downsample a photo over the pixel limit, or null (the test hook's). */
  hook() {
    return {
      fitOffer: () => ($('fit-offer').hidden ? null : { text: $('fit-offer-text').textContent, button: !$('fit-accept').hidden }),
    };
  }

  // ------------------------------------------------------------------------ the controls

  /** The Examples menu, a heading per kind, and the empty image pane's example buttons. */
  private buildExamples(): void {
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
    $('open-views').addEventListener('click', () => this.host.setViewsMode(true));
    $('views-open').addEventListener('click', () => $<HTMLInputElement>('file-views').click());
    pickedAll('file-views', (files) => this.openViewPhotos(files));
    $('add-view').addEventListener('click', () => this.photoPanel.addView());
    $('add-set-view').addEventListener('click', () => this.addSetView());
    $('view-back').addEventListener('click', () => this.host.setViewsMode(true));
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
}
