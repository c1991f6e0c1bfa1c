// Photo sets: several photos of one still object under moving lights, solved by photometric
// stereo on the server. This module owns the pane that shows what it found (the object relit
// under a light the user drags, its normals, albedo, confidence, and the photos themselves),
// the panel group of its settings (their words: words.ts), and its requests; the App gives it the
// 3D view and the busy/toast helpers.
//
// Relighting is done on the page, per pixel, from the normals and albedo the server sends as PNGs
// (relight.ts), in the viewing mode and under the lights of the Relight group (relightPanel.ts).
// A drag redraws at most once per animation frame. Save picture downloads what the pane shows.
import * as api from './api';
import type { Options, PhotoSetInfo, StereoParams, StereoResult } from './api.gen';
import { NetworkError, send, UNREACHABLE } from './connection';
import { $, showMessage } from './dom';
import { ModelRequest, ModelState } from './modelState';
import { decodeMaps, lightFromDisc, relight, type Maps } from './relight';
import { RelightPanel } from './relightPanel';
import { download } from './state';
import { fillStereoChoices } from './words';

export type StereoShow = 'relight' | 'normals' | 'albedo' | 'confidence' | 'photo';

export interface StereoHost {
  /** Show a solved mesh in the 3D view (refit the camera when asked). */
  showMesh(result: StereoResult, mesh: api.DecodedMesh, refit: boolean): void;
  busy(text: string, work: () => Promise<void>): Promise<void>;
  solving(on: boolean): void;
  toast(message: string, kind?: 'error' | 'info'): void;
  /** The settings changed: keep them for a reload. */
  changed(): void;
  /** Only how the pane shows the set changed (its viewing mode, lights): keep it for a reload. */
  viewingChanged(): void;
  /** The model's state changed (the badge, the export menu and the dimming follow it). */
  modelChanged(): void;
}

export class StereoSession {
  info: PhotoSetInfo | null = null;
  params: StereoParams;
  result: StereoResult | null = null;
  show: StereoShow = 'relight';
  /** The Relight group: the viewing mode, its settings and the lights. */
  readonly viewing: RelightPanel;
  photoIndex = 0;
  appliedCount = 0;
  /** What the photo set's model on screen is: current, computing, stale or failed. */
  readonly model: ModelState;
  private maps: Maps | null = null;
  private photo: ImageData | null = null;
  /** The solves, one at a time (the App's "Solving…" on while one is out). */
  private readonly requests: ModelRequest;
  private requestCounter = 0;
  private frame = 0;
  private refitNext = true;
  private readonly canvas: HTMLCanvasElement;
  private readonly dome: HTMLCanvasElement;

  constructor(
    private readonly options: Options,
    private readonly host: StereoHost,
  ) {
    this.params = structuredClone(options.stereo_defaults);
    this.model = new ModelState(() => host.modelChanged());
    this.requests = new ModelRequest(this.model, (on) => host.solving(on));
    this.canvas = $<HTMLCanvasElement>('stereo-canvas');
    this.dome = $<HTMLCanvasElement>('light-dome');
    this.viewing = new RelightPanel(() => {
      if (this.show !== 'relight') this.setShow('relight');
      else this.draw();
      host.viewingChanged();
    });
    this.buildPanel();
    this.bindPane();
  }

  // ----------------------------------------------------------------------- opening

  async openFiles(files: File[]): Promise<boolean> {
    // as a DiLiGenT-style folder is read (the CLI's photo_files): a mask and ground-truth normal
    // maps are not photos; filenames.txt, where there is one, names the photos in order (a whole
    // MIT-Berkeley folder holds other pictures too), else they are ordered by their names,
    // numbers as numbers
    const listing = files.find((f) => /^filenames\.txt$/i.test(f.name)) ?? null;
    const ignored = /^(normal_gt|normal_map)\.|^filenames\.txt$/i;
    files = files.filter((f) => !ignored.test(f.name));
    let images = files.filter((f) => !/\.(txt|lp|json|csv|mat)$/i.test(f.name) && !/^mask\./i.test(f.name));
    images.sort((a, b) => a.name.localeCompare(b.name, undefined, { numeric: true }));
    if (listing) {
      const byName = new Map(images.map((f) => [f.name, f]));
      const named = (await listing.text()).split(/\s+/).filter(Boolean).map((name) => byName.get(name.split(/[\\/]/).pop() ?? ''));
      if (named.every((f) => f !== undefined) && named.length >= 3) images = named as File[];
    }
    const texts = files.filter((f) => /\.(txt|lp|csv)$/i.test(f.name));
    const intensities = texts.find((f) => /intensit/i.test(f.name)) ?? null;
    // the light file by its usual names first (a folder may hold other text files)
    const lights =
      texts.find((f) => /^light_directions\.txt$|\.lp$/i.test(f.name)) ?? texts.find((f) => f !== intensities) ?? null;
    const mask = files.find((f) => /^mask\./i.test(f.name)) ?? null;
    if (images.length < 3) {
      this.host.toast(
        `Photometric stereo needs at least 3 photos of one still object; ${images.length} chosen — select all the photos (and their light file) at once`,
      );
      return false;
    }
    const total = files.reduce((sum, f) => sum + f.size, 0);
    const limit = this.options.limits.max_upload_bytes;
    if (total > limit) {
      this.host.toast(`The photos together are ${(total / 1e6).toFixed(1)} MB; the limit is ${(limit / 1e6).toFixed(1)} MB — open fewer or smaller photos`);
      return false;
    }
    let opened = false;
    await this.host.busy(`Uploading ${images.length} photos…`, async () => {
      const info = await api.uploadPhotoSet(images, { lights, intensities, mask });
      this.open(info);
      opened = true;
    });
    return opened;
  }

  async openExample(name: string): Promise<boolean> {
    let opened = false;
    await this.host.busy('Opening photo set…', async () => {
      this.open(await api.openPhotoSetExample(name));
      opened = true;
    });
    return opened;
  }

  /** The photo set a reloaded page had open, with its settings (the server may have forgotten it)
   * and, where the reload kept them, how it was viewed (relightModes.ts restoreSettings). */
  reopen(info: PhotoSetInfo, params: StereoParams, viewing?: unknown): void {
    if (viewing !== undefined) this.viewing.restore(viewing);
    this.open(info, params);
  }

  /** Back to one photo: nothing of the set is shown or solved any more. */
  close(): void {
    this.requests.abort();
    this.info = null;
    this.result = null;
    this.maps = null;
    this.model.reset();
  }

  /** What a reload needs to show the set again (a project keeps this; viewingSession() a reload only). */
  session(): { info: PhotoSetInfo; params: StereoParams } | null {
    return this.info ? { info: structuredClone(this.info), params: structuredClone(this.params) } : null;
  }

  /** How the set is viewed: its viewing mode, the mode's settings and the lights. */
  viewingSession() {
    return structuredClone(this.viewing.settings);
  }

  private open(info: PhotoSetInfo, params?: StereoParams): void {
    this.info = info;
    this.params = { ...structuredClone(this.options.stereo_defaults), ...currentNames(params ?? info.suggested) };
    this.result = null;
    this.maps = null;
    this.photo = null;
    this.photoIndex = 0;
    this.refitNext = true;
    this.model.changed('another photo set opened');
    this.canvas.width = info.width;
    this.canvas.height = info.height;
    $<HTMLInputElement>('stereo-photo').max = String(info.count);
    $<HTMLInputElement>('stereo-photo').value = '1';
    const parts = [`${info.count} photos`, `${info.width} × ${info.height}`, info.colour ? 'colour' : 'grey'];
    parts.push(info.lights_file ? 'light file' : 'no light file');
    if (info.intensities_file) parts.push('light strengths');
    if (info.mask) parts.push('mask');
    $('stereo-summary').textContent = parts.join(' · ');
    this.showParams();
    this.setError(null);
    this.setShow(this.show); // its button marked as the one on (none was, at the first set)
    this.solve();
  }

  // ----------------------------------------------------------------------- solving

  /** The open set's request at its current settings (for the Print and Maps panels), or null. */
  current(): api.StereoRequestBody | null {
    return this.info ? { photoset_id: this.info.photoset_id, params: structuredClone(this.params), request_id: 0 } : null;
  }

  /** Show the set's model in the 3D view again (in place of a print's solid). */
  showModel(): void {
    if (this.result) this.host.showMesh(this.result, api.decodeMesh(this.result.mesh), false);
  }

  request(): api.StereoRequestBody {
    return { ...this.current()!, request_id: ++this.requestCounter };
  }

  async solve(): Promise<void> {
    if (!this.info) return;
    const body = this.request();
    await this.requests.run(
      async ({ signal, version }) => {
        const result = await api.stereo(body, signal);
        if (!result || result.request_id !== this.requestCounter) return;
        const mesh = api.decodeMesh(result.mesh);
        const maps = await decodeMaps(result);
        if (result.request_id !== this.requestCounter) return;
        this.result = result;
        this.maps = maps;
        this.host.showMesh(result, mesh, this.refitNext);
        this.model.arrived(version);
        this.refitNext = false;
        this.appliedCount += 1;
        this.setError(null);
        this.showNote(result);
        this.draw();
      },
      (err, version) => {
        const message =
          err instanceof NetworkError
            ? 'The server is not reachable (stopped or restarting): the photo set is solved again once it answers' // the App sends it again
            : err instanceof api.ApiError && err.status === 404
              ? 'The server no longer has these photos (it was restarted without its sessions, or let them go): open them again with Open photos'
              : err.message;
        this.setError(message);
        this.model.failed(version, err instanceof NetworkError ? UNREACHABLE : message);
      },
    );
  }

  async exportFormat(suffix: string): Promise<{ blob: Blob; filename: string }> {
    return api.exportStereo(this.request(), suffix);
  }

  private change(patch: Partial<StereoParams>): void {
    const onlyStep = Object.keys(patch).every((key) => key === 'step');
    this.params = { ...this.params, ...patch };
    this.model.changed();
    this.showParams();
    this.host.changed();
    if (!onlyStep) this.refitNext = true;
    this.solve();
  }

  // ------------------------------------------------------------------------- panel

  private buildPanel(): void {
    const model = $<HTMLSelectElement>('stereo-model');
    const integrator = $<HTMLSelectElement>('stereo-integrator');
    fillStereoChoices(model, integrator, this.options);
    model.addEventListener('change', () => this.change({ model: model.value }));
    integrator.addEventListener('change', () => this.change({ integrator: integrator.value }));
    for (const button of document.querySelectorAll<HTMLButtonElement>('#stereo-lights button')) {
      button.addEventListener('click', () => {
        const lights = button.dataset.lights as StereoParams['lights'];
        if (lights === 'file' && !this.info?.lights_file) {
          this.setError('This photo set came without a light file: open the photos again together with their light file (.txt or .lp), or choose Sphere or Unknown');
          return;
        }
        this.change({ lights });
      });
    }
    const sphere = $<HTMLInputElement>('stereo-sphere');
    sphere.addEventListener('change', () => {
      const text = sphere.value.trim();
      if (!text || text.toLowerCase() === 'auto') return this.change({ sphere: null });
      const numbers = text.split(/[\s,]+/).map(Number);
      if (numbers.length !== 3 || !numbers.every(Number.isFinite) || numbers[2] <= 0) {
        this.setError(`"${text}" is not a circle: give the sphere's column, row and radius in pixels (e.g. 120, 80, 40), or leave it empty to find it`);
        return;
      }
      this.change({ sphere: numbers as [number, number, number] });
    });
    const step = $<HTMLInputElement>('stereo-step');
    step.addEventListener('input', () => ($('stereo-step-out').textContent = step.value));
    step.addEventListener('change', () => this.change({ step: Number(step.value) }));
  }

  private showParams(): void {
    $<HTMLSelectElement>('stereo-model').value = this.params.model;
    $<HTMLSelectElement>('stereo-integrator').value = this.params.integrator;
    for (const button of document.querySelectorAll<HTMLButtonElement>('#stereo-lights button')) {
      button.classList.toggle('on', button.dataset.lights === this.params.lights);
      if (button.dataset.lights === 'file') button.classList.toggle('unavailable', !this.info?.lights_file);
    }
    $('stereo-sphere-row').hidden = this.params.lights !== 'sphere';
    const sphere = this.params.sphere;
    $<HTMLInputElement>('stereo-sphere').value = sphere ? sphere.map((v) => Math.round(v * 10) / 10).join(', ') : '';
    $<HTMLInputElement>('stereo-step').value = String(this.params.step);
    $('stereo-step-out').textContent = String(this.params.step);
  }

  private showNote(result: StereoResult): void {
    const notes: string[] = [];
    // a depth no photo shows (a slab: lights read from the photos, resolved wrong), and what to do
    const quality = result.info.quality as { warning?: string } | undefined;
    if (quality?.warning) notes.push(`Warning: ${quality.warning[0].toUpperCase()}${quality.warning.slice(1)}.`);
    const lights = { file: 'from the light file', sphere: 'read from the sphere', unknown: 'read from the photos' }[this.params.lights];
    notes.push(`${result.lights.length} lights ${lights}.`);
    if (result.sphere) {
      const [x, y, r] = result.sphere;
      notes.push(`Sphere at column ${x.toFixed(0)}, row ${y.toFixed(0)}, radius ${r.toFixed(0)}.`);
    }
    if (result.photos_dropped.length) {
      notes.push(`Left out (they contradict the others): photo ${result.photos_dropped.map((i) => i + 1).join(', ')}.`);
    }
    if (result.photos_rescaled.length) {
      const shown = result.photos_rescaled.slice(0, 6).map(([i, f]) => `${i + 1} ×${f.toFixed(2)}`);
      notes.push(`Light strength corrected: photo ${shown.join(', ')}${result.photos_rescaled.length > 6 ? ', …' : ''}.`);
    }
    const normals = result.timings.normals, depth = result.timings.depth;
    if (normals !== undefined) notes.push(`Normals ${normals.toFixed(2)} s, depth ${(depth ?? 0).toFixed(2)} s.`);
    $('stereo-note').textContent = notes.join(' ');
  }

  /** A message that stays until the next result (or the next error). */
  private setError(message: string | null): void {
    showMessage('stereo-error', message);
  }

  // -------------------------------------------------------------------------- pane

  private bindPane(): void {
    for (const button of document.querySelectorAll<HTMLButtonElement>('#stereo-show button')) {
      button.addEventListener('click', () => this.setShow(button.dataset.show as StereoShow));
    }
    const photo = $<HTMLInputElement>('stereo-photo');
    photo.addEventListener('input', () => this.showPhoto(Number(photo.value) - 1));
    $('stereo-picture').addEventListener('click', () => this.savePicture());
    // a drag on the disc moves the light whose handle is nearest; one on the image, the last picked
    const dragOn = (element: HTMLCanvasElement, toDisc: (event: PointerEvent) => [number, number], picks: boolean) => {
      const move = (event: PointerEvent) => {
        if (!this.maps) return;
        this.setLight(lightFromDisc(...toDisc(event)));
      };
      element.addEventListener('pointerdown', (event) => {
        if (event.button !== 0) return;
        element.setPointerCapture(event.pointerId);
        if (this.show !== 'relight') this.setShow('relight');
        if (picks) this.viewing.pick(...toDisc(event));
        move(event);
      });
      element.addEventListener('pointermove', (event) => {
        if (element.hasPointerCapture(event.pointerId)) move(event);
      });
    };
    dragOn(this.canvas, (event) => {
      const [row, col] = this.pixelAt(event.clientX, event.clientY);
      const maps = this.maps!;
      return [(col - maps.centre[0]) / maps.radius, -(row - maps.centre[1]) / maps.radius];
    }, false);
    dragOn(this.dome, (event) => {
      const rect = this.dome.getBoundingClientRect();
      const half = rect.width / 2;
      return [(event.clientX - rect.left - half) / (half - 6), -(event.clientY - rect.top - half) / (half - 6)];
    }, true);
  }

  setShow(show: StereoShow): void {
    this.show = show;
    for (const button of document.querySelectorAll<HTMLButtonElement>('#stereo-show button')) {
      button.classList.toggle('on', button.dataset.show === show);
    }
    $('stereo-photo-row').hidden = show !== 'photo';
    if (show === 'photo') this.showPhoto(this.photoIndex);
    else this.draw();
  }

  /** Move the light a drag moves (the Relight group redraws and keeps it). */
  setLight(light: [number, number, number]): void {
    this.viewing.moveActive(light);
  }

  /** What the pane shows, drawn now, downloaded as a PNG named after the set and the view. */
  private savePicture(): void {
    if (!this.info || !this.maps) return void this.host.toast('Nothing to save yet: the photo set is still being solved');
    if (this.frame) {
      cancelAnimationFrame(this.frame);
      this.frame = 0;
    }
    this.render();
    const stem = this.info.name.replace(/\.[^.]+$/, '').replace(/[^\w.-]+/g, '_') || 'photo_set';
    const view = { relight: `relight-${this.viewing.settings.mode}`, photo: `photo-${this.photoIndex + 1}` }[this.show as string] ?? this.show;
    this.canvas.toBlob((blob) => {
      if (blob) download(blob, `${stem}-${view}.png`);
      else this.host.toast('The browser could not make a PNG of the picture');
    }, 'image/png');
  }

  /** Where the image lies on the page: the canvas shows it fitted and centred. */
  private placement(): { left: number; top: number; scale: number } {
    const rect = this.canvas.getBoundingClientRect();
    const scale = Math.min(rect.width / this.canvas.width, rect.height / this.canvas.height);
    const left = rect.left + (rect.width - scale * this.canvas.width) / 2;
    const top = rect.top + (rect.height - scale * this.canvas.height) / 2;
    return { left, top, scale };
  }

  /** (row, col) of the image under a page point. */
  pixelAt(clientX: number, clientY: number): [number, number] {
    const { left, top, scale } = this.placement();
    return [(clientY - top) / scale - 0.5, (clientX - left) / scale - 0.5];
  }

  private async showPhoto(index: number): Promise<void> {
    if (!this.info) return;
    this.photoIndex = Math.max(0, Math.min(this.info.count - 1, index));
    $('stereo-photo-out').textContent = `${this.photoIndex + 1} / ${this.info.count}`;
    const id = this.info.photoset_id;
    try {
      const response = await send(api.photoSetPhotoUrl(id, this.photoIndex));
      if (!response.ok) throw new Error((await response.json()).detail ?? response.statusText);
      const image = await createImageBitmap(await response.blob());
      const canvas = document.createElement('canvas');
      canvas.width = image.width;
      canvas.height = image.height;
      const context = canvas.getContext('2d')!;
      context.drawImage(image, 0, 0);
      if (this.info?.photoset_id !== id || this.show !== 'photo') return;
      this.photo = context.getImageData(0, 0, image.width, image.height);
      this.draw();
    } catch (err) {
      this.setError(`Cannot show photo ${this.photoIndex + 1}: ${(err as Error).message}`);
    }
  }

  /** Redraw the pane (at most once per frame). */
  draw(): void {
    if (this.frame) return;
    this.frame = requestAnimationFrame(() => {
      this.frame = 0;
      this.render();
    });
  }

  private render(): void {
    const context = this.canvas.getContext('2d')!;
    const maps = this.maps;
    this.drawDome();
    $('stereo-empty').hidden = maps !== null;
    if (!maps) {
      context.clearRect(0, 0, this.canvas.width, this.canvas.height);
      return;
    }
    if (this.show === 'normals') return context.putImageData(maps.normalsImage, 0, 0);
    if (this.show === 'albedo') return context.putImageData(maps.albedoImage, 0, 0);
    if (this.show === 'confidence') return context.putImageData(maps.confidenceImage, 0, 0);
    if (this.show === 'photo') {
      if (this.photo) context.putImageData(this.photo, 0, 0);
      return;
    }
    const settings = this.viewing.settings;
    context.putImageData(relight(maps, settings), 0, 0);
    const [x, y, z] = settings.lights[this.viewing.active];
    const slant = (Math.acos(z) * 180) / Math.PI;
    const tilt = (Math.atan2(y, x) * 180) / Math.PI;
    const count = settings.lights.length;
    const which = count > 1 ? `light ${this.viewing.active + 1} of ${count}:` : 'light';
    $('stereo-light-out').textContent = `${which} slant ${slant.toFixed(0)}°, tilt ${tilt.toFixed(0)}°`;
  }

  private drawDome(): void {
    const size = this.dome.width;
    const half = size / 2;
    const r = half - 6;
    const context = this.dome.getContext('2d')!;
    context.clearRect(0, 0, size, size);
    context.fillStyle = 'rgba(15, 23, 42, 0.72)';
    context.beginPath();
    context.arc(half, half, r, 0, 2 * Math.PI);
    context.fill();
    context.strokeStyle = 'rgba(148, 163, 184, 0.6)';
    context.stroke();
    context.beginPath();
    context.arc(half, half, r * Math.sin(Math.PI / 4), 0, 2 * Math.PI);
    context.stroke();
    context.fillStyle = 'rgba(148, 163, 184, 0.9)';
    for (const [x, y] of this.result?.lights ?? []) {
      context.beginPath();
      context.arc(half + x * r, half - y * r, 2, 0, 2 * Math.PI);
      context.fill();
    }
    this.viewing.drawHandles(context, half, r);
  }

  // ------------------------------------------------------------------------ hook

  hook() {
    return {
      info: () => (this.info ? structuredClone(this.info) : null),
      params: () => structuredClone(this.params),
      show: () => this.show,
      /** The light a drag moves, all the lights, and the Relight group's settings. */
      light: () => [...this.viewing.settings.lights[this.viewing.active]],
      lights: () => structuredClone(this.viewing.settings.lights),
      viewing: () => this.viewingSession(),
      applied: () => this.appliedCount,
      /** The photo set's model: current, computing, stale or failed (modelState.ts). */
      modelState: () => this.model.view(),
      error: () => ($('stereo-error').hidden ? null : $('stereo-error').textContent),
      note: () => $('stereo-note').textContent,
      lastResult: () => {
        const r = this.result;
        if (!r) return null;
        return {
          request_id: r.request_id,
          vertex_count: r.mesh.vertex_count,
          lights: r.lights,
          sphere: r.sphere,
          photos_dropped: r.photos_dropped,
          photos_rescaled: r.photos_rescaled,
          albedo_white: r.albedo_white,
          depth_range: r.depth_range,
          info: r.info,
        };
      },
      /** The pane's pixels at (row, col) as drawn now: [r, g, b]. */
      shownAt: (row: number, col: number) => Array.from(this.canvas.getContext('2d')!.getImageData(col, row, 1, 1).data.slice(0, 3)),
      /** The decoded normal and linear albedo at (row, col), or null off the object. */
      mapsAt: (row: number, col: number) => {
        const maps = this.maps;
        const i = row * (maps?.width ?? 0) + col;
        if (!maps || !maps.mask[i]) return null;
        return { normal: Array.from(maps.normals.slice(3 * i, 3 * i + 3)), albedo: Array.from(maps.albedo.slice(3 * i, 3 * i + 3)) };
      },
      /** The page point over image pixel (row, col), for a test's mouse. */
      pagePoint: (row: number, col: number) => {
        const { left, top, scale } = this.placement();
        return { x: left + (col + 0.5) * scale, y: top + (row + 0.5) * scale };
      },
    };
  }
}

/** Saved parameters in today's names: a session or project saved before the rename holds the
 * photometric model as `method` (the server takes either; sent both, it refuses the request). */
function currentNames(params: StereoParams): StereoParams {
  const { method, ...rest } = params as StereoParams & { method?: string };
  return method === undefined || rest.model !== undefined ? rest : { ...rest, model: method };
}
