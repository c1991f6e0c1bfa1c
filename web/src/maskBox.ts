// The mask tool's Box mode: the box the user drags round the object, in image pixels, its dashed
// outline over the image, and the box the server's cut takes (POST /api/images/{id}/mask/box:
// shadeform.masks.segment_from_box, GrabCut inside the box on the photo's colours).
import type { Point } from './geometry';

/** Rows and columns ``[top, left, bottom, right]``, bottom and right exclusive. */
export type PixelBox = [number, number, number, number];

/** The fewest pixels a box spans each way (the server refuses less than 3 x 3). */
export const MIN_BOX = 3;

export class MaskBox {
  private start: Point | null = null;
  private end: Point | null = null;

  get dragging(): boolean {
    return this.start !== null;
  }

  begin(at: Point): void {
    this.start = at;
    this.end = at;
  }

  drag(at: Point): void {
    if (this.start) this.end = at;
  }

  forget(): void {
    this.start = this.end = null;
  }

  /** The dragged box in whole pixels cut to a ``width`` x ``height`` image (every pixel whose
   * centre it covers), and the drag forgotten; null when it spans fewer than MIN_BOX pixels. */
  finish(width: number, height: number): PixelBox | null {
    const [start, end] = [this.start, this.end];
    this.forget();
    if (!start || !end) return null;
    const clamp = (v: number, hi: number) => Math.min(hi, Math.max(0, v));
    const left = clamp(Math.ceil(Math.min(start[0], end[0])), width);
    const right = clamp(Math.floor(Math.max(start[0], end[0])) + 1, width);
    const top = clamp(Math.ceil(Math.min(start[1], end[1])), height);
    const bottom = clamp(Math.floor(Math.max(start[1], end[1])) + 1, height);
    return right - left >= MIN_BOX && bottom - top >= MIN_BOX ? [top, left, bottom, right] : null;
  }

  /** The box being dragged, dashed, over the image. */
  draw(ctx: CanvasRenderingContext2D, toScreen: (p: Point) => Point): void {
    if (!this.start || !this.end) return;
    const [x0, y0] = toScreen(this.start);
    const [x1, y1] = toScreen(this.end);
    ctx.setLineDash([6, 4]);
    ctx.lineWidth = 3;
    ctx.strokeStyle = 'rgba(0,0,0,0.6)';
    ctx.strokeRect(x0, y0, x1 - x0, y1 - y0);
    ctx.lineWidth = 1.5;
    ctx.strokeStyle = '#5eead4';
    ctx.strokeRect(x0, y0, x1 - x0, y1 - y0);
    ctx.setLineDash([]);
  }
}
