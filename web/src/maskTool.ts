// The mask tool: the object mask as a bitmap the user edits in the image pane (brush, polygon,
// invert, fill holes) or asks the server for (automatic, a threshold, "click the object", a box
// round it, a file), and the side panel's Mask group.
//
// The mask every solve and export uses is params.mask: null for the automatic one (the
// server's; each result brings it, and the pane shows it), else base64 of a PNG that this tool
// encodes after every finished edit (a stroke, a polygon, a click, a slider's release). Image
// coordinates follow docs/conventions.md: x = column, y = row, pixel centres at whole numbers.
import * as api from './api';
import type { Channel, MaskResult } from './api.gen';
import { segmentDistance, type Point } from './geometry';
import { MaskBox, MIN_BOX } from './maskBox';
import { MASK_EDGE, MASK_FILL } from './maskColours';
import type { MaskDecodeReply } from './maskWorker';
import { percentOfWhite, thresholdWords } from './words';

export type MaskMode = 'brush' | 'polygon' | 'object' | 'box';
export type MaskOp = 'add' | 'erase';

/** Pixel bounds, columns x0 .. x1 - 1 and rows y0 .. y1 - 1. */
export interface Rect {
  x0: number;
  y0: number;
  x1: number;
  y1: number;
}

const SNAP = 10; // screen px: a click this near the first corner closes the polygon
const THRESHOLD_STEPS = 1000; // the threshold slider's positions, on a square-root scale

// ------------------------------------------------------------------------------- the bitmap

/** A mask, one byte per pixel (1 = object), row by row. */
export class MaskBits {
  readonly bits: Uint8Array;
  /** The bits' tinted layer, drawn by the mask worker: used by the first full paint, then dropped. */
  layer: ImageBitmap | null = null;
  /** Its copy at most SMALL_SIDE on a side (a large mask's), for the pane zoomed out; taken by the pane. */
  small: ImageBitmap | null = null;

  constructor(readonly width: number, readonly height: number, bits?: Uint8Array) {
    this.bits = bits ?? new Uint8Array(width * height);
  }

  /** How many pixels are set. Four bits (bytes of 0 or 1) a step, added in the four byte lanes
   * of a 32-bit word and summed before a lane could pass 255: a 12 Mpx mask is counted on the
   * page's thread, 12 ms one byte a step there. */
  get count(): number {
    const bits = this.bits;
    const head = Math.min(bits.length, (4 - (bits.byteOffset % 4)) % 4);
    const words = Math.floor((bits.length - head) / 4);
    const lanes = new Uint32Array(bits.buffer, bits.byteOffset + head, words);
    let total = 0;
    for (let i = 0; i < head; i++) total += bits[i];
    for (let start = 0; start < words; start += 255) {
      let sum = 0;
      for (let i = start, end = Math.min(words, start + 255); i < end; i++) sum += lanes[i];
      total += (sum & 0xff) + ((sum >>> 8) & 0xff) + ((sum >>> 16) & 0xff) + (sum >>> 24);
    }
    for (let i = head + 4 * words; i < bits.length; i++) total += bits[i];
    return total;
  }

  at(row: number, col: number): boolean {
    return row >= 0 && col >= 0 && row < this.height && col < this.width && this.bits[row * this.width + col] === 1;
  }

  private clip(x0: number, y0: number, x1: number, y1: number): Rect {
    return {
      x0: Math.max(0, Math.floor(x0)),
      y0: Math.max(0, Math.floor(y0)),
      x1: Math.min(this.width, Math.ceil(x1) + 1),
      y1: Math.min(this.height, Math.ceil(y1) + 1),
    };
  }

  /** Every pixel whose centre lies within ``radius`` of the segment a-b takes ``value``. */
  stroke(a: Point, b: Point, radius: number, value: 0 | 1): Rect {
    const length = Math.hypot(b[0] - a[0], b[1] - a[1]);
    // short pieces keep each bounding box small on a long, fast stroke
    const pieces = Math.max(1, Math.ceil(length / Math.max(2, radius)));
    for (let k = 0; k < pieces; k++) {
      const p: Point = [a[0] + ((b[0] - a[0]) * k) / pieces, a[1] + ((b[1] - a[1]) * k) / pieces];
      const q: Point = [a[0] + ((b[0] - a[0]) * (k + 1)) / pieces, a[1] + ((b[1] - a[1]) * (k + 1)) / pieces];
      const box = this.clip(Math.min(p[0], q[0]) - radius, Math.min(p[1], q[1]) - radius, Math.max(p[0], q[0]) + radius, Math.max(p[1], q[1]) + radius);
      for (let row = box.y0; row < box.y1; row++) {
        for (let col = box.x0; col < box.x1; col++) {
          if (segmentDistance(col, row, p, q) <= radius) this.bits[row * this.width + col] = value;
        }
      }
    }
    return this.clip(Math.min(a[0], b[0]) - radius, Math.min(a[1], b[1]) - radius, Math.max(a[0], b[0]) + radius, Math.max(a[1], b[1]) + radius);
  }

  /** Pixels whose centre is inside the polygon (even-odd rule, as the library's regions) take ``value``. */
  polygon(points: Point[], value: 0 | 1): Rect {
    const ys = points.map((p) => p[1]);
    const box = this.clip(Math.min(...points.map((p) => p[0])), Math.min(...ys), Math.max(...points.map((p) => p[0])), Math.max(...ys));
    for (let row = box.y0; row < box.y1; row++) {
      const crossings: number[] = [];
      for (let i = 0, j = points.length - 1; i < points.length; j = i++) {
        const [xi, yi] = points[i];
        const [xj, yj] = points[j];
        if (yi > row !== yj > row) crossings.push(((xj - xi) * (row - yi)) / (yj - yi) + xi);
      }
      crossings.sort((p, q) => p - q);
      // a centre c is inside when an odd number of crossings lie right of it: x[2k] <= c < x[2k + 1]
      for (let k = 0; k + 1 < crossings.length; k += 2) {
        const from = Math.max(0, Math.ceil(crossings[k]));
        const to = Math.min(this.width, Math.ceil(crossings[k + 1]));
        this.bits.fill(value, row * this.width + from, row * this.width + Math.max(from, to));
      }
    }
    return box;
  }

  invert(): void {
    for (let i = 0; i < this.bits.length; i++) this.bits[i] ^= 1;
  }

  /** Background pixels not connected (4-neighbours) to the image's border become object; returns how many. */
  fillHoles(): number {
    const { width, height, bits } = this;
    const outside = new Uint8Array(bits.length);
    const queue = new Int32Array(bits.length);
    let head = 0;
    let tail = 0;
    const visit = (i: number) => {
      if (!bits[i] && !outside[i]) {
        outside[i] = 1;
        queue[tail++] = i;
      }
    };
    for (let col = 0; col < width; col++) {
      visit(col);
      visit((height - 1) * width + col);
    }
    for (let row = 0; row < height; row++) {
      visit(row * width);
      visit(row * width + width - 1);
    }
    while (head < tail) {
      const i = queue[head++];
      const col = i % width;
      if (col > 0) visit(i - 1);
      if (col < width - 1) visit(i + 1);
      if (i >= width) visit(i - width);
      if (i < bits.length - width) visit(i + width);
    }
    let filled = 0;
    for (let i = 0; i < bits.length; i++) {
      if (!bits[i] && !outside[i]) {
        bits[i] = 1;
        filled++;
      }
    }
    return filled;
  }

  /** A PNG of the mask: white object, black background, opaque (what load_mask and the CLI read). */
  png(): Promise<Blob> {
    const canvas = document.createElement('canvas');
    canvas.width = this.width;
    canvas.height = this.height;
    const ctx = canvas.getContext('2d')!;
    const pixels = ctx.createImageData(this.width, this.height);
    const data = pixels.data;
    for (let i = 0; i < this.bits.length; i++) {
      const v = this.bits[i] ? 255 : 0;
      data[4 * i] = v;
      data[4 * i + 1] = v;
      data[4 * i + 2] = v;
      data[4 * i + 3] = 255;
    }
    ctx.putImageData(pixels, 0, 0);
    return new Promise((resolve, reject) =>
      canvas.toBlob((blob) => (blob ? resolve(blob) : reject(new Error('the browser could not encode the mask as PNG'))), 'image/png'),
    );
  }

  async base64(): Promise<string> {
    return api.bytesToBase64(new Uint8Array(await (await this.png()).arrayBuffer()));
  }

  /** A mask from a PNG (base64) the server sent or this tool made: bright pixels are object.
   * Read, and its layer tinted, in the mask worker (maskWorker.ts): the page never blocks on it. */
  static async fromPng(text: string, width: number, height: number): Promise<MaskBits> {
    const bytes = api.base64ToBytes(text) as Uint8Array<ArrayBuffer>;
    const buffer = bytes.byteOffset === 0 && bytes.byteLength === bytes.buffer.byteLength ? bytes.buffer : bytes.slice().buffer;
    const id = ++maskCounter;
    const reply = await new Promise<MaskDecodeReply>((resolve) => {
      maskDecoding.set(id, resolve);
      maskWorker().postMessage({ id, bytes: buffer, width, height }, [buffer]);
    });
    if (!reply.ok) throw new Error(reply.message);
    const mask = new MaskBits(width, height, reply.bits);
    mask.layer = reply.layer;
    mask.small = reply.small;
    return mask;
  }
}

let worker: Worker | null = null;
let maskCounter = 0;
const maskDecoding = new Map<number, (reply: MaskDecodeReply) => void>();

function maskWorker(): Worker {
  if (worker) return worker;
  worker = new Worker(new URL('./maskWorker.ts', import.meta.url), { type: 'module' });
  worker.onmessage = (event: MessageEvent<MaskDecodeReply>) => {
    const resolve = maskDecoding.get(event.data.id);
    maskDecoding.delete(event.data.id);
    resolve?.(event.data);
  };
  return worker;
}

/**
 * Draw the mask into ``layer`` (one canvas pixel per image pixel): object pixels tinted, its
 * edge bright. Only ``dirty`` (and the one-pixel ring round it, whose edges it moves) is redone.
 */
export function paintMask(mask: MaskBits, layer: HTMLCanvasElement, dirty?: Rect): void {
  const { width: w, height: h, bits } = mask;
  if (layer.width !== w || layer.height !== h) {
    layer.width = w;
    layer.height = h;
    dirty = undefined;
  }
  const worker = mask.layer;
  mask.layer = null; // the bits may change after this paint: only this one may use it
  if (!dirty && worker && worker.width === w && worker.height === h) {
    const ctx = layer.getContext('2d')!;
    ctx.clearRect(0, 0, w, h);
    ctx.drawImage(worker, 0, 0);
    worker.close();
    return;
  }
  const x0 = Math.max(0, (dirty?.x0 ?? 0) - 1);
  const y0 = Math.max(0, (dirty?.y0 ?? 0) - 1);
  const x1 = Math.min(w, (dirty?.x1 ?? w) + 1);
  const y1 = Math.min(h, (dirty?.y1 ?? h) + 1);
  if (x1 <= x0 || y1 <= y0) return;
  const ctx = layer.getContext('2d')!;
  const pixels = ctx.createImageData(x1 - x0, y1 - y0);
  const data = pixels.data;
  for (let r = y0; r < y1; r++) {
    for (let c = x0; c < x1; c++) {
      const i = r * w + c;
      const o = 4 * ((r - y0) * (x1 - x0) + (c - x0));
      if (!bits[i]) continue; // stays transparent
      const edge = c === 0 || r === 0 || c === w - 1 || r === h - 1 || !bits[i - 1] || !bits[i + 1] || !bits[i - w] || !bits[i + w];
      data.set(edge ? MASK_EDGE : MASK_FILL, o);
    }
  }
  ctx.putImageData(pixels, x0, y0);
}

// ------------------------------------------------------------------------------- the tool

/** What the tool needs from the app. */
export interface MaskHost {
  /** The open image and the channel masks are found on, or null. */
  image(): { id: string; width: number; height: number; channel: Channel } | null;
  /**
   * The user's mask changed (a finished edit): base64 PNG, or null for the automatic mask.
   * ``refit``: the mask may hold another object (a click, a threshold, a file): frame it anew.
   */
  changed(png: string | null, refit: boolean): void;
  /** The mask was cleared to be painted anew: the model, solved with the old one, is out of date
   * (nothing is solved on an empty mask; the next edit solves). */
  cleared(): void;
  /** Show these bits in the image pane; ``dirty`` is the part that changed. */
  show(mask: MaskBits | null, dirty?: Rect): void;
  /** Redraw the pane's overlays (cursor, corners, clicks). */
  redraw(): void;
  hint(text: string): void;
  /** Offer a file as a download. */
  download(blob: Blob, filename: string): void;
  /** The current image's name without its suffix, for file names. */
  stem(): string;
  /** A message about what the tool refused (until the next edit of the polygon), or null. */
  notice(text: string | null): void;
}

/** Said when a mask polygon is closed with fewer than three corners (they are kept). */
export const TOO_FEW_MASK_CORNERS = 'A mask polygon needs at least three points; click more points or press Escape';

const $ = <T extends HTMLElement>(id: string) => document.getElementById(id) as T;

export class MaskTool {
  mode: MaskMode = 'brush';
  op: MaskOp = 'add';
  radius = 8;
  private mask: MaskBits | null = null;
  private user = false; // params.mask is set: the bits are the user's, not the automatic ones
  private what = '';
  private draft: Point[] = [];
  private readonly box = new MaskBox();
  private inside: Array<[number, number]> = [];
  private outside: Array<[number, number]> = [];
  private last: Point | null = null; // the brush's previous point while painting
  private painting: 0 | 1 | null = null;
  private thresholdSent = 0;
  private thresholdBusy = false;
  private thresholdWaiting = false;
  private autoNote = '';
  private solvedPng = ''; // the last result's mask, already shown
  private readonly radiusInput = $<HTMLInputElement>('mask-radius');
  private readonly thresholdInput = $<HTMLInputElement>('mask-threshold');
  private readonly darkInput = $<HTMLInputElement>('mask-dark');

  constructor(private readonly host: MaskHost) {
    for (const button of document.querySelectorAll<HTMLButtonElement>('#mask-mode button')) {
      button.addEventListener('click', () => this.setMode(button.dataset.maskMode as MaskMode));
    }
    for (const button of document.querySelectorAll<HTMLButtonElement>('#mask-op button')) {
      button.addEventListener('click', () => this.setOp(button.dataset.maskOp as MaskOp));
    }
    this.radiusInput.addEventListener('input', () => this.setRadius(Number(this.radiusInput.value)));
    this.thresholdInput.addEventListener('input', () => this.threshold(false));
    this.thresholdInput.addEventListener('change', () => this.threshold(true));
    this.darkInput.addEventListener('change', () => this.threshold(true));
    $('mask-auto').addEventListener('click', () => this.automatic());
    $('mask-clear').addEventListener('click', () => this.clear());
    $('mask-invert').addEventListener('click', () => this.invert());
    $('mask-fill').addEventListener('click', () => this.fillHoles());
    $('mask-save').addEventListener('click', () => this.save());
    $('mask-load').addEventListener('click', () => $<HTMLInputElement>('file-mask').click());
    const file = $<HTMLInputElement>('file-mask');
    file.addEventListener('change', () => {
      const chosen = file.files?.[0];
      file.value = ''; // the same file again must fire again
      if (chosen) this.load(chosen);
    });
    this.setRadius(this.radius);
    this.showControls();
  }

  // ----------------------------------------------------------------------- state from the app

  /**
   * A new image: its mask is ``png`` (the user's, from a session or project) or the automatic one.
   * ``describe`` false: what the automatic mask is (a full-resolution mask on the server: 1.6 s
   * at 12 Mpx) is asked later (describe()), so that it does not compete with the first view.
   */
  async open(png: string | null, describe = true): Promise<void> {
    this.mask = null;
    this.solvedPng = '';
    this.user = png !== null;
    this.draft = [];
    this.host.notice(null);
    this.clearClicks();
    this.host.show(null);
    this.clearError();
    this.what = png ? 'from the saved session' : '';
    this.autoNote = ''; // the last image's, until this one's is known
    this.showNote();
    if (png) {
      const image = this.host.image();
      if (!image) return;
      try {
        this.show(await MaskBits.fromPng(png, image.width, image.height));
      } catch (err) {
        this.error((err as Error).message);
      }
    }
    if (describe) await this.describeAutomatic();
  }

  /** Say what the automatic mask is (open()'s, when it was put off). */
  describe(): Promise<void> {
    return this.describeAutomatic();
  }

  /** The mask a result was solved with: shown when the automatic one is in use. */
  async solvedWith(png: string): Promise<void> {
    if (this.user || png === this.solvedPng) return;
    const image = this.host.image();
    if (!image) return;
    this.solvedPng = png;
    try {
      const mask = await MaskBits.fromPng(png, image.width, image.height);
      // not over a stroke in progress: it edits the bits shown
      if (!this.user && this.painting === null) this.show(mask);
    } catch (err) {
      this.error((err as Error).message);
    }
  }

  /** The channel changed: the automatic mask may differ. */
  channelChanged(): void {
    if (!this.user) this.describeAutomatic();
  }

  /** For the test hook: what the pane shows. */
  state() {
    return {
      user: this.user,
      mode: this.mode,
      op: this.op,
      radius: this.radius,
      pixels: this.mask?.count ?? 0,
      threshold: this.thresholdValue(),
      dark: this.darkInput.checked,
      note: $('mask-note').textContent,
      error: $('mask-error').hidden ? null : $('mask-error').textContent,
      clicks: { inside: this.inside.length, outside: this.outside.length },
    };
  }

  at(row: number, col: number): boolean {
    return this.mask?.at(row, col) ?? false;
  }

  // -------------------------------------------------------------------------- panel controls

  setMode(mode: MaskMode): void {
    this.mode = mode;
    this.draft = [];
    this.box.forget();
    this.host.notice(null);
    if (mode !== 'object') this.clearClicks();
    this.showControls();
    this.host.hint(this.hint());
    this.host.redraw();
  }

  setOp(op: MaskOp): void {
    this.op = op;
    this.showControls();
    this.host.hint(this.hint());
  }

  setRadius(radius: number): void {
    this.radius = Math.max(1, Math.min(200, Math.round(radius)));
    this.radiusInput.value = String(this.radius);
    $('mask-radius-out').textContent = `${this.radius} px`;
    this.host.redraw();
  }

  private showControls(): void {
    for (const button of document.querySelectorAll<HTMLButtonElement>('#mask-mode button')) {
      button.classList.toggle('on', button.dataset.maskMode === this.mode);
    }
    for (const button of document.querySelectorAll<HTMLButtonElement>('#mask-op button')) {
      button.classList.toggle('on', button.dataset.maskOp === this.op);
    }
    const object = this.mode === 'object';
    $('mask-op').querySelector<HTMLButtonElement>('[data-mask-op="add"]')!.textContent = object ? 'On object' : 'Add';
    $('mask-op').querySelector<HTMLButtonElement>('[data-mask-op="erase"]')!.textContent = object ? 'On background' : 'Erase';
    this.radiusInput.closest('.row')!.classList.toggle('dimmed', this.mode !== 'brush');
  }

  private thresholdValue(): number {
    return (Number(this.thresholdInput.value) / THRESHOLD_STEPS) ** 2;
  }

  private showThreshold(value: number | null): void {
    if (value !== null && Number.isFinite(value)) {
      this.thresholdInput.value = String(Math.round(Math.sqrt(Math.min(1, Math.max(0, value))) * THRESHOLD_STEPS));
    }
    $('mask-threshold-out').textContent = percentOfWhite(this.thresholdValue()); // 31%, 0.56%: in its width
  }

  private showNote(): void {
    const count = this.mask ? ` · ${this.mask.count.toLocaleString()} pixels` : '';
    $('mask-note').textContent = this.user
      ? `Your mask${count}${this.what ? ` · ${this.what}` : ''}`
      : `Automatic${this.autoNote ? `: ${this.autoNote}` : ''}`;
    $('mask-auto').toggleAttribute('disabled', !this.user);
  }

  /** A message that stays until the next mask action succeeds. */
  private error(message: string): void {
    const line = $('mask-error');
    line.textContent = message;
    line.hidden = false;
  }

  private clearError(): void {
    $('mask-error').hidden = true;
    $('mask-error').textContent = '';
  }

  // ------------------------------------------------------------------------------ actions

  private show(mask: MaskBits, dirty?: Rect): void {
    this.mask = mask;
    this.host.show(mask, dirty);
    this.showNote();
  }

  /** The edit is done: the bits become the user's mask, and the app solves with it. */
  private async commit(what: string, refit = false): Promise<void> {
    if (!this.mask) return;
    this.user = true;
    this.what = what;
    this.clearError();
    this.showNote();
    if (!this.mask.count) return this.error('the mask is empty: nothing would be solved; add the object, or go back to Automatic');
    this.host.changed(await this.mask.base64(), refit);
  }

  /** Bits to edit: the mask shown (automatic or the user's), or an empty one. */
  private editable(): MaskBits | null {
    const image = this.host.image();
    if (!image) {
      this.error('open an image first, then edit its mask');
      return null;
    }
    if (!this.mask || this.mask.width !== image.width || this.mask.height !== image.height) {
      this.mask = new MaskBits(image.width, image.height);
    }
    return this.mask;
  }

  async automatic(): Promise<void> {
    this.user = false;
    this.solvedPng = '';
    this.what = '';
    this.clearClicks();
    this.draft = [];
    this.clearError();
    this.host.changed(null, true);
    await this.describeAutomatic(true);
  }

  /** Ask the server what the automatic mask is (its note, its threshold), and show it if asked. */
  private async describeAutomatic(showIt = false): Promise<void> {
    const image = this.host.image();
    if (!image) return;
    try {
      const result = await api.autoMask(image.id, { channel: image.channel, threshold: null, dark: null });
      if (this.host.image()?.id !== image.id) return;
      this.autoNote = result.note;
      this.showThreshold(result.threshold);
      this.darkInput.checked = result.dark;
      if (showIt && !this.user) await this.apply(result, false);
      this.showNote();
    } catch (err) {
      this.error((err as Error).message);
    }
  }

  private async apply(result: MaskResult, commit: boolean, what = ''): Promise<void> {
    const image = this.host.image();
    if (!image) return;
    this.show(await MaskBits.fromPng(result.mask_png, image.width, image.height));
    if (commit) await this.commit(what, true);
  }

  /** The threshold slider: a live outline while it moves, the mask on release. */
  private async threshold(final: boolean): Promise<void> {
    this.showThreshold(null);
    const image = this.host.image();
    if (!image) return;
    if (!final && this.thresholdBusy) {
      this.thresholdWaiting = true;
      return;
    }
    const id = ++this.thresholdSent;
    this.thresholdBusy = true;
    this.thresholdWaiting = false;
    const value = this.thresholdValue();
    const dark = this.darkInput.checked;
    try {
      const result = await api.autoMask(image.id, { channel: image.channel, threshold: value, dark });
      if (id !== this.thresholdSent) return; // a newer value is on its way
      this.clearClicks();
      await this.apply(result, final, `pixels ${thresholdWords(value, dark)}`);
      if (!final) {
        this.clearError();
        $('mask-note').textContent = `Pixels ${thresholdWords(value, dark)}: ${result.pixels.toLocaleString()} of them · release to use it`;
      }
    } catch (err) {
      if (id === this.thresholdSent) this.error((err as Error).message);
    } finally {
      if (id === this.thresholdSent) {
        this.thresholdBusy = false;
        if (this.thresholdWaiting) this.threshold(false);
      }
    }
  }

  /** An empty mask to paint or outline the object on; solved from the next edit on. */
  clear(): void {
    const mask = this.editable();
    if (!mask) return;
    mask.bits.fill(0);
    this.clearClicks();
    this.draft = [];
    this.user = true;
    this.what = 'cleared: paint or outline the object';
    this.clearError();
    this.show(mask);
    this.host.cleared();
  }

  invert(): void {
    const mask = this.mask && this.editable();
    if (!mask) return this.error('no mask to invert yet');
    mask.invert();
    this.show(mask);
    this.commit('inverted', true);
  }

  fillHoles(): void {
    const mask = this.mask && this.editable();
    if (!mask) return this.error('no mask to fill yet');
    const filled = mask.fillHoles();
    this.show(mask);
    this.commit(`${filled.toLocaleString()} hole pixels filled`);
  }

  async save(): Promise<void> {
    if (!this.mask) return this.error('no mask to save yet: open an image first');
    try {
      this.host.download(await this.mask.png(), `${this.host.stem()}.mask.png`);
      this.clearError();
    } catch (err) {
      this.error((err as Error).message);
    }
  }

  async load(file: File): Promise<void> {
    const image = this.host.image();
    if (!image) return this.error('open an image first, then load a mask for it');
    try {
      const result = await api.maskFile(image.id, file);
      this.clearClicks();
      await this.apply(result, true, `loaded from ${file.name}`);
    } catch (err) {
      this.error(`${file.name}: ${(err as Error).message}`);
    }
  }

  private clearClicks(): void {
    this.inside = [];
    this.outside = [];
  }

  private async clicked(at: Point, onObject: boolean): Promise<void> {
    const image = this.host.image();
    if (!image) return;
    const row = Math.round(at[1]);
    const col = Math.round(at[0]);
    if (row < 0 || col < 0 || row >= image.height || col >= image.width) return;
    (onObject ? this.inside : this.outside).push([row, col]);
    this.host.redraw();
    if (!this.inside.length) {
      this.host.hint('Now click the object: the background clicks are kept');
      return;
    }
    try {
      const result = await api.seedMask(image.id, {
        channel: image.channel, inside: this.inside, outside: this.outside, radius: 2,
      });
      await this.apply(result, true, result.note);
    } catch (err) {
      // the click that failed is taken back, so that the next one can succeed
      (onObject ? this.inside : this.outside).pop();
      this.host.redraw();
      this.error((err as Error).message);
    }
  }

  /** The box dragged round the object, sent to the server's cut. */
  private async boxed(): Promise<void> {
    const image = this.host.image();
    const box = image ? this.box.finish(image.width, image.height) : null;
    this.host.redraw();
    if (!image) return;
    if (!box) return this.error(`drag a box round the object, at least ${MIN_BOX} pixels each way`);
    try {
      const result = await api.boxMask(image.id, { channel: image.channel, box });
      this.clearClicks();
      await this.apply(result, true, result.note);
    } catch (err) {
      this.error((err as Error).message);
    }
  }

  // --------------------------------------------------------------------- pane interaction

  /** A press on the image with the mask tool; ``flip`` (Alt) swaps add and erase. */
  down(at: Point, flip: boolean): void {
    const add = (this.op === 'add') !== flip;
    if (this.mode === 'object') {
      this.clicked(at, add);
      return;
    }
    if (this.mode === 'polygon') {
      this.polygonClick(at, add);
      return;
    }
    if (this.mode === 'box') {
      this.box.begin(at);
      return;
    }
    const mask = this.editable();
    if (!mask) return;
    this.clearClicks();
    this.painting = add ? 1 : 0;
    this.last = at;
    this.show(mask, mask.stroke(at, at, this.radius, this.painting));
  }

  move(at: Point): void {
    if (this.box.dragging) return this.box.drag(at), this.host.redraw();
    if (this.painting === null || !this.mask || !this.last) return;
    const dirty = this.mask.stroke(this.last, at, this.radius, this.painting);
    this.last = at;
    this.host.show(this.mask, dirty);
  }

  up(): void {
    if (this.box.dragging) return void this.boxed();
    if (this.painting === null) return;
    const added = this.painting === 1;
    this.painting = null;
    this.last = null;
    this.commit(added ? 'painted' : 'erased');
  }

  private polygonAdd = true;

  private polygonClick(at: Point, add: boolean): void {
    const image = this.host.image();
    if (!image) return;
    const point: Point = [Math.min(image.width - 0.5, Math.max(-0.5, at[0])), Math.min(image.height - 0.5, Math.max(-0.5, at[1]))];
    // a click on the first corner closes the polygon (and is refused, saying so, under three)
    if (this.draft.length && this.nearFirst(at)) return this.closePolygon();
    if (!this.draft.length) this.polygonAdd = add;
    this.draft.push(point);
    this.draftEdited();
  }

  /** The draft changed: a refusal said about the old one no longer holds. */
  private draftEdited(): void {
    this.host.notice(null);
    this.host.hint(this.hint());
    this.host.redraw();
  }

  private scale = 1;
  private nearFirst(at: Point): boolean {
    const first = this.draft[0];
    return Math.hypot(at[0] - first[0], at[1] - first[1]) * this.scale <= SNAP;
  }

  private closePolygon(): void {
    if (this.draft.length < 3) return this.host.notice(TOO_FEW_MASK_CORNERS);
    const mask = this.editable();
    if (!mask) return;
    this.clearClicks();
    const dirty = mask.polygon(this.draft, this.polygonAdd ? 1 : 0);
    const added = this.polygonAdd;
    this.draft = [];
    this.show(mask, dirty);
    this.draftEdited();
    this.commit(added ? 'polygon added' : 'polygon cut');
  }

  /** Keys while the mask tool is on; true when used. */
  key(event: KeyboardEvent): boolean {
    if (this.mode === 'polygon' && this.draft.length) {
      if (event.key === 'Enter') return this.closePolygon(), true;
      if (event.key === 'Escape') return (this.draft = []), this.draftEdited(), true;
      if (event.key === 'Backspace') return this.draft.pop(), this.draftEdited(), true;
    }
    if (event.key === 'Escape' && (this.inside.length || this.outside.length)) {
      this.clearClicks();
      this.host.redraw();
      return true;
    }
    if (event.key === '[' || event.key === ']') {
      this.setRadius(this.radius * (event.key === ']' ? 1.25 : 0.8) + (event.key === ']' ? 1 : -1));
      return true;
    }
    return false;
  }

  cursor(): string {
    return this.mode === 'brush' ? 'none' : 'crosshair';
  }

  hint(): string {
    const flip = this.op === 'add' ? 'Alt erases' : 'Alt adds';
    if (this.mode === 'brush') return `Drag to ${this.op === 'add' ? 'paint the object' : 'erase'} · ${flip} · [ ] brush size · Shift-drag pans`;
    if (this.mode === 'polygon') {
      if (this.draft.length < 3) return `Click corners of a polygon to ${this.op === 'add' ? 'add' : 'cut'} · ${flip}`;
      return 'Click the first corner or press Enter to close · Backspace removes a corner · Esc cancels';
    }
    if (this.mode === 'box') return 'Drag a box round the object: it is found inside, on its colours and edges';
    return this.op === 'add'
      ? 'Click the object: it grows from your clicks · Alt-click marks background · Esc forgets the clicks'
      : 'Click the background · Alt-click marks the object · Esc forgets the clicks';
  }

  /** The tool's marks over the image: brush outline, polygon corners, clicks. */
  draw(ctx: CanvasRenderingContext2D, toScreen: (p: Point) => Point, scale: number, pointer: Point | null): void {
    this.scale = scale;
    if (this.mode === 'brush' && pointer) {
      const [sx, sy] = toScreen(pointer);
      ctx.beginPath();
      ctx.arc(sx, sy, Math.max(2, this.radius * scale), 0, 2 * Math.PI);
      ctx.lineWidth = 3;
      ctx.strokeStyle = 'rgba(0,0,0,0.6)';
      ctx.stroke();
      ctx.lineWidth = 1.5;
      ctx.strokeStyle = this.op === 'add' ? '#5eead4' : '#fca5a5';
      ctx.stroke();
    }
    if (this.mode === 'polygon' && this.draft.length) {
      const colour = this.polygonAdd ? '#5eead4' : '#fca5a5';
      const points = pointer ? [...this.draft, pointer] : this.draft;
      ctx.beginPath();
      points.forEach((p, i) => {
        const [sx, sy] = toScreen(p);
        if (i === 0) ctx.moveTo(sx, sy);
        else ctx.lineTo(sx, sy);
      });
      ctx.setLineDash([6, 4]);
      ctx.lineWidth = 1.75;
      ctx.strokeStyle = colour;
      ctx.stroke();
      ctx.setLineDash([]);
      this.draft.forEach((p, i) => {
        const [sx, sy] = toScreen(p);
        ctx.beginPath();
        ctx.arc(sx, sy, i === 0 ? 5 : 3.5, 0, 2 * Math.PI);
        ctx.fillStyle = i === 0 ? '#fff' : colour;
        ctx.fill();
      });
    }
    this.box.draw(ctx, toScreen);
    for (const [list, colour] of [[this.inside, '#22c55e'], [this.outside, '#ef4444']] as const) {
      for (const [row, col] of list) {
        const [sx, sy] = toScreen([col, row]);
        ctx.beginPath();
        ctx.arc(sx, sy, 5.5, 0, 2 * Math.PI);
        ctx.fillStyle = colour;
        ctx.fill();
        ctx.lineWidth = 2;
        ctx.strokeStyle = '#0b1220';
        ctx.stroke();
      }
    }
  }
}
