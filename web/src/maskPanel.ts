// The side panel's Mask group: its controls (how the mask tool edits: brush, polygon, object or
// box, adding or erasing; the brush's size; the threshold and whether the object is dark; the
// buttons: Automatic, Clear, Invert, Fill holes, Load, Save) reported to the tool (maskTool.ts),
// and what the group shows: which mask is used and what it came from, and an error line that
// stays until the next mask action succeeds.
import { $, showMessage } from './dom';
import { percentOfWhite } from './words';

export type MaskMode = 'brush' | 'polygon' | 'object' | 'box';
export type MaskOp = 'add' | 'erase';

const THRESHOLD_STEPS = 1000; // the threshold slider's positions, on a square-root scale

/** What the group's controls ask of the tool. */
export interface MaskPanelEvents {
  mode(mode: MaskMode): void;
  op(op: MaskOp): void;
  radius(radius: number): void;
  /** The threshold or the dark choice moved; ``final`` on the slider's release (or a tick). */
  threshold(final: boolean): void;
  automatic(): void;
  clear(): void;
  invert(): void;
  fillHoles(): void;
  save(): void;
  load(file: File): void;
}

export class MaskPanel {
  private readonly radiusInput = $<HTMLInputElement>('mask-radius');
  private readonly thresholdInput = $<HTMLInputElement>('mask-threshold');
  private readonly darkInput = $<HTMLInputElement>('mask-dark');

  constructor(events: MaskPanelEvents) {
    for (const button of document.querySelectorAll<HTMLButtonElement>('#mask-mode button')) {
      button.addEventListener('click', () => events.mode(button.dataset.maskMode as MaskMode));
    }
    for (const button of document.querySelectorAll<HTMLButtonElement>('#mask-op button')) {
      button.addEventListener('click', () => events.op(button.dataset.maskOp as MaskOp));
    }
    this.radiusInput.addEventListener('input', () => events.radius(Number(this.radiusInput.value)));
    this.thresholdInput.addEventListener('input', () => events.threshold(false));
    this.thresholdInput.addEventListener('change', () => events.threshold(true));
    this.darkInput.addEventListener('change', () => events.threshold(true));
    $('mask-auto').addEventListener('click', () => events.automatic());
    $('mask-clear').addEventListener('click', () => events.clear());
    $('mask-invert').addEventListener('click', () => events.invert());
    $('mask-fill').addEventListener('click', () => events.fillHoles());
    $('mask-save').addEventListener('click', () => events.save());
    $('mask-load').addEventListener('click', () => $<HTMLInputElement>('file-mask').click());
    const file = $<HTMLInputElement>('file-mask');
    file.addEventListener('change', () => {
      const chosen = file.files?.[0];
      file.value = ''; // the same file again must fire again
      if (chosen) events.load(chosen);
    });
  }

  /** The mode and operation buttons (the operation's words follow the mode), the brush's row. */
  showControls(mode: MaskMode, op: MaskOp): void {
    for (const button of document.querySelectorAll<HTMLButtonElement>('#mask-mode button')) {
      button.classList.toggle('on', button.dataset.maskMode === mode);
    }
    for (const button of document.querySelectorAll<HTMLButtonElement>('#mask-op button')) {
      button.classList.toggle('on', button.dataset.maskOp === op);
    }
    const object = mode === 'object';
    $('mask-op').querySelector<HTMLButtonElement>('[data-mask-op="add"]')!.textContent = object ? 'On object' : 'Add';
    $('mask-op').querySelector<HTMLButtonElement>('[data-mask-op="erase"]')!.textContent = object ? 'On background' : 'Erase';
    this.radiusInput.closest('.row')!.classList.toggle('dimmed', mode !== 'brush');
  }

  showRadius(radius: number): void {
    this.radiusInput.value = String(radius);
    $('mask-radius-out').textContent = `${radius} px`;
  }

  /** The threshold the slider is at, as a share of white. */
  thresholdValue(): number {
    return (Number(this.thresholdInput.value) / THRESHOLD_STEPS) ** 2;
  }

  /** Move the slider to ``value`` (null: leave it) and say where it is. */
  showThreshold(value: number | null): void {
    if (value !== null && Number.isFinite(value)) {
      this.thresholdInput.value = String(Math.round(Math.sqrt(Math.min(1, Math.max(0, value))) * THRESHOLD_STEPS));
    }
    $('mask-threshold-out').textContent = percentOfWhite(this.thresholdValue()); // 31%, 0.56%: in its width
  }

  /** Whether the object is darker than its background (the threshold's side). */
  get dark(): boolean {
    return this.darkInput.checked;
  }

  set dark(on: boolean) {
    this.darkInput.checked = on;
  }

  /** Which mask is used: the user's (its pixels, what it came from) or the automatic one (the
   * server's note about it); Automatic is offered only in place of the user's. */
  showNote(user: boolean, pixels: number | null, what: string, autoNote: string): void {
    const count = pixels !== null ? ` · ${pixels.toLocaleString()} pixels` : '';
    this.note = user ? `Your mask${count}${what ? ` · ${what}` : ''}` : `Automatic${autoNote ? `: ${autoNote}` : ''}`;
    $('mask-auto').toggleAttribute('disabled', !user);
  }

  get note(): string | null {
    return $('mask-note').textContent;
  }

  set note(text: string) {
    $('mask-note').textContent = text;
  }

  /** A message that stays until the next mask action succeeds (null takes it away). */
  error(message: string | null): void {
    showMessage('mask-error', message);
  }

  /** The error shown, or null. */
  get shownError(): string | null {
    return $('mask-error').hidden ? null : $('mask-error').textContent;
  }
}
