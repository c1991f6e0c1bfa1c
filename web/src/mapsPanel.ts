// The Maps panel: the open photo's or photo set's model as texture maps (shadeform.maps on the
// server): normal maps in the OpenGL and DirectX conventions, height, ambient occlusion and
// curvature (and a photo set's albedo), each
// previewed small with its legend, all downloaded at once as a zip of full-resolution PNGs (the
// files `shadeform maps` writes, with a README.txt).
//
// The maps depend on the model's settings but its mesh step; their state is a ModelState of
// their own (modelState.ts): an edit makes the previews out of date (dimmed), "Make maps" makes
// them current, and the zip is offered only then, so that what is downloaded is what is shown.
import * as api from './api';
import type { MapsResult, ReconstructRequest, StereoRequest } from './api.gen';
import { $, showMessage } from './dom';
import { LatestRequest, ModelState, statusText } from './modelState';
import { inputsKey } from './printPanel';
import { download } from './state';
import './print.css';

export interface MapsHost {
  /** The open photo's or photo set's model at its current settings, or null when none is open. */
  request(): api.ModelSource | null;
  busy(text: string, work: () => Promise<void>): Promise<void>;
  toast(message: string, kind?: 'error' | 'info'): void;
}

/** Each map's title in the panel (the server's legend says what its values mean). */
const TITLES: Record<string, string> = {
  normal_opengl: 'Normal (OpenGL)',
  normal_directx: 'Normal (DirectX)',
  height: 'Height',
  ambient_occlusion: 'Ambient occlusion',
  curvature: 'Curvature',
  albedo: 'Albedo',
};

export class MapsPanel {
  /** The previews' state: current only when they were made from the settings shown. */
  readonly model = new ModelState(() => this.render());
  private key: string | null = null;
  private readonly requests = new LatestRequest(this.model, (message) => this.showError(message), () => this.render());
  private result: MapsResult | null = null;
  private made: ReconstructRequest | StereoRequest | null = null; // what the previews on record were made from
  private ready = false;

  constructor(private readonly host: MapsHost) {
    $('maps-group').innerHTML = `
      <h2>Maps</h2>
      <div class="hint-text">Texture maps of the model for a game engine or a renderer: normals, height, ambient occlusion, curvature (and a photo set's albedo).</div>
      <div class="buttons">
        <button class="btn small primary" id="maps-make" title="Make every map of the model's current settings and preview them here">Make maps</button>
        <button class="btn small" id="maps-zip" title="Every map at full resolution as a PNG (16-bit normals and height), with a README.txt legend">Download all (zip)</button>
      </div>
      <div class="print-status" id="maps-status" role="status"></div>
      <div class="maps-grid" id="maps-grid"></div>
      <div class="mask-error" id="maps-error" role="alert" hidden></div>`;
    $('maps-make').addEventListener('click', () => void this.make());
    $('maps-zip').addEventListener('click', () => void this.zip());
    this.ready = true;
    this.render();
  }

  /** The model's settings or the image may have changed: the previews go out of date. */
  sync(): void {
    const request = this.host.request();
    const key = request ? inputsKey(request) : null;
    if (key === this.key) return;
    this.key = key;
    if (key === null) {
      this.requests.abort();
      this.result = null;
      this.model.reset();
    } else if (this.model.status !== 'none') {
      this.model.changed("the model's settings changed");
    }
    this.render();
  }

  /** Ask the server for every map of the settings shown, and preview them. */
  async make(): Promise<void> {
    const base = this.host.request();
    if (!base) return this.host.toast('Open a photo first, then make its maps');
    this.sync();
    const request: ReconstructRequest | StereoRequest =
      base.kind === 'photo'
        ? { ...base.request, request_id: this.requests.nextId(), preview: false }
        : { ...base.request, request_id: this.requests.nextId() };
    await this.requests.run(
      (signal) => api.maps(request, signal),
      (result) => {
        this.result = result;
        this.made = request;
        this.showMaps(result);
      },
    );
  }

  /** Download every map of the current previews' settings as one zip. */
  async zip(): Promise<void> {
    const made = this.made;
    if (this.model.status !== 'current' || !made) {
      return this.host.toast('Nothing downloaded: make the maps for these settings first');
    }
    await this.host.busy('Writing the maps…', async () => {
      const { blob, filename } = await api.mapsZip(made);
      download(blob, filename);
    });
  }

  /** Read-only views for the tests (window.shadeform.maps). */
  hook() {
    return {
      /** The previews: current, computing, stale, failed or none (modelState.ts). */
      modelState: () => this.model.view(),
      /** The maps previewed: name, bits of its file, legend, and whether its picture has loaded. */
      maps: () =>
        [...document.querySelectorAll<HTMLElement>('#maps-grid figure')].map((figure) => {
          const image = figure.querySelector('img')!;
          return {
            name: figure.dataset.map!,
            bits: Number(figure.dataset.bits),
            legend: figure.dataset.legend!,
            loaded: image.complete && image.naturalWidth > 0,
            width: image.naturalWidth,
            height: image.naturalHeight,
          };
        }),
      zipEnabled: () => !$<HTMLButtonElement>('maps-zip').disabled,
      error: () => ($('maps-error').hidden ? null : $('maps-error').textContent),
      lastResult: () => {
        const r = this.result;
        if (!r) return null;
        return { request_id: r.request_id, width: r.width, height: r.height, names: r.maps.map((m) => m.name), timings: r.timings, info: r.info };
      },
    };
  }

  // ------------------------------------------------------------------------------ private

  private showMaps(result: MapsResult): void {
    const grid = $('maps-grid');
    grid.replaceChildren(
      ...result.maps.map((map) => {
        const figure = document.createElement('figure');
        figure.dataset.map = map.name;
        figure.dataset.bits = String(map.bits);
        figure.dataset.legend = map.legend;
        figure.title = `${TITLES[map.name] ?? map.name}: ${map.legend} (${map.bits}-bit PNG, ${result.width} × ${result.height})`;
        const image = document.createElement('img');
        image.src = `data:image/png;base64,${map.png}`;
        image.alt = TITLES[map.name] ?? map.name;
        const caption = document.createElement('figcaption');
        const name = document.createElement('b');
        name.textContent = TITLES[map.name] ?? map.name;
        const legend = document.createElement('small');
        legend.textContent = `${map.bits}-bit · ${map.legend}`;
        caption.append(name, legend);
        figure.append(image, caption);
        return figure;
      }),
    );
  }

  private showError(message: string | null): void {
    showMessage('maps-error', message);
  }

  private render(): void {
    if (!this.ready) return; // the state's first call comes before the panel is built
    const { status, message } = this.model;
    const open = this.key !== null; // sync() keeps it
    const r = this.result;
    let text = status === 'none' ? (open ? 'Not made yet' : 'Open a photo to make its maps') : statusText(status, message);
    if (r && status !== 'none') text += ` · ${r.width} × ${r.height} px`;
    const line = $('maps-status');
    line.dataset.status = status;
    line.textContent = text;
    $('maps-grid').classList.toggle('outdated', status !== 'current');
    if (status === 'none') $('maps-grid').replaceChildren();
    const zip = $<HTMLButtonElement>('maps-zip');
    zip.disabled = status !== 'current';
    zip.title = zip.disabled
      ? 'Make the maps for these settings first'
      : 'Every map at full resolution as a PNG (16-bit normals and height), with a README.txt legend';
    $<HTMLButtonElement>('maps-make').disabled = !open;
  }
}
