// The one photo open in single-photo mode, shared by the App's panels (main.ts makes it): the
// image and where it came from, its settings, the last result drawn, and its model's state.
import * as api from './api';
import type { ImageInfo, Options, ReconstructRequest, ReconstructResult } from './api.gen';
import type { Sources } from './imagePane';
import { ModelState } from './modelState';
import type { ImageSource, Params } from './sessionTypes';

export class Photo {
  image: ImageInfo | null = null;
  source: ImageSource | null = null;
  /** An upload's original bytes (for re-upload and projects). */
  imageBytes: Blob | null = null;
  params: Params;
  /** The last result drawn (a quick look's until the full one comes). */
  result: ReconstructResult | null = null;
  /** The camera fits the next model drawn (another image, another object in the mask). */
  refitNext = true;
  /** The server's start-up image last shown: a server started anew with an image shows it. */
  initialId: string | null = null;
  /** The one photo's model (the photo set's and the views' are theirs). */
  readonly model: ModelState;

  constructor(
    private readonly options: Options,
    modelChanged: () => void,
  ) {
    this.model = new ModelState(modelChanged);
    this.params = structuredClone(options.defaults);
  }

  /** The reconstruction request for the current settings. */
  request(requestId: number): ReconstructRequest {
    return {
      image_id: this.image!.image_id, params: structuredClone(this.params), request_id: requestId, preview: false,
    };
  }

  /** Whether the open photo is large: its full solve runs in the background, with progress. */
  large(): boolean {
    return !!this.image && this.image.width * this.image.height > this.options.limits.large_pixels;
  }

  /** The image pane's pictures of the photo: as it is, its channel before and after the filter. */
  sources(): Sources {
    const id = this.image!.image_id;
    return {
      photo: api.photoUrl(id),
      before: api.channelUrl(id, this.params.channel, { kind: 'none', size: this.params.filter.size }),
      after: api.channelUrl(id, this.params.channel, this.params.filter),
    };
  }

  /** The photo's name without its suffix, for the files saved from it. */
  stem(): string {
    const name = this.image?.name ?? 'shadeform';
    return name.replace(/\.[^.]+$/, '').replace(/[^\w.-]+/g, '_') || 'shadeform';
  }
}

/** Why an image id stopped working, in the user's words. */
export function forgotten(name: string): string {
  return `The server no longer had ${name} (it was restarted without its sessions, or let it go)`;
}
