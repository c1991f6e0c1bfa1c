// The areas a result says the shading cannot settle (``info.unsure``: convex or concave?), read
// from the result for the image pane (which outlines them) and the parameter panel (which lists
// them, each with its question); and the colours both draw regions and those areas in.
import type { Point } from './geometry';
import type { Axis } from './sessionTypes';

export const AXIS_COLOURS: Record<Axis, string> = { x: '#ff9f43', y: '#38bdf8', both: '#c084fc' };
/** The dashed outline of an area the shading cannot settle (convex or concave). */
export const UNSURE_COLOUR = '#fbbf24';

/** An area the library reports in ``info.unsure``: its outline, suggested axis, share and centre. */
export interface Unsure {
  polygon: Point[];
  axis: Axis;
  share: number;
  centre: Point;
}

/** The unsure areas of a result's ``info`` (none when absent or malformed). */
export function readUnsure(info: Record<string, unknown> | undefined): Unsure[] {
  const list = info?.unsure;
  if (!Array.isArray(list)) return [];
  const point = (p: unknown): p is Point => Array.isArray(p) && p.length === 2 && p.every((v) => typeof v === 'number' && Number.isFinite(v));
  return list.flatMap((entry): Unsure[] => {
    const { polygon, axis, share, centre } = (entry ?? {}) as Partial<Record<keyof Unsure, unknown>>;
    if (!Array.isArray(polygon) || polygon.length < 3 || !polygon.every(point)) return [];
    if (axis !== 'x' && axis !== 'y' && axis !== 'both') return [];
    const middle = point(centre) ? centre : polygonMean(polygon);
    return [{ polygon: polygon.map(([x, y]): Point => [x, y]), axis, share: typeof share === 'number' ? share : 0, centre: [middle[0], middle[1]] }];
  });
}

function polygonMean(polygon: Point[]): Point {
  const n = polygon.length;
  return [polygon.reduce((s, p) => s + p[0], 0) / n, polygon.reduce((s, p) => s + p[1], 0) / n];
}

/** The question an unsure area asks, in the panel's list (the image shows its number). */
export function unsureQuestion(axis: Axis): string {
  return axis === 'both' ? 'concave along x and y?' : `concave along ${axis}?`;
}

