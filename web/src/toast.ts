// Messages at the bottom of the window (#toast holds them). An error stays until the user
// dismisses it (its × button, or Escape while focus is on it): a message that vanishes on its
// own may never have been read. Information fades after a few seconds. The same error twice is
// shown once.

export type ToastKind = 'error' | 'info';

const INFO_MS = 3000;
const MOST = 4; // the oldest goes beyond this

function box(): HTMLElement {
  return document.getElementById('toast')!;
}

/** Show ``message``; returns what takes it away again (a message its cause has outlived). */
export function toast(message: string, kind: ToastKind = 'error'): () => void {
  const container = box();
  const items = Array.from(container.querySelectorAll<HTMLElement>('.toast-item'));
  const same = items.find((item) => item.dataset.kind === kind && item.querySelector('.toast-text')!.textContent === message);
  if (same) same.remove(); // shown again, as the newest
  const item = document.createElement('div');
  item.className = `toast-item ${kind}`;
  item.dataset.kind = kind;
  item.setAttribute('role', kind === 'error' ? 'alert' : 'status');
  const text = document.createElement('span');
  text.className = 'toast-text';
  text.textContent = message;
  const close = document.createElement('button');
  close.className = 'toast-close';
  close.type = 'button';
  close.textContent = '×';
  close.title = 'Dismiss (Esc)';
  close.setAttribute('aria-label', 'Dismiss this message');
  close.addEventListener('click', () => dismiss(item));
  item.append(text, close);
  container.append(item);
  const all = container.querySelectorAll('.toast-item');
  for (let i = 0; i < all.length - MOST; i++) all[i].remove();
  if (kind === 'info') window.setTimeout(() => dismiss(item), INFO_MS);
  container.hidden = false;
  return () => {
    if (item.isConnected) dismiss(item);
  };
}

function dismiss(item: HTMLElement): void {
  const container = box();
  const hadFocus = item.contains(document.activeElement);
  item.remove();
  const left = container.querySelectorAll<HTMLElement>('.toast-close');
  container.hidden = left.length === 0;
  // focus was on the message: it moves to the next one (else to the page, as the item is gone)
  if (hadFocus && left.length) left[left.length - 1].focus();
}

/** Escape on a message dismisses it (and goes no further: it is not a shortcut then). */
export function bindToasts(): void {
  box().addEventListener('keydown', (event) => {
    if (event.key !== 'Escape') return;
    const item = (event.target as HTMLElement).closest<HTMLElement>('.toast-item');
    if (!item) return;
    event.preventDefault();
    event.stopPropagation();
    dismiss(item);
  });
}

/** The messages shown now, oldest first (for the test hook). */
export function toasts(): Array<{ kind: ToastKind; text: string }> {
  return Array.from(box().querySelectorAll<HTMLElement>('.toast-item')).map((item) => ({
    kind: item.dataset.kind as ToastKind,
    text: item.querySelector('.toast-text')!.textContent ?? '',
  }));
}
