// A Web Worker that reads the image pane's pictures (the photo, its channel, the filtered one) into
// ImageBitmaps, with a small copy of a large one: decoded and scaled off the page's thread. A
// bitmap made on the page is scaled on the page's thread when its promise resolves, even when the
// file was decoded elsewhere: 500 ms for a 12 Mpx photo's small copy on a loaded 2-core machine.

export interface PictureRequest {
  id: number;
  /** An absolute URL (http, data or blob). */
  url: string;
}

export type PictureReply =
  | { id: number; ok: true; full: ImageBitmap; small: ImageBitmap | null }
  | { id: number; ok: false; message: string };

/** Long side of the copy of a large picture drawn while it is shown smaller (a 2K screen's). */
export const SMALL_SIDE = 2048;

async function read(url: string): Promise<{ full: ImageBitmap; small: ImageBitmap | null }> {
  const response = await fetch(url);
  if (!response.ok) throw new Error(`${response.status}`);
  const blob = await response.blob();
  const full = await createImageBitmap(blob);
  const side = Math.max(full.width, full.height);
  if (side <= SMALL_SIDE) return { full, small: null };
  const k = SMALL_SIDE / side;
  const small = await createImageBitmap(full, {
    resizeWidth: Math.max(1, Math.round(full.width * k)),
    resizeHeight: Math.max(1, Math.round(full.height * k)),
    resizeQuality: 'medium',
  });
  return { full, small };
}

const scope = globalThis as unknown as { document?: unknown; onmessage: unknown; postMessage: (m: unknown, t: Transferable[]) => void };
if (typeof scope.document === 'undefined') {
  scope.onmessage = async (event: MessageEvent<PictureRequest>) => {
    const { id, url } = event.data;
    try {
      const { full, small } = await read(url);
      scope.postMessage({ id, ok: true, full, small } satisfies PictureReply, small ? [full, small] : [full]);
    } catch (err) {
      scope.postMessage({ id, ok: false, message: (err as Error).message } satisfies PictureReply, []);
    }
  };
}
