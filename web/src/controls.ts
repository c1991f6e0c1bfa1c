// The side panel of parameters. It only shows values and reports edits; photoPanel.ts wires it, and
// the settings are the Photo's (photo.ts).
//
// Sliders report while dragging ("drag", debounced by the caller) and once more on release
// ("now"); selects and buttons report "now".
import type { Options, ReconstructResult } from './api.gen';
import type { Axis, Params, Region } from './sessionTypes';
import { AXIS_COLOURS, UNSURE_COLOUR, unsureQuestion, type Unsure } from './unsure';
import {
  depthBoundedText,
  maskWarningText,
  readDepthBounded,
  readUnsureOthers,
  unsureOthersText,
  type UnsureOthers,
} from './words';

export type Urgency = 'now' | 'drag';

export interface PanelEvents {
  change(patch: Partial<Params>, urgency: Urgency): void;
  axis(axis: Axis): void;
  selectRegion(index: number): void;
  removeRegion(index: number): void;
  removeReference(index: number): void;
  clearReferences(): void;
  drawRegion(): void;
  editReferences(): void;
  /** Turn on the image pane's mask tool (the Mask group itself belongs to maskTool.ts). */
  editMask(): void;
  loadRegions(): void;
  saveRegions(): void;
  clearRegions(): void;
  /** Add the newest result's ``index``-th unsure area as a concave region with its suggested axis. */
  markUnsure(index: number): void;
}

const $ = <T extends HTMLElement>(id: string) => document.getElementById(id) as T;

function fillSelect(select: HTMLSelectElement, entries: Array<[string, string]>, tips: Record<string, string> = {}): void {
  select.replaceChildren(...entries.map(([value, text]) => {
    const option = new Option(text, value);
    if (tips[value]) option.title = tips[value];
    return option;
  }));
}

function descriptions(entries: Array<{ name: string; description: string }>): Record<string, string> {
  return Object.fromEntries(entries.map((e) => [e.name, capitalised(e.description)]));
}

const CHANNEL_NAMES: Record<string, string> = { luma: 'Luma (Rec. 601)', r: 'Red', g: 'Green', b: 'Blue', max: 'Max of R, G, B' };
const FILTER_NAMES: Record<string, string> = { none: 'None', gaussian: 'Gaussian', mean: 'Mean', median: 'Median', minimum: 'Minimum' };

function capitalised(text: string): string {
  return text.charAt(0).toUpperCase() + text.slice(1);
}

export class Panel {
  private params: Params;
  /** The last result's light estimate in whole degrees, where it was estimated: Slant / tilt starts there. */
  private estimated: { slant: number; tilt: number } | null = null;
  /** The last result's lesser unsure areas, counted but not listed (``info["unsure_others"]``). */
  private unsureOthers: UnsureOthers = { areas: 0, share: 0 };
  private readonly channel = $<HTMLSelectElement>('channel');
  private readonly filterKind = $<HTMLSelectElement>('filter-kind');
  private readonly filterSize = $<HTMLInputElement>('filter-size');
  private readonly slant = $<HTMLInputElement>('slant');
  private readonly tilt = $<HTMLInputElement>('tilt');
  private readonly solver = $<HTMLSelectElement>('solver');
  private readonly solverNote = $<HTMLElement>('solver-note');
  private solverHelp: Record<string, string> = {};
  private readonly integrator = $<HTMLSelectElement>('integrator');
  private readonly refine = $<HTMLInputElement>('refine');
  private readonly step = $<HTMLInputElement>('step');

  constructor(options: Options, private readonly events: PanelEvents) {
    this.params = structuredClone(options.defaults);
    fillSelect(this.channel, options.channels.map((c) => [c, CHANNEL_NAMES[c] ?? c]));
    fillSelect(this.filterKind, options.filters.map((f) => [f, FILTER_NAMES[f] ?? capitalised(f)]));
    // names, help lines and order come from the library's registries: a new solver shows up here
    this.solverHelp = descriptions(options.solvers);
    fillSelect(this.solver, options.solvers.map((m): [string, string] => [m.name, m.name === 'auto' ? 'Auto (best measured)' : capitalised(m.name)]), this.solverHelp);
    fillSelect(this.integrator, [['', 'Method default'], ...options.integrators.map((i): [string, string] => [i.name, capitalised(i.name)])],
      descriptions(options.integrators));

    this.channel.addEventListener('change', () => this.emit({ channel: this.channel.value as Params['channel'] }));
    this.filterKind.addEventListener('change', () => {
      const kind = this.filterKind.value as Params['filter']['kind'];
      // gaussian takes any sigma > 0; the window filters a whole-number radius >= 1
      const size = kind === 'gaussian' ? this.params.filter.size || 1 : Math.max(1, Math.round(this.params.filter.size));
      this.emit({ filter: { kind, size } });
    });
    this.slider(this.filterSize, (v) => ({ filter: { ...this.params.filter, size: v } }));
    // touching slant or tilt means "this direction": switch to that mode, from the direction the
    // sliders show (frontal's slant 0, the estimate), not from hidden earlier values
    const touched = (): Partial<Params> => ({
      light: { ...this.params.light, mode: 'slant_tilt', slant: Number(this.slant.value), tilt: Number(this.tilt.value) },
    });
    this.slider(this.slant, touched);
    this.slider(this.tilt, touched);
    this.solver.addEventListener('change', () => this.emit({ solver: this.solver.value }));
    this.integrator.addEventListener('change', () => this.emit({ integrator: this.integrator.value || null }));
    this.slider(this.refine, (v) => ({ refine: v }));
    this.slider(this.step, (v) => ({ step: v }));

    for (const button of document.querySelectorAll<HTMLButtonElement>('#light-mode button')) {
      button.addEventListener('click', () => {
        const mode = button.dataset.mode as Params['light']['mode'];
        // from an estimate to Slant / tilt: the sliders start at the estimate, to be corrected
        const start = mode === 'slant_tilt' && this.params.light.mode === 'estimate' ? this.estimated : null;
        this.emit({ light: { ...this.params.light, ...(start ?? {}), mode } });
      });
    }
    for (const button of document.querySelectorAll<HTMLButtonElement>('#axis button')) {
      button.addEventListener('click', () => events.axis(button.dataset.axis as Axis));
    }
    $('refs-clear').addEventListener('click', () => events.clearReferences());
    $('refs-tool').addEventListener('click', () => events.editReferences());
    $('mask-tool').addEventListener('click', () => events.editMask());
    $('regions-tool').addEventListener('click', () => events.drawRegion());
    $('regions-load').addEventListener('click', () => events.loadRegions());
    $('regions-save').addEventListener('click', () => events.saveRegions());
    $('regions-clear').addEventListener('click', () => events.clearRegions());
  }

  private slider(input: HTMLInputElement, patch: (value: number) => Partial<Params>): void {
    input.addEventListener('input', () => {
      this.showOutputs(input);
      this.emit(patch(Number(input.value)), 'drag');
    });
    input.addEventListener('change', () => this.emit(patch(Number(input.value)), 'now'));
  }

  private emit(patch: Partial<Params>, urgency: Urgency = 'now'): void {
    this.events.change(patch, urgency);
  }

  private showOutputs(...inputs: HTMLInputElement[]): void {
    for (const input of inputs) {
      const out = document.getElementById(`${input.id}-out`);
      if (!out) continue;
      const value = Number(input.value);
      out.textContent = input === this.slant || input === this.tilt ? `${value}°` : input === this.step ? `${value} px` : String(value);
    }
  }

  /**
   * The slant and tilt sliders show the light that is used: the user's angles in Slant / tilt;
   * in Frontal slant 0 (tilt then means nothing: "—"); in Estimate the estimate once a result
   * has one. Outside Slant / tilt both are greyed (class ``dimmed``), and touching one switches
   * to Slant / tilt from what it shows.
   */
  private showLight(): void {
    const light = this.params.light;
    const shown = shownLight(light, this.estimated);
    this.slant.value = String(shown.slant ?? light.slant);
    this.tilt.value = String(shown.tilt ?? light.tilt);
    this.showOutputs(this.slant, this.tilt);
    if (shown.slant === null) $('slant-out').textContent = '—';
    if (shown.tilt === null) $('tilt-out').textContent = '—';
    const why = light.mode === 'z'
      ? 'Frontal: the light comes from the camera (slant 0°; tilt does not apply). Drag to set a direction instead.'
      : 'Estimated from the photo. Drag to correct it (switches to Slant / tilt).';
    for (const input of [this.slant, this.tilt]) {
      const row = input.closest<HTMLElement>('.row')!;
      const manual = light.mode === 'slant_tilt';
      row.classList.toggle('dimmed', !manual);
      row.dataset.tip ??= row.title;
      row.title = manual ? row.dataset.tip : why;
    }
  }

  /** Show ``params`` in every control. */
  show(params: Params): void {
    this.params = structuredClone(params);
    this.channel.value = params.channel;
    this.filterKind.value = params.filter.kind;
    this.solver.value = params.solver;
    this.solverNote.textContent = this.solverHelp[params.solver] ?? '';
    this.integrator.value = params.integrator ?? '';
    this.refine.value = String(params.refine);
    this.step.value = String(params.step);
    this.showOutputs(this.filterSize, this.refine, this.step);
    this.showLight();
    $('filter-size-row').classList.toggle('disabled', params.filter.kind === 'none');
    const gaussian = params.filter.kind === 'gaussian';
    this.filterSize.step = gaussian ? '0.5' : '1';
    this.filterSize.min = gaussian ? '0.5' : '1';
    $('filter-size-row').querySelector('span')!.textContent = gaussian ? 'Sigma' : 'Radius';
    this.filterSize.value = String(params.filter.size);
    this.showOutputs(this.filterSize);
    for (const button of document.querySelectorAll<HTMLButtonElement>('#light-mode button')) {
      button.classList.toggle('on', button.dataset.mode === params.light.mode);
    }
  }

  /** The light the result was solved with (the estimate, when estimated). */
  showResult(result: ReconstructResult | null): void {
    const out = $('light-readout');
    const unsure = $('light-unsure');
    // the estimate's own confidence: the chance that the true light is within 10 degrees of it
    const estimate = result?.info.light_estimate as { slant: number; tilt: number; confidence: number; unsure: boolean } | undefined;
    this.estimated = estimate
      ? { slant: Math.min(Number(this.slant.max), Math.round(estimate.slant)), tilt: Math.round(estimate.tilt) }
      : null;
    if (this.params.light.mode === 'estimate') this.showLight();
    showDepthNote(result);
    // a quick look may leave the areas out: the last ones are kept until a result says
    if (!result) this.unsureOthers = { areas: 0, share: 0 };
    else if (!result.preview || 'unsure' in result.info) this.unsureOthers = readUnsureOthers(result.info);
    unsure.hidden = !estimate?.unsure;
    unsure.textContent = estimate?.unsure
      ? `The light read from the photo is unsure (a ${Math.round(100 * estimate.confidence)}\u00a0% chance of being within 10°): if you know where the light was, choose Slant / tilt and set it.`
      : '';
    if (!result) {
      out.textContent = '';
      return;
    }
    const [x, y, z] = result.light;
    const slant = (Math.acos(Math.max(-1, Math.min(1, z))) * 180) / Math.PI;
    const tilt = (Math.atan2(y, x) * 180) / Math.PI;
    const estimated = this.params.light.mode === 'estimate' ? 'Estimated: ' : 'Used: ';
    const angles = slant < 0.05 ? 'frontal' : `slant ${slant.toFixed(1)}°, tilt ${tilt.toFixed(1)}°`;
    const sure = estimate ? ` · confidence ${estimate.confidence.toFixed(2)}` : '';
    out.textContent = `${estimated}L = (${x.toFixed(2)}, ${y.toFixed(2)}, ${z.toFixed(2)}) · ${angles}${sure}`;
  }

  showReferences(user: Array<[number, number]>, used: Array<[number, number]>): void {
    const list = $('refs-list');
    const isUser = (r: number, c: number) => user.some(([ur, uc]) => ur === r && uc === c);
    const items: HTMLLIElement[] = user.map(([r, c], i) => {
      const li = document.createElement('li');
      li.innerHTML = `<span class="swatch" style="background:#22d3ee;border-radius:50%"></span><span class="what">${i === 0 ? 'Main' : `#${i + 1}`}</span><span class="meta">row ${r}, col ${c}</span>`;
      const remove = document.createElement('button');
      remove.textContent = '×';
      remove.title = 'Remove this reference';
      remove.addEventListener('click', () => this.events.removeReference(i));
      li.append(remove);
      return li;
    });
    for (const [r, c] of used) {
      if (isUser(r, c)) continue;
      const li = document.createElement('li');
      li.title = 'Chosen automatically: the brightest point of a part of the object that has no reference point';
      li.innerHTML = `<span class="swatch" style="border:1.5px solid #fde047;transform:rotate(45deg);width:8px;height:8px"></span><span class="what">Automatic</span><span class="meta">row ${r}, col ${c}</span>`;
      items.push(li);
    }
    list.replaceChildren(...items);
    $('refs-note').textContent = user.length
      ? 'Depth is measured from the first (depth 0 there); each is taken to face the light straight on.'
      : 'None set: depth is measured from the brightest point, taken to face the light straight on.';
    ($('refs-clear') as HTMLButtonElement).disabled = user.length === 0;
  }

  /**
   * The areas the shading cannot settle, under the regions list: one line saying how many, and per
   * area a button that makes it a concave region (disabled once a region has exactly its outline).
   */
  showUnsure(areas: Unsure[], regions: Region[]): void {
    let box = document.getElementById('unsure');
    if (!box) {
      box = document.createElement('div');
      box.id = 'unsure';
      box.className = 'unsure';
      box.setAttribute('aria-live', 'polite');
      $('regions-list').after(box);
    }
    box.hidden = areas.length === 0;
    if (!areas.length) {
      box.replaceChildren();
      return;
    }
    const note = document.createElement('div');
    note.className = 'hint-text unsure-note';
    note.textContent = `Unsure: ${areas.length} area${areas.length === 1 ? '' : 's'} the shading cannot settle` +
      unsureOthersText(this.unsureOthers);
    note.title = 'The photo fits a bump and a dent equally well here; it is solved as convex unless you mark it concave.' +
      (this.unsureOthers.areas ? ' The smaller ones matter less to the shape; only those that matter most are listed.' : '');
    const same = (a: Array<[number, number]>, b: Array<[number, number]>) => JSON.stringify(a) === JSON.stringify(b);
    const items = areas.map((area, i) => {
      const li = document.createElement('li');
      const swatch = document.createElement('span');
      swatch.className = 'swatch';
      swatch.style.border = `1.5px dashed ${UNSURE_COLOUR}`;
      const what = document.createElement('span');
      what.className = 'what';
      what.textContent = `?${i + 1} ${unsureQuestion(area.axis).replace(/^c/, 'C')}`;
      const meta = document.createElement('span');
      meta.className = 'meta';
      meta.textContent = `${Math.max(1, Math.round(area.share * 100))}%`;
      meta.title = 'Share of the object';
      const mark = document.createElement('button');
      mark.className = 'btn small';
      mark.textContent = `Mark concave (${area.axis})`;
      const marked = regions.some((r) => r.axis === area.axis && same(r.polygon, area.polygon));
      mark.disabled = marked;
      mark.title = marked ? 'Already a concave region' : 'Add this area as a concave region with the suggested axis';
      mark.addEventListener('click', () => this.events.markUnsure(i));
      li.append(swatch, what, meta, mark);
      return li;
    });
    const list = document.createElement('ul');
    list.className = 'items unsure-list';
    list.setAttribute('aria-label', 'Unsure areas');
    list.append(...items);
    box.replaceChildren(note, list);
  }

  showRegions(regions: Region[], selected: number | null, newAxis: Axis): void {
    const items = regions.map((region, i) => {
      const li = document.createElement('li');
      li.classList.toggle('selected', i === selected);
      li.innerHTML = `<span class="swatch" style="background:${AXIS_COLOURS[region.axis]}"></span><span class="what">Region ${i + 1}</span><span class="meta">${region.axis === 'both' ? 'x and y' : region.axis} · ${region.polygon.length} corners</span>`;
      li.addEventListener('click', () => this.events.selectRegion(i));
      const remove = document.createElement('button');
      remove.textContent = '×';
      remove.title = 'Delete this region (Del)';
      remove.addEventListener('click', (event) => {
        event.stopPropagation();
        this.events.removeRegion(i);
      });
      li.append(remove);
      return li;
    });
    $('regions-list').replaceChildren(...items);
    const axis = selected !== null && regions[selected] ? regions[selected].axis : newAxis;
    for (const button of document.querySelectorAll<HTMLButtonElement>('#axis button')) {
      button.classList.toggle('on', button.dataset.axis === axis);
    }
    $('axis-note').textContent =
      selected !== null
        ? `Region ${selected + 1} selected: the axis applies to it.`
        : regions.length
          ? 'Axis for new regions. Select a region to change its own.'
          : 'Mark where the surface curves away from you: a dent, a bowl, a groove.';
    ($('regions-save') as HTMLButtonElement).disabled = regions.length === 0;
    ($('regions-clear') as HTMLButtonElement).disabled = regions.length === 0;
  }
}

/**
 * The slant and tilt the sliders show for ``light``; null where there is none to show (a frontal
 * light's tilt, an estimate not made yet).
 */
export function shownLight(
  light: Params['light'],
  estimated: { slant: number; tilt: number } | null,
): { slant: number | null; tilt: number | null } {
  if (light.mode === 'z') return { slant: 0, tilt: null };
  if (light.mode === 'estimate') return estimated ?? { slant: null, tilt: null };
  return { slant: light.slant, tilt: light.tilt };
}

/**
 * Under the model's badge, while the result on screen says so: its depth ran past what the
 * object's outline allows and was pulled back (``info["depth_bounded"]``), or its automatic mask
 * is doubtful (``info["mask_warning"]``), in words, with why in the tooltip.
 */
function showDepthNote(result: ReconstructResult | null): void {
  let note = document.getElementById('depth-note');
  if (!note) {
    note = document.createElement('div');
    note.id = 'depth-note';
    note.className = 'depth-note single-only';
    note.setAttribute('role', 'status');
    $('view-host').append(note);
  }
  const said = readDepthBounded(result?.info);
  const notes = [said ? depthBoundedText(said) : null, maskWarningText(result?.info)].filter(
    (note): note is { text: string; tip: string } => note !== null,
  );
  note.hidden = notes.length === 0;
  note.textContent = notes.map((one) => one.text).join('. ');
  note.title = notes.map((one) => one.tip).join('\n');
}
