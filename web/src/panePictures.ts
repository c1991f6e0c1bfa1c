// The image pane's pictures (the photo, the channel before and after its filter), read off the
// page's thread in the picture worker (pictureWorker.ts): decoded, with a small copy for a photo
// shown smaller than it is.
import type { PictureReply, PictureRequest } from './pictureWorker';

/** A picture of the pane: decoded, and its small copy where it is larger than SMALL_SIDE. */
export interface Picture {
  full: ImageBitmap | null;
  small: ImageBitmap | null;
  failed: boolean;
}

let pictures: Worker | null = null;
let pictureId = 0;
const reading = new Map<number, (reply: PictureReply) => void>();

/** Read ``url`` into ``picture`` in the picture worker (pictureWorker.ts). */
export async function loadPicture(url: string, picture: Picture): Promise<void> {
  if (!pictures) {
    pictures = new Worker(new URL('./pictureWorker.ts', import.meta.url), { type: 'module' });
    pictures.onmessage = (event: MessageEvent<PictureReply>) => {
      reading.get(event.data.id)?.(event.data);
      reading.delete(event.data.id);
    };
  }
  const id = ++pictureId;
  const reply = await new Promise<PictureReply>((resolve) => {
    reading.set(id, resolve);
    pictures!.postMessage({ id, url: new URL(url, location.href).href } satisfies PictureRequest);
  });
  if (reply.ok) {
    picture.small = reply.small;
    picture.full = reply.full;
  } else {
    picture.failed = true; // tried again when the server answers (retryImages)
  }
}
