// Generated from shadeform.app.schema by `python -m shadeform.app.schema`; do not edit.
// A test (tests/test_app_api.py) fails when this file and the schema disagree.

export type Axis = "x" | "y" | "both";

export type Channel = "luma" | "r" | "g" | "b" | "max";

export type FilterKind = "none" | "gaussian" | "mean" | "median" | "minimum";

export type LightMode = "z" | "slant_tilt" | "estimate";

export type Outline = "mask" | "frame";

export type StereoLights = "file" | "sphere" | "unknown";

/** Smoothing before the solve (:func:`shadeform.preprocess.parse_filter`). */
export interface FilterParams {
  kind: FilterKind;
  /** Gaussian sigma, or the window radius (whole number) of mean, median and minimum. */
  size: number;
}

/** Where the light is: +z, slant/tilt in degrees (``docs/conventions.md``), or estimated. */
export interface LightParams {
  mode: LightMode;
  slant: number;
  tilt: number;
}

/** One concave region: polygon ``[[x, y], ...]`` (x = column, y = row, input pixels). */
export interface ConcaveRegion {
  polygon: [number, number][];
  axis: Axis;
}

/** The CLI's regions JSON, exactly: ``{"regions": [...]}``. */
export interface ConcaveRegions {
  regions: ConcaveRegion[];
}

/** Everything the user sets for one reconstruction. */
export interface ReconstructParams {
  channel: Channel;
  filter: FilterParams;
  light: LightParams;
  /** One of ``Options.solvers``; "auto" is the best measured for the light. */
  solver: string;
  /** One of ``Options.integrators``, or null for the solver's own. */
  integrator: string | null;
  /** Integrability refinement iterations (propagation only). */
  refine: number;
  /** Mesh granularity: pixels per vertex. Changing only this re-meshes without a new solve. */
  step: number;
  /** Reference pixels ``[row, col]`` chosen by the user; the automatic ones are added. */
  references: [number, number][];
  concave: ConcaveRegions;
  /** The user's object mask: base64 of an image file (PNG) of the image's size, non-zero = object (``shadeform.load_mask``'s rule); null for the automatic one. Every solve and export uses it. */
  mask: string | null;
}

/** A reconstruction (or export) of a stored image with these parameters. */
export interface ReconstructRequest {
  image_id: string;
  params: ReconstructParams;
  /** Chosen by the client, echoed in the result: a response older than the newest is stale. */
  request_id: number;
  /** Answer at once with a quick look solved at the mesh's grid (or a coarser one within the solver's pixel budget), unless the full result is already known or the grid is the image's own; the result's ``preview`` says which came. */
  preview: boolean;
}

/** A solver or integrator the library offers (its registry: :func:`shadeform.solvers.available_solvers`, :func:`shadeform.integration.available_integrators`). */
export interface MethodInfo {
  name: string;
  /** One line in the user's words. */
  description: string;
  /** Its own options (``--option NAME=VALUE`` on the command line); absent when it has none. */
  options?: OptionInfo[];
}

/** One option of a solver's (or another registry entry's) own (:class:`shadeform.registry.Option`). */
export interface OptionInfo {
  name: string;
  type: "bool" | "int" | "float" | "str";
  default: boolean | number | string;
  /** One line in the user's words. */
  help: string;
}

/** A mesh format the export endpoint writes (:func:`shadeform.available_formats`). */
export interface FormatInfo {
  suffix: string;
  description: string;
}

/** A shipped example (:data:`shadeform.examples.EXAMPLES`). */
export interface ExampleInfo {
  name: string;
  title: string;
}

/** What an upload may be. */
export interface Limits {
  max_upload_bytes: number;
  max_pixels: number;
  /** Images with more pixels get their quick look on a downsampled copy and their full solve in the background (``/api/solves``: progress, cancel). */
  large_pixels: number;
  /** A photo over ``max_pixels`` but at most this many times it may be opened downsampled to fit (``POST /api/images?fit=true``). */
  fit_factor: number;
}

/** A stored image; ``image_id`` names it in every later request. */
export interface ImageInfo {
  image_id: string;
  name: string;
  width: number;
  height: number;
  /** 1 for a gray file, 3 for colour. */
  channels: number;
  /** Settings the image is best reconstructed with (the examples have them), else null. */
  suggested: ReconstructParams | null;
}

/** What the library offers, the upload limits and the default parameters. */
export interface Options {
  /** "auto" first, then every registered solver. */
  solvers: MethodInfo[];
  integrators: MethodInfo[];
  channels: string[];
  filters: string[];
  formats: FormatInfo[];
  examples: ExampleInfo[];
  /** Photometric stereo's models (``StereoParams.model``), the default first. */
  stereo_models: MethodInfo[];
  photo_set_examples: ExampleInfo[];
  stereo_defaults: StereoParams;
  relief_defaults: ReliefParams;
  /** Shipped view sets: one object photographed from several sides, to fuse. */
  view_set_examples: ExampleInfo[];
  limits: Limits;
  defaults: ReconstructParams;
  /** The image the server was started with (``shadeform app IMAGE``), else null. */
  initial_image: ImageInfo | null;
}

/** A triangle mesh in the convention of ``docs/conventions.md`` ("Meshes"), as base64. */
export interface MeshData {
  vertex_count: number;
  triangle_count: number;
  /** float32 little-endian, 3 per vertex: (x, y, z) = (col, -row, depth) */
  positions: string;
  /** float32 little-endian, 3 per vertex, unit length */
  normals: string;
  /** float32 little-endian, 2 per vertex: u = (col + 0.5) / W, v = 1 - (row + 0.5) / H; empty for a mesh without texture coordinates (a fused model) */
  uvs: string;
  /** uint32 little-endian, 3 per triangle, counter-clockwise seen from +z */
  indices: string;
}

/** One reconstruction: the mesh, and what the library used and found. */
export interface ReconstructResult {
  request_id: number;
  /** True for a quick look solved at the mesh's grid or a coarser one: the full result is still to come. */
  preview: boolean;
  mesh: MeshData;
  /** The object mask as a base64 8-bit grey PNG (255 = object), the image's size; empty in a quick look of a large photo (``info.level``): the full result brings it. */
  mask_png: string;
  /** Unit vector toward the light that was used (given or estimated). */
  light: [number, number, number];
  /** Reference pixels used, ``[row, col]``: the user's, then the automatic ones. */
  references: [number, number][];
  /** Smallest and largest depth on the object, pixel units. */
  depth_range: [number, number];
  /** Seconds per stage: the library's stages, then mesh, encode, total. */
  timings: Record<string, number>;
  /** What ran (the library's ``Reconstruction.info`` plus ``cached``: whether the solve was reused). */
  info: Record<string, unknown>;
}

/** A full-resolution solve running in the background (``/api/solves``). */
export interface SolveJob {
  job_id: string;
  /** The request's ``request_id``, echoed. */
  request_id: number;
  state: "running" | "done" | "cancelled" | "failed";
  /** The stage done last (``timings``' names), ``queued``, ``mesh`` or ``done``. */
  stage: string;
  /** What the solve is doing, in the user's words. */
  stage_text: string;
  /** Rough share of the work done, 0 to 1. */
  fraction: number;
  /** Seconds since it started (to its end, once ended). */
  elapsed: number;
  /** Why it ended without a result: the error, or what cancelled it; else null. */
  detail: string | null;
}

/** Everything the user sets for photometric stereo on a photo set. */
export interface StereoParams {
  /** Where the lights come from: "file" (the set's light file), "sphere" (a shiny sphere in the photos) or "unknown" (read from the photos alone). */
  lights: StereoLights;
  /** The sphere's circle ``[column, row, radius]`` in pixels; null to find it (lights "sphere" only). */
  sphere: [number, number, number] | null;
  /** The photometric model: one of ``Options.stereo_models``. */
  model: string;
  /** One of ``Options.integrators``. */
  integrator: string;
  /** Mesh granularity: pixels per vertex. Changing only this re-meshes without a new solve. */
  step: number;
}

/** Photometric stereo (or its export) on a stored photo set with these parameters. */
export interface StereoRequest {
  photoset_id: string;
  params: StereoParams;
  /** Chosen by the client, echoed in the result: a response older than the newest is stale. */
  request_id: number;
}

/** A photo set the server holds (several photos of one still object, lights moving). */
export interface PhotoSetInfo {
  photoset_id: string;
  name: string;
  /** How many photos. */
  count: number;
  width: number;
  height: number;
  /** Whether the photos have colour. */
  colour: boolean;
  /** The photos' file names, in the set's order. */
  names: string[];
  /** Whether a light file came with the photos. */
  lights_file: boolean;
  /** Whether a file of the lights' strengths came with them. */
  intensities_file: boolean;
  /** Whether a mask came with them. */
  mask: boolean;
  /** Settings to start from. */
  suggested: StereoParams;
}

/** Photometric stereo's result: the mesh, the maps to view and relight, what was found. */
export interface StereoResult {
  request_id: number;
  mesh: MeshData;
  /** The object mask as a base64 8-bit grey PNG (255 = object). */
  mask_png: string;
  /** Normals as a base64 8-bit RGB PNG, ``(n + 1) / 2`` per channel (x right, y up, z toward the viewer), black off the object. */
  normals_png: string;
  /** Albedo as a base64 8-bit RGB PNG, sRGB-encoded, white = ``albedo_white``. */
  albedo_png: string;
  /** The linear albedo shown as white (its 99.5th percentile). */
  albedo_white: number;
  /** Each normal's confidence in [0, 1] as a base64 8-bit grey PNG. */
  confidence_png: string;
  /** The unit direction toward each photo's light that was used (given, from the sphere or read from the photos). */
  lights: [number, number, number][];
  /** The sphere's circle ``[column, row, radius]`` the lights were read from, if they were. */
  sphere: [number, number, number] | null;
  /** Photos (0-based) left out: they contradict the others. */
  photos_dropped: number[];
  /** Photos whose light was brighter (factor > 1) or dimmer than said, and the factor. */
  photos_rescaled: [number, number][];
  /** The lights' mean direction (to shade the model). */
  light: [number, number, number];
  /** Smallest and largest depth on the object, pixel units. */
  depth_range: [number, number];
  /** Seconds per stage. */
  timings: Record<string, number>;
  /** What ran (the library's ``Reconstruction.info`` plus ``cached``). */
  info: Record<string, unknown>;
}

/** One view of a fusion: a stored photo (or photo set), its turntable angle and how it is reconstructed. */
export interface FuseView {
  /** The view's stored photo; null when the view is a photo set. */
  image_id: string | null;
  /** A stored photo set (``POST /api/photosets``) instead of a photo: several photos of this view under different lights, solved by photometric stereo as ``/api/stereo`` solves it (``stereo``; cache included). Its shape needs no hints: it is never solved again for settling, and ``params`` may not draw concave regions on it. */
  photo_set_id: string | null;
  /** Turntable angle in degrees: the object turned by it about the camera's vertical axis, right-handed about +y (``docs/conventions.md``, "Turntable views"). */
  angle: number;
  /** The view's reconstruction, exactly as ``/api/reconstruct`` makes it (its ``step`` is the finest grid of its partial model). */
  params: ReconstructParams;
  /** A photo-set view's photometric stereo, as ``/api/stereo`` takes it (its ``step`` is the finest grid of its partial model); unused for a photo. */
  stereo: StereoParams;
}

/** Several views of one object fused into one closed model (or its export). */
export interface FuseRequest {
  /** Two to 24 views. */
  views: FuseView[];
  /** Correct the poses and depth offsets so that the views agree. */
  refine_poses: boolean;
  /** Read each view's unsure areas (what its photo leaves open: ``info['unsure']``) as concave where the other views' silhouettes say so (``shadeform.fusion.settle``). */
  settle: boolean;
  /** Voxel edge in pixels; null: 1, or coarser for a big object (the library's default). */
  resolution: number | null;
  /** Chosen by the client, echoed in the result: a response older than the newest is stale. */
  request_id: number;
}

/** What one view of a fusion was reconstructed with. */
export interface FusedView {
  /** The view's object mask as a base64 8-bit grey PNG (255 = object). */
  mask_png: string;
  /** Unit vector toward the light that was used. */
  light: [number, number, number];
  /** Whether its reconstruction was reused, not solved for this request. */
  cached: boolean;
  /** Unsure areas of the view's photo that the other views showed to be concave: its partial model and the fused one read them so (add them to the view's regions to keep them). */
  settled: ConcaveRegion[];
  /** The 4x4 matrix (rows) that took the view's own mesh (``(col, -row, depth)``) to its partial model in the object frame: its refined pose and depth offset. */
  transform: number[][];
  /** How well the fused model keeps the view's outline: the IoU of its projection into the view with the view's mask (``shadeform.fusion.outlines.outline_iou``); below 0.95 parts the view shows are missing or the model reaches past them. */
  outline_iou: number;
}

/** The fused model, and each view's partial model where the fusion placed it. */
export interface FuseResult {
  request_id: number;
  /** The fused model: closed, outward-facing, in the object frame (the frame of the view at angle 0, x = 0 on the turntable axis), pixel units; no texture coordinates. */
  mesh: MeshData;
  /** Each view's own mesh (on a coarser grid, to stay light), moved into the object frame where the fusion placed it; in the views' order. */
  parts: MeshData[];
  /** Per view, in order. */
  views: FusedView[];
  /** The turntable axis's column in the photos (the object frame's x = 0). */
  axis: number;
  /** The fused model's volume, cubic pixels. */
  volume: number;
  /** Whether the fused model is closed (every edge shared by two faces). */
  watertight: boolean;
  /** Other placements the photos fit about as well as the fused model's (``shadeform.fusion.Rival``): per placement, per view the degrees it is turned from where the model has it (0: not turned). Not empty: the photos do not decide, and the model may be wrong. */
  rivals: number[][];
  /** Whether the views fix the object's depth (``shadeform.fusion.Placement.depth_fixed``): false when they all look along one line (from opposite sides only), and the model's thickness rests on each photo's shading alone. */
  depth_fixed: boolean;
  /** Seconds per stage: reconstruct (the views solved anew), place, solid, parts, encode, total. */
  timings: Record<string, number>;
  /** What ran: ``resolution`` (the voxel edge used), ``refine_poses``, ``settle``, ``cached`` (whether the fusion was reused). */
  info: Record<string, unknown>;
}

/** A view set the server opened: its photos (stored images) and their turntable angles. */
export interface ViewSetInfo {
  name: string;
  /** One stored image per view, in order. */
  images: ImageInfo[];
  /** Each view's turntable angle in degrees. */
  angles: number[];
}

/** The automatic object mask of a stored image, or the one of a threshold (:func:`shadeform.preprocess.object_mask`). */
export interface AutoMaskRequest {
  channel: Channel;
  /** Object = pixels above it (below it with ``dark``), the largest part that is not mostly frame border, holes filled; null for the automatic mask. */
  threshold: number | null;
  /** The object is darker than its background; null: decided from the image (with a threshold: false). */
  dark: boolean | null;
}

/** The object under the user's clicks (:func:`shadeform.masks.segment_from_seeds`). */
export interface SeedMaskRequest {
  channel: Channel;
  /** Pixels ``[row, col]`` on the object. */
  inside: [number, number][];
  /** Pixels ``[row, col]`` on the background. */
  outside: [number, number][];
  /** Each click marks a disk of this radius, pixels. */
  radius: number;
}

/** The object inside a box the user drew (:func:`shadeform.masks.segment_from_box`). */
export interface BoxMaskRequest {
  channel: Channel;
  /** ``[top, left, bottom, right]`` in pixels, bottom and right exclusive. */
  box: [number, number, number, number];
}

/** A mask file the user loads, to be checked against the image and made the app's PNG. */
export interface MaskFileRequest {
  /** base64 of the file's bytes (PNG, TIFF, BMP, ...); non-zero = object. */
  data: string;
}

/** An object mask made or checked by the server. */
export interface MaskResult {
  /** The mask as a base64 8-bit grey PNG (255 = object), the image's size. */
  mask_png: string;
  /** How many pixels are object. */
  pixels: number;
  /** The threshold nearest to this mask (a place to start a threshold slider), in the channel's units; null when it did not come from one. */
  threshold: number | null;
  /** Whether the object is darker than its background. */
  dark: boolean;
  /** One line in the user's words saying what was found. */
  note: string;
  /** How sure the mask is, 0 to 1 (the agreement of the ways of finding it); null for a threshold's or a file's mask. Below ``shadeform.masks.LOW_CONFIDENCE`` the note says it is doubtful. */
  confidence: number | null;
}

/** A print's options (:func:`shadeform.relief`); the server checks them (:func:`shadeform.solid.check_options`) and says what is wrong in one line. */
export interface ReliefParams {
  /** Longest side of the outline, mm (exact). */
  width_mm: number;
  /** Relief depth, lowest to highest point, mm. */
  height_mm: number;
  /** Flat base under the relief's lowest point, mm. */
  base_mm: number;
  /** Walls along the object's outline, or the frame. */
  outline: Outline;
  /** Bas-relief compression in [0, 1]; 0 scales linearly. */
  compress: number;
  /** Engrave instead of emboss. */
  invert: boolean;
  /** A flat rim around the outline, mm; 0 for none. */
  border_mm: number;
  /** The thinnest wall the printer makes, mm. */
  min_wall_mm: number;
  /** Triangle budget (at least 12); null: two triangles per pixel. */
  max_triangles: number | null;
}

/** A print-ready solid of a stored image's reconstruction with these parameters. */
export interface ReliefRequest {
  image_id: string;
  params: ReconstructParams;
  relief: ReliefParams;
  /** Chosen by the client, echoed in the result. */
  request_id: number;
}

/** A print-ready solid of a stored photo set's photometric stereo with these parameters. */
export interface StereoReliefRequest {
  photoset_id: string;
  params: StereoParams;
  relief: ReliefParams;
  /** Chosen by the client, echoed in the result. */
  request_id: number;
}

/** The solid, in millimetres, and its measures. */
export interface ReliefResult {
  request_id: number;
  /** The closed solid, mm: x along the image's columns, y up the image, base on z = 0; no texture coordinates. */
  mesh: MeshData;
  /** Extent along x, y, z, mm (z: base plus relief). */
  size_mm: [number, number, number];
  volume_mm3: number;
  triangle_count: number;
  /** Farthest the printed top is from the full-resolution relief. */
  deviation_mm: number;
  /** One image pixel in the print, mm. */
  pixel_mm: number;
  /** Seconds: reconstruct (if solved), relief, encode, total. */
  timings: Record<string, number>;
  /** ``cached``: the model was reused; ``reused``: the solid too. */
  info: Record<string, unknown>;
}

/** One texture map, small, with what its file holds. */
export interface MapPreview {
  /** normal_opengl, normal_directx, height, ambient_occlusion, curvature, or a photo set's albedo. */
  name: string;
  /** A preview: base64 8-bit PNG, at most 256 pixels on a side. */
  png: string;
  /** Bits per sample of the map's file in the zip. */
  bits: number;
  /** What the map's values mean. */
  legend: string;
}

/** Previews of every texture map of a reconstruction (:func:`shadeform.maps`). */
export interface MapsResult {
  request_id: number;
  /** The maps' full width in pixels (the image's). */
  width: number;
  height: number;
  maps: MapPreview[];
  /** Seconds: reconstruct (if solved), maps, encode, total. */
  timings: Record<string, number>;
  /** ``cached``: the model was reused; ``reused``: the maps too. */
  info: Record<string, unknown>;
}

/** Where a project's photo came from, to open it again: a shipped example (by name), an upload, the image the server was started with, photo ``index`` of a shipped view set, or a photo set (a view that is one: ``ProjectViewEntry.photo_set``). */
export interface ProjectSource {
  kind: "example" | "upload" | "initial" | "viewset" | "photoset";
  name: string;
  /** An upload's MIME type. */
  type: string | null;
  /** The photo's place in its view set. */
  index: number | null;
}

/** A project's photo: a project file carries its bytes; the server's projects name the image in the server's session store instead (``info.image_id``), which keeps the bytes. */
export interface ProjectImage {
  name: string;
  /** The file's MIME type. */
  type: string;
  /** base64 of the image file (project files). */
  data: string | null;
  /** A shipped example's name. */
  example: string | null;
  source: ProjectSource | null;
  /** The image as the server stored it (its id in the session store). */
  info: ImageInfo | null;
}

/** How the client shows the model and the image (the project file's ``view``). */
export interface DisplaySettings {
  wireframe: boolean;
  normalColours: boolean;
  texture: boolean;
  maskOverlay: boolean;
  lightArrow: boolean;
}

/** A photo set in a project: the set the server stored and the user's settings. */
export interface ProjectPhotoSet {
  info: PhotoSetInfo;
  params: StereoParams;
}

/** One view in a project: its stored photo, where the photo came from, angle and settings; or a stored photo set (``photo_set``; ``image`` then names the set, its ``image_id`` the set's id). */
export interface ProjectViewEntry {
  image: ImageInfo;
  source: ProjectSource;
  angle: number;
  params: ReconstructParams;
  /** The view is this photo set and its photometric stereo (``FuseView.photo_set_id``); null: a photo. */
  photo_set: ProjectPhotoSet | null;
}

/** The views in a project (several sides of one object, fused) and the fusion's settings. */
export interface ProjectViews {
  views: ProjectViewEntry[];
  /** Correct the poses so that the views agree (``FuseRequest.refine_poses``). */
  refine_poses: boolean;
  settle: boolean;
  resolution: number | null;
  showParts: boolean;
  /** The view being edited in single-photo mode, if one is. */
  editing: number | null;
}

/** A project as the client's project file holds it: one photo (``image`` and ``params``), a photo set (``photo_set``) or views (``views``), with the display settings. */
export interface ProjectDocument {
  format: "shadeform-project";
  /** 1: the only version so far. */
  version: number;
  /** Shown in Open recent; null: what the project is of. */
  name: string | null;
  image: ProjectImage | null;
  params: ReconstructParams | null;
  view: DisplaySettings;
  photo_set: ProjectPhotoSet | null;
  views: ProjectViews | null;
}

/** A project the server keeps, as Open recent lists it. */
export interface ProjectInfo {
  id: string;
  name: string;
  /** What the project is of: the photo's name, the photo set's, the views'. */
  image: string;
  kind: "photo" | "photo_set" | "views";
  /** Seconds since the epoch. */
  created: number;
  /** Seconds since the epoch, when it was last saved. */
  updated: number;
}

/** The projects the server keeps, the most recently updated first. */
export interface ProjectList {
  projects: ProjectInfo[];
}

/** A project the server keeps, with its document. */
export interface Project {
  id: string;
  name: string;
  /** What the project is of: the photo's name, the photo set's, the views'. */
  image: string;
  kind: "photo" | "photo_set" | "views";
  /** Seconds since the epoch. */
  created: number;
  /** Seconds since the epoch, when it was last saved. */
  updated: number;
  document: ProjectDocument;
}

/** Every error response: one line saying what was wrong and what to do. */
export interface ErrorBody {
  detail: string;
}
