// The mask tool's marks over the image (maskTool.ts): the brush's outline at the pointer, the
// polygon being drawn, the box being dragged, the clicks on the object and on the background;
// and the hint that says what the tool does next.
import type { Point } from './geometry';
import type { MaskBox } from './maskBox';
import type { MaskMode, MaskOp } from './maskPanel';
import type { ToScreen } from './paneDraw';

/** What the tool has marked on the image. */
export interface MaskMarks {
  mode: MaskMode;
  op: MaskOp;
  radius: number;
  /** The polygon's corners so far, and whether it adds (else cuts). */
  draft: Point[];
  polygonAdd: boolean;
  box: MaskBox;
  /** Clicks on the object and on the background, (row, col). */
  inside: Array<[number, number]>;
  outside: Array<[number, number]>;
}

/** The marks, drawn with the image at ``scale`` screen pixels a pixel; ``pointer`` in image coordinates. */
export function drawMaskMarks(ctx: CanvasRenderingContext2D, toScreen: ToScreen, scale: number, pointer: Point | null, marks: MaskMarks): void {
  const { mode, op, radius, draft, polygonAdd, box, inside, outside } = marks;
  if (mode === 'brush' && pointer) {
    const [sx, sy] = toScreen(pointer);
    ctx.beginPath();
    ctx.arc(sx, sy, Math.max(2, radius * scale), 0, 2 * Math.PI);
    ctx.lineWidth = 3;
    ctx.strokeStyle = 'rgba(0,0,0,0.6)';
    ctx.stroke();
    ctx.lineWidth = 1.5;
    ctx.strokeStyle = op === 'add' ? '#5eead4' : '#fca5a5';
    ctx.stroke();
  }
  if (mode === 'polygon' && draft.length) {
    const colour = polygonAdd ? '#5eead4' : '#fca5a5';
    const points = pointer ? [...draft, pointer] : draft;
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
    draft.forEach((p, i) => {
      const [sx, sy] = toScreen(p);
      ctx.beginPath();
      ctx.arc(sx, sy, i === 0 ? 5 : 3.5, 0, 2 * Math.PI);
      ctx.fillStyle = i === 0 ? '#fff' : colour;
      ctx.fill();
    });
  }
  box.draw(ctx, toScreen);
  for (const [list, colour] of [[inside, '#22c55e'], [outside, '#ef4444']] as const) {
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

/** What the tool does next, for the pane's status line; ``corners``: the polygon's so far. */
export function maskHint(mode: MaskMode, op: MaskOp, corners: number): string {
  const flip = op === 'add' ? 'Alt erases' : 'Alt adds';
  if (mode === 'brush') return `Drag to ${op === 'add' ? 'paint the object' : 'erase'} · ${flip} · [ ] brush size · Shift-drag pans`;
  if (mode === 'polygon') {
    if (corners < 3) return `Click corners of a polygon to ${op === 'add' ? 'add' : 'cut'} · ${flip}`;
    return 'Click the first corner or press Enter to close · Backspace removes a corner · Esc cancels';
  }
  if (mode === 'box') return 'Drag a box round the object: it is found inside, on its colours and edges';
  return op === 'add'
    ? 'Click the object: it grows from your clicks · Alt-click marks background · Esc forgets the clicks'
    : 'Click the background · Alt-click marks the object · Esc forgets the clicks';
}
