// Why the instructor's root connection did not open, and what the dashboard says then.
//
// The root (ws://HOST:PORT/) admits only the instructor's token and refuses anything else at
// the handshake, with its reason in an HTTP answer. A browser never shows a page that answer:
// a refused WebSocket is a close with code 1006 and no reason, exactly like an unreachable
// server. So the page tells the two apart itself: observedRoslib() reports how each socket
// closed (opened or not, the close frame's code and reason, which a server that accepts and
// then closes does send), and the page's own server's /healthz says whether the server is up
// and hosts a class. explainClosed() turns that into the sentence the dashboard shows. Behind
// nginx, with a root per worker, a worker that fails while another accepted the same token is
// not a token problem: explainWorkerClosed() says that worker is out of reach.

/** The page server's health document (same server, so readable), relative to the page. */
export const HEALTH_URL = 'healthz';

/**
 * `ROSLIB` with its Ros wrapped: every socket reports, when it closes, {opened, code, reason}
 * to `onClose`. Everything else is roslibjs's own, so Connection (connection.js) runs on it
 * unchanged.
 */
export function observedRoslib(ROSLIB, onClose) {
  class Ros extends ROSLIB.Ros {
    constructor(options) {
      super(options);
      let opened = false;
      this.on('connection', () => {
        opened = true;
      });
      this.on('close', (event) => {
        onClose({ opened, code: event?.code ?? null, reason: event?.reason ?? '' });
      });
    }
  }
  return { ...ROSLIB, Ros };
}

/** The page server's /healthz document, or null when it does not answer. */
export async function probeHealth(fetchImpl = globalThis.fetch) {
  try {
    const response = await fetchImpl(HEALTH_URL, { cache: 'no-store' });
    if (!response.ok) return null;
    const health = await response.json();
    return health && typeof health === 'object' ? health : null;
  } catch {
    return null;
  }
}

/** Said whenever the dashboard has no token, or its token was not accepted. */
export const NEEDS_TOKEN = 'This dashboard needs the instructor\'s token: the --admin-token '
  + 'that websim serve was started with (its banner prints the link, /class?token=...).';

/**
 * Why the root connection at `url` (shown without the token) closed before it opened, as one
 * message: {kind: 'error' | 'warn', text, askToken}. `close` is observedRoslib()'s report,
 * `health` probeHealth()'s answer (null: the server does not answer at all).
 */
export function explainClosed({ url, close, health }) {
  if (close?.reason) {
    return { kind: 'error', askToken: true, text: `The server closed ${url}: ${close.reason}` };
  }
  if (!health) {
    return {
      kind: 'warn', askToken: false,
      text: `Cannot reach the server at ${url}. Is websim serve running? Retrying…`,
    };
  }
  if (!Number.isInteger(health.robot_count)) {
    return {
      kind: 'error', askToken: false,
      text: 'This server runs a single robot, not a class: the dashboard is for '
        + '"websim serve --class ROSTER|N --admin-token TOKEN".',
    };
  }
  return {
    kind: 'error', askToken: true,
    text: `The class server refused the instructor's connection (${url}). ${NEEDS_TOKEN} `
      + 'Check it, or enter it again below. (Browsers do not show the reason the server '
      + 'gives; it also logs it.)',
  };
}

/** The message when /websim/robots fails on an open root connection (a server without classes). */
export function explainNoRobots(reason) {
  return {
    kind: 'error', askToken: false,
    text: `The server does not list a class's robots (/websim/robots: ${reason}). The `
      + 'dashboard is for "websim serve --class ROSTER|N --admin-token TOKEN".',
  };
}

/**
 * Why worker `url`'s root connection (shown without the token) did not open while another
 * worker's opened with the same token: the token is right, so this worker is down, or nginx
 * cannot reach it. {kind, text, askToken: false}; `close` is observedRoslib()'s report.
 */
export function explainWorkerClosed({ url, close }) {
  if (close?.reason) {
    return { kind: 'error', askToken: false, text: `The worker closed ${url}: ${close.reason}` };
  }
  return {
    kind: 'warn', askToken: false,
    text: `Cannot reach the class worker at ${url}: nginx answers, but not that worker (is its `
      + '"websim serve --class ... --worker" running?). Its robots are missing until it '
      + 'answers; the other workers\' robots are shown. Retrying…',
  };
}
