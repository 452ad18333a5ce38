// Where the Code panel keeps a program, and how it talks to the server about it.
//
// In this browser: localStorage, per robot page and language (a single robot keeps it only
// here). On the server (a class robot whose page has its token): the class state keeps a few
// recent versions per student (websim/code_routes.py), which survive a restart and follow the
// student to another machine. The server's routes live under the page's own path (`code/...`),
// and it says what it offers (`code/starters.json`: saving, submitting, limits).

/** localStorage keys: this prefix, the page's path, the language. */
export const LOCAL_PREFIX = 'websim.code:';

export function localKey(location, language) {
  return `${LOCAL_PREFIX}${new URL(location.href).pathname}:${language}`;
}

/** What this browser kept: {text, savedAt (ms since the epoch)} or null. */
export function loadLocal(storage, key) {
  try {
    const kept = JSON.parse(storage.getItem(key) || 'null');
    return kept && typeof kept.text === 'string' ? kept : null;
  } catch {
    return null;
  }
}

/** Keep `text` in this browser; throws when the browser refuses (its storage is full). */
export function saveLocal(storage, key, text, now = Date.now()) {
  storage.setItem(key, JSON.stringify({ text, savedAt: now }));
  return now;
}

/** UTF-8 bytes of `text` (what the server's size limit counts). */
export function utf8Bytes(text) {
  return new TextEncoder().encode(text).length;
}

/** An answer the server refused: its reason, and the HTTP status. */
export class CodeServerError extends Error {
  constructor(status, reason) {
    super(reason);
    this.name = 'CodeServerError';
    this.status = status;
  }
}

/** The page's server's Code routes (`base`: 'code/', relative to the page). */
export class CodeServer {
  constructor(base, token = '', fetchImpl = globalThis.fetch.bind(globalThis)) {
    this.base = base;
    this.token = token;
    this.fetch = fetchImpl;
  }

  async _call(path, { method = 'GET', body } = {}) {
    const headers = {};
    if (this.token) headers.Authorization = `Bearer ${this.token}`;
    if (body !== undefined) headers['Content-Type'] = 'application/json';
    const response = await this.fetch(this.base + path, {
      method, headers, body: body === undefined ? undefined : JSON.stringify(body), cache: 'no-store',
    });
    const type = response.headers.get('Content-Type') || '';
    const answer = type.startsWith('application/json') ? await response.json()
      : { reason: (await response.text()).slice(0, 300) };
    if (!response.ok) {
      throw new CodeServerError(response.status, answer.reason || `HTTP ${response.status}`);
    }
    return answer;
  }

  /** {assignments, examples, saving, submitting, limits}; null where the server has none. */
  async starters() {
    try {
      return await this._call('starters.json');
    } catch (error) {
      if (error.status === 404) return null;
      throw error;
    }
  }

  saved() {
    return this._call('saved');
  }

  save(language, text, reason) {
    return this._call('saved', { method: 'POST', body: { language, text, reason } });
  }

  submit(language, text, assignment) {
    return this._call('submit', { method: 'POST', body: { language, text, assignment } });
  }

  submission() {
    return this._call('submission');
  }

  async report(scenario) {
    const headers = this.token ? { Authorization: `Bearer ${this.token}` } : {};
    const response = await this.fetch(`${this.base}report/${encodeURIComponent(scenario)}`,
      { headers, cache: 'no-store' });
    if (!response.ok) throw new CodeServerError(response.status, `HTTP ${response.status}`);
    return response.text();
  }
}
