// Plain words for what the panel shows: a brightness threshold as a share of white, the photo
// set's models by what they assume (the library's own name kept in the tooltip), and the notes a
// result's info carries that a newcomer needs explained (a depth pulled back, unsure areas not
// listed). The numbers come from the server; only their wording lives here.

/** A brightness in [0, 1] (the photo's linear values) as a share of white: "31%", "3.1%", "0.26%". */
export function percentOfWhite(value: number): string {
  const percent = 100 * Math.min(1, Math.max(0, value));
  if (percent === 0) return '0%';
  if (percent >= 10) return `${percent.toFixed(0)}%`;
  if (percent >= 1) return `${percent.toFixed(1)}%`;
  return percent >= 0.01 ? `${percent.toFixed(2)}%` : '<0.01%';
}

/** What a threshold keeps, in words: "brighter than 0.26% of white". */
export function thresholdWords(value: number, dark: boolean): string {
  return `${dark ? 'darker' : 'brighter'} than ${percentOfWhite(value)} of white`;
}

/**
 * The photo set's photometric models (``Options.stereo_models``) by what they assume of the
 * surface; the library's name and its description go in the option's tooltip. A model not listed
 * here shows its own name.
 */
const STEREO_MODEL_WORDS: Record<string, string> = {
  bivariate: 'Glossy or matte',
  robust: 'Matte, skip glints',
  least_squares: 'Matte, every photo',
};

/** The photo set's Reflectance (photometric model) and Integrator choices, from the server's registries. */
export function fillStereoChoices(
  model: HTMLSelectElement,
  integrator: HTMLSelectElement,
  options: { stereo_models: Array<{ name: string; description: string }>; integrators: Array<{ name: string; description: string }> },
): void {
  model.append(...stereoModelOptions(options.stereo_models));
  integrator.append(...integratorOptions(options.integrators));
}

/** The photo set's Reflectance choices (photometric models): what each assumes, its name and description in the tooltip. */
export function stereoModelOptions(entries: Array<{ name: string; description: string }>): HTMLOptionElement[] {
  return entries.map(({ name, description }) => {
    const option = new Option(STEREO_MODEL_WORDS[name] ?? name.replace(/_/g, ' '), name);
    option.title = `${capitalised(description)} (the CLI's: shadeform stereo --model ${name})`;
    return option;
  });
}

/** The Integrator choices, each with what it does in its tooltip. */
export function integratorOptions(entries: Array<{ name: string; description: string }>): HTMLOptionElement[] {
  return entries.map(({ name, description }) => {
    const option = new Option(capitalised(name), name);
    option.title = capitalised(description);
    return option;
  });
}

function capitalised(text: string): string {
  return text.charAt(0).toUpperCase() + text.slice(1);
}

/** ``info["depth_bounded"]`` of a result: the share of the object pulled back, and how far it had strayed. */
export interface DepthBounded {
  pixels: number;
  max_over: number;
}

export function readDepthBounded(info: Record<string, unknown> | undefined): DepthBounded | null {
  const said = info?.depth_bounded as Partial<DepthBounded> | undefined;
  if (!said || typeof said.pixels !== 'number' || typeof said.max_over !== 'number') return null;
  return { pixels: said.pixels, max_over: said.max_over };
}

/** The message shown with a model whose depth was pulled back within what its outline allows. */
export function depthBoundedText(said: DepthBounded): { text: string; tip: string } {
  const share = Math.max(0.1, 100 * said.pixels);
  return {
    text:
      `Depth limited on ${share < 10 ? share.toFixed(1) : share.toFixed(0)}% of the object: the solve went up to ` +
      `${said.max_over.toFixed(1)}× deeper than its outline allows and was pulled back there`,
    tip:
      "An object's outline says roughly how deep it can be (about half its width). Where the solved " +
      'depth went far beyond that (a spike or a sheet, often from a shadow or a dent read as a bump), it ' +
      'was squeezed back smoothly. The shape there is a guess: check it, mark concave regions, or improve the mask.',
  };
}

/** ``info["unsure_others"]``: the lesser unsure areas the result counts but does not list. */
export interface UnsureOthers {
  areas: number;
  share: number;
}

export function readUnsureOthers(info: Record<string, unknown> | undefined): UnsureOthers {
  const said = info?.unsure_others as Partial<UnsureOthers> | undefined;
  const areas = typeof said?.areas === 'number' && said.areas > 0 ? Math.round(said.areas) : 0;
  return { areas, share: areas && typeof said?.share === 'number' ? said.share : 0 };
}

/** " (and 2 smaller ones, 4% of the object, not listed)", or "" where there are none. */
export function unsureOthersText(others: UnsureOthers): string {
  if (!others.areas) return '';
  const share = Math.max(1, Math.round(100 * others.share));
  return ` (and ${others.areas} smaller one${others.areas === 1 ? '' : 's'}, ${share}% of the object, not listed)`;
}

/** ``info["mask_warning"]``: the automatic mask is doubtful; what to do, with the library's line as the tip. */
export function maskWarningText(info: Record<string, unknown> | undefined): { text: string; tip: string } | null {
  const said = info?.mask_warning;
  if (typeof said !== 'string' || !said) return null;
  return {
    text: 'The object was found automatically and its outline is doubtful: check the mask, or click or box the object',
    tip: capitalised(said),
  };
}
