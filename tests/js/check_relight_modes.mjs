// Unit checks of the app's viewing modes (web/src/relightModes.ts) against slow, per-pixel
// references written from the formulas in that module's header, plus properties each mode must
// have. tests/test_relight_modes.py compiles the module to plain JavaScript with esbuild and runs
//
//   node tests/js/check_relight_modes.mjs relightModes.mjs
//   -> one JSON line: {"check name": null (passed) or "what went wrong", ...}
const modes = await import(new URL(process.argv[2], `file://${process.cwd()}/`).href);
const { shade, unsharpNormals, maskedBoxBlur, restoreSettings, RELIGHT_DEFAULTS } = modes;

// ------------------------------------------------------------------------ surfaces

/** A hemisphere (radius r px) with ripples on it, on a size x size image; grey-ish albedo. */
function bumpySphere(size = 48, r = 20, ripple = 0.25) {
  const count = size * size;
  const mask = new Uint8Array(count);
  const normals = new Float32Array(3 * count);
  const albedo = new Float32Array(3 * count);
  const c = (size - 1) / 2;
  for (let row = 0; row < size; row++) {
    for (let col = 0; col < size; col++) {
      const x = (col - c) / r, y = -(row - c) / r;
      if (x * x + y * y >= 0.95) continue;
      const i = row * size + col;
      mask[i] = 1;
      let n = [x + ripple * Math.sin(2.1 * col), y + ripple * Math.cos(1.7 * row), Math.sqrt(1 - x * x - y * y)];
      n = normalise(n);
      normals.set(n, 3 * i);
      albedo.set([0.8, 0.5 + 0.3 * (col / size), 0.3], 3 * i);
    }
  }
  return { width: size, height: size, mask, normals, albedo };
}

/** Every pixel on the object with the same normal (a tilted plane), a hole in the middle. */
function flatField(size = 32, normal = normalise([0.3, -0.2, 0.9])) {
  const count = size * size;
  const mask = new Uint8Array(count).fill(1);
  for (let row = 12; row < 16; row++) for (let col = 10; col < 20; col++) mask[row * size + col] = 0;
  const normals = new Float32Array(3 * count);
  const albedo = new Float32Array(3 * count).fill(0.6);
  for (let i = 0; i < count; i++) if (mask[i]) normals.set(normal, 3 * i);
  return { width: size, height: size, mask, normals, albedo };
}

// ------------------------------------------------------------------------ references

const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
function normalise(v) {
  const length = Math.hypot(...v);
  return v.map((x) => x / length);
}
const normalAt = (normals, i) => [normals[3 * i], normals[3 * i + 1], normals[3 * i + 2]];

/** One pixel's linear RGB, written straight from the formulas. */
function referencePixel(normal, albedo, settings) {
  const view = [0, 0, 1];
  let sum = [0, 0, 0];
  for (const light of settings.lights.map(normalise)) {
    const cosine = dot(normal, light);
    if (settings.mode === 'diffuse-gain') {
      const value = Math.max(0, 1 - settings.gain * (1 - cosine)); // L(l0) + g (L(l) - L(l0)), per unit albedo
      sum = sum.map((s, c) => s + albedo[c] * value);
    } else if (settings.mode === 'specular-enhancement') {
      if (cosine <= 0) continue;
      const half = normalise([light[0] + view[0], light[1] + view[1], light[2] + view[2]]);
      const value = settings.diffuse * cosine + settings.specular * Math.max(0, dot(normal, half)) ** settings.exponent;
      sum = sum.map((s) => s + value); // albedo a constant white
    } else {
      sum = sum.map((s, c) => s + albedo[c] * Math.max(0, cosine));
    }
  }
  return sum.map((s) => s * settings.brightness);
}

function referenceShade(surface, settings, normals = surface.normals) {
  const out = new Float32Array(3 * surface.width * surface.height);
  for (let i = 0; i < surface.width * surface.height; i++) {
    if (!surface.mask[i]) continue;
    const albedo = [surface.albedo[3 * i], surface.albedo[3 * i + 1], surface.albedo[3 * i + 2]];
    out.set(referencePixel(normalAt(normals, i), albedo, settings), 3 * i);
  }
  return out;
}

/** The mean over the object's pixels of the (2r + 1)-square window, by looking at every one. */
function referenceBlur(values, mask, width, height, r) {
  const out = new Float32Array(values.length);
  for (let row = 0; row < height; row++) {
    for (let col = 0; col < width; col++) {
      if (!mask[row * width + col]) continue;
      const sum = [0, 0, 0];
      let n = 0;
      for (let y = Math.max(0, row - r); y <= Math.min(height - 1, row + r); y++) {
        for (let x = Math.max(0, col - r); x <= Math.min(width - 1, col + r); x++) {
          const j = y * width + x;
          if (!mask[j]) continue;
          for (let c = 0; c < 3; c++) sum[c] += values[3 * j + c];
          n += 1;
        }
      }
      out.set(sum.map((s) => s / n), 3 * (row * width + col));
    }
  }
  return out;
}

function referenceUnsharp(surface, r, amount) {
  const { width, height, mask, normals } = surface;
  const blurred = referenceBlur(referenceBlur(normals, mask, width, height, r), mask, width, height, r);
  const out = new Float32Array(normals.length);
  for (let i = 0; i < width * height; i++) {
    if (!mask[i]) continue;
    const n = normalAt(normals, i), b = normalAt(blurred, i);
    out.set(normalise(n.map((v, c) => v + amount * (v - b[c]))), 3 * i);
  }
  return out;
}

// ------------------------------------------------------------------------ checks

function maxDifference(a, b) {
  if (a.length !== b.length) return Infinity;
  let worst = 0;
  for (let i = 0; i < a.length; i++) worst = Math.max(worst, Number.isNaN(a[i] - b[i]) ? Infinity : Math.abs(a[i] - b[i]));
  return worst;
}

function close(what, got, want, tolerance = 1e-5) {
  const difference = maxDifference(got, want);
  if (!(difference <= tolerance)) throw new Error(`${what}: off by ${difference} (tolerance ${tolerance})`);
}

const settings = (patch) => ({ ...restoreSettings(null), ...patch });
const twoLights = [normalise([0.5, 0.3, 0.8]), normalise([-0.6, -0.1, 0.7])];

const checks = {
  'each mode matches the reference'() {
    const surface = bumpySphere();
    for (const mode of ['default', 'diffuse-gain', 'specular-enhancement', 'unsharp-masking']) {
      const s = settings({ mode, lights: twoLights, brightness: 1.3, gain: 4, exponent: 25, radius: 3, amount: 2.5 });
      const normals = mode === 'unsharp-masking' ? referenceUnsharp(surface, s.radius, s.amount) : surface.normals;
      const fast = shade(surface, s, mode === 'unsharp-masking' ? unsharpNormals(surface, s.radius, s.amount) : surface.normals);
      close(mode, fast, referenceShade(surface, s, normals));
    }
  },
  'the masked blur matches the reference at every radius'() {
    // inside the image, and cut by its edges (the first and last pixels of a line on the object)
    for (const sphere of [18, 30]) {
      const surface = bumpySphere(40, sphere);
      for (const r of [0, 1, 4, 25, 60]) {
        const { normals, mask } = surface;
        close(`sphere ${sphere}, radius ${r}`, maskedBoxBlur(normals, mask, 40, 40, r), referenceBlur(normals, mask, 40, 40, r));
      }
    }
  },
  'unsharp masking of a flat normal field is the identity'() {
    const surface = flatField();
    for (const [r, amount] of [[1, 1], [5, 3], [40, 10]]) close(`radius ${r} amount ${amount}`, unsharpNormals(surface, r, amount), surface.normals, 1e-6);
  },
  'unsharp masking with no amount is the identity, and more amount bends the ripples further'() {
    const surface = bumpySphere();
    close('amount 0', unsharpNormals(surface, 4, 0), surface.normals, 1e-6);
    const deviation = (normals) => {
      let sum = 0;
      for (let i = 0; i < surface.mask.length; i++) if (surface.mask[i]) sum += Math.acos(Math.min(1, dot(normalAt(normals, i), normalAt(surface.normals, i))));
      return sum;
    };
    const one = deviation(unsharpNormals(surface, 4, 1)), three = deviation(unsharpNormals(surface, 4, 3));
    if (!(one > 0 && three > 1.5 * one)) throw new Error(`deviations ${one} (amount 1), ${three} (amount 3)`);
  },
  'specular enhancement peaks where the reflected light meets the viewer'() {
    const surface = bumpySphere(101, 48, 0); // a smooth hemisphere
    const light = normalise([0.5, 0.2, 0.8]);
    const out = shade(surface, settings({ mode: 'specular-enhancement', lights: [light], diffuse: 0, specular: 1, exponent: 60 }));
    let best = 0;
    for (let i = 1; i < surface.mask.length; i++) if (out[3 * i] > out[3 * best]) best = i;
    const n = normalAt(surface.normals, best);
    // the mirror direction of the light about the brightest pixel's normal: toward the camera
    const cosine = dot(n, light);
    const reflected = light.map((l, c) => 2 * cosine * n[c] - l);
    const degrees = (Math.acos(Math.min(1, reflected[2])) * 180) / Math.PI;
    if (!(degrees < 2.5)) throw new Error(`the brightest pixel reflects the light ${degrees.toFixed(2)} degrees from the viewer`);
    if (!(Math.abs(out[3 * best] - 1) < 1e-3)) throw new Error(`the peak is ${out[3 * best]}, not ks = 1`);
  },
  'specular enhancement is grey, whatever the albedo'() {
    const surface = bumpySphere();
    const out = shade(surface, settings({ mode: 'specular-enhancement' }));
    for (let i = 0; i < surface.mask.length; i++) {
      if (out[3 * i] !== out[3 * i + 1] || out[3 * i] !== out[3 * i + 2]) throw new Error(`pixel ${i} is not grey`);
    }
  },
  'two equal lights at the same place give twice one light, in every mode'() {
    const surface = bumpySphere();
    const light = normalise([0.2, 0.5, 0.7]);
    for (const mode of ['default', 'diffuse-gain', 'specular-enhancement', 'unsharp-masking']) {
      const one = shade(surface, settings({ mode, lights: [light] }));
      const two = shade(surface, settings({ mode, lights: [light, light] }));
      close(mode, two, one.map((v) => 2 * v));
    }
  },
  'diffuse gain of 1 is the default shading, and more gain darkens only where the light leaves the normal'() {
    const surface = bumpySphere();
    const light = normalise([0.3, 0.3, 0.9]);
    const plain = shade(surface, settings({ mode: 'default', lights: [light] }));
    close('gain 1', shade(surface, settings({ mode: 'diffuse-gain', gain: 1, lights: [light] })), plain);
    const steep = shade(surface, settings({ mode: 'diffuse-gain', gain: 5, lights: [light] }));
    for (let i = 0; i < surface.mask.length; i++) {
      if (!surface.mask[i]) continue;
      const cosine = dot(normalAt(surface.normals, i), light);
      if (steep[3 * i] > plain[3 * i] + 1e-6) throw new Error(`pixel ${i} brighter under more gain`);
      if (cosine > 0.99999 && Math.abs(steep[3 * i] - plain[3 * i]) > 1e-4) throw new Error(`pixel ${i} facing the light changed`);
    }
  },
  'nothing is drawn off the object, and no mode makes NaN'() {
    const surface = bumpySphere();
    surface.normals.fill(0, 0, 3 * 50); // a degenerate normal on a masked-out corner
    for (const mode of ['default', 'diffuse-gain', 'specular-enhancement', 'unsharp-masking']) {
      const s = settings({ mode, lights: twoLights, amount: 10, radius: 1, exponent: 200 });
      const out = shade(surface, s, mode === 'unsharp-masking' ? unsharpNormals(surface, s.radius, s.amount) : surface.normals);
      for (let i = 0; i < surface.mask.length; i++) {
        for (let c = 0; c < 3; c++) {
          const v = out[3 * i + c];
          if (Number.isNaN(v) || v < 0) throw new Error(`${mode}: pixel ${i} is ${v}`);
          if (!surface.mask[i] && v !== 0) throw new Error(`${mode}: pixel ${i} off the object is ${v}`);
        }
      }
    }
  },
  'saved settings are read back clamped, and junk falls back to the defaults'() {
    const back = restoreSettings({ mode: 'specular-enhancement', gain: 1e9, exponent: -3, lights: [[0, 0, 2], [1, 0, -1], 'x', [0, 1, 1], [1, 1, 1], [1, 0, 1]] });
    if (back.mode !== 'specular-enhancement' || back.gain !== 10 || back.exponent !== 1) throw new Error(JSON.stringify(back));
    if (back.lights.length !== 3 || Math.abs(Math.hypot(...back.lights[1]) - 1) > 1e-9 || back.lights[0][2] !== 1) throw new Error(JSON.stringify(back.lights));
    const junk = restoreSettings({ mode: 'sepia', brightness: 'high', lights: [] });
    if (JSON.stringify(junk) !== JSON.stringify(RELIGHT_DEFAULTS)) throw new Error(JSON.stringify(junk));
  },
};

const results = {};
for (const [name, check] of Object.entries(checks)) {
  try {
    check();
    results[name] = null;
  } catch (err) {
    results[name] = err.message;
  }
}
process.stdout.write(JSON.stringify(results) + '\n');
