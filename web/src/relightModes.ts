// The photo set's viewing modes, the ones RTIViewer's users know, per pixel over typed arrays
// (relight.ts encodes what they give for the screen, stereo.ts shows it). Every mode sums the
// contributions of up to MAX_LIGHTS lights, each a unit direction toward the light with y up and
// z toward the camera; the viewer looks down -z, so the view direction is v = (0, 0, 1).
//
// - Default: albedo * max(0, n . l), Lambert's law on the stereo normals.
// - Diffuse gain (Malzbender, Gelb & Wolters, "Polynomial Texture Maps", SIGGRAPH 2001, the
//   "diffuse gain" enhancement RTIViewer offers): a pixel's response L(l) to the light is
//   replaced by one with the same value and slope at its brightest light l0 and g times the
//   curvature. For the PTM's biquadratic, whose slope is zero at l0, that is exactly
//   L'(l) = L(l0) + g (L(l) - L(l0)); for a Lambertian pixel l0 = n and L(l0) = albedo, so
//   L'(l) = albedo * max(0, 1 - g (1 - n . l)): the light fades g times faster as it leaves the
//   normal, which steepens the shading's response to the surface's direction.
// - Specular enhancement (the same paper's "specular enhancement", RTIViewer's kd, ks and
//   exponent): the albedo set to a constant white, and a Blinn-Phong lobe added,
//   kd * max(0, n . l) + ks * max(0, n . h)^exponent with h = (l + v) / |l + v|, zero where the
//   light is behind the surface. The lobe peaks where the light's mirror direction meets the
//   viewer, so fine relief catches glints.
// - Normal unsharp masking (Palma, Corsini, Cignoni, Scopigno & Mudge, "Dynamic shading
//   enhancement for reflectance transformation imaging", ACM JOCCH 2010; RTIViewer's "normals
//   enhancement"): n' = normalise(n + amount * (n - blur(n))), shaded as Default. The blur is a
//   box of half-width `radius` applied twice (a tent, close to a Gaussian), over the object's
//   pixels only, so that the background does not bend the outline's normals.
//
// tests/js/check_relight_modes.mjs checks each mode against a slow per-pixel reference.

export type Vec3 = [number, number, number];
export type RelightMode = 'default' | 'diffuse-gain' | 'specular-enhancement' | 'unsharp-masking';
export const RELIGHT_MODES: RelightMode[] = ['default', 'diffuse-gain', 'specular-enhancement', 'unsharp-masking'];
export const MAX_LIGHTS = 3;

/** How the relit object is drawn: the mode, its lights and every mode's own settings. */
export interface RelightSettings {
  mode: RelightMode;
  lights: Vec3[];
  /** Multiplies what every mode gives (linear). */
  brightness: number;
  /** Diffuse gain: g, 1 = the plain shading. */
  gain: number;
  /** Specular enhancement: the diffuse weight kd, the specular weight ks and the lobe's exponent. */
  diffuse: number;
  specular: number;
  exponent: number;
  /** Normal unsharp masking: the blur's half-width in pixels and how much of the detail is added. */
  radius: number;
  amount: number;
}

export type RelightNumber = Exclude<keyof RelightSettings, 'mode' | 'lights'>;

/** Each number's range (the sliders' too) and step. The defaults were chosen by eye on the
 * shipped vase set and on DiLiGenT's objects: a visible effect that leaves the shape readable. */
export const RELIGHT_RANGES: Record<RelightNumber, { min: number; max: number; step: number }> = {
  brightness: { min: 0.2, max: 3, step: 0.05 },
  gain: { min: 1, max: 10, step: 0.1 },
  diffuse: { min: 0, max: 1, step: 0.05 },
  specular: { min: 0, max: 1.5, step: 0.05 },
  exponent: { min: 1, max: 200, step: 1 },
  radius: { min: 1, max: 40, step: 1 },
  amount: { min: 0, max: 10, step: 0.1 },
};

/** The light the pane starts with: up and to the right, 34 degrees from the camera. */
export const DEFAULT_LIGHT: Vec3 = [0.4, 0.4, Math.sqrt(1 - 0.32)];

export const RELIGHT_DEFAULTS: RelightSettings = {
  mode: 'default',
  lights: [DEFAULT_LIGHT],
  brightness: 1,
  gain: 2,
  diffuse: 0.6,
  specular: 0.6,
  exponent: 40,
  radius: 8,
  amount: 2,
};

/** The surface a mode shades: per pixel, row-major; normals unit (zero off the object), albedo linear. */
export interface Surface {
  width: number;
  height: number;
  mask: Uint8Array;
  normals: Float32Array;
  albedo: Float32Array;
}

/** Saved settings (a reload's, maybe of an older page or edited by hand) made whole and valid. */
export function restoreSettings(saved: unknown): RelightSettings {
  const settings: RelightSettings = { ...RELIGHT_DEFAULTS, lights: [...RELIGHT_DEFAULTS.lights] };
  if (typeof saved !== 'object' || saved === null) return settings;
  const given = saved as Record<string, unknown>;
  if (RELIGHT_MODES.includes(given.mode as RelightMode)) settings.mode = given.mode as RelightMode;
  for (const key of Object.keys(RELIGHT_RANGES) as RelightNumber[]) {
    const value = given[key];
    const { min, max } = RELIGHT_RANGES[key];
    if (typeof value === 'number' && Number.isFinite(value)) settings[key] = Math.min(max, Math.max(min, value));
  }
  if (Array.isArray(given.lights)) {
    const lights = given.lights
      .filter((l): l is Vec3 => Array.isArray(l) && l.length === 3 && l.every(Number.isFinite) && l[2] > 0)
      .slice(0, MAX_LIGHTS)
      .map(unit);
    if (lights.length) settings.lights = lights;
  }
  return settings;
}

export function unit(v: readonly number[]): Vec3 {
  const length = Math.hypot(v[0], v[1], v[2]);
  return length > 0 ? [v[0] / length, v[1] / length, v[2] / length] : [0, 0, 1];
}

/**
 * The object under ``settings``' lights in its mode, linear RGB (3 per pixel, 0 off the object).
 * ``normals`` replaces the surface's own (unsharp masking passes its enhanced ones; shadeFor
 * picks them).
 */
export function shade(surface: Surface, settings: RelightSettings, normals = surface.normals): Float32Array {
  const { width, height, mask, albedo } = surface;
  const count = width * height;
  const out = new Float32Array(3 * count);
  // flat, for the pixel loop: each light's direction and its half vector with the view
  const lights = Float64Array.from(settings.lights.flatMap(unit));
  const halves = Float64Array.from(settings.lights.flatMap((l) => unit(unit(l).map((v, c) => v + (c === 2 ? 1 : 0)))));
  const lightCount = settings.lights.length;
  const { mode, brightness, gain, diffuse: kd, specular: ks, exponent } = settings;
  const specular = mode === 'specular-enhancement';
  const diffuseGain = mode === 'diffuse-gain';
  // below this n . h the lobe is under 1e-6 (under a thousandth of the screen's least step):
  // left out, which spares most pixels the power
  const faint = Math.exp(Math.log(1e-6) / exponent);
  for (let i = 0; i < count; i++) {
    if (!mask[i]) continue;
    const nx = normals[3 * i], ny = normals[3 * i + 1], nz = normals[3 * i + 2];
    let lit = 0, glint = 0;
    for (let k = 0; k < 3 * lightCount; k += 3) {
      const cosine = nx * lights[k] + ny * lights[k + 1] + nz * lights[k + 2];
      if (diffuseGain) {
        lit += Math.max(0, 1 - gain * (1 - cosine));
      } else if (cosine > 0) {
        lit += cosine;
        if (specular) {
          const facing = nx * halves[k] + ny * halves[k + 1] + nz * halves[k + 2];
          if (facing > faint) glint += facing ** exponent;
        }
      }
    }
    if (specular) {
      const grey = brightness * (kd * lit + ks * glint);
      out[3 * i] = out[3 * i + 1] = out[3 * i + 2] = grey;
    } else {
      const scale = brightness * lit;
      for (let c = 0; c < 3; c++) out[3 * i + c] = albedo[3 * i + c] * scale;
    }
  }
  return out;
}

/**
 * Normal unsharp masking: normalise(n + amount * (n - blur(n))) on the object, zero off it.
 * blur is the masked box of half-width ``radius`` applied twice; a normal whose sum vanishes keeps
 * its own direction.
 */
export function unsharpNormals(surface: Surface, radius: number, amount: number): Float32Array {
  const { width, height, mask, normals } = surface;
  const blurred = maskedBoxBlur(maskedBoxBlur(normals, mask, width, height, radius), mask, width, height, radius);
  const out = new Float32Array(normals.length);
  for (let i = 0, count = width * height; i < count; i++) {
    if (!mask[i]) continue;
    const p = 3 * i;
    const x = normals[p] + amount * (normals[p] - blurred[p]);
    const y = normals[p + 1] + amount * (normals[p + 1] - blurred[p + 1]);
    const z = normals[p + 2] + amount * (normals[p + 2] - blurred[p + 2]);
    const length = Math.hypot(x, y, z);
    if (length > 1e-6) {
      out[p] = x / length;
      out[p + 1] = y / length;
      out[p + 2] = z / length;
    } else {
      out.set(normals.subarray(p, p + 3), p);
    }
  }
  return out;
}

/** The mean of 3-vectors over the object's pixels in the (2 radius + 1)-square about each pixel
 * (clipped at the image's edges); zero off the object. */
export function maskedBoxBlur(values: Float32Array, mask: Uint8Array, width: number, height: number, radius: number): Float32Array {
  const count = width * height;
  const packed = new Float32Array(4 * count); // mask * value, and the mask: one box sum for both
  for (let i = 0; i < count; i++) {
    if (!mask[i]) continue;
    packed[4 * i] = values[3 * i];
    packed[4 * i + 1] = values[3 * i + 1];
    packed[4 * i + 2] = values[3 * i + 2];
    packed[4 * i + 3] = 1;
  }
  const r = Math.max(0, Math.round(radius));
  const sums = sumAlongColumns(sumAlongRows(packed, width, height, r), width, height, r);
  const out = new Float32Array(3 * count);
  for (let i = 0; i < count; i++) {
    const weight = sums[4 * i + 3];
    if (!mask[i] || weight <= 0) continue;
    for (let c = 0; c < 3; c++) out[3 * i + c] = sums[4 * i + c] / weight;
  }
  return out;
}

/** Sums of 4-channel ``src`` over the 2r + 1 pixels about each along its row (clipped at the
 * ends): a running sum, so each pixel costs the same whatever r. */
function sumAlongRows(src: Float32Array, width: number, height: number, r: number): Float32Array {
  const out = new Float32Array(src.length);
  for (let row = 0; row < height; row++) {
    const start = 4 * row * width;
    for (let c = 0; c < 4; c++) {
      let sum = 0;
      for (let j = 0; j <= Math.min(r, width - 1); j++) sum += src[start + 4 * j + c];
      for (let j = 0; j < width; j++) {
        out[start + 4 * j + c] = sum;
        if (j + r + 1 < width) sum += src[start + 4 * (j + r + 1) + c];
        if (j - r >= 0) sum -= src[start + 4 * (j - r) + c];
      }
    }
  }
  return out;
}

/** The same along columns, a row at a time (the running sums of all columns kept side by side,
 * so memory is read in order). */
function sumAlongColumns(src: Float32Array, width: number, height: number, r: number): Float32Array {
  const out = new Float32Array(src.length);
  const line = 4 * width;
  const sums = new Float64Array(line);
  for (let row = 0; row <= Math.min(r, height - 1); row++) {
    for (let k = 0; k < line; k++) sums[k] += src[row * line + k];
  }
  for (let row = 0; row < height; row++) {
    out.set(sums, row * line);
    const enter = row + r + 1, leave = row - r;
    if (enter < height) for (let k = 0; k < line; k++) sums[k] += src[enter * line + k];
    if (leave >= 0) for (let k = 0; k < line; k++) sums[k] -= src[leave * line + k];
  }
  return out;
}
