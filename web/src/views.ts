// Views: photos of one object from several sides, each reconstructed as one photo is (its own
// mask, regions, light and method), placed in one frame and fused into one closed model on the
// server. This module owns the list of views (the image pane shows them as cards: the photo with
// the mask it was solved with, its name, its turntable angle, Edit and Remove), the panel group
// of the fusion's settings, and the fuse requests; the App gives it the 3D view, single-photo
// mode (where a view is edited) and the busy/toast helpers.
//
// A view's settings are the single-photo ones: "Edit" opens the view's photo in single-photo
// mode with them, and what the user changes there is written back into the view (App calls
// edited()); back in this panel the model is fused again, and the server solves only the views
// whose settings changed (it keeps each view's reconstruction).
import * as api from './api';
import type { FuseRequest, FuseResult, ImageInfo, Options } from './api.gen';
import { NetworkError, UNREACHABLE } from './connection';
import { ModelState } from './modelState';
import type { ImageSource, Params } from './state';

/** One view: a stored photo, where it came from (to reopen it), its angle and its settings. */
export interface View {
  image: ImageInfo;
  source: ImageSource;
  angle: number;
  params: Params;
}

/** What a reload needs to show the views again. */
export interface ViewsSaved {
  views: View[];
  refine: boolean;
  settle: boolean;
  resolution: number | null;
  showParts: boolean;
  /** The view being edited in single-photo mode, if one is. */
  editing: number | null;
}

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

/** The partial models' colours, view by view (the cards' swatches show the same). */
export const PART_COLOURS = ['#f59e0b', '#38bdf8', '#a3e635', '#f472b6', '#a78bfa', '#2dd4bf', '#fb7185', '#facc15'];

/** A voxel of 2 px: a 256-pixel object fuses in about a second, where the library's finest
 * default (1 px) takes several; the user can ask for it. */
export const DEFAULT_RESOLUTION = 2;

/** Below this a view's outline is not kept (shadeform.fusion.outlines.OUTLINE_KEPT). */
const OUTLINE_KEPT = 0.95;

const $ = <T extends HTMLElement>(id: string) => document.getElementById(id) as T;

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
  refine = true;
  settle = true;
  resolution: number | null = DEFAULT_RESOLUTION;
  showParts = true;
  editing: number | null = null;
  result: FuseResult | null = null;
  appliedCount = 0;
  /** What the fused model on screen is: current, computing, stale or failed. */
  readonly model: ModelState;
  private requestCounter = 0;
  private inFlight: AbortController | null = null;
  private refitNext = true;
  private retried = false;

  constructor(
    private readonly options: Options,
    private readonly host: ViewsHost,
  ) {
    this.model = new ModelState(() => host.modelChanged());
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

  /** An angle for the next view: a quarter turn past the last one. */
  nextAngle(): number {
    const last = this.views.at(-1);
    return last ? (((last.angle + 90) % 360) + 360) % 360 : 0;
  }

  /** The views a reloaded page had (the server may have forgotten their photos). */
  restore(saved: ViewsSaved): void {
    this.views = structuredClone(saved.views);
    this.refine = saved.refine ?? true;
    this.settle = saved.settle ?? true;
    this.resolution = saved.resolution === undefined ? DEFAULT_RESOLUTION : saved.resolution;
    this.showParts = saved.showParts ?? true;
    this.editing = saved.editing ?? null;
    if (this.editing !== null && !this.views[this.editing]) this.editing = null;
    this.render();
  }

  session(): ViewsSaved {
    return {
      views: structuredClone(this.views),
      refine: this.refine,
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
    this.inFlight?.abort();
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
      views: this.views.map((view) => ({ image_id: view.image.image_id, angle: view.angle, params: structuredClone(view.params) })),
      refine: this.refine,
      settle: this.settle,
      resolution: this.resolution,
      request_id: ++this.requestCounter,
    };
  }

  async solve(): Promise<void> {
    this.inFlight?.abort();
    this.inFlight = null;
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
    const controller = new AbortController();
    this.inFlight = controller;
    const body = this.request();
    const version = this.model.computing();
    this.host.solving(true);
    try {
      const result = await api.fuse(body, controller.signal);
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
    } catch (err) {
      if ((err as Error).name === 'AbortError' || body.request_id !== this.requestCounter) return;
      if (err instanceof NetworkError) {
        // the App fuses again once the server answers
        this.setError('The server is not reachable (stopped or restarting): the views are fused again once it answers');
        this.model.failed(version, UNREACHABLE);
        return;
      }
      if (err instanceof api.ApiError && err.status === 404 && (await this.reopenForgotten(err.message, version))) return;
      this.setError((err as Error).message);
      this.model.failed(version, (err as Error).message);
    } finally {
      if (this.inFlight === controller) {
        this.inFlight = null;
        this.host.solving(false);
      }
    }
  }

  /** The server forgot a view's photo ("view N: unknown image id ..."): reopen it if it is an
   * example and fuse again (once), or say which photo to open again. */
  private async reopenForgotten(message: string, version: number): Promise<boolean> {
    const found = /^view (\d+):/.exec(message);
    const index = found ? Number(found[1]) - 1 : -1;
    const view = this.views[index];
    if (!view) return false;
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
    const solved = result.views.filter((view) => !view.cached).length;
    const seconds = ((result.timings.place ?? 0) + (result.timings.solid ?? 0)).toFixed(1);
    const parts = [
      `Volume ${Math.round(result.volume).toLocaleString()} cubic px, ${result.watertight ? 'closed' : 'NOT closed'}.`,
      `Turntable axis at column ${result.axis.toFixed(1)}; voxel ${Number(result.info.resolution).toFixed(2)} px.`,
      result.info.cached ? 'Fused model reused.' : `Fused in ${seconds} s.`,
    ];
    if (solved) parts.push(`${solved} of ${result.views.length} views solved anew.`);
    const outlines = result.views.map((view) => view.outline_iou);
    parts.push(`Outlines kept: ${outlines.map((value, i) => `view ${i + 1} ${(100 * value).toFixed(0)}%`).join(', ')}.`);
    $('views-note').textContent = parts.join(' ');
    // photos that fit another placement about as well: said apart, in the colour of unsure areas
    const rivals = result.rivals.map((turns) =>
      turns.flatMap((turn, i) => (turn > 0 ? [`view ${i + 1} turned ${Math.round(turn)}°`] : [])).join(', '),
    );
    const warnings = [];
    if (!result.depth_fixed) {
      warnings.push(
        'The views look along one line only (from opposite sides), so they cannot tell how deep the object is: ' +
          "the model's depth rests on each photo's shading alone, the two joined at their shared outline; add a photo from the side (e.g. at 90°).",
      );
    }
    const poor = outlines.flatMap((value, i) => (value < OUTLINE_KEPT ? [`view ${i + 1} (${(100 * value).toFixed(0)}%)`] : []));
    if (poor.length) {
      warnings.push(
        `The model covers the outline of ${poor.join(', ')} poorly: parts the photo shows are missing or the model ` +
          "reaches past them; check that view's mask and angle.",
      );
    }
    if (rivals.length) {
      warnings.push(
        `The photos fit another placement about as well (${rivals.join('; or ')}), so the model may be wrong there: ` +
          'add a photo between two views (e.g. at 45°), or give the angles exactly and untick Refine the poses.',
      );
    }
    const rival = $('views-rival');
    rival.hidden = warnings.length === 0;
    rival.textContent = warnings.join(' ');
  }

  /** A message that stays until the next result (or the next error). */
  setError(message: string | null): void {
    const box = $('views-error');
    box.hidden = message === null;
    box.textContent = message ?? '';
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
    for (const [id, key] of [['views-refine', 'refine'], ['views-settle', 'settle']] as const) {
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
    this.inFlight?.abort();
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
    const cards = this.views.map((view, index) => this.card(view, index));
    list.replaceChildren(...cards);
    $('views-empty').hidden = this.views.length > 0;
    $<HTMLSelectElement>('views-resolution').value = this.resolution === null ? 'auto' : String(this.resolution);
    $<HTMLInputElement>('views-refine').checked = this.refine;
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

  private card(view: View, index: number): HTMLElement {
    const card = document.createElement('li');
    card.className = 'view-card';
    card.dataset.index = String(index);
    const colour = PART_COLOURS[index % PART_COLOURS.length];
    card.innerHTML = `
      <div class="thumb"><img alt="" /><div class="tint"></div><span class="swatch"></span></div>
      <div class="about">
        <b class="name"></b>
        <label class="angle" title="Turntable angle in degrees: how far the object was turned about the vertical axis (right-handed about +y) for this photo">
          Angle <input type="text" inputmode="decimal" spellcheck="false" /> °
        </label>
        <small class="settings"></small>
        <div class="settled" hidden>
          <span></span>
          <button class="btn small" data-act="keep" title="Make these areas the view's own concave regions: they stay when you edit it">Keep as regions</button>
        </div>
        <div class="buttons">
          <button class="btn small" data-act="edit" title="Open this photo with its settings (mask, regions, light, method) to change them; the fused model follows">Edit</button>
          <button class="btn small danger" data-act="remove" title="Leave this photo out of the fused model">Remove</button>
        </div>
      </div>`;
    card.querySelector('img')!.src = api.photoUrl(view.image.image_id);
    card.querySelector<HTMLElement>('.swatch')!.style.background = colour;
    card.querySelector<HTMLElement>('.swatch')!.textContent = String(index + 1);
    card.querySelector('.name')!.textContent = view.image.name;
    card.querySelector<HTMLElement>('.name')!.title = view.image.name;
    const input = card.querySelector('input')!;
    input.value = String(view.angle);
    input.dataset.angle = String(index);
    input.setAttribute('aria-label', `View ${index + 1} angle in degrees`);
    card.querySelector('.settings')!.textContent = settingsText(view.params);
    // what the fusion read as concave in this view's photo, from the other views
    const current = this.result && this.result.views.length === this.views.length ? this.result.views[index] : null;
    const settled = current?.settled.length ?? 0;
    if (settled) {
      card.querySelector<HTMLElement>('.settled')!.hidden = false;
      card.querySelector('.settled span')!.textContent =
        `${settled} unsure area${settled === 1 ? '' : 's'} read as concave from the other views`;
    }
    // the mask the view was solved with, tinted in its model's colour
    const mask = current?.mask_png;
    const tint = card.querySelector<HTMLElement>('.tint')!;
    if (mask) {
      tint.style.background = colour;
      tint.style.maskImage = `url(data:image/png;base64,${mask})`;
    } else {
      tint.hidden = true;
    }
    return card;
  }

  // ------------------------------------------------------------------------ hook

  hook() {
    return {
      views: () => this.views.map((view) => ({ image_id: view.image.image_id, name: view.image.name, angle: view.angle, params: structuredClone(view.params) })),
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

/** What a view's settings say in a few words: mask, regions, light, method. */
function settingsText(params: Params): string {
  const parts = [params.mask ? 'your mask' : 'automatic mask'];
  const regions = params.concave.regions.length;
  if (regions) parts.push(`${regions} concave region${regions === 1 ? '' : 's'}`);
  const light = params.light;
  parts.push(light.mode === 'z' ? 'frontal light' : light.mode === 'estimate' ? 'light estimated' : `light ${light.slant.toFixed(0)}° / ${light.tilt.toFixed(0)}°`);
  if (params.method !== 'auto') parts.push(params.method);
  return parts.join(' · ');
}
