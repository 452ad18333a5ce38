// The one connection to rosbridge (roslibjs): status, reconnect with backoff, re-subscribing.
//
// Every other module talks to the robot through a Connection: subscribe() and publisher()
// registrations outlive a dropped socket and are re-created on each new one, so a restarted
// bridge (or robot) brings the page back by itself. Nothing is queued while disconnected: a
// /cmd_vel published to a dead socket is dropped, never replayed later.
//
// Each attempt gets a new ROSLIB.Ros and new ROSLIB.Topic objects. (roslibjs's own
// re-subscription, reconnect_on_close, replays on the same Ros object; turning it off breaks
// subscribe() in roslib 1.4.1, whose fallback calls callOnConnection unbound. The old Ros's
// replay handlers wait for a 'connection' that never comes: harmless.)

/** rosbridge's conventional port. */
export const DEFAULT_WS_PORT = 9090;

/** Reconnect delays: the first retry after RETRY_FIRST_MS, doubling up to RETRY_MAX_MS. */
export const RETRY_FIRST_MS = 500;
export const RETRY_MAX_MS = 5000;

/** A service call that gets no answer in this time fails (the bridge gives up after 5 s). */
export const SERVICE_TIMEOUT_MS = 6000;

/** ws://HOST:9090 for the page's host (wss:// when the page came over https). */
export function defaultWsUrl(location) {
  const scheme = location.protocol === 'https:' ? 'wss' : 'ws';
  const host = location.hostname || 'localhost';
  return `${scheme}://${host}:${DEFAULT_WS_PORT}`;
}

/**
 * A bridge address as a WebSocket URL: ws:// and wss:// URLs as they are; a path such as
 * /rosbridge (a bridge proxied by the page's own server) on the page's host and port.
 */
export function resolveWsUrl(value, location) {
  const text = value.trim();
  if (!text.startsWith('/')) return text;
  const scheme = location.protocol === 'https:' ? 'wss' : 'ws';
  return `${scheme}://${location.host}${text}`;
}

/**
 * The bridge of the page's own server: `configured` (config.json's choice for this site, set
 * by whoever runs the server), else defaultWsUrl(). The one bridge the admin token goes to.
 */
export function ownWsUrl(location, configured = null) {
  return typeof configured === 'string' && configured.trim()
    ? resolveWsUrl(configured, location) : defaultWsUrl(location);
}

/** The bridge the address bar's ?ws= names (resolved like any bridge address), or null. */
export function linkedWsUrl(location) {
  const value = new URLSearchParams(location.search).get('ws');
  return value && value.trim() ? resolveWsUrl(value, location) : null;
}

/**
 * `href` (a link to another page of this site) carrying this page's ?ws=, so the page it opens
 * dials the bridge this one was told to; unchanged without one. Same-origin path and query.
 */
export function withPageBridge(href, location) {
  const ws = new URLSearchParams(location.search).get('ws');
  if (!ws || !ws.trim()) return href;
  const target = new URL(href, location.href);
  target.searchParams.set('ws', ws);
  return `${target.pathname}${target.search}${target.hash}`;
}

/** The WebSocket URL a page starts with: its ?ws= parameter, else ownWsUrl(). */
export function initialWsUrl(location, configured = null) {
  return linkedWsUrl(location) ?? ownWsUrl(location, configured);
}

/**
 * True when the WebSocket URLs `a` and `b` name the same bridge: equal once parsed (scheme,
 * user, host, port and path, query; `ws://h:9090` is `ws://h:9090/`), the fragment aside.
 * False when either is not a URL.
 */
export function sameBridge(a, b) {
  const parse = (text) => {
    try {
      const url = new URL(String(text).trim());
      url.hash = '';
      return url.href;
    } catch {
      return null;
    }
  };
  const first = parse(a);
  return first !== null && first === parse(b);
}

/**
 * The admin token to send to the bridge at `url`: `token` when `url` is `ownUrl`, the page's
 * own bridge (ownWsUrl()), else ''. A bridge named by a link or typed into the page never
 * gets it: anybody can send an instructor a link.
 */
export function tokenFor(url, ownUrl, token) {
  return token && ownUrl && sameBridge(url, ownUrl) ? token : '';
}

/**
 * The site's settings from config.json next to the pages: {ws, adminWs}, each a bridge URL or
 * path, or null for the default. A missing or broken file means defaults: {}.
 */
export async function loadSiteConfig(fetchImpl = globalThis.fetch) {
  try {
    const response = await fetchImpl('config.json', { cache: 'no-cache' });
    if (!response.ok) return {};
    const config = await response.json();
    return config && typeof config === 'object' ? config : {};
  } catch {
    return {};
  }
}

/** `url` with `token=TOKEN` added to its query (`?` or `&`); unchanged without a token. */
export function withToken(url, token) {
  if (!token) return url;
  const [base, fragment] = url.split('#', 2);
  const joined = `${base}${base.includes('?') ? '&' : '?'}token=${encodeURIComponent(token)}`;
  return fragment === undefined ? joined : `${joined}#${fragment}`;
}

/** Where /admin keeps the admin token: sessionStorage, so one tab, until it closes. */
export const TOKEN_KEY = 'websim.adminToken';

/** The token from ?token= (then stored and stripped from the address bar) or this tab's store. */
export function takeToken(location, history, storage) {
  const address = new URL(location.href);
  const fromUrl = address.searchParams.get('token');
  if (fromUrl) {
    storage.setItem(TOKEN_KEY, fromUrl);
    address.searchParams.delete('token');
    history.replaceState(null, '', address);
  }
  return storage.getItem(TOKEN_KEY) ?? '';
}

/** Where a class robot's page keeps its robot's token: localStorage, per robot page path. */
export const ROBOT_TOKEN_PREFIX = 'websim.robotToken:';

/**
 * The robot's token a student's page holds: from the links file's #token= (or ?token=), then
 * kept in `storage` under the page's path and taken out of the address bar (and so out of
 * any Referer and bookmark), else what `storage` kept for this robot; '' without one.
 */
export function takeRobotToken(location, history, storage) {
  const address = new URL(location.href);
  const hash = new URLSearchParams(address.hash.replace(/^#/, ''));
  const fromUrl = hash.get('token') || address.searchParams.get('token');
  const key = ROBOT_TOKEN_PREFIX + address.pathname;
  if (fromUrl) {
    storage.setItem(key, fromUrl);
    address.searchParams.delete('token');
    hash.delete('token');
    const rest = hash.toString();
    address.hash = rest ? `#${rest}` : '';
    history.replaceState(null, '', address);
  }
  return storage.getItem(key) ?? '';
}

/** Keep `token` as this robot page's token (an open class handed it to this page). */
export function keepRobotToken(location, storage, token) {
  storage.setItem(ROBOT_TOKEN_PREFIX + new URL(location.href).pathname, token);
}

/** `url` with any token= parameter removed: what may be shown or logged. */
export function withoutToken(url) {
  return url.replace(/([?&])token=[^&#]*(&?)/, (match, sep, next) => (next ? sep : ''))
    .replace(/[?&]$/, '');
}

/**
 * Delay (ms) before reconnect attempt number `attempt` (0-based): exponential backoff, with
 * +-20 % jitter so a classroom of browsers does not reconnect in lockstep.
 */
export function retryDelayMs(attempt, random = Math.random) {
  const base = Math.min(RETRY_MAX_MS, RETRY_FIRST_MS * 2 ** attempt);
  return Math.round(base * (0.8 + 0.4 * random()));
}

/** A service call the bridge answered with a failure; the message is its reason. */
export class ServiceCallError extends Error {
  constructor(reason) {
    super(String(reason));
    this.name = 'ServiceCallError';
  }
}

/**
 * A rosbridge connection that keeps itself up.
 *
 * Events (EventTarget): 'status' with detail {status, url, message}, where status is one of
 * connecting, connected, closed, error; 'connected'; 'disconnected'; 'beforeclose' (sent
 * while still connected, before the page closes the socket itself: last words such as a zero
 * velocity command go there); 'published' with detail {topic, msg} after each message this
 * page's publishers sent.
 */
export class Connection extends EventTarget {
  /**
   * @param {object} ROSLIB the roslibjs namespace
   * @param {{url: string, token?: string, tokenUrl?: string}} options token: the admin token,
   *   sent as ?token= (never shown) only to tokenUrl, the page's own bridge (tokenFor())
   */
  constructor(ROSLIB, { url, token = '', tokenUrl = null }) {
    super();
    this.ROSLIB = ROSLIB;
    this.url = url;
    this.token = token;
    this.tokenUrl = tokenUrl;
    this.status = 'closed';
    this.message = '';
    this._ros = null;
    this._attempt = 0;
    this._retryTimer = null;
    this._wanted = false;
    this._subscriptions = new Set();
    this._publishers = new Map(); // topic -> {topic, type, handle, api}
  }

  get isConnected() {
    return this.status === 'connected';
  }

  /** True when the current bridge gets the token: the page has one and this is its own bridge. */
  get sendsToken() {
    return Boolean(tokenFor(this.url, this.tokenUrl, this.token));
  }

  /** Connects (or reconnects now) to `url`, or to the current URL. */
  connect(url = this.url, token = this.token) {
    this._shutdown();
    this.url = url;
    this.token = token;
    this._wanted = true;
    this._attempt = 0;
    this._open();
  }

  /** Closes the connection for good (no reconnect); 'beforeclose' listeners speak first. */
  close() {
    this._wanted = false;
    this._shutdown();
    this._setStatus('closed', 'disconnected');
  }

  /**
   * Subscribes `onMessage(msg)` to `topic` on this and every later socket.
   * @returns {() => void} unsubscribe
   */
  subscribe(topic, type, onMessage, { throttleMs = 0, queueLength = 1 } = {}) {
    const entry = { topic, type, onMessage, throttleMs, queueLength, handle: null };
    this._subscriptions.add(entry);
    if (this.isConnected) this._attach(entry);
    return () => {
      this._subscriptions.delete(entry);
      if (entry.handle && this.isConnected) entry.handle.unsubscribe();
      entry.handle = null;
    };
  }

  /**
   * The page's publisher on `topic` (one per topic): publish(msg) sends now and returns true,
   * or drops the message and returns false when not connected.
   */
  publisher(topic, type) {
    const existing = this._publishers.get(topic);
    if (existing) return existing.api;
    const entry = { topic, type, handle: null, api: null };
    this._publishers.set(topic, entry);
    entry.api = {
      publish: (msg) => {
        if (!this.isConnected) return false;
        if (!entry.handle) {
          entry.handle = new this.ROSLIB.Topic({
            ros: this._ros, name: topic, messageType: type,
          });
        }
        entry.handle.publish(new this.ROSLIB.Message(msg));
        this.dispatchEvent(new CustomEvent('published', { detail: { topic, msg } }));
        return true;
      },
    };
    return entry.api;
  }

  /**
   * Calls a service; resolves with its response. Rejects with a ServiceCallError carrying the
   * bridge's reason (e.g. "set_parameters needs admin rights; ..."), or an Error when not
   * connected or on a timeout.
   */
  callService(name, type, request = {}, timeoutMs = SERVICE_TIMEOUT_MS) {
    if (!this.isConnected) {
      return Promise.reject(new Error(`not connected to ${withoutToken(this.url)}`));
    }
    const service = new this.ROSLIB.Service({ ros: this._ros, name, serviceType: type });
    return new Promise((resolve, reject) => {
      const timer = setTimeout(
        () => reject(new Error(`${name}: no answer within ${timeoutMs / 1000} s`)), timeoutMs);
      service.callService(new this.ROSLIB.ServiceRequest(request),
        (response) => { clearTimeout(timer); resolve(response); },
        (reason) => { clearTimeout(timer); reject(new ServiceCallError(reason)); });
    });
  }

  _open() {
    let ros;
    const shownUrl = withoutToken(this.url);
    try {
      const token = tokenFor(this.url, this.tokenUrl, this.token); // the one place it is sent
      ros = new this.ROSLIB.Ros({ url: withToken(this.url, token) });
    } catch (error) {
      this._wanted = false;
      this._setStatus('error', `"${shownUrl}" is not a WebSocket URL (${error.message})`);
      return;
    }
    this._ros = ros;
    let opened = false;
    let failed = false;
    // While retrying, the message keeps saying what is wrong instead of flickering.
    this._setStatus('connecting', this._attempt === 0 ? `connecting to ${shownUrl}…` : this.message);
    ros.on('connection', () => {
      if (ros !== this._ros) return;
      opened = true;
      this._attempt = 0;
      for (const entry of this._subscriptions) this._attach(entry);
      this._setStatus('connected', `connected to ${shownUrl}`);
      this.dispatchEvent(new Event('connected'));
    });
    ros.on('error', () => {
      failed = true;
    });
    ros.on('close', () => {
      if (ros !== this._ros) return;
      this._detachAll();
      this._ros = null;
      if (opened) this.dispatchEvent(new Event('disconnected'));
      this._retryTimer = setTimeout(() => this._open(), retryDelayMs(this._attempt));
      this._attempt += 1;
      if (opened) {
        this._setStatus('closed', `The connection to ${shownUrl} was lost. Reconnecting…`);
      } else {
        this._setStatus(failed ? 'error' : 'closed', `Cannot reach the bridge at ${shownUrl}. `
          + 'Is websim serve (or rosbridge) running? Retrying…');
      }
    });
  }

  _attach(entry) {
    const handle = new this.ROSLIB.Topic({
      ros: this._ros,
      name: entry.topic,
      messageType: entry.type,
      throttle_rate: entry.throttleMs,
      queue_length: entry.queueLength,
    });
    handle.subscribe((msg) => {
      try {
        entry.onMessage(msg);
      } catch (error) {
        console.warn(`websim: a ${entry.topic} message could not be used:`, error);
      }
    });
    entry.handle = handle;
  }

  _detachAll() {
    for (const entry of this._subscriptions) entry.handle = null;
    for (const entry of this._publishers.values()) entry.handle = null;
  }

  _shutdown() {
    clearTimeout(this._retryTimer);
    this._retryTimer = null;
    const ros = this._ros;
    if (!ros) return;
    if (this.isConnected) {
      this.dispatchEvent(new Event('beforeclose'));
      this.dispatchEvent(new Event('disconnected'));
    }
    this._ros = null;
    this._detachAll();
    ros.close();
  }

  _setStatus(status, message) {
    this.status = status;
    this.message = message;
    this.dispatchEvent(new CustomEvent('status', {
      detail: { status, message, url: withoutToken(this.url) },
    }));
  }
}
