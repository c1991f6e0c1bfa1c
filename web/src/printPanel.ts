// The Print panel: the open photo's model, or the open photo set's, as a closed solid in
// millimetres (shadeform.relief on the server), shown in the 3D view with its measures beside it,
// downloaded as STL or 3MF.
//
// The solid depends on the model's settings (all but the mesh's step: it is made from the
// full-resolution depth) and on the print options here. Its state is a ModelState of its own
// (modelState.ts): an edit of either makes a built solid out of date, "Build solid" makes it
// current, and the downloads are enabled only then, so that the file is the solid shown for the
// settings shown. The App tells the panel when its inputs may have changed (sync()).
//
// The 3D view shows one mesh: a built solid replaces the model there (frame "solid", so the
// camera fits it), and a new model of the photo replaces the solid; "Show model" / "Show solid"
// switch between the two without asking the server again.
import * as THREE from 'three';
import * as api from './api';
import type { Options, ReliefParams, ReliefRequest, ReliefResult, StereoReliefRequest } from './api.gen';
import { $, showMessage } from './dom';
import { LatestRequest, ModelState, statusText } from './modelState';
import { download } from './state';
import type { Viewer } from './viewer';
import './print.css';

export interface PrintHost {
  /** The open photo's or photo set's model at its current settings, or null when none is open. */
  request(): api.ModelSource | null;
  /** Show the model in the 3D view again, in place of the solid. */
  showModel(): void;
  /** A solid is on screen (the 3D view's controls are on). */
  shown(): void;
  busy(text: string, work: () => Promise<void>): Promise<void>;
  toast(message: string, kind?: 'error' | 'info'): void;
}

const STORAGE_KEY = 'shadeform.print.v1';
const FRAME = 'solid';
// a three-quarter view from the right and below the photo's frame, the measured edges nearest
// (the solid's x = columns, y = up the photo, z = toward the camera as for the model)
const VIEW_YAW = 30;
const VIEW_PITCH = -25;
// the share of the view's width and height the solid's box may take: room for the labels beside it
const VIEW_FILL = 0.75;

/** The numeric options typed into the panel; the triangle budget may be empty (no budget). */
const NUMBERS = [
  { key: 'width_mm', id: 'print-width', label: 'Width', unit: 'mm', step: '1', min: '1', title: 'Longest side of the outline, mm (exact)' },
  { key: 'height_mm', id: 'print-height', label: 'Relief', unit: 'mm', step: '0.5', min: '0.1', title: 'Relief depth from its lowest to its highest point, mm' },
  { key: 'base_mm', id: 'print-base', label: 'Base', unit: 'mm', step: '0.5', min: '0.8', title: 'Thickness of the flat base under the relief, mm' },
  { key: 'border_mm', id: 'print-border', label: 'Border', unit: 'mm', step: '1', min: '0', title: 'A flat rim around the outline, mm (0: none); included in the width' },
  { key: 'max_triangles', id: 'print-triangles', label: 'Triangles', unit: 'max', step: '10000', min: '12', title: 'Triangle budget: the top is simplified to at most this many triangles (empty: two per pixel, can be huge)' },
] as const;

type NumberKey = (typeof NUMBERS)[number]['key'];

export class PrintPanel {
  /** The solid's state: current only when it was built from the settings shown. */
  readonly model = new ModelState(() => this.render());
  private options: ReliefParams;
  private key: string | null = null; // the inputs the state is about (sync())
  private modelKey: string | null = null;
  private readonly requests = new LatestRequest(this.model, (message) => this.showError(message), () => this.render());
  private result: ReliefResult | null = null;
  private built: ReliefRequest | StereoReliefRequest | null = null; // what the solid on record was built from
  private mesh: api.DecodedMesh | null = null;
  private problem: string | null = null; // what is wrong with a typed option, before any request
  private readonly dims: HTMLElement;
  private readonly labels: HTMLElement[];

  constructor(
    defaults: Options['relief_defaults'],
    private readonly viewer: Viewer,
    private readonly host: PrintHost,
  ) {
    this.options = { ...defaults, ...loadOptions(defaults) };
    this.buildControls();
    this.show();
    // the measures beside the solid: a line of text and a label on each measured edge
    this.dims = document.createElement('div');
    this.dims.className = 'print-dims';
    this.dims.id = 'print-dims';
    this.dims.hidden = true;
    this.labels = ['x', 'y', 'z'].map((axis) => {
      const label = document.createElement('div');
      label.className = `dim-label dim-${axis}`;
      label.hidden = true;
      return label;
    });
    $('view-host').append(this.dims, ...this.labels);
    viewer.onRender(() => this.placeLabels());
    this.render();
  }

  /** The model's settings or the image may have changed: a built solid goes out of date. */
  sync(): void {
    const request = this.host.request();
    const modelKey = request ? inputsKey(request) : null;
    const key = modelKey === null ? null : `${modelKey}|${JSON.stringify(this.options)}`;
    if (key === this.key) return;
    const why = modelKey !== this.modelKey ? "the model's settings changed" : 'print settings changed';
    this.key = key;
    this.modelKey = modelKey;
    if (modelKey === null) {
      this.requests.abort();
      this.model.reset();
    } else if (this.model.status !== 'none') {
      this.model.changed(why);
    }
    this.render();
  }

  /** Ask the server for the solid of the settings shown, and show it. */
  async buildSolid(): Promise<void> {
    const base = this.host.request();
    if (!base) return this.host.toast('Open a photo first, then build its print');
    if (this.problem) return this.showError(this.problem);
    this.sync();
    const request = api.reliefRequest(base, structuredClone(this.options), this.requests.nextId());
    await this.requests.run(
      (signal) => api.relief(request, signal),
      (result) => {
        this.result = result;
        this.built = request;
        this.mesh = api.decodeMesh(result.mesh);
        this.showSolid();
      },
    );
  }

  /** Download the current solid as ``suffix`` (.stl, .3mf). */
  async exportFormat(suffix: string): Promise<void> {
    const built = this.built;
    if (this.model.status !== 'current' || !built) {
      return this.host.toast('Nothing downloaded: build the solid for these settings first');
    }
    await this.host.busy(`Exporting the solid as ${suffix}…`, async () => {
      const { blob, filename } = await api.exportRelief(built, suffix);
      download(blob, filename);
    });
  }

  /** Read-only views for the tests (window.shadeform.print). */
  hook() {
    return {
      /** The solid: current, computing, stale, failed or none (modelState.ts). */
      modelState: () => this.model.view(),
      options: () => structuredClone(this.options),
      /** Whether the 3D view shows the solid (rather than the photo's model). */
      shown: () => this.viewer.shownFrame === FRAME,
      /** The measures written beside the solid, or null when it is not on screen. */
      dimensions: () => (this.dims.hidden ? null : this.dims.textContent),
      /** Which downloads are enabled. */
      downloads: () => ({ stl: !$<HTMLButtonElement>('print-stl').disabled, '3mf': !$<HTMLButtonElement>('print-3mf').disabled }),
      error: () => ($('print-error').hidden ? null : $('print-error').textContent),
      lastResult: () => {
        const r = this.result;
        if (!r) return null;
        return {
          request_id: r.request_id,
          vertex_count: r.mesh.vertex_count,
          triangle_count: r.triangle_count,
          size_mm: r.size_mm,
          volume_mm3: r.volume_mm3,
          deviation_mm: r.deviation_mm,
          pixel_mm: r.pixel_mm,
          timings: r.timings,
          info: r.info,
        };
      },
    };
  }

  // ------------------------------------------------------------------------------ private

  /** The panel's controls, into #print-group. */
  private buildControls(): void {
    const group = $('print-group');
    group.innerHTML = `
      <h2>Print</h2>
      <div class="hint-text">The model as a closed solid in millimetres, with a flat base, to slice and print.</div>
      ${NUMBERS.map((n) => `
        <label class="row print-number" title="${n.title}">
          <span>${n.label}</span>
          <input type="number" id="${n.id}" min="${n.min}" step="${n.step}" ${n.key === 'max_triangles' ? 'placeholder="no limit"' : ''} />
          <em>${n.unit}</em>
        </label>`).join('')}
      <label class="row slider" title="Bas-relief compression: 0 scales the depth linearly; more flattens large depth jumps and keeps fine detail">
        <span>Compress</span>
        <input type="range" id="print-compress" min="0" max="1" step="0.05" />
        <output id="print-compress-out"></output>
      </label>
      <div class="row">
        <span title="What the solid's sides follow">Sides</span>
        <div class="segmented" id="print-outline" role="group" aria-label="Sides">
          <button data-outline="mask" title="Walls along the object's outline">Outline</button>
          <button data-outline="frame" title="A rectangular plaque: the image frame, the background at the lowest level">Frame</button>
        </div>
      </div>
      <label class="toggle print-invert" title="Engrave instead of emboss: the highest point becomes the lowest"><input type="checkbox" id="print-invert" /> Engrave (invert the relief)</label>
      <div class="buttons">
        <button class="btn small primary" id="print-build" title="Make the solid of the model's settings and these print settings">Build solid</button>
        <button class="btn small" id="print-switch" title="Switch the 3D view between the solid and the photo's model">Show model</button>
      </div>
      <div class="print-status" id="print-status" role="status"></div>
      <div class="buttons print-downloads">
        <span>Download</span>
        <button class="btn small" id="print-stl" title="Binary STL, millimetres">STL</button>
        <button class="btn small" id="print-3mf" title="3MF, the unit (millimetres) in the file">3MF</button>
      </div>
      <div class="mask-error" id="print-error" role="alert" hidden></div>`;
    for (const n of NUMBERS) {
      $<HTMLInputElement>(n.id).addEventListener('input', () => this.edited());
    }
    $<HTMLInputElement>('print-compress').addEventListener('input', () => this.edited());
    $<HTMLInputElement>('print-invert').addEventListener('change', () => this.edited());
    for (const button of group.querySelectorAll<HTMLButtonElement>('#print-outline button')) {
      button.addEventListener('click', () => {
        this.options.outline = button.dataset.outline as ReliefParams['outline'];
        this.show();
        this.edited();
      });
    }
    $('print-build').addEventListener('click', () => void this.buildSolid());
    $('print-switch').addEventListener('click', () => this.switchView());
    $('print-stl').addEventListener('click', () => void this.exportFormat('.stl'));
    $('print-3mf').addEventListener('click', () => void this.exportFormat('.3mf'));
  }

  /** The options into the controls. */
  private show(): void {
    for (const n of NUMBERS) {
      const value = this.options[n.key];
      $<HTMLInputElement>(n.id).value = value === null ? '' : String(value);
    }
    $<HTMLInputElement>('print-compress').value = String(this.options.compress);
    $('print-compress-out').textContent = this.options.compress.toFixed(2);
    $<HTMLInputElement>('print-invert').checked = this.options.invert;
    for (const button of document.querySelectorAll<HTMLButtonElement>('#print-outline button')) {
      button.classList.toggle('on', button.dataset.outline === this.options.outline);
    }
  }

  /** The controls into the options; the server checks the values (and says what is wrong). */
  private edited(): void {
    this.problem = null;
    for (const n of NUMBERS) {
      const text = $<HTMLInputElement>(n.id).value.trim();
      const value = Number(text);
      if (n.key === 'max_triangles' && text === '') {
        this.options.max_triangles = null;
      } else if (text === '' || !Number.isFinite(value)) {
        this.problem ??= `${n.label}: give a number${n.unit === 'mm' ? ' of millimetres' : ''}`;
      } else {
        (this.options as Record<NumberKey, number | null>)[n.key] = value;
      }
    }
    this.options.compress = Number($<HTMLInputElement>('print-compress').value);
    this.options.invert = $<HTMLInputElement>('print-invert').checked;
    $('print-compress-out').textContent = this.options.compress.toFixed(2);
    localStorage.setItem(STORAGE_KEY, JSON.stringify(this.options));
    this.showError(this.problem);
    this.sync();
  }

  private showSolid(): void {
    const mesh = this.mesh;
    const result = this.result;
    if (!mesh || !result) return;
    this.viewer.setMesh(mesh, { refit: true, frame: FRAME });
    this.viewer.fitView(VIEW_YAW, VIEW_PITCH, VIEW_FILL);
    this.viewer.setGuides(measureLines(mesh));
    this.host.shown();
    const [w, d, h] = result.size_mm;
    $('mesh-info').textContent =
      `solid · ${result.triangle_count.toLocaleString()} triangles · ${mm(w)} × ${mm(d)} × ${mm(h)} mm · ` +
      `${(result.volume_mm3 / 1000).toFixed(1)} cm³` +
      (result.deviation_mm > 0 ? ` · within ${result.deviation_mm.toFixed(3)} mm of the full relief` : '');
    $('timing').textContent = `server ${((result.timings.total ?? 0) * 1000).toFixed(0)} ms`;
  }

  private switchView(): void {
    if (this.viewer.shownFrame === FRAME) this.host.showModel();
    else this.showSolid();
    this.render();
  }

  private showError(message: string | null): void {
    showMessage('print-error', message);
  }

  /** Everything drawn from the solid's state: the status line, the buttons, the measures. */
  private render(): void {
    // called by the state's constructor, before the panel is built
    if (!this.dims) return;
    const { status, message } = this.model;
    const open = this.modelKey !== null;
    const r = this.result;
    const parts: string[] = [];
    if (status === 'none') parts.push(open ? 'Not built yet' : 'Open a photo to print its model');
    else parts.push(statusText(status, message));
    if (r && status !== 'none') {
      const [w, d, h] = r.size_mm;
      parts.push(`${mm(w)} × ${mm(d)} × ${mm(h)} mm · ${r.triangle_count.toLocaleString()} triangles`);
    }
    const line = $('print-status');
    line.dataset.status = status;
    line.textContent = parts.join(' · ');
    const current = status === 'current';
    for (const id of ['print-stl', 'print-3mf']) {
      const button = $<HTMLButtonElement>(id);
      button.disabled = !current;
      button.title = current
        ? id === 'print-stl' ? 'Binary STL, millimetres' : '3MF, the unit (millimetres) in the file'
        : 'Build the solid for these settings first';
    }
    $<HTMLButtonElement>('print-build').disabled = !open;
    this.placeLabels();
  }

  /** The measures beside the solid, where its edges are drawn now (after every frame). */
  private placeLabels(): void {
    const onScreen = this.viewer.shownFrame === FRAME && this.result !== null && this.mesh !== null;
    // a new model of the photo may have taken the view: the switch says where it leads now
    const switcher = $<HTMLButtonElement>('print-switch');
    switcher.textContent = onScreen ? 'Show model' : 'Show solid';
    switcher.disabled = !this.mesh || this.modelKey === null; // (per frame: no request built here)
    this.dims.hidden = !onScreen;
    $('view-host').classList.toggle('solid-outdated', onScreen && this.model.status !== 'current');
    if (!onScreen) {
      for (const label of this.labels) label.hidden = true;
      return;
    }
    const [w, d, h] = this.result!.size_mm;
    // short: the badge of the photo's model is beside it, the panel says why
    const state = { none: '', current: '', computing: ' · building…', stale: ' · out of date', failed: ' · failed' }[this.model.status];
    this.dims.textContent = `Solid ${mm(w)} × ${mm(d)} × ${mm(h)} mm${state}`;
    const [low, high] = bounds(this.mesh!);
    const middles: [number, number, number][] = [
      [(low[0] + high[0]) / 2, low[1], low[2]], // the width, along the front bottom edge
      [high[0], (low[1] + high[1]) / 2, low[2]], // the depth, along the right bottom edge
      [high[0], low[1], (low[2] + high[2]) / 2], // the height, up the front right corner
    ];
    const room = $('view-host').clientWidth;
    [w, d, h].forEach((size, i) => {
      const label = this.labels[i];
      const at = this.viewer.toScreen(...middles[i]);
      label.hidden = at === null;
      if (!at) return;
      label.textContent = `${mm(size)} mm`;
      // kept inside the view: an edge near its side would push its label out of sight
      const x = Math.max(4, Math.min(at[0], room - label.offsetWidth - 16));
      label.style.transform = `translate(${x.toFixed(1)}px, ${at[1].toFixed(1)}px)`;
    });
  }
}

/** What a solid (or the maps) depends on of the model: its photo or photo set and its settings
 * but the mesh's step. */
export function inputsKey(source: api.ModelSource): string {
  const { step: _step, ...params } = source.request.params;
  const id = source.kind === 'photo' ? source.request.image_id : source.request.photoset_id;
  return JSON.stringify([source.kind, id, params]);
}

function mm(value: number): string {
  return value.toFixed(1);
}

/** The options kept from the last visit: only the fields the server knows (it refuses others). */
function loadOptions(defaults: ReliefParams): Partial<ReliefParams> {
  let saved: unknown;
  try {
    saved = JSON.parse(localStorage.getItem(STORAGE_KEY) ?? '{}');
  } catch {
    return {};
  }
  if (!saved || typeof saved !== 'object') return {};
  const known = Object.entries(saved).filter(
    ([key, value]) =>
      key in defaults && (value === null ? key === 'max_triangles' : typeof value === typeof defaults[key as keyof ReliefParams]),
  );
  return Object.fromEntries(known) as Partial<ReliefParams>;
}

function bounds(mesh: api.DecodedMesh): [number[], number[]] {
  const low = [Infinity, Infinity, Infinity];
  const high = [-Infinity, -Infinity, -Infinity];
  const p = mesh.positions;
  for (let i = 0; i < p.length; i += 3) {
    for (let k = 0; k < 3; k++) {
      if (p[i + k] < low[k]) low[k] = p[i + k];
      if (p[i + k] > high[k]) high[k] = p[i + k];
    }
  }
  return [low, high];
}

/** The solid's bounding box, faint, with the three measured edges bright. */
function measureLines(mesh: api.DecodedMesh): THREE.Object3D {
  const [a, b] = bounds(mesh);
  const corner = (i: number, j: number, k: number) => [i ? b[0] : a[0], j ? b[1] : a[1], k ? b[2] : a[2]];
  const box: number[] = [];
  for (const [p, q] of [
    [[0, 0, 0], [0, 1, 0]], [[0, 1, 0], [1, 1, 0]], [[0, 0, 1], [1, 0, 1]], [[0, 0, 1], [0, 1, 1]],
    [[0, 1, 1], [1, 1, 1]], [[1, 0, 1], [1, 1, 1]], [[0, 0, 0], [0, 0, 1]], [[0, 1, 0], [0, 1, 1]],
    [[1, 1, 0], [1, 1, 1]],
  ]) box.push(...corner(p[0], p[1], p[2]), ...corner(q[0], q[1], q[2]));
  const measured = [
    ...corner(0, 0, 0), ...corner(1, 0, 0), // width
    ...corner(1, 0, 0), ...corner(1, 1, 0), // depth
    ...corner(1, 0, 0), ...corner(1, 0, 1), // height
  ];
  const lines = (points: number[], colour: number, opacity: number) => {
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute('position', new THREE.Float32BufferAttribute(points, 3));
    const material = new THREE.LineBasicMaterial({ color: colour, transparent: true, opacity, depthTest: false });
    const segments = new THREE.LineSegments(geometry, material);
    segments.renderOrder = 1; // over the solid: a measure is read through it
    return segments;
  };
  const group = new THREE.Group();
  group.add(lines(box, 0x9aa1b2, 0.35), lines(measured, 0xfbbf24, 0.95));
  return group;
}
