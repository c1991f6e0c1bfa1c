// The Views panel's words and cards (views.ts owns the panel): one card per view (the photo
// with the mask it was solved with, tinted in its partial model's colour, its name, turntable
// angle and settings, Edit and Remove, and the areas the other views settled; a photo set's view
// shows its first photo, a "set · N photos" badge and no Edit), the partial models' colours, and
// the note and warnings of a fusion's result.
import * as api from './api';
import type { FuseResult, FusedView } from './api.gen';
import type { Params, View, ViewPhotoSet } from './sessionTypes';

/** The partial models' colours, view by view (the cards' swatches show the same). */
export const PART_COLOURS = ['#f59e0b', '#38bdf8', '#a3e635', '#f472b6', '#a78bfa', '#2dd4bf', '#fb7185', '#facc15'];

/** Below this a view's outline is not kept (shadeform.fusion.outlines.OUTLINE_KEPT). */
const OUTLINE_KEPT = 0.95;

/** A view's card; ``current``: what the fusion on screen found of it (null: none of these views). */
export function viewCard(view: View, index: number, current: FusedView | null): HTMLElement {
  const card = document.createElement('li');
  card.className = 'view-card';
  card.dataset.index = String(index);
  const colour = PART_COLOURS[index % PART_COLOURS.length];
  card.innerHTML = `
      <div class="thumb"><img alt="" /><div class="tint"></div><span class="swatch"></span><span class="set-badge" hidden></span></div>
      <div class="about">
        <b class="name"></b>
        <label class="angle" title="Turntable angle in degrees: how far the object was turned about the vertical axis (right-handed about +y) for this photo">
          Angle <input type="text" inputmode="decimal" spellcheck="false" /> °
        </label>
        <small class="settings"></small>
        <div class="settled" hidden>
          <span></span>
          <button class="btn small" data-act="keep" title="Make these areas the view's own concave regions: they stay when you edit it">Keep as regions</button>
        </div>
        <div class="buttons">
          <button class="btn small" data-act="edit" title="Open this photo with its settings (mask, regions, light, solver) to change them; the fused model follows">Edit</button>
          <button class="btn small danger" data-act="remove" title="Leave this photo out of the fused model">Remove</button>
        </div>
      </div>`;
  const set = view.photo_set ?? null;
  card.querySelector('img')!.src = set ? api.photoSetPhotoUrl(set.info.photoset_id, 0) : api.photoUrl(view.image.image_id);
  if (set) {
    const badge = card.querySelector<HTMLElement>('.set-badge')!;
    badge.hidden = false;
    badge.textContent = `set · ${set.info.count} photos`;
    badge.title = 'A photo set: this side under several lights, solved by photometric stereo (no mask, regions or light to set)';
    card.querySelector<HTMLElement>('[data-act="edit"]')!.hidden = true;
  }
  card.querySelector<HTMLElement>('.swatch')!.style.background = colour;
  card.querySelector<HTMLElement>('.swatch')!.textContent = String(index + 1);
  card.querySelector('.name')!.textContent = view.image.name;
  card.querySelector<HTMLElement>('.name')!.title = view.image.name;
  const input = card.querySelector('input')!;
  input.value = String(view.angle);
  input.dataset.angle = String(index);
  input.setAttribute('aria-label', `View ${index + 1} angle in degrees`);
  card.querySelector('.settings')!.textContent = set ? setSettingsText(set) : settingsText(view.params);
  // what the fusion read as concave in this view's photo, from the other views
  const settled = current?.settled.length ?? 0;
  if (settled) {
    card.querySelector<HTMLElement>('.settled')!.hidden = false;
    card.querySelector('.settled span')!.textContent =
      `${settled} unsure area${settled === 1 ? '' : 's'} read as concave from the other views`;
  }
  // the mask the view was solved with, tinted in its model's colour
  const mask = current?.mask_png;
  const tint = card.querySelector<HTMLElement>('.tint')!;
  if (mask) {
    tint.style.background = colour;
    tint.style.maskImage = `url(data:image/png;base64,${mask})`;
  } else {
    tint.hidden = true;
  }
  return card;
}

/** What a fusion found, in the panel's note, and its warnings (shown apart, in the colour of unsure areas). */
export function fusionNote(result: FuseResult): { note: string; warnings: string[] } {
  const solved = result.views.filter((view) => !view.cached).length;
  const seconds = ((result.timings.place ?? 0) + (result.timings.solid ?? 0)).toFixed(1);
  const parts = [
    `Volume ${Math.round(result.volume).toLocaleString()} cubic px, ${result.watertight ? 'closed' : 'NOT closed'}.`,
    `Turntable axis at column ${result.axis.toFixed(1)}; voxel ${Number(result.info.resolution).toFixed(2)} px.`,
    result.info.cached ? 'Fused model reused.' : `Fused in ${seconds} s.`,
  ];
  if (solved) parts.push(`${solved} of ${result.views.length} views solved anew.`);
  const outlines = result.views.map((view) => view.outline_iou);
  parts.push(`Outlines kept: ${outlines.map((value, i) => `view ${i + 1} ${(100 * value).toFixed(0)}%`).join(', ')}.`);
  // photos that fit another placement about as well: said apart, in the colour of unsure areas
  const rivals = result.rivals.map((turns) =>
    turns.flatMap((turn, i) => (turn > 0 ? [`view ${i + 1} turned ${Math.round(turn)}°`] : [])).join(', '),
  );
  const warnings: string[] = [];
  if (!result.depth_fixed) {
    warnings.push(
      'The views look along one line only (from opposite sides), so they cannot tell how deep the object is: ' +
        "the model's depth rests on each photo's shading alone, the two joined at their shared outline; add a photo from the side (e.g. at 90°).",
    );
  }
  const poor = outlines.flatMap((value, i) => (value < OUTLINE_KEPT ? [`view ${i + 1} (${(100 * value).toFixed(0)}%)`] : []));
  if (poor.length) {
    warnings.push(
      `The model covers the outline of ${poor.join(', ')} poorly: parts the photo shows are missing or the model ` +
        "reaches past them; check that view's mask and angle.",
    );
  }
  if (rivals.length) {
    warnings.push(
      `The photos fit another placement about as well (${rivals.join('; or ')}), so the model may be wrong there: ` +
        'add a photo between two views (e.g. at 45°), or give the angles exactly and untick Refine the poses.',
    );
  }
  return { note: parts.join(' '), warnings };
}

/** What a view's settings say in a few words: mask, regions, light, solver. */
function settingsText(params: Params): string {
  const parts = [params.mask ? 'your mask' : 'automatic mask'];
  const regions = params.concave.regions.length;
  if (regions) parts.push(`${regions} concave region${regions === 1 ? '' : 's'}`);
  const light = params.light;
  parts.push(light.mode === 'z' ? 'frontal light' : light.mode === 'estimate' ? 'light estimated' : `light ${light.slant.toFixed(0)}° / ${light.tilt.toFixed(0)}°`);
  if (params.solver !== 'auto') parts.push(params.solver);
  return parts.join(' · ');
}

/** What a photo set's view is solved with, in a few words: photometric stereo, its lights, model. */
function setSettingsText(set: ViewPhotoSet): string {
  const lights = { file: 'lights from its file', sphere: 'lights from a sphere', unknown: 'lights read from the photos' }[set.params.lights];
  return ['photometric stereo', lights, set.params.model.replace('_', ' ')].join(' · ');
}
