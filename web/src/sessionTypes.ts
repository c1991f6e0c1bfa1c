// What a session holds of a photo, shared by what keeps it (state.ts: a reload, the project files,
// the server's projects) and what works on it (the App the open photo's, views.ts each view's):
// its settings with the regions, where the image came from; and the views with their settings.
import type { ImageInfo, PhotoSetInfo, ReconstructParams, StereoParams } from './api.gen';

export type Params = ReconstructParams;
export type Region = Params['concave']['regions'][number];
export type Axis = Region['axis'];

/** Where the current image came from: a shipped example is reopened by name, an upload re-sent. */
export type ImageSource =
  | { kind: 'example'; name: string }
  | { kind: 'upload'; name: string; type: string }
  | { kind: 'initial'; name: string } // the image `shadeform app IMAGE` was started with
  | { kind: 'viewset'; name: string; index: number } // a photo of a shipped view set
  | { kind: 'photoset'; name: string }; // a view that is a photo set (View.photo_set): never reopened as a photo

/** A view that is a photo set: the set the server stored and its photometric stereo's settings. */
export interface ViewPhotoSet {
  info: PhotoSetInfo;
  params: StereoParams;
}

/** One view: a stored photo, where it came from (to reopen it), its angle and its settings; or,
 * with ``photo_set``, a stored photo set (``image`` then names the set: its id, name and size). */
export interface View {
  image: ImageInfo;
  source: ImageSource;
  angle: number;
  params: Params;
  photo_set?: ViewPhotoSet | null;
}

/** What a reload needs to show the views again. */
export interface ViewsSaved {
  views: View[];
  refine_poses: boolean;
  settle: boolean;
  resolution: number | null;
  showParts: boolean;
  /** The view being edited in single-photo mode, if one is. */
  editing: number | null;
}
