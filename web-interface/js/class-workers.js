// Where a class's root views are. One `websim serve --class` process has one, at its
// WebSocket root. A class spread over `--worker` processes behind nginx has one per worker:
// the nginx that `websim nginx-config` writes lists their paths in /workers.json on the page
// port ({"workers": ["/workers/0/", "/workers/1/"]}) and proxies each path to that worker's
// root on the WebSocket port. Pure functions and one fetch: no DOM, no connection.
//
// The document names paths, never URLs: they are joined to the page's own bridge address
// (class-plan.js rootWsUrl), so the instructor's token goes to this server and nowhere else.

/** The page server's list of workers, relative to the page (as /class is, at the top). */
export const WORKERS_URL = 'workers.json';

/** A worker's root path: absolute, no query or fragment, nothing but path characters. */
const WORKER_PATH = /^\/(?!\/)[A-Za-z0-9._~%/-]*$/;

/** Most workers a class may list: the dashboard holds one WebSocket per worker. */
export const MAX_WORKERS = 64;

/** Thrown when workers.json is there but is not a list of worker paths. */
export class WorkersError extends Error {
  constructor(reason) {
    super(`${WORKERS_URL}: ${reason}; expected {"workers": ["/workers/0/", ...]} (websim `
      + 'nginx-config writes it)');
    this.name = 'WorkersError';
  }
}

/** The worker paths of a workers.json document, each once, in order; throws WorkersError. */
export function parseWorkers(document) {
  const workers = document?.workers;
  if (!Array.isArray(workers)) throw new WorkersError('no "workers" list');
  if (workers.length === 0) throw new WorkersError('the "workers" list is empty');
  if (workers.length > MAX_WORKERS) {
    throw new WorkersError(`${workers.length} workers, more than ${MAX_WORKERS}`);
  }
  for (const path of workers) {
    if (typeof path !== 'string' || !WORKER_PATH.test(path)) {
      throw new WorkersError(`${JSON.stringify(path)?.slice(0, 80)} is not a path on this server`);
    }
  }
  return [...new Set(workers)];
}

/**
 * The page server's worker paths (parseWorkers), or null when one process serves the class:
 * its workers.json says {"workers": null} (websim serve's own), or it has none (a 404) or does
 * not answer. Throws WorkersError for a document that is there but wrong: guessing a single
 * process then would show an empty class.
 */
export async function loadWorkers(fetchImpl = globalThis.fetch) {
  let response;
  try {
    response = await fetchImpl(WORKERS_URL, { cache: 'no-store' });
  } catch {
    return null;
  }
  if (!response.ok) return null;
  let document;
  try {
    document = await response.json();
  } catch (error) {
    throw new WorkersError(`not JSON (${error.message})`);
  }
  if (document?.workers === null) return null;
  return parseWorkers(document);
}

/** `rootUrl` (ws://HOST:PORT/) with its path replaced by worker path `path`. */
export function workerWsUrl(rootUrl, path) {
  const url = new URL(rootUrl);
  url.pathname = path;
  url.search = '';
  url.hash = '';
  return url.href;
}

/**
 * The root connections the dashboard opens: one per worker path (`workers` from
 * loadWorkers), else `rootUrl` alone. Each {url, label}: label names it in messages ('' for
 * the single root, whose messages are as they always were).
 */
export function rootTargets(rootUrl, workers) {
  if (!workers) return [{ url: rootUrl, label: '' }];
  return workers.map((path, index) => ({
    url: workerWsUrl(rootUrl, path), label: `Worker ${index} (${path})`,
  }));
}
