// Why the instructor's root connection did not open, and what the dashboard says then.
//
// The root (ws://HOST:PORT/) admits only the instructor's token and refuses anything else at
// the handshake, before anything changes, with its reason in an HTTP answer (403 for a wrong
// token). A browser never shows a page that answer: a refused WebSocket is a close with code
// 1006 and no reason, exactly like an unreachable server. So the page asks the server itself:
// the page's own server's /healthz?token=... says whether the server is up, hosts a class, and
// takes the token (token_accepted); the page asks before it connects with a token
// (tokenRefused(): a wrong one is asked for again at once, and never tried on a socket) and
// again when a root closes before it opened. observedRoslib() reports how each socket closed
// (opened or not, the close frame's code and reason, which a server that accepts and then
// closes does send). explainClosed() turns that into the sentence the dashboard shows. Behind
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

/**
 * The page server's /healthz document, or null when it does not answer. With `token` the
 * server says whether it takes it (`token_accepted`); the token goes to the page's own
 * server only, which is where it came from (the dashboard's link).
 */
export async function probeHealth(token = '', fetchImpl = globalThis.fetch) {
  const url = token ? `${HEALTH_URL}?token=${encodeURIComponent(token)}` : HEALTH_URL;
  try {
    const response = await fetchImpl(url, { cache: 'no-store' });
    if (!response.ok) return null;
    const health = await response.json();
    return health && typeof health === 'object' ? health : null;
  } catch {
    return null;
  }
}

/**
 * Whether a /healthz answer (probeHealth() with a token) says the class server does not take
 * the token: then the root refuses it (403) whatever the page retries. False when not known
 * (no answer, a single robot, a server that does not say).
 */
export function tokenRefused(health) {
  return Number.isInteger(health?.robot_count) && health.token_accepted === false;
}

/** Said whenever the dashboard has no token, or its token was not accepted. */
export const NEEDS_TOKEN = 'This dashboard needs the instructor\'s token: the --admin-token '
  + 'that websim serve was started with (its banner prints the link, /class?token=...).';

/** Said when the class server does not take the token (tokenRefused()). */
export const WRONG_TOKEN = 'The class server refused this token: it is not the instructor\'s '
  + 'token. Enter the --admin-token that websim serve was started with (its banner and the '
  + 'links file\'s #instructor row print the dashboard\'s link with it).';

/**
 * Why the root connection at `url` (shown without the token) closed before it opened, as one
 * message: {kind: 'error' | 'warn', text, askToken}. `close` is observedRoslib()'s report,
 * `health` probeHealth()'s answer with the token (null: the server does not answer at all).
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
  if (tokenRefused(health)) return { kind: 'error', askToken: true, text: WRONG_TOKEN };
  if (health.token_accepted === true) {
    return {
      kind: 'warn', askToken: false,
      text: `The class server takes the token but refused ${url}: most likely this page's `
        + 'origin is not allowed (websim serve --allow-origin ORIGIN admits it). Its log says '
        + 'why; browsers do not show it. Retrying…',
    };
  }
  return { // a server that does not say whether it takes the token
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
