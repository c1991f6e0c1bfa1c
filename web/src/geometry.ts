// Small plane-geometry helpers for the image pane's editors (points are [x, y]).

export type Point = [number, number];

/** Even-odd rule: whether (x, y) lies inside the polygon (a ray crossing count). */
export function insidePolygon(x: number, y: number, polygon: Point[]): boolean {
  let inside = false;
  for (let i = 0, j = polygon.length - 1; i < polygon.length; j = i++) {
    const [xi, yi] = polygon[i];
    const [xj, yj] = polygon[j];
    if (yi > y !== yj > y && x < ((xj - xi) * (y - yi)) / (yj - yi) + xi) inside = !inside;
  }
  return inside;
}

/** Distance from (x, y) to the segment a-b. */
export function segmentDistance(x: number, y: number, a: Point, b: Point): number {
  const dx = b[0] - a[0];
  const dy = b[1] - a[1];
  const length2 = dx * dx + dy * dy;
  const t = length2 > 0 ? Math.max(0, Math.min(1, ((x - a[0]) * dx + (y - a[1]) * dy) / length2)) : 0;
  return Math.hypot(x - (a[0] + t * dx), y - (a[1] + t * dy));
}

/** Distance from (x, y) to the polygon's outline. */
export function outlineDistance(x: number, y: number, polygon: Point[]): number {
  let best = Infinity;
  for (let i = 0, j = polygon.length - 1; i < polygon.length; j = i++) {
    best = Math.min(best, segmentDistance(x, y, polygon[j], polygon[i]));
  }
  return best;
}

/** Round a coordinate to 1/100 pixel: exact enough, and a readable regions file. */
export function tidy(value: number): number {
  return Math.round(value * 100) / 100;
}
