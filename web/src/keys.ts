// The keyboard shortcuts, at the document level, wherever the focus is: a clicked checkbox,
// button, select or slider keeps focus but must not swallow them. Only typing is left alone (a
// text or number field), and so are the keys a focused control uses itself (see ownKey).
import { $ } from './dom';
import type { Tool } from './imagePane';
import type { Axis } from './sessionTypes';
import type { ViewSettings } from './state';
import type { Viewer } from './viewer';

/** What the shortcuts do. */
export interface KeyHost {
  viewer: Viewer;
  /** Ctrl/Cmd S. */
  saveProject(): void;
  /** The image pane's own keys (its tool's, the selection's); true when it used the key. */
  paneKey(event: KeyboardEvent): boolean;
  setTool(tool: Tool): void;
  setAxis(axis: Axis): void;
  toggleView(key: keyof ViewSettings): void;
}

export function bindKeys(host: KeyHost): void {
  const viewer = host.viewer;
  document.addEventListener('keydown', (event) => {
    const target = event.target as HTMLElement;
    if ($<HTMLDialogElement>('help-dialog').open || $<HTMLDialogElement>('recent-dialog').open) return;
    if (typing(target) || ownKey(target, event.key)) return;
    const openMenus = document.querySelectorAll('.menu.open');
    if (event.key === 'Escape' && openMenus.length) {
      openMenus.forEach((menu) => menu.classList.remove('open'));
      return;
    }
    if ((event.ctrlKey || event.metaKey) && event.key.toLowerCase() === 's') {
      event.preventDefault();
      host.saveProject();
      return;
    }
    if (event.ctrlKey || event.metaKey || event.altKey) return;
    // the image pane's keys act on one photo only
    const photo = !document.body.classList.contains('stereo-mode') && !document.body.classList.contains('views-mode');
    if (photo && host.paneKey(event)) {
      event.preventDefault();
      return;
    }
    const actions: Record<string, () => void> = {
      o: () => $<HTMLInputElement>('file-image').click(),
      v: () => host.setTool('select'),
      p: () => host.setTool('polygon'),
      f: () => host.setTool('reference'),
      k: () => host.setTool('mask'),
      x: () => host.setAxis('x'),
      y: () => host.setAxis('y'),
      b: () => host.setAxis('both'),
      m: () => host.toggleView('maskOverlay'),
      w: () => host.toggleView('wireframe'),
      n: () => host.toggleView('normalColours'),
      t: () => host.toggleView('texture'),
      l: () => host.toggleView('lightArrow'),
      r: () => viewer.recenter(),
      ArrowLeft: () => viewer.rotate(-15, 0),
      ArrowRight: () => viewer.rotate(15, 0),
      ArrowUp: () => viewer.rotate(0, 10),
      ArrowDown: () => viewer.rotate(0, -10),
      '+': () => viewer.zoom(1.2),
      '=': () => viewer.zoom(1.2),
      '-': () => viewer.zoom(1 / 1.2),
      '?': () => $<HTMLDialogElement>('help-dialog').showModal(),
    };
    if (!photo) for (const key of 'vpfkxybm') delete actions[key];
    const act = event.key === 'O' ? () => $<HTMLInputElement>('file-photos').click() : (actions[event.key] ?? actions[event.key.toLowerCase()]);
    if (act) {
      event.preventDefault();
      act();
    }
  });
}

/** Input types that take no typing: keys there are shortcuts. */
const NOT_TYPED = new Set(['checkbox', 'radio', 'range', 'button', 'submit', 'reset', 'color', 'file', 'image']);

/** Whether keys at ``target`` are text being typed (a text or number field, a text area). */
function typing(target: HTMLElement): boolean {
  if (target.isContentEditable || target instanceof HTMLTextAreaElement) return true;
  return target instanceof HTMLInputElement && !NOT_TYPED.has(target.type);
}

/**
 * Whether a focused control uses ``key`` itself: arrows (and Home, End, Page keys) move a slider
 * or a select's choice; Enter and Space press a button or tick a box. Other keys stay shortcuts
 * there (and are kept from a select's type-to-choose by the handler's preventDefault).
 */
function ownKey(target: HTMLElement, key: string): boolean {
  const slider = target instanceof HTMLInputElement && target.type === 'range';
  if ((slider || target instanceof HTMLSelectElement) && /^(Arrow|Page|Home$|End$)/.test(key)) return true;
  const pressable = target instanceof HTMLButtonElement || target instanceof HTMLSelectElement || target instanceof HTMLInputElement;
  return pressable && (key === 'Enter' || key === ' ');
}
