// The photo set's Relight group: the viewing mode (relightModes.ts) with its own sliders, shown
// only for the mode on, the brightness, and the lights (up to MAX_LIGHTS, each with its own
// coloured handle on the light disc, one of them the one a drag moves). stereo.ts owns the pane
// and tells this where the user drags; this tells it when to redraw and when to keep the settings.
import { $ } from './dom';
import {
  DEFAULT_LIGHT,
  MAX_LIGHTS,
  RELIGHT_RANGES,
  restoreSettings,
  type RelightMode,
  type RelightNumber,
  type RelightSettings,
  type Vec3,
} from './relightModes';

/** The handles' colours on the disc, light by light. */
export const LIGHT_COLOURS = ['#facc15', '#22d3ee', '#f472b6'];

/** Each slider: its element's id, its number in the settings, how many decimals it shows. */
const SLIDERS: { id: string; key: RelightNumber; digits: number }[] = [
  { id: 'stereo-brightness', key: 'brightness', digits: 2 },
  { id: 'relight-gain', key: 'gain', digits: 1 },
  { id: 'relight-diffuse', key: 'diffuse', digits: 2 },
  { id: 'relight-specular', key: 'specular', digits: 2 },
  { id: 'relight-exponent', key: 'exponent', digits: 0 },
  { id: 'relight-radius', key: 'radius', digits: 0 },
  { id: 'relight-amount', key: 'amount', digits: 1 },
];

/** What each mode does, in the user's words (under the mode select). */
const MODE_HINTS: Record<RelightMode, string> = {
  default: 'The surface colour under your lights, as a matte object.',
  'diffuse-gain': 'The light fades faster as it leaves each spot’s direction: the shape shows more strongly.',
  'specular-enhancement': 'A plain grey shiny surface: fine relief catches the highlights.',
  'unsharp-masking': 'Fine bumps exaggerated against their smoothed surroundings, then lit as matte.',
};

export class RelightPanel {
  settings: RelightSettings = restoreSettings(null);
  /** The light a drag moves. */
  active = 0;

  /** ``changed(what)``: redraw; 'light' while a light is dragged, 'settings' when another setting changed. */
  constructor(private readonly changed: (what: 'light' | 'settings') => void) {
    const mode = $<HTMLSelectElement>('relight-mode');
    mode.addEventListener('change', () => this.set({ mode: mode.value as RelightMode }));
    for (const { id, key } of SLIDERS) {
      const slider = $<HTMLInputElement>(id);
      const { min, max, step } = RELIGHT_RANGES[key];
      Object.assign(slider, { min: String(min), max: String(max), step: String(step) });
      slider.addEventListener('input', () => this.set({ [key]: Number(slider.value) }));
    }
    $('relight-add').addEventListener('click', () => this.addLight());
    $('relight-reset').addEventListener('click', () => this.set({ lights: [DEFAULT_LIGHT] }));
    this.show();
  }

  /** Settings a reload kept (null: the defaults). */
  restore(saved: unknown): void {
    this.settings = restoreSettings(saved);
    this.active = 0;
    this.show();
  }

  /** Move the active light (a drag on the image or the disc). */
  moveActive(light: Vec3): void {
    const lights = [...this.settings.lights];
    lights[this.active] = light;
    this.settings = { ...this.settings, lights };
    this.changed('light');
  }

  /** Make the light whose handle is nearest disc point (x, y) the active one. */
  pick(x: number, y: number): void {
    const distances = this.settings.lights.map(([lx, ly]) => Math.hypot(lx - x, ly - y));
    this.active = distances.indexOf(Math.min(...distances));
  }

  /** Another light, across from the first (up to MAX_LIGHTS); it becomes the one a drag moves. */
  addLight(): void {
    const lights = this.settings.lights;
    if (lights.length >= MAX_LIGHTS) return;
    const [x, y, z] = lights[0];
    const spot: Vec3 = lights.length === 1 ? [-x, y, z] : [x, -y, z];
    this.set({ lights: [...lights, spot] });
    this.active = this.settings.lights.length - 1;
  }

  private set(patch: Partial<RelightSettings>): void {
    this.settings = { ...this.settings, ...patch };
    this.active = Math.min(this.active, this.settings.lights.length - 1);
    this.show();
    this.changed('settings');
  }

  private show(): void {
    const settings = this.settings;
    $<HTMLSelectElement>('relight-mode').value = settings.mode;
    $('relight-mode-hint').textContent = MODE_HINTS[settings.mode];
    for (const row of document.querySelectorAll<HTMLElement>('#relight-group [data-mode]')) {
      row.hidden = row.dataset.mode !== settings.mode;
    }
    for (const { id, key, digits } of SLIDERS) {
      $<HTMLInputElement>(id).value = String(settings[key]);
      $(`${id}-out`).textContent = settings[key].toFixed(digits);
    }
    const count = settings.lights.length;
    $<HTMLButtonElement>('relight-add').disabled = count >= MAX_LIGHTS;
    $('relight-lights-out').textContent = count === 1 ? '1 light' : `${count} lights`;
  }

  /** The lights' handles on a disc of radius r about (centre, centre), the active one ringed. */
  drawHandles(context: CanvasRenderingContext2D, centre: number, r: number): void {
    this.settings.lights.forEach(([x, y], k) => {
      context.fillStyle = LIGHT_COLOURS[k];
      context.beginPath();
      context.arc(centre + x * r, centre - y * r, 5, 0, 2 * Math.PI);
      context.fill();
      if (k === this.active && this.settings.lights.length > 1) {
        context.strokeStyle = '#ffffff';
        context.beginPath();
        context.arc(centre + x * r, centre - y * r, 7.5, 0, 2 * Math.PI);
        context.stroke();
      }
    });
  }
}
