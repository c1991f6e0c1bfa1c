// A Web Worker that reads a mask PNG into bits and draws its tinted layer, off the page's thread:
// a 12 Mpx photo's mask is 12 million pixels to read back from a canvas and to tint, hundreds of
// milliseconds on the page. The bits come back transferred, the layer as an ImageBitmap.
import { MASK_EDGE, MASK_FILL } from './maskColours';

export interface MaskDecodeRequest {
  id: number;
  bytes: ArrayBuffer;
  width: number;
  height: number;
}

export type MaskDecodeReply =
  | { id: number; ok: true; bits: Uint8Array; layer: ImageBitmap; small: ImageBitmap | null }
  | { id: number; ok: false; message: string };

/** Long side of a large mask's small layer: the image pane's small photo's (pictureWorker.ts). */
const SMALL_SIDE = 2048;

async function decode({ bytes, width, height }: MaskDecodeRequest): Promise<{ bits: Uint8Array; layer: ImageBitmap; small: ImageBitmap | null }> {
  const bitmap = await createImageBitmap(new Blob([bytes], { type: 'image/png' }));
  if (bitmap.width !== width || bitmap.height !== height) {
    throw new Error(`mask is ${bitmap.width}x${bitmap.height} but the image is ${width}x${height}; give a mask of the image's size`);
  }
  const canvas = new OffscreenCanvas(width, height);
  const ctx = canvas.getContext('2d', { willReadFrequently: true })!;
  ctx.drawImage(bitmap, 0, 0);
  bitmap.close();
  const data = ctx.getImageData(0, 0, width, height).data;
  const bits = new Uint8Array(width * height);
  for (let i = 0; i < bits.length; i++) bits[i] = data[4 * i] > 127 ? 1 : 0;
  // the layer: as paintMask draws it (object tinted, its edge bright, background transparent)
  const tint = new ImageData(width, height);
  const out = tint.data;
  for (let r = 0; r < height; r++) {
    for (let c = 0; c < width; c++) {
      const i = r * width + c;
      if (!bits[i]) continue;
      const edge = c === 0 || r === 0 || c === width - 1 || r === height - 1 || !bits[i - 1] || !bits[i + 1] || !bits[i - width] || !bits[i + width];
      out.set(edge ? MASK_EDGE : MASK_FILL, 4 * i);
    }
  }
  const side = Math.max(width, height);
  const k = SMALL_SIDE / side;
  const small =
    side > SMALL_SIDE
      ? await createImageBitmap(tint, {
          resizeWidth: Math.max(1, Math.round(width * k)),
          resizeHeight: Math.max(1, Math.round(height * k)),
          resizeQuality: 'medium',
        })
      : null;
  return { bits, layer: await createImageBitmap(tint), small };
}

const scope = globalThis as unknown as { onmessage: unknown; postMessage: (m: unknown, t: Transferable[]) => void };
scope.onmessage = async (event: MessageEvent<MaskDecodeRequest>) => {
  const { id } = event.data;
  try {
    const { bits, layer, small } = await decode(event.data);
    const moved: Transferable[] = [bits.buffer, layer, ...(small ? [small] : [])];
    scope.postMessage({ id, ok: true, bits, layer, small } satisfies MaskDecodeReply, moved);
  } catch (err) {
    scope.postMessage({ id, ok: false, message: (err as Error).message } satisfies MaskDecodeReply, []);
  }
};
