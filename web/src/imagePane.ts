// The left pane: the photo (or its preprocessed channel, or both split before/after), the mask
// overlay and the mask tool's marks, the reference pixels and the concave-region editor, on one
// canvas. This module holds the pane's state, its input (pointer, wheel, keys) and the order it
// draws in; the marks are drawn by paneDraw.ts, the pictures read by panePictures.ts, and the
// unsure areas read from a result by unsure.ts.
//
// Image coordinates follow docs/conventions.md: x = column, y = row, pixel centres at whole
// numbers, so pixel (r, c) covers [c - 0.5, c + 0.5] x [r - 0.5, r + 0.5] (the same grid the
// library rasterises region polygons on).
import { insidePolygon, outlineDistance, tidy, type Point } from './geometry';
import { MaskOverlay, type MaskBits, type Rect } from './maskBits';
import type { MaskTool } from './maskTool';
import { drawDraft, drawReferences, drawRegion, drawSplit, drawUnsure, HANDLE } from './paneDraw';
import { loadPicture, type Picture } from './panePictures';
import type { Axis, Region } from './sessionTypes';
import { AXIS_COLOURS, type Unsure } from './unsure';

export type Tool = 'select' | 'polygon' | 'reference' | 'mask';
export type Display = 'photo' | 'channel' | 'filtered' | 'split';

export interface PaneEvents {
  /** The regions changed; ``final`` is false while a drag is still going on. */
  regions(regions: Region[], final: boolean): void;
  references(references: Array<[number, number]>): void;
  selection(index: number | null): void;
  /** Pointer over the image (pixel under it) or null when it leaves. */
  hover(pixel: { row: number; col: number } | null): void;
  /** A short hint about what the current tool does next. */
  hint(text: string): void;
  /** A message about what the tool refused (shown until the next edit of the draft), or null. */
  notice(text: string | null): void;
}

/** Said when a region is closed with fewer than three corners (it is kept, not dropped). */
export const TOO_FEW_CORNERS = 'A region needs at least three points; click more points or press Escape';

export interface Sources {
  photo: string;
  before: string; // channel, no filter
  after: string; // channel, filtered
}

const SNAP = 10; // px: distance at which a click hits a point or closes a polygon
const DRAG_START = 3; // px: movement before a press becomes a drag

type Drag =
  | { kind: 'pan'; x: number; y: number; offX: number; offY: number }
  | { kind: 'move'; index: number; x: number; y: number; original: Point[]; moved: boolean }
  | { kind: 'vertex'; index: number; vertex: number; moved: boolean }
  | { kind: 'split' }
  | { kind: 'mask' };

export class ImagePane {
  readonly canvas: HTMLCanvasElement;
  private readonly context: CanvasRenderingContext2D;
  private width = 0;
  private height = 0;
  private scale = 1;
  private offX = 0;
  private offY = 0;
  private fitted = false;
  private sources: Sources | null = null;
  private readonly images = new Map<string, Picture>();
  /** The mask's layer drawn over the picture. */
  private readonly mask = new MaskOverlay();
  private regionList: Region[] = [];
  private unsureList: Unsure[] = [];
  private selected: number | null = null;
  private draft: Point[] = [];
  private pointer: Point | null = null; // image coordinates of the pointer
  private userRefs: Array<[number, number]> = [];
  private usedRefs: Array<[number, number]> = [];
  private drag: Drag | null = null;
  private pressAt: Point = [0, 0];
  private split = 0.5;
  private frame = 0;
  /**
   * The host's size as its ResizeObserver last saw it: a new image is fitted to it without
   * reading layout right after the page changed (a forced style and layout in the task that
   * opens an image), null until it is observed.
   */
  private hostSize: { width: number; height: number } | null = null;
  tool: Tool = 'select';
  display: Display = 'photo';
  showMask = true;
  newAxis: Axis = 'both';
  /** What the mask tool does with presses, keys and drawing on the image. */
  maskEditor: MaskTool | null = null;

  constructor(private readonly host: HTMLElement, private readonly events: PaneEvents) {
    this.canvas = document.createElement('canvas');
    this.canvas.className = 'image-canvas';
    this.canvas.tabIndex = 0;
    this.canvas.setAttribute('aria-label', 'Image: references and concave regions');
    host.append(this.canvas);
    this.context = this.canvas.getContext('2d')!;
    new ResizeObserver((entries) => {
      const box = entries[entries.length - 1].borderBoxSize?.[0];
      this.hostSize = box ? { width: box.inlineSize, height: box.blockSize } : null;
      this.resize();
    }).observe(host);
    this.canvas.addEventListener('pointerdown', (e) => this.onDown(e));
    this.canvas.addEventListener('pointermove', (e) => this.onMove(e));
    this.canvas.addEventListener('pointerup', (e) => this.onUp(e));
    this.canvas.addEventListener('pointerleave', () => {
      this.pointer = null;
      this.events.hover(null);
      this.redraw();
    });
    this.canvas.addEventListener('wheel', (e) => this.onWheel(e), { passive: false });
    this.canvas.addEventListener('dblclick', () => this.tool === 'select' && this.fit());
    this.canvas.addEventListener('contextmenu', (e) => e.preventDefault());
  }

  // ---------------------------------------------------------------------------- inputs

  setImage(width: number, height: number, sources: Sources): void {
    const sameSize = width === this.width && height === this.height;
    this.width = width;
    this.height = height;
    this.sources = sources;
    this.draft = [];
    this.events.notice(null);
    if (!sameSize) {
      this.mask.forget();
      this.fitted = false;
    }
    this.resize();
  }

  /** Ask again for the previews that failed to load (the server was away): they load when shown. */
  retryImages(): void {
    for (const [url, picture] of this.images) if (picture.failed) this.images.delete(url);
    this.redraw();
  }

  /** New preview addresses (channel or filter changed); images load when first shown. */
  setSources(sources: Sources): void {
    this.sources = sources;
    this.redraw();
  }

  setRegions(regions: Region[]): void {
    this.regionList = regions.map((r) => ({ polygon: r.polygon.map(([x, y]): Point => [x, y]), axis: r.axis }));
    if (this.selected !== null && this.selected >= regions.length) this.select(null);
    this.redraw();
  }

  /** The newest result's unsure areas, outlined dashed (an empty list hides them). */
  setUnsure(areas: Unsure[]): void {
    this.unsureList = areas;
    this.redraw();
  }

  get unsure(): Unsure[] {
    return this.unsureList;
  }

  get regions(): Region[] {
    return this.regionList;
  }

  setReferences(user: Array<[number, number]>, used: Array<[number, number]>): void {
    this.userRefs = user.map(([r, c]) => [r, c]);
    this.usedRefs = used.map(([r, c]) => [r, c]);
    this.redraw();
  }

  /** The object mask as a tinted overlay with its outline; ``dirty``: only that part changed. */
  setMask(mask: MaskBits | null, dirty?: Rect): void {
    this.mask.set(mask, dirty);
    this.redraw();
  }

  setTool(tool: Tool): void {
    if (tool !== 'polygon') this.draft = [];
    this.events.notice(null);
    this.tool = tool;
    this.canvas.dataset.tool = tool;
    this.events.hint(this.hintText());
    this.redraw();
  }

  get selection(): number | null {
    return this.selected;
  }

  select(index: number | null): void {
    this.selected = index;
    this.events.selection(index);
    this.redraw();
  }

  /** Page coordinates of image point (x, y): lets the end-to-end test click on pixels. */
  pagePoint(x: number, y: number): { x: number; y: number } {
    const rect = this.canvas.getBoundingClientRect();
    return { x: rect.left + (x + 0.5) * this.scale + this.offX, y: rect.top + (y + 0.5) * this.scale + this.offY };
  }

  // -------------------------------------------------------------------------- commands

  /** Enter closes the polygon being drawn, Escape cancels it, Delete removes the selection. */
  key(event: KeyboardEvent): boolean {
    if (this.tool === 'mask' && this.maskEditor?.key(event)) return true;
    if (this.tool === 'polygon' && this.draft.length) {
      if (event.key === 'Enter') return this.closeDraft(), true;
      if (event.key === 'Escape') return (this.draft = []), this.draftEdited(), true;
      if (event.key === 'Backspace') return this.draft.pop(), this.draftEdited(), true;
    }
    if ((event.key === 'Delete' || event.key === 'Backspace') && this.selected !== null) {
      this.removeRegion(this.selected);
      return true;
    }
    if (event.key === 'Escape' && this.selected !== null) return this.select(null), true;
    return false;
  }

  removeRegion(index: number): void {
    this.regionList.splice(index, 1);
    this.select(null);
    this.events.regions(this.regionList, true);
  }

  setAxis(index: number, axis: Axis): void {
    const region = this.regionList[index];
    if (!region || region.axis === axis) return;
    region.axis = axis;
    this.events.regions(this.regionList, true);
    this.redraw();
  }

  fit(): void {
    const rect = this.hostSize ?? this.host.getBoundingClientRect();
    if (!this.width || !rect.width || !rect.height) return;
    const margin = 24;
    this.scale = Math.max(0.01, Math.min((rect.width - 2 * margin) / this.width, (rect.height - 2 * margin) / this.height));
    this.offX = (rect.width - this.width * this.scale) / 2;
    this.offY = (rect.height - this.height * this.scale) / 2;
    this.fitted = true;
    this.redraw();
  }

  zoom(factor: number, atX?: number, atY?: number): void {
    const rect = this.host.getBoundingClientRect();
    const cx = atX ?? rect.width / 2;
    const cy = atY ?? rect.height / 2;
    const scale = Math.min(64, Math.max(0.05, this.scale * factor));
    // keep the point under the cursor where it is
    this.offX = cx - ((cx - this.offX) * scale) / this.scale;
    this.offY = cy - ((cy - this.offY) * scale) / this.scale;
    this.scale = scale;
    this.redraw();
  }

  // --------------------------------------------------------------------------- pointer

  private toImage(event: MouseEvent): Point {
    const rect = this.canvas.getBoundingClientRect();
    return [(event.clientX - rect.left - this.offX) / this.scale - 0.5, (event.clientY - rect.top - this.offY) / this.scale - 0.5];
  }

  private toScreen([x, y]: Point): Point {
    return [(x + 0.5) * this.scale + this.offX, (y + 0.5) * this.scale + this.offY];
  }

  private screenDistance(a: Point, b: Point): number {
    return Math.hypot(a[0] - b[0], a[1] - b[1]) * this.scale;
  }

  private clampToImage([x, y]: Point): Point {
    return [tidy(Math.min(this.width - 0.5, Math.max(-0.5, x))), tidy(Math.min(this.height - 0.5, Math.max(-0.5, y)))];
  }

  private onDown(event: PointerEvent): void {
    if (!this.width) return;
    this.canvas.focus();
    const at = this.toImage(event);
    this.pressAt = [event.clientX, event.clientY];
    this.canvas.setPointerCapture(event.pointerId);
    if (event.button === 1 || event.button === 2 || (event.button === 0 && event.shiftKey)) {
      this.drag = { kind: 'pan', x: event.clientX, y: event.clientY, offX: this.offX, offY: this.offY };
      return;
    }
    if (event.button !== 0) return;
    if (this.display === 'split' && Math.abs(this.toScreen(at)[0] - this.toScreen([this.split * this.width - 0.5, 0])[0]) < 6) {
      this.drag = { kind: 'split' };
      return;
    }
    if (this.tool === 'polygon') return this.polygonClick(at);
    if (this.tool === 'reference') return this.referenceClick(at);
    if (this.tool === 'mask' && this.maskEditor) {
      this.drag = { kind: 'mask' };
      this.maskEditor.down(at, event.altKey);
      return;
    }
    this.selectPress(at, event);
  }

  private polygonClick(at: Point): void {
    // a click on the first corner closes the region (and is refused, saying so, under three)
    if (this.draft.length && this.screenDistance(at, this.draft[0]) <= SNAP) return this.closeDraft();
    this.draft.push(this.clampToImage(at));
    this.draftEdited();
  }

  private closeDraft(): void {
    if (this.draft.length < 3) {
      // the corners stay: the user adds more, or Escape drops them
      this.events.notice(TOO_FEW_CORNERS);
      return;
    }
    this.regionList.push({ polygon: this.draft, axis: this.newAxis });
    this.draft = [];
    this.select(this.regionList.length - 1);
    this.events.regions(this.regionList, true);
    this.draftEdited();
  }

  /** The draft changed: a refusal said about the old one no longer holds. */
  private draftEdited(): void {
    this.events.notice(null);
    this.hintAndDraw();
  }

  private referenceClick(at: Point): void {
    const hit = this.userRefs.findIndex(([r, c]) => this.screenDistance(at, [c, r]) <= SNAP);
    if (hit >= 0) {
      this.userRefs.splice(hit, 1);
    } else {
      const row = Math.round(at[1]);
      const col = Math.round(at[0]);
      if (row < 0 || col < 0 || row >= this.height || col >= this.width) return;
      this.userRefs.push([row, col]);
    }
    this.events.references(this.userRefs.map(([r, c]) => [r, c]));
    this.redraw();
  }

  private selectPress(at: Point, event: PointerEvent): void {
    const selected = this.selected !== null ? this.regionList[this.selected] : null;
    if (selected) {
      const vertex = selected.polygon.findIndex((p) => this.screenDistance(at, p) <= HANDLE + 3);
      if (vertex >= 0) {
        this.drag = { kind: 'vertex', index: this.selected!, vertex, moved: false };
        return;
      }
    }
    // topmost region under the pointer, or whose outline is within a few screen pixels
    for (let i = this.regionList.length - 1; i >= 0; i--) {
      const polygon = this.regionList[i].polygon;
      if (insidePolygon(at[0], at[1], polygon) || outlineDistance(at[0], at[1], polygon) * this.scale <= 4) {
        this.select(i);
        this.drag = { kind: 'move', index: i, x: at[0], y: at[1], original: polygon.map(([x, y]): Point => [x, y]), moved: false };
        return;
      }
    }
    this.select(null);
    this.drag = { kind: 'pan', x: event.clientX, y: event.clientY, offX: this.offX, offY: this.offY };
  }

  private onMove(event: PointerEvent): void {
    if (!this.width) return;
    const at = this.toImage(event);
    this.pointer = at;
    const row = Math.round(at[1]);
    const col = Math.round(at[0]);
    const onImage = row >= 0 && col >= 0 && row < this.height && col < this.width;
    this.events.hover(onImage ? { row, col } : null);
    const drag = this.drag;
    const travelled = Math.hypot(event.clientX - this.pressAt[0], event.clientY - this.pressAt[1]);
    if (drag?.kind === 'pan') {
      this.offX = drag.offX + event.clientX - drag.x;
      this.offY = drag.offY + event.clientY - drag.y;
    } else if (drag?.kind === 'mask') {
      this.maskEditor?.move(at);
    } else if (drag?.kind === 'split') {
      this.split = Math.min(1, Math.max(0, (at[0] + 0.5) / this.width));
    } else if (drag?.kind === 'move' && (drag.moved || travelled >= DRAG_START)) {
      drag.moved = true;
      const dx = at[0] - drag.x;
      const dy = at[1] - drag.y;
      this.regionList[drag.index].polygon = drag.original.map(([x, y]): Point => [tidy(x + dx), tidy(y + dy)]);
      this.events.regions(this.regionList, false);
    } else if (drag?.kind === 'vertex' && (drag.moved || travelled >= DRAG_START)) {
      drag.moved = true;
      this.regionList[drag.index].polygon[drag.vertex] = this.clampToImage(at);
      this.events.regions(this.regionList, false);
    }
    this.updateCursor(at);
    this.redraw();
  }

  private onUp(event: PointerEvent): void {
    const drag = this.drag;
    this.drag = null;
    if (this.canvas.hasPointerCapture(event.pointerId)) this.canvas.releasePointerCapture(event.pointerId);
    if ((drag?.kind === 'move' || drag?.kind === 'vertex') && drag.moved) this.events.regions(this.regionList, true);
    if (drag?.kind === 'mask') this.maskEditor?.up();
  }

  private onWheel(event: WheelEvent): void {
    if (!this.width) return;
    event.preventDefault();
    const rect = this.canvas.getBoundingClientRect();
    this.zoom(Math.exp(-event.deltaY * 0.0015), event.clientX - rect.left, event.clientY - rect.top);
  }

  private updateCursor(at: Point): void {
    let cursor = 'default';
    if (this.drag?.kind === 'pan') cursor = 'grabbing';
    else if (this.display === 'split' && Math.abs(this.toScreen(at)[0] - this.toScreen([this.split * this.width - 0.5, 0])[0]) < 6) cursor = 'ew-resize';
    else if (this.tool === 'polygon') cursor = this.draft.length >= 3 && this.screenDistance(at, this.draft[0]) <= SNAP ? 'pointer' : 'crosshair';
    else if (this.tool === 'reference') cursor = 'crosshair';
    else if (this.tool === 'mask') cursor = this.maskEditor?.cursor() ?? 'crosshair';
    else if (this.drag) cursor = 'move';
    else if (this.regionList.some((r) => insidePolygon(at[0], at[1], r.polygon))) cursor = 'move';
    this.canvas.style.cursor = cursor;
  }

  private hintText(): string {
    if (this.tool === 'polygon') {
      if (!this.draft.length) return 'Click to place the first corner of a concave region';
      if (this.draft.length < 3) return 'Click to add corners · Esc cancels';
      return 'Click the first corner or press Enter to close · Backspace removes a corner · Esc cancels';
    }
    if (this.tool === 'reference') return 'Click a point facing the light to measure depth from it · click one to remove it';
    if (this.tool === 'mask' && this.maskEditor) return this.maskEditor.hint();
    return 'Click a region to select it · drag to move · drag empty space to pan · wheel zooms';
  }

  private hintAndDraw(): void {
    this.events.hint(this.hintText());
    this.redraw();
  }

  // ----------------------------------------------------------------------------- drawing

  private resize(): void {
    // before its first observation the observer is due (and calls this): reading the size here
    // would force a style and layout in the middle of the app's start
    const rect = this.hostSize;
    if (!rect) return;
    const dpr = window.devicePixelRatio || 1;
    this.canvas.width = Math.max(1, Math.round(rect.width * dpr));
    this.canvas.height = Math.max(1, Math.round(rect.height * dpr));
    this.canvas.style.width = `${rect.width}px`;
    this.canvas.style.height = `${rect.height}px`;
    if (!this.fitted) this.fit();
    this.redraw();
  }

  /**
   * The picture at ``url`` to draw at the scale shown: decoded off the page's thread (an
   * ImageBitmap; an <img> drawn on a canvas was decoded on it, 180 ms for a 12 Mpx photo), with
   * a copy at most SMALL_SIDE (pictureWorker.ts) on a side for a photo shown smaller than that (a software canvas
   * scaling 12 Mpx at every frame blocked the page too). Null until it is ready.
   */
  private image(url: string): ImageBitmap | null {
    let picture = this.images.get(url);
    if (!picture) {
      picture = { full: null, small: null, failed: false };
      this.images.set(url, picture);
      if (this.images.size > 12) this.images.delete(this.images.keys().next().value!); // oldest
      void loadPicture(url, picture).then(() => this.redraw());
    }
    const full = picture.full;
    if (!full) return null;
    const shown = this.width * this.scale * (window.devicePixelRatio || 1);
    return picture.small && shown <= picture.small.width * 1.25 ? picture.small : full;
  }

  redraw(): void {
    if (this.frame) return;
    this.frame = requestAnimationFrame(() => {
      this.frame = 0;
      this.draw();
    });
  }

  private draw(): void {
    const ctx = this.context;
    const dpr = window.devicePixelRatio || 1;
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    ctx.clearRect(0, 0, this.canvas.width, this.canvas.height);
    if (!this.width || !this.sources) return;
    const w = this.width * this.scale;
    const h = this.height * this.scale;
    // big pixels stay crisp: this is a tool for picking pixels
    ctx.imageSmoothingEnabled = this.scale < 2;
    ctx.fillStyle = '#000';
    ctx.fillRect(this.offX, this.offY, w, h);
    if (this.display === 'split') {
      const cut = this.split * w;
      this.drawClipped(this.sources.before, this.offX, cut);
      this.drawClipped(this.sources.after, this.offX + cut, w - cut);
    } else {
      const url = this.display === 'photo' ? this.sources.photo : this.display === 'channel' ? this.sources.before : this.sources.after;
      const image = this.image(url);
      if (image) ctx.drawImage(image, this.offX, this.offY, w, h);
    }
    const mask = this.showMask || this.tool === 'mask' ? this.mask.picture(w * (window.devicePixelRatio || 1)) : null;
    if (mask) {
      ctx.imageSmoothingEnabled = false;
      ctx.drawImage(mask, this.offX, this.offY, w, h);
    }
    ctx.strokeStyle = 'rgba(255,255,255,0.18)';
    ctx.lineWidth = 1;
    ctx.strokeRect(this.offX - 0.5, this.offY - 0.5, w + 1, h + 1);
    const toScreen = (p: Point) => this.toScreen(p);
    this.regionList.forEach((region, i) => drawRegion(ctx, toScreen, region, i === this.selected));
    this.unsureList.forEach((area, i) => drawUnsure(ctx, toScreen, area, i));
    if (this.tool === 'polygon' && this.draft.length) {
      const closable = this.draft.length >= 3 && this.pointer !== null && this.screenDistance(this.pointer, this.draft[0]) <= SNAP;
      drawDraft(ctx, toScreen, this.draft, this.pointer, AXIS_COLOURS[this.newAxis], closable);
    }
    drawReferences(ctx, toScreen, this.userRefs, this.usedRefs);
    if (this.tool === 'mask') this.maskEditor?.draw(ctx, toScreen, this.scale, this.pointer);
    if (this.display === 'split') drawSplit(ctx, this.offX + this.split * this.width * this.scale, this.offY, this.offY + h);
  }

  private drawClipped(url: string, left: number, width: number): void {
    const image = this.image(url);
    if (!image || width <= 0) return;
    const ctx = this.context;
    ctx.save();
    ctx.beginPath();
    ctx.rect(left, this.offY, width, this.height * this.scale);
    ctx.clip();
    ctx.drawImage(image, this.offX, this.offY, this.width * this.scale, this.height * this.scale);
    ctx.restore();
  }
}
