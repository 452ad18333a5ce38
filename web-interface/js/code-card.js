// The Code card on the robot's page: closed, it loads nothing; "Open the editor" (or a page
// that had it open) loads the panel (code-panel.js), the editor and the Python runtime. So a
// student who only drives downloads none of them.

import { tokenFor, withoutToken } from './connection.js';

/** Where a page remembers that its Code panel was open. */
export const OPEN_KEY_PREFIX = 'websim.codeOpen:';

/**
 * Wire the card: {card, open: button, panel, state badges}; `connection` is the page's own
 * (the program talks to the bridge it talks to, with its token); `stopRobot()` sends a zero
 * velocity command; `onRun()` is told when a program starts (the PID and teleop stand down).
 */
export function bindCodeCard(elements, { connection, robot, stopRobot, onRun,
  storage = window.localStorage, location = window.location }) {
  const key = OPEN_KEY_PREFIX + new URL(location.href).pathname;
  let panel = null;
  const open = async () => {
    if (panel) return panel;
    elements.open.disabled = true;
    elements.open.textContent = 'Opening…';
    try {
      const { CodePanel } = await import('./code-panel.js');
      panel = new CodePanel(elements, {
        robotLink: () => ({
          url: connection.url,
          token: tokenFor(connection.url, connection.tokenUrl, connection.token),
          shownUrl: withoutToken(connection.url),
        }),
        pageToken: () => connection.token,
        robot,
        stopRobot,
        onRun,
        storage,
        location,
      });
      await panel.open();
      storage.setItem(key, '1');
      elements.intro.hidden = true;
      return panel;
    } catch (error) {
      elements.open.disabled = false;
      elements.open.textContent = 'Open the editor';
      elements.state.textContent = /specifier/.test(error.message)
        ? 'the editor needs websim serve: this server gave the page no import map for it'
        : `the editor could not load: ${error.message}`;
      elements.state.dataset.state = 'failed';
      throw error;
    }
  };
  elements.open.addEventListener('click', () => { open().catch(() => {}); });
  if (storage.getItem(key) === '1') open().catch(() => {});
  return { open, get panel() { return panel; } };
}
