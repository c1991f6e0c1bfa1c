// The mask tool: the object mask as a bitmap the user edits in the image pane (brush, polygon,
// invert, fill holes) or asks the server for (automatic, a threshold, "click the object", a box
// round it, a file), with the side panel's Mask group. This module holds the tool's state and
// actions; the bitmap is maskBits.ts's, the Mask group's controls and words maskPanel.ts's, the
// marks drawn over the image maskMarks.ts's.
//
// The mask every solve and export uses is params.mask: null for the automatic one (the
// server's; each result brings it, and the pane shows it), else base64 of a PNG that this tool
// encodes after every finished edit (a stroke, a polygon, a click, a slider's release). Image
// coordinates follow docs/conventions.md: x = column, y = row, pixel centres at whole numbers.
import * as api from './api';
import type { Channel, MaskResult } from './api.gen';
import type { Point } from './geometry';
import { MaskBits, type Rect } from './maskBits';
import { MaskBox, MIN_BOX } from './maskBox';
import { drawMaskMarks, maskHint } from './maskMarks';
import { MaskPanel, type MaskMode, type MaskOp } from './maskPanel';
import type { ToScreen } from './paneDraw';
import { thresholdWords } from './words';

export type { MaskMode, MaskOp } from './maskPanel';

const SNAP = 10; // screen px: a click this near the first corner closes the polygon

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
  private readonly panel: MaskPanel;

  constructor(private readonly host: MaskHost) {
    this.panel = new MaskPanel({
      mode: (mode) => this.setMode(mode),
      op: (op) => this.setOp(op),
      radius: (radius) => this.setRadius(radius),
      threshold: (final) => this.threshold(final),
      automatic: () => this.automatic(),
      clear: () => this.clear(),
      invert: () => this.invert(),
      fillHoles: () => this.fillHoles(),
      save: () => this.save(),
      load: (file) => this.load(file),
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
      threshold: this.panel.thresholdValue(),
      dark: this.panel.dark,
      note: this.panel.note,
      error: this.panel.shownError,
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
    this.panel.showRadius(this.radius);
    this.host.redraw();
  }

  private showControls(): void {
    this.panel.showControls(this.mode, this.op);
  }

  private showNote(): void {
    this.panel.showNote(this.user, this.mask ? this.mask.count : null, this.what, this.autoNote);
  }

  /** A message that stays until the next mask action succeeds. */
  private error(message: string): void {
    this.panel.error(message);
  }

  private clearError(): void {
    this.panel.error(null);
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
      this.panel.showThreshold(result.threshold);
      this.panel.dark = result.dark;
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
    this.panel.showThreshold(null);
    const image = this.host.image();
    if (!image) return;
    if (!final && this.thresholdBusy) {
      this.thresholdWaiting = true;
      return;
    }
    const id = ++this.thresholdSent;
    this.thresholdBusy = true;
    this.thresholdWaiting = false;
    const value = this.panel.thresholdValue();
    const dark = this.panel.dark;
    try {
      const result = await api.autoMask(image.id, { channel: image.channel, threshold: value, dark });
      if (id !== this.thresholdSent) return; // a newer value is on its way
      this.clearClicks();
      await this.apply(result, final, `pixels ${thresholdWords(value, dark)}`);
      if (!final) {
        this.clearError();
        this.panel.note = `Pixels ${thresholdWords(value, dark)}: ${result.pixels.toLocaleString()} of them · release to use it`;
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
    return maskHint(this.mode, this.op, this.draft.length);
  }

  /** The tool's marks over the image: brush outline, polygon corners, clicks. */
  draw(ctx: CanvasRenderingContext2D, toScreen: ToScreen, scale: number, pointer: Point | null): void {
    this.scale = scale;
    const { mode, op, radius, draft, polygonAdd, box, inside, outside } = this;
    drawMaskMarks(ctx, toScreen, scale, pointer, { mode, op, radius, draft, polygonAdd, box, inside, outside });
  }
}
