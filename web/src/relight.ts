// The photo set's relighting, per pixel (stereo.ts shows it): the normals, albedo and confidence
// the server sends as PNGs decoded into maps, and the object drawn from them under a light the
// user moves, in the viewing mode the user picks (relightModes.ts): linear light, sRGB on screen.
import type { StereoResult } from './api.gen';
import { shade, unsharpNormals, type RelightSettings } from './relightModes';

/** sRGB decoding (8-bit code -> linear) and encoding (linear, 4096 steps -> 8-bit code). */
const SRGB_TO_LINEAR = Float32Array.from({ length: 256 }, (_, i) => {
  const v = i / 255;
  return v <= 0.04045 ? v / 12.92 : ((v + 0.055) / 1.055) ** 2.4;
});
const ENCODE_STEPS = 4096;
const LINEAR_TO_SRGB = Uint8ClampedArray.from({ length: ENCODE_STEPS + 1 }, (_, i) => {
  const v = i / ENCODE_STEPS;
  return Math.round(255 * (v <= 0.0031308 ? 12.92 * v : 1.055 * v ** (1 / 2.4) - 0.055));
});

/** The decoded maps of one result, per pixel (row-major, the photos' size). */
export interface Maps {
  width: number;
  height: number;
  mask: Uint8Array;
  normals: Float32Array; // 3 per pixel, unit
  albedo: Float32Array; // 3 per pixel, linear, 1 = the server's albedo_white
  normalsImage: ImageData;
  albedoImage: ImageData;
  confidenceImage: ImageData;
  /** The object's centre and half-size in pixels: where a drag over the image points the light. */
  centre: [number, number];
  radius: number;
}

async function decodePng(base64: string): Promise<ImageData> {
  const image = new Image();
  image.src = `data:image/png;base64,${base64}`;
  await image.decode();
  const canvas = document.createElement('canvas');
  canvas.width = image.naturalWidth;
  canvas.height = image.naturalHeight;
  const context = canvas.getContext('2d', { willReadFrequently: true })!;
  context.drawImage(image, 0, 0);
  return context.getImageData(0, 0, canvas.width, canvas.height);
}

export async function decodeMaps(result: StereoResult): Promise<Maps> {
  const [maskImage, normalsImage, albedoImage, confidenceImage] = await Promise.all(
    [result.mask_png, result.normals_png, result.albedo_png, result.confidence_png].map(decodePng),
  );
  const { width, height } = normalsImage;
  const count = width * height;
  const mask = new Uint8Array(count);
  const normals = new Float32Array(3 * count);
  const albedo = new Float32Array(3 * count);
  let top = height, bottom = -1, left = width, right = -1;
  for (let i = 0; i < count; i++) {
    if (maskImage.data[4 * i] < 128) continue;
    mask[i] = 1;
    const nx = normalsImage.data[4 * i] / 127.5 - 1;
    const ny = normalsImage.data[4 * i + 1] / 127.5 - 1;
    const nz = normalsImage.data[4 * i + 2] / 127.5 - 1;
    const length = Math.hypot(nx, ny, nz) || 1;
    normals[3 * i] = nx / length;
    normals[3 * i + 1] = ny / length;
    normals[3 * i + 2] = nz / length;
    for (let c = 0; c < 3; c++) albedo[3 * i + c] = SRGB_TO_LINEAR[albedoImage.data[4 * i + c]];
    const row = Math.floor(i / width), col = i - row * width;
    top = Math.min(top, row);
    bottom = Math.max(bottom, row);
    left = Math.min(left, col);
    right = Math.max(right, col);
  }
  if (bottom < 0) [top, bottom, left, right] = [0, height - 1, 0, width - 1];
  // the maps shown as they are, off the object dark
  for (const shown of [normalsImage, albedoImage, confidenceImage]) {
    for (let i = 0; i < count; i++) {
      if (!mask[i]) shown.data.set([24, 26, 31, 255], 4 * i);
    }
  }
  return {
    width,
    height,
    mask,
    normals,
    albedo,
    normalsImage,
    albedoImage,
    confidenceImage,
    centre: [(left + right) / 2, (top + bottom) / 2],
    radius: Math.max(right - left, bottom - top, 2) / 2,
  };
}

/** A light direction from a point on the unit disc (the hemisphere seen from the camera). */
export function lightFromDisc(x: number, y: number): [number, number, number] {
  const r = Math.hypot(x, y);
  const limit = 0.985; // at most 80 degrees from the camera: a grazing light shows nothing
  if (r > limit) [x, y] = [(x / r) * limit, (y / r) * limit];
  return [x, y, Math.sqrt(Math.max(0, 1 - x * x - y * y))];
}

/** Unsharp masking's normals of each maps at the radius and amount last asked for: a drag of
 * the light reuses them. */
const enhanced = new WeakMap<Maps, { radius: number; amount: number; normals: Float32Array }>();

/** The object in ``settings``' mode under its lights (relightModes.ts), sRGB-encoded. */
export function relight(maps: Maps, settings: RelightSettings): ImageData {
  let normals = maps.normals;
  if (settings.mode === 'unsharp-masking') {
    const { radius, amount } = settings;
    let kept = enhanced.get(maps);
    if (!kept || kept.radius !== radius || kept.amount !== amount) {
      kept = { radius, amount, normals: unsharpNormals(maps, radius, amount) };
      enhanced.set(maps, kept);
    }
    normals = kept.normals;
  }
  const linear = shade(maps, settings, normals);
  const { width, height, mask } = maps;
  const out = new ImageData(width, height);
  const data = out.data;
  for (let i = 0, count = width * height; i < count; i++) {
    const p = 4 * i;
    data[p + 3] = 255;
    if (!mask[i]) {
      data[p] = 24;
      data[p + 1] = 26;
      data[p + 2] = 31;
      continue;
    }
    for (let c = 0; c < 3; c++) {
      const v = linear[3 * i + c]; // NaN (never made) would show black, not garbage
      data[p + c] = v > 0 ? LINEAR_TO_SRGB[Math.min(ENCODE_STEPS, Math.round(v * ENCODE_STEPS))] : 0;
    }
  }
  return out;
}
