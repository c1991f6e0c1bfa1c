// The Project menu and the server's projects. The work open (one photo, a photo set or the views)
// is autosaved to the server as a project (state.ts, ProjectAutosave: this module makes its
// snapshot); Project ▸ Open recent… lists the server's projects to reopen one or forget one, and a
// page whose storage is empty offers the newest on the empty image pane. Save project… downloads
// the photo with its settings as one file (Open project… reads one: openPanel.ts).
import * as api from './api';
import type { ImageInfo, Options, ProjectInfo } from './api.gen';
import { send } from './connection';
import { $ } from './dom';
import { forgotten, type Photo } from './photo';
import type { PhotoPanel } from './photoPanel';
import type { ImageSource, Params } from './sessionTypes';
import {
  deleteProject,
  download,
  fetchProject,
  fromProjectSource,
  listProjects,
  PROJECT_FORMAT,
  PROJECT_VERSION,
  projectDocument,
  storeImageBytes,
  toProjectSource,
  type ProjectAutosave,
  type ProjectSnapshot,
} from './state';
import type { StereoSession } from './stereo';
import { toast } from './toast';
import type { ViewerPanel } from './viewerPanel';
import type { ViewsSession } from './views';

export interface ProjectsHost {
  busy(text: string, work: () => Promise<void>): Promise<void>;
  /** Make ``info`` the photo open, with ``params`` or else its suggested settings. */
  showImage(info: ImageInfo, source: ImageSource, params: Params | null): void;
  setStereoMode(on: boolean): void;
  setViewsMode(on: boolean): void;
  /** Open view ``index``'s photo in single-photo mode, to edit it. */
  editView(index: number): void;
  /** A fresh id for an image the server forgot, or null (openPanel.ts). */
  reopen(source: ImageSource): Promise<ImageInfo | null>;
}

/** What a project of each kind is, in Open recent. */
const KIND_WORDS: Record<ProjectInfo['kind'], string> = { photo: 'photo', photo_set: 'photo set', views: 'views' };

export class ProjectsPanel {
  constructor(
    private readonly options: Options,
    private readonly photo: Photo,
    private readonly projects: ProjectAutosave,
    private readonly stereo: StereoSession,
    private readonly views: ViewsSession,
    private readonly photoPanel: PhotoPanel,
    private readonly viewerPanel: ViewerPanel,
    private readonly host: ProjectsHost,
  ) {}

  /** The Project menu's actions and the empty pane's Open recent…. */
  bind(): void {
    $('resume-more').addEventListener('click', () => this.showRecent());
    $('project-menu').addEventListener('click', (event) => {
      const action = (event.target as HTMLElement).closest<HTMLElement>('[data-action]')?.dataset.action;
      if (action === 'save-project') this.saveProject();
      if (action === 'open-project') $<HTMLInputElement>('file-project').click();
      if (action === 'open-recent') this.showRecent();
      if (action === 'save-regions') this.photoPanel.saveRegions();
      if (action === 'load-regions') $<HTMLInputElement>('file-regions').click();
    });
  }

  /** What is open, as the server keeps it: the project file's document, images by their ids. */
  snapshot(): ProjectSnapshot | null {
    const base = {
      format: PROJECT_FORMAT, version: PROJECT_VERSION, name: null, view: { ...this.viewerPanel.view },
      image: null, params: null, photo_set: null, views: null,
    } as const;
    const body = document.body.classList;
    // a view being edited in single-photo mode is the views' work
    if (body.contains('views-mode') || this.views.editing !== null) {
      const saved = this.views.session();
      if (!saved.views.length) return null;
      const views = saved.views.map((view) => ({ ...view, source: toProjectSource(view.source), photo_set: view.photo_set ?? null }));
      return { kind: 'views', document: { ...base, views: { ...saved, views } } };
    }
    if (body.contains('stereo-mode')) {
      const set = this.stereo.session();
      return set && { kind: 'photo_set', document: { ...base, photo_set: set } };
    }
    const { image: info, source } = this.photo;
    if (!info || !source) return null;
    const image = {
      name: source.name,
      type: source.kind === 'upload' ? source.type : '',
      data: null, // the server's session store has the bytes
      example: source.kind === 'example' ? source.name : null,
      source: toProjectSource(source),
      info: { ...info },
    };
    return { kind: 'photo', document: { ...base, image, params: structuredClone(this.photo.params) } };
  }

  /** Save project…: the photo (its bytes) with its settings, downloaded as one file. */
  async saveProject(): Promise<void> {
    const photo = this.photo;
    if (!photo.image || !photo.source) return void toast('Open an image first; a project holds the image with its settings');
    await this.host.busy('Saving project…', async () => {
      let bytes = photo.imageBytes;
      if (!bytes) {
        const response = await send(api.photoUrl(photo.image!.image_id));
        if (!response.ok) throw new Error('the server no longer has this image; open it again, then save');
        bytes = await response.blob();
      }
      const project = await projectDocument(photo.source!, bytes, photo.params, this.viewerPanel.view);
      download(new Blob([JSON.stringify(project)], { type: 'application/json' }), `${photo.stem()}.shadeform.json`);
    });
  }

  /** Reopen server project ``id``: its photo (by its id in the server's store, as a reload does),
   * photo set or views, with its settings; from now on the autosave goes to it. */
  private async openServerProject(id: string): Promise<void> {
    $<HTMLDialogElement>('recent-dialog').close();
    $('resume').hidden = true;
    await this.host.busy('Opening project…', async () => {
      const { document: doc } = await fetchProject(id);
      this.projects.settle(); // the work open now keeps its last change before this replaces it
      const showAsSaved = () => {
        this.viewerPanel.view = { ...this.viewerPanel.view, ...doc.view };
        this.viewerPanel.applyView();
      };
      if (doc.photo_set) {
        showAsSaved();
        this.projects.use('photo_set', id);
        this.stereo.reopen(doc.photo_set.info, doc.photo_set.params);
        this.host.setStereoMode(true);
        return;
      }
      if (doc.views) {
        showAsSaved();
        this.projects.use('views', id);
        const views = doc.views.views.map((view) => ({ ...view, source: fromProjectSource(view.source) }));
        this.views.restore({ ...doc.views, views });
        const editing = this.views.editing;
        if (editing !== null) this.host.editView(editing);
        else this.host.setViewsMode(true);
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
      else info = await this.host.reopen(source);
      if (!info) throw new Error(`${forgotten(image.name)}; the project has no copy of it: open the image again`);
      // only now that it opened: what is open until now keeps its copy if it did not
      this.photo.imageBytes = bytes;
      await storeImageBytes(bytes);
      showAsSaved();
      this.projects.use('photo', id);
      this.views.editing = null;
      this.host.showImage(info, source, { ...this.options.defaults, ...doc.params });
    });
  }

  /** Project ▸ Open recent…: the server's projects, newest first, to reopen or forget. */
  async showRecent(): Promise<void> {
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
        toast(`Could not forget ${project.name}: ${(err as Error).message}`);
      }
    });
    item.append(button, forget);
    return item;
  }

  /** A page without storage (first visit, cleared, another browser): offer the newest server
   * project on the empty image pane, without opening it. */
  async offerNewest(): Promise<void> {
    let projects: ProjectInfo[] | null = null;
    try {
      projects = await listProjects();
    } catch {
      return; // the server away: the connection says so
    }
    const newest = projects?.[0];
    // something was opened meanwhile: the offer is moot
    if (!newest || $('image-empty').hidden || this.photo.image || document.body.classList.contains('stereo-mode')) return;
    $('resume-name').textContent = newest.name;
    $('resume-detail').textContent = `${describe(newest)} · ${ago(newest.updated)}`;
    $('resume-open').onclick = () => this.openServerProject(newest.id);
    $('resume').hidden = false;
  }
}

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
