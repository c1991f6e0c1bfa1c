// Views: photos of one object from several sides, each reconstructed as one photo is (its own
// mask, regions, light and solver), placed in one frame and fused into one closed model on the
// server. This module owns the list of views (the image pane shows them as cards: the photo with
// the mask it was solved with, its name, its turntable angle, Edit and Remove: viewCards.ts draws
// them), the panel group of the fusion's settings, and the fuse requests; the App gives it the 3D
// view, single-photo mode (where a view is edited) and the busy/toast helpers.
//
// A view's settings are the single-photo ones: "Edit" opens the view's photo in single-photo
// mode with them, and what the user changes there is written back into the view (App calls
// edited()); back in this panel the model is fused again, and the server solves only the views
// whose settings changed (it keeps each view's reconstruction).
//
// A view may instead be a photo set (View.photo_set: several photos of that side under different
// lights, opened in the photo-set mode and added with "Add this set as a view"): the server
// solves it by photometric stereo with the set's settings, once, and never again for settling;
// its card has no Edit (its shape needs no mask, regions or light to be drawn).
import * as api from './api';
import type { FuseRequest, FuseResult, ImageInfo, Options, PhotoSetInfo, StereoParams } from './api.gen';
import { NetworkError, UNREACHABLE } from './connection';
import { $, showMessage } from './dom';
import { ModelRequest, ModelState } from './modelState';
import type { ImageSource, Params, View, ViewsSaved } from './sessionTypes';
import { fusionNote, viewCard } from './viewCards';

export interface ViewsHost {
  /** Show the fused model and the partial models (in PART_COLOURS order); refit the camera when asked. */
  showFused(result: FuseResult, fused: api.DecodedMesh, parts: api.DecodedMesh[], refit: boolean): void;
  /** Show or hide the partial models in the 3D view. */
  showParts(on: boolean): void;
  /** Open view ``index`` in single-photo mode with its settings, to edit them. */
  edit(index: number): void;
  /** A fresh id for a photo the server forgot (examples by name), or null when it cannot be reopened. */
  reopen(source: ImageSource): Promise<ImageInfo | null>;
  busy(text: string, work: () => Promise<void>): Promise<void>;
  solving(on: boolean): void;
  toast(message: string, kind?: 'error' | 'info'): void;
  /** The views or their settings changed: keep them for a reload. */
  changed(): void;
  /** The fused model's state changed (the badge, the export menu and the dimming follow it). */
  modelChanged(): void;
}

/** A voxel of 2 px: a 256-pixel object fuses in about a second, where the library's finest
 * default (1 px) takes several; the user can ask for it. */
export const DEFAULT_RESOLUTION = 2;

/**
 * A partial model as drawn over the fused one: each vertex lifted off the surface along its
 * normal by ``distance`` times (0.25 + how squarely the view's camera saw it). Partial models lie
 * within a voxel of the fused surface and of each other, so drawn where they are they would
 * flicker through one another; lifted this way, where two overlap the one whose photo looked at
 * the surface more squarely shows, and the seams between colours fall where two views saw it
 * equally. ``transform`` is the part's FusedView.transform: its third column is the direction
 * toward that view's camera in the object frame.
 */
export function lifted(part: api.DecodedMesh, transform: number[][], distance: number): api.DecodedMesh {
  const toward = [transform[0][2], transform[1][2], transform[2][2]];
  const positions = new Float32Array(part.positions);
  const n = part.normals;
  for (let i = 0; i < positions.length; i += 3) {
    const facing = Math.max(0, n[i] * toward[0] + n[i + 1] * toward[1] + n[i + 2] * toward[2]);
    const lift = distance * (0.25 + facing);
    positions[i] += n[i] * lift;
    positions[i + 1] += n[i + 1] * lift;
    positions[i + 2] += n[i + 2] * lift;
  }
  return { ...part, positions };
}

/** The angle a user typed ("90", "-45.5", "90°"), or null when it is not a finite number. */
export function parseAngle(text: string): number | null {
  const trimmed = text.trim().replace(/°$/, '').trim();
  if (!trimmed) return null;
  const value = Number(trimmed);
  return Number.isFinite(value) ? value : null;
}

export class ViewsSession {
  views: View[] = [];
  refinePoses = true;
  settle = true;
  resolution: number | null = DEFAULT_RESOLUTION;
  showParts = true;
  editing: number | null = null;
  result: FuseResult | null = null;
  appliedCount = 0;
  /** What the fused model on screen is: current, computing, stale or failed. */
  readonly model: ModelState;
  /** The fusions, one at a time (the App's "Solving…" on while one is out). */
  private readonly requests: ModelRequest;
  private requestCounter = 0;
  private refitNext = true;
  private retried = false;

  constructor(
    private readonly options: Options,
    private readonly host: ViewsHost,
  ) {
    this.model = new ModelState(() => host.modelChanged());
    this.requests = new ModelRequest(this.model, (on) => host.solving(on));
    this.bindPanel();
  }

  // ----------------------------------------------------------------------- opening

  /** Several photos from around the object as a new set of views, angles evenly spaced. */
  async openFiles(files: File[]): Promise<boolean> {
    const images = files.filter((f) => f.type.startsWith('image/') || /\.(png|jpe?g|tiff?|bmp|webp)$/i.test(f.name));
    if (images.length < 2) {
      this.host.toast(`Fusing needs photos of the object from at least two sides; ${images.length} chosen — select all the views' photos at once`);
      return false;
    }
    const limit = this.options.limits.max_upload_bytes;
    const large = images.find((f) => f.size > limit);
    if (large) {
      this.host.toast(`${large.name} is ${(large.size / 1e6).toFixed(1)} MB; the limit is ${(limit / 1e6).toFixed(1)} MB — use smaller photos`);
      return false;
    }
    images.sort((a, b) => a.name.localeCompare(b.name, undefined, { numeric: true }));
    let opened = false;
    await this.host.busy(`Uploading ${images.length} photos…`, async () => {
      const infos = [];
      for (const file of images) infos.push(await api.uploadImage(file, file.name));
      this.replace(
        infos.map((image, i) => ({
          image,
          source: { kind: 'upload', name: image.name, type: images[i].type },
          angle: Math.round(((i * 360) / infos.length) * 100) / 100,
          params: this.defaults(image),
        })),
      );
      opened = true;
    });
    return opened;
  }

  async openExample(name: string): Promise<boolean> {
    let opened = false;
    await this.host.busy('Opening view set…', async () => {
      const set = await api.openViewSetExample(name);
      this.replace(
        set.images.map((image, index) => ({
          image,
          source: { kind: 'viewset', name, index },
          angle: set.angles[index],
          params: this.defaults(image),
        })),
      );
      opened = true;
    });
    return opened;
  }

  /** Add the photo open in single-photo mode, with its settings; returns its index. */
  add(view: View): number {
    this.views.push(structuredClone(view));
    this.model.changed('a view was added');
    this.host.changed();
    this.render();
    return this.views.length - 1;
  }

  /** Add a photo set (open in the photo-set mode, with its settings) as a view; returns its index. */
  addPhotoSet(info: PhotoSetInfo, params: StereoParams): number {
    const image: ImageInfo = {
      image_id: info.photoset_id,
      name: info.name,
      width: info.width,
      height: info.height,
      channels: info.colour ? 3 : 1,
      suggested: null,
    };
    const view: View = {
      image,
      source: { kind: 'photoset', name: info.name },
      angle: this.nextAngle(),
      params: this.defaults(image),
      photo_set: { info, params },
    };
    return this.add(view);
  }

  /** An angle for the next view: a quarter turn past the last one. */
  nextAngle(): number {
    const last = this.views.at(-1);
    return last ? (((last.angle + 90) % 360) + 360) % 360 : 0;
  }

  /** The views a reloaded page had (the server may have forgotten their photos). */
  restore(saved: ViewsSaved): void {
    this.views = structuredClone(saved.views);
    // `refine`: the name a session or project saved before the rename holds it under
    this.refinePoses = saved.refine_poses ?? (saved as { refine?: boolean }).refine ?? true;
    this.settle = saved.settle ?? true;
    this.resolution = saved.resolution === undefined ? DEFAULT_RESOLUTION : saved.resolution;
    this.showParts = saved.showParts ?? true;
    this.editing = saved.editing ?? null;
    if (this.editing !== null && (!this.views[this.editing] || this.views[this.editing].photo_set)) this.editing = null;
    this.render();
  }

  session(): ViewsSaved {
    return {
      views: structuredClone(this.views),
      refine_poses: this.refinePoses,
      settle: this.settle,
      resolution: this.resolution,
      showParts: this.showParts,
      editing: this.editing,
    };
  }

  /** The panel is shown: list the views and fuse them (the server reuses what did not change). */
  show(): void {
    this.editing = null;
    this.refitNext = true; // the 3D view showed another model meanwhile
    this.render();
    this.solve();
  }

  /** The panel is left: nothing is fused any more. */
  close(): void {
    this.requests.abort();
    this.model.reset();
  }

  /** What the user changed while editing a view in single-photo mode goes into the view. */
  edited(image: ImageInfo, source: ImageSource, params: Params): void {
    const index = this.editing;
    if (index === null || !this.views[index]) return;
    this.views[index] = { ...this.views[index], image: structuredClone(image), source: structuredClone(source), params: structuredClone(params) };
  }

  private defaults(image: ImageInfo): Params {
    return structuredClone({ ...this.options.defaults, ...(image.suggested ?? {}) });
  }

  private replace(views: View[]): void {
    this.views = views;
    this.editing = null;
    this.result = null;
    this.model.changed('other views opened');
    this.refitNext = true;
    this.host.changed();
    this.render();
  }

  // ----------------------------------------------------------------------- solving

  request(): FuseRequest {
    return {
      views: this.views.map((view) => ({
        image_id: view.photo_set ? null : view.image.image_id,
        photo_set_id: view.photo_set ? view.photo_set.info.photoset_id : null,
        angle: view.angle,
        params: structuredClone(view.params),
        stereo: structuredClone(view.photo_set?.params ?? this.options.stereo_defaults),
      })),
      refine_poses: this.refinePoses,
      settle: this.settle,
      resolution: this.resolution,
      request_id: ++this.requestCounter,
    };
  }

  async solve(): Promise<void> {
    this.requests.abort();
    if (this.views.length < 2) {
      this.result = null;
      this.setError(null);
      // a fused model still on screen is no longer the views': it stays, out of date
      if (this.model.shown) this.model.changed('fusing needs at least two views');
      else this.model.reset();
      $('views-note').textContent = this.views.length
        ? 'Add a photo of the object from another side: fusing needs at least two views.'
        : '';
      return;
    }
    const body = this.request();
    await this.requests.run(
      async ({ signal, version }) => {
        const result = await api.fuse(body, signal);
        if (result.request_id !== this.requestCounter) return;
        const fused = api.decodeMesh(result.mesh);
        // lifted by a voxel and a half at most: off the fused surface, never far from it
        const lift = 1.5 * Number(result.info.resolution);
        const parts = result.parts.map((part, i) => lifted(api.decodeMesh(part), result.views[i].transform, lift));
        this.result = result;
        this.retried = false;
        this.host.showFused(result, fused, parts, this.refitNext);
        this.model.arrived(version);
        this.refitNext = false;
        this.appliedCount += 1;
        this.setError(null);
        this.showNote(result);
        this.render();
      },
      async (err, version) => {
        if (body.request_id !== this.requestCounter) return;
        if (err instanceof NetworkError) {
          // the App fuses again once the server answers
          this.setError('The server is not reachable (stopped or restarting): the views are fused again once it answers');
          this.model.failed(version, UNREACHABLE);
          return;
        }
        if (err instanceof api.ApiError && err.status === 404 && (await this.reopenForgotten(err.message, version))) return;
        this.setError(err.message);
        this.model.failed(version, err.message);
      },
    );
  }

  /** The server forgot a view's photo ("view N: unknown image id ..."): reopen it if it is an
   * example and fuse again (once), or say which photo to open again. */
  private async reopenForgotten(message: string, version: number): Promise<boolean> {
    const found = /^view (\d+):/.exec(message);
    const index = found ? Number(found[1]) - 1 : -1;
    const view = this.views[index];
    if (!view) return false;
    if (view.photo_set) {
      const said = `The server no longer has view ${index + 1}'s photo set, ${view.image.name} (it was restarted without its sessions, or let it go): remove the view, open the set's photos again and add it with Add this set as a view`;
      this.setError(said);
      this.model.failed(version, said);
      return true;
    }
    let info: ImageInfo | null = null;
    try {
      if (!this.retried) info = await this.host.reopen(view.source);
    } catch (err) {
      if (err instanceof NetworkError) {
        this.model.failed(version, UNREACHABLE); // away again: fused once it answers
        return true;
      }
    }
    if (!info) {
      const said = `The server no longer has view ${index + 1}'s photo, ${view.image.name} (it was restarted without its sessions, or let it go): remove the view and add the photo again, or open the view photos again`;
      this.setError(said);
      this.model.failed(version, said);
      return true;
    }
    this.retried = true;
    this.host.toast(`The server no longer had view ${index + 1}'s photo, ${view.image.name} (it was restarted without its sessions, or let it go): opened it again`, 'info');
    // an example comes back with the very pixels: the view's settings still apply
    this.views[index] = { ...view, image: info };
    this.host.changed();
    this.render();
    await this.solve();
    return true;
  }

  async exportFormat(suffix: string): Promise<{ blob: Blob; filename: string }> {
    if (this.views.length < 2) throw new Error('Fusing needs at least two views: add views first, then export the fused model');
    return api.exportFused(this.request(), suffix);
  }

  private showNote(result: FuseResult): void {
    const { note, warnings } = fusionNote(result);
    $('views-note').textContent = note;
    const rival = $('views-rival');
    rival.hidden = warnings.length === 0;
    rival.textContent = warnings.join(' ');
  }

  /** A message that stays until the next result (or the next error). */
  setError(message: string | null): void {
    showMessage('views-error', message);
  }

  // ------------------------------------------------------------------------- panel

  private bindPanel(): void {
    const resolution = $<HTMLSelectElement>('views-resolution');
    resolution.addEventListener('change', () => {
      this.resolution = resolution.value === 'auto' ? null : Number(resolution.value);
      this.model.changed();
      this.host.changed();
      this.solve();
    });
    for (const [id, key] of [['views-refine-poses', 'refinePoses'], ['views-settle', 'settle']] as const) {
      const box = $<HTMLInputElement>(id);
      box.addEventListener('change', () => {
        this[key] = box.checked;
        this.model.changed();
        this.host.changed();
        this.solve();
      });
    }
    const parts = $<HTMLInputElement>('parts-toggle');
    parts.addEventListener('change', () => {
      this.showParts = parts.checked;
      this.host.showParts(this.showParts);
      this.host.changed();
    });
    $('views-list').addEventListener('click', (event) => {
      const button = (event.target as HTMLElement).closest<HTMLButtonElement>('button[data-act]');
      const card = button?.closest<HTMLElement>('[data-index]');
      if (!button || !card) return;
      const index = Number(card.dataset.index);
      if (button.dataset.act === 'edit') this.edit(index);
      if (button.dataset.act === 'remove') this.remove(index);
      if (button.dataset.act === 'keep') this.keepSettled(index);
    });
    $('views-list').addEventListener('change', (event) => {
      const input = (event.target as HTMLElement).closest<HTMLInputElement>('input[data-angle]');
      if (input) this.setAngle(Number(input.dataset.angle), input.value);
    });
  }

  private edit(index: number): void {
    this.requests.abort();
    this.model.changed('a view is being edited');
    this.editing = index;
    this.host.edit(index);
  }

  private remove(index: number): void {
    this.views.splice(index, 1);
    this.model.changed('a view was removed');
    this.result = null;
    this.host.changed();
    this.render();
    this.solve();
  }

  /** The areas the other views settled as concave become the view's own regions. */
  private keepSettled(index: number): void {
    const settled = this.result?.views[index]?.settled ?? [];
    const view = this.views[index];
    const regions = [...view.params.concave.regions, ...structuredClone(settled)];
    view.params = { ...view.params, concave: { regions } };
    this.model.changed('regions changed');
    this.host.changed();
    this.render();
    this.solve();
  }

  setAngle(index: number, text: string): void {
    const angle = parseAngle(text);
    if (angle === null) {
      this.setError(`"${text}" is not an angle: give view ${index + 1}'s turntable angle in degrees (the object turned about the vertical axis, e.g. 90)`);
      return;
    }
    this.views[index].angle = angle;
    this.model.changed('an angle changed');
    this.host.changed();
    this.solve();
  }

  /** The cards, the panel's settings and the summary, from the current state. */
  render(): void {
    const list = $('views-list');
    // what the fusion found of each view, where the result is the views' own
    const current = this.result && this.result.views.length === this.views.length ? this.result.views : null;
    const cards = this.views.map((view, index) => viewCard(view, index, current?.[index] ?? null));
    list.replaceChildren(...cards);
    $('views-empty').hidden = this.views.length > 0;
    $<HTMLSelectElement>('views-resolution').value = this.resolution === null ? 'auto' : String(this.resolution);
    $<HTMLInputElement>('views-refine-poses').checked = this.refinePoses;
    $<HTMLInputElement>('views-settle').checked = this.settle;
    $<HTMLInputElement>('parts-toggle').checked = this.showParts;
    const first = this.views[0]?.image;
    $('views-summary').textContent = first
      ? `${this.views.length} view${this.views.length === 1 ? '' : 's'} · ${first.width} × ${first.height}`
      : 'No views yet';
    const count = $('views-count');
    count.textContent = this.views.length ? String(this.views.length) : '';
    count.hidden = !this.views.length;
  }

  // ------------------------------------------------------------------------ hook

  hook() {
    return {
      views: () =>
        this.views.map((view) => ({
          image_id: view.image.image_id,
          name: view.image.name,
          angle: view.angle,
          params: structuredClone(view.params),
          photo_set_id: view.photo_set?.info.photoset_id ?? null,
        })),
      applied: () => this.appliedCount,
      /** The fused model: current, computing, stale or failed (modelState.ts). */
      modelState: () => this.model.view(),
      editing: () => this.editing,
      error: () => ($('views-error').hidden ? null : $('views-error').textContent),
      note: () => $('views-note').textContent,
      /** The warning that the photos fit another placement as well, or null. */
      rival: () => ($('views-rival').hidden ? null : $('views-rival').textContent),
      lastResult: () => {
        const r = this.result;
        if (!r) return null;
        return {
          request_id: r.request_id,
          vertex_count: r.mesh.vertex_count,
          triangle_count: r.mesh.triangle_count,
          part_vertex_counts: r.parts.map((part) => part.vertex_count),
          cached: r.views.map((view) => view.cached),
          settled: r.views.map((view) => view.settled.length),
          outline_iou: r.views.map((view) => view.outline_iou),
          axis: r.axis,
          volume: r.volume,
          watertight: r.watertight,
          depth_fixed: r.depth_fixed,
          timings: r.timings,
          info: r.info,
        };
      },
    };
  }
}
