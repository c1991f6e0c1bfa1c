// The page's elements by id, and the message lines that stay: a panel's error (the photo set's,
// the views', the Print and Maps panels', the mask's) and the notice over the image.

export const $ = <T extends HTMLElement>(id: string) => document.getElementById(id) as T;

/** Show ``text`` in the message line ``id`` until the next call; null hides it. */
export function showMessage(id: string, text: string | null): void {
  const line = $(id);
  line.hidden = text === null;
  line.textContent = text ?? '';
}
