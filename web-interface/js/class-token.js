// The instructor's token: taken once per tab as /admin takes its token (connection.js
// takeToken: ?token= from the banner's link is stored in sessionStorage and stripped from the
// address bar), else asked for in a small form. The root connection is the only place it goes
// (Connection sends it only to its tokenUrl, the page's own server's root).

import { takeToken, TOKEN_KEY } from './connection.js';

/** The token from ?token= (then stored and stripped from the address) or this tab's store. */
export function instructorToken(location, history, storage) {
  return takeToken(location, history, storage);
}

/** Keeps `token` for this tab; returns it trimmed ('' for none, then nothing is kept). */
export function storeToken(storage, token) {
  const trimmed = String(token ?? '').trim();
  if (trimmed) storage.setItem(TOKEN_KEY, trimmed);
  return trimmed;
}

export function forgetToken(storage) {
  storage.removeItem(TOKEN_KEY);
}

/**
 * The token card (a form that takes a token) and the button that forgets it (in the top bar,
 * shown while a token is kept).
 * @param {{card: HTMLElement, form: HTMLFormElement, input: HTMLInputElement,
 *          forget: HTMLButtonElement}} elements
 * @param {{storage: Storage, onToken: (token: string) => void}} options onToken('') on forget
 * @returns {{ask: (asking: boolean) => void}} ask(true) shows the form (no token, or refused)
 */
export function bindTokenCard({ card, form, input, forget }, { storage, onToken }) {
  const ask = (asking) => {
    const shown = !card.hidden;
    card.hidden = !asking;
    forget.hidden = !storage.getItem(TOKEN_KEY);
    if (asking && !shown) input.focus(); // once, not at every retry
  };
  form.addEventListener('submit', (event) => {
    event.preventDefault();
    const token = storeToken(storage, input.value);
    if (!token) return;
    input.value = '';
    card.hidden = true;
    forget.hidden = false;
    onToken(token);
  });
  forget.addEventListener('click', () => {
    forgetToken(storage);
    ask(true);
    onToken('');
  });
  return { ask };
}
