// The object mask as a bitmap (one byte a pixel): its edits (a brush stroke, a polygon, invert,
// fill holes), its PNG both ways (read, and its layer tinted, in the mask worker: maskWorker.ts),
// and its layer as the image pane draws it over the picture (paintMask, MaskOverlay). Image
// coordinates follow docs/conventions.md: x = column, y = row, pixel centres at whole numbers.
import * as api from './api';
import { segmentDistance, type Point } from './geometry';
import { MASK_EDGE, MASK_FILL } from './maskColours';
import type { MaskDecodeReply } from './maskWorker';

/** Pixel bounds, columns x0 .. x1 - 1 and rows y0 .. y1 - 1. */
export interface Rect {
  x0: number;
  y0: number;
  x1: number;
  y1: number;
}

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

/**
 * The mask as the image pane draws it over the picture: the mask worker's layer as it came
 * (drawing a 12 Mpx one into a canvas took the page 40 ms), a canvas once edited; and the
 * worker's small copy of it, drawn while the image is shown smaller.
 */
export class MaskOverlay {
  private layer: HTMLCanvasElement | ImageBitmap | null = null;
  private small: ImageBitmap | null = null;

  /** Another image's size: nothing of the last mask is drawn again. */
  forget(): void {
    this.layer = null;
    this.small = null;
  }

  /** The object mask as a tinted overlay with its outline; ``dirty``: only that part changed. */
  set(mask: MaskBits | null, dirty?: Rect): void {
    // a new mask brings its small copy (or none); an edit makes the one shown out of date
    const small = dirty ? null : (mask?.small ?? null);
    if (mask) mask.small = null;
    if (small !== this.small) this.small?.close();
    this.small = small;
    const shown = this.layer;
    const ready = mask?.layer && mask.layer.width === mask.width && mask.layer.height === mask.height ? mask.layer : null;
    if (!mask) {
      this.layer = null;
    } else if (!dirty && ready) {
      mask.layer = null; // the bits may change after this: only this mask may use it
      this.layer = ready;
    } else {
      // an edit: into a canvas, from the layer shown (where it is the worker's) or painted anew
      let layer = shown instanceof HTMLCanvasElement ? shown : null;
      if (!layer) {
        layer = Object.assign(document.createElement('canvas'), { width: mask.width, height: mask.height });
        if (shown && dirty && shown.width === mask.width && shown.height === mask.height) layer.getContext('2d')!.drawImage(shown, 0, 0);
        else dirty = undefined;
      }
      paintMask(mask, layer, dirty);
      this.layer = layer;
    }
    if (shown instanceof ImageBitmap && shown !== this.layer) shown.close();
  }

  /** What to draw for the image shown ``width`` device pixels wide, or null without a mask. */
  picture(width: number): HTMLCanvasElement | ImageBitmap | null {
    if (!this.layer) return null;
    const small = this.small && width <= this.small.width * 1.25 ? this.small : null;
    return small ?? this.layer;
  }
}
