// What the image pane draws over the picture, each mark from what it is and where the image lies
// on screen (``toScreen``: image point to canvas pixels): the concave regions with their axis
// tags and handles, the unsure areas' dashed outlines, the region being drawn, the reference
// points, and the before | after split; and the small text tags they carry.
import type { Point } from './geometry';
import type { Region } from './sessionTypes';
import { AXIS_COLOURS, UNSURE_COLOUR, type Unsure } from './unsure';

/** Image point -> canvas pixel (CSS pixels), as the pane shows the image now. */
export type ToScreen = (p: Point) => Point;

export const HANDLE = 5; // px: vertex handle half-size

function path(ctx: CanvasRenderingContext2D, toScreen: ToScreen, points: Point[], close: boolean): void {
  ctx.beginPath();
  points.forEach((p, i) => {
    const [sx, sy] = toScreen(p);
    if (i === 0) ctx.moveTo(sx, sy);
    else ctx.lineTo(sx, sy);
  });
  if (close) ctx.closePath();
}

export function drawRegion(ctx: CanvasRenderingContext2D, toScreen: ToScreen, region: Region, selected: boolean): void {
  const colour = AXIS_COLOURS[region.axis];
  path(ctx, toScreen, region.polygon, true);
  ctx.fillStyle = colour + (selected ? '40' : '2a');
  ctx.fill();
  ctx.lineWidth = selected ? 2.5 : 1.75;
  ctx.strokeStyle = colour;
  ctx.setLineDash([]);
  ctx.stroke();
  // axis tag just above the topmost corner, clear of the references inside
  const top = region.polygon.reduce((best, p) => (p[1] < best[1] ? p : best));
  const [tx, ty] = toScreen(top);
  label(ctx, region.axis === 'both' ? 'concave x·y' : `concave ${region.axis}`, tx, ty - 13, colour);
  if (!selected) return;
  for (const p of region.polygon) {
    const [sx, sy] = toScreen(p);
    ctx.fillStyle = '#fff';
    ctx.strokeStyle = colour;
    ctx.lineWidth = 1.5;
    ctx.fillRect(sx - HANDLE, sy - HANDLE, 2 * HANDLE, 2 * HANDLE);
    ctx.strokeRect(sx - HANDLE, sy - HANDLE, 2 * HANDLE, 2 * HANDLE);
  }
}

/** One unsure area: its dashed outline and a short numbered tag (the panel's list says what it
 * asks: a relief can have many, and full questions would cover the photo). */
export function drawUnsure(ctx: CanvasRenderingContext2D, toScreen: ToScreen, area: Unsure, index: number): void {
  path(ctx, toScreen, area.polygon, true);
  ctx.lineWidth = 3.5;
  ctx.strokeStyle = 'rgba(0,0,0,0.55)';
  ctx.setLineDash([7, 5]);
  ctx.stroke();
  ctx.lineWidth = 1.75;
  ctx.strokeStyle = UNSURE_COLOUR;
  ctx.stroke();
  ctx.setLineDash([]);
  const [cx, cy] = toScreen(area.centre);
  label(ctx, `?${index + 1}`, cx, cy, UNSURE_COLOUR);
}

/** The region being drawn: its corners, and the line on to the pointer; ``closable``: the pointer
 * is on the first corner, which a click closes it at. */
export function drawDraft(
  ctx: CanvasRenderingContext2D,
  toScreen: ToScreen,
  draft: Point[],
  pointer: Point | null,
  colour: string,
  closable: boolean,
): void {
  const points = pointer ? [...draft, pointer] : draft;
  path(ctx, toScreen, points, false);
  ctx.strokeStyle = colour;
  ctx.lineWidth = 1.75;
  ctx.setLineDash([6, 4]);
  ctx.stroke();
  ctx.setLineDash([]);
  draft.forEach((p, i) => {
    const [sx, sy] = toScreen(p);
    ctx.beginPath();
    ctx.arc(sx, sy, i === 0 ? (closable ? 7 : 5) : 3.5, 0, 2 * Math.PI);
    ctx.fillStyle = i === 0 ? '#fff' : colour;
    ctx.fill();
    ctx.strokeStyle = colour;
    ctx.lineWidth = 2;
    ctx.stroke();
  });
}

/** The reference points: the user's (``user``, numbered) and those the solve used (``used``). */
export function drawReferences(
  ctx: CanvasRenderingContext2D,
  toScreen: ToScreen,
  user: Array<[number, number]>,
  used: Array<[number, number]>,
): void {
  const isUser = (r: number, c: number) => user.some(([ur, uc]) => ur === r && uc === c);
  // automatic references (the brightest pixel of each part): a hollow diamond
  for (const [r, c] of used) {
    if (isUser(r, c)) continue;
    const [sx, sy] = toScreen([c, r]);
    ctx.save();
    ctx.translate(sx, sy);
    ctx.rotate(Math.PI / 4);
    ctx.lineWidth = 3.5;
    ctx.strokeStyle = 'rgba(0,0,0,0.65)';
    ctx.strokeRect(-5, -5, 10, 10);
    ctx.lineWidth = 1.75;
    ctx.strokeStyle = '#fde047';
    ctx.strokeRect(-5, -5, 10, 10);
    ctx.restore();
    label(ctx, 'auto', sx + 10, sy - 10, '#fde047');
  }
  // the user's: a filled dot with a ring, numbered (the first is the main one: z = 0 there)
  user.forEach(([r, c], i) => {
    const [sx, sy] = toScreen([c, r]);
    ctx.beginPath();
    ctx.arc(sx, sy, 6, 0, 2 * Math.PI);
    ctx.fillStyle = '#22d3ee';
    ctx.fill();
    ctx.lineWidth = 2;
    ctx.strokeStyle = '#0b1220';
    ctx.stroke();
    label(ctx, String(i + 1), sx + 11, sy - 10, '#22d3ee');
  });
}

/** The before | after split: its line at ``x`` from ``top`` to ``bottom``, its handle and words. */
export function drawSplit(ctx: CanvasRenderingContext2D, x: number, top: number, bottom: number): void {
  ctx.strokeStyle = '#fff';
  ctx.lineWidth = 2;
  ctx.beginPath();
  ctx.moveTo(x, top);
  ctx.lineTo(x, bottom);
  ctx.stroke();
  ctx.beginPath();
  ctx.arc(x, (top + bottom) / 2, 9, 0, 2 * Math.PI);
  ctx.fillStyle = '#fff';
  ctx.fill();
  ctx.fillStyle = '#111';
  ctx.font = '600 10px system-ui, sans-serif';
  ctx.textAlign = 'center';
  ctx.textBaseline = 'middle';
  ctx.fillText('↔', x, (top + bottom) / 2 + 0.5);
  label(ctx, 'before', x - 34, top + 14, '#e5e7eb');
  label(ctx, 'after', x + 30, top + 14, '#e5e7eb');
}

/** A small text tag with a dark halo, readable on any photo. */
function label(ctx: CanvasRenderingContext2D, text: string, x: number, y: number, colour: string): void {
  const m = ctx.getTransform();
  // drawn once into a sprite and copied at every frame after: the halo (strokeText) is the glyphs'
  // outlines stroked anew at each call, 3-5 ms a frame of the page's thread for a relief's
  // numbered unsure areas in a software canvas (Chromium traces of bench_app_large.py's page).
  // Only where the tag is drawn upright at the pane's scale and without a dash (every caller now)
  if (m.b !== 0 || m.c !== 0 || m.a !== m.d || m.a <= 0 || ctx.getLineDash().length) {
    drawLabel(ctx, text, x, y, colour);
    return;
  }
  const sprite = labelSprite(text, colour, m.a);
  // at whole device pixels: the copy is the sprite's pixels, unscaled (at most half a pixel moved)
  const left = Math.round(m.a * x + m.e - sprite.width / 2);
  const top = Math.round(m.d * y + m.f - sprite.height / 2);
  ctx.save();
  ctx.setTransform(1, 0, 0, 1, 0, 0);
  ctx.drawImage(sprite, left, top);
  ctx.restore();
}

function drawLabel(ctx: CanvasRenderingContext2D | OffscreenCanvasRenderingContext2D, text: string, x: number, y: number, colour: string): void {
  ctx.font = LABEL_FONT;
  ctx.textAlign = 'center';
  ctx.textBaseline = 'middle';
  ctx.lineWidth = 3;
  ctx.strokeStyle = 'rgba(0,0,0,0.75)';
  ctx.strokeText(text, x, y);
  ctx.fillStyle = colour;
  ctx.fillText(text, x, y);
}

const LABEL_FONT = '600 11px system-ui, sans-serif';
/** The tags drawn so far, by text, colour and device pixel ratio (a few dozen at most in use). */
const labelSprites = new Map<string, HTMLCanvasElement>();

function labelSprite(text: string, colour: string, ratio: number): HTMLCanvasElement {
  const key = `${text}\u0000${colour}\u0000${ratio}`;
  let sprite = labelSprites.get(key);
  if (sprite) return sprite;
  sprite = document.createElement('canvas');
  const measure = sprite.getContext('2d')!;
  measure.font = LABEL_FONT;
  // the text's width, the halo (3 px wide) and a pixel to spare on each side; 11 px text in 24 px
  const width = Math.ceil(measure.measureText(text).width) + 8;
  const height = 24;
  // even sizes: the middle, where the text is drawn, is a whole pixel in the sprite and the pane
  sprite.width = 2 * Math.ceil((width * ratio) / 2);
  sprite.height = 2 * Math.ceil((height * ratio) / 2);
  const ctx = sprite.getContext('2d')!;
  ctx.setTransform(ratio, 0, 0, ratio, 0, 0);
  drawLabel(ctx, text, sprite.width / ratio / 2, sprite.height / ratio / 2, colour);
  if (labelSprites.size >= 256) labelSprites.delete(labelSprites.keys().next().value!);
  labelSprites.set(key, sprite);
  return sprite;
}
