// Where the dashboard's root connections are (web-interface/js/class-workers.js): nginx's
// /workers.json read and checked, each worker path joined to the page's own bridge, and no
// workers.json (a 404 from a single process) meaning the one root as before.
import assert from 'node:assert/strict';
import { test } from 'node:test';

import {
  loadWorkers, MAX_WORKERS, parseWorkers, rootTargets, WORKERS_URL, WorkersError, workerWsUrl,
} from '../../web-interface/js/class-workers.js';
import { rootWsUrl } from '../../web-interface/js/class-plan.js';

const answer = (status, body) => async (url, options) => {
  assert.equal(url, WORKERS_URL);
  assert.deepEqual(options, { cache: 'no-store' });
  return {
    ok: status >= 200 && status < 300,
    status,
    json: async () => (typeof body === 'string' ? JSON.parse(body) : body),
  };
};

test('workers.json as websim nginx-config writes it: each path once, in order', async () => {
  const written = '{"workers": ["/workers/0/", "/workers/1/"]}\n';
  assert.deepEqual(await loadWorkers(answer(200, written)), ['/workers/0/', '/workers/1/']);
  assert.deepEqual(parseWorkers({ workers: ['/w/a/', '/w/b/', '/w/a/'] }), ['/w/a/', '/w/b/']);
});

test('no workers.json, or no answer: a single process, one root as before', async () => {
  assert.equal(await loadWorkers(answer(200, '{"about": "one process", "workers": null}')),
    null, 'websim serve\'s own answer');
  assert.equal(await loadWorkers(answer(404, 'not json')), null);
  assert.equal(await loadWorkers(async () => { throw new TypeError('offline'); }), null);
  const root = rootWsUrl({ protocol: 'http:', hostname: 'lab', host: 'lab:8080' }, null);
  assert.deepEqual(rootTargets(root, null), [{ url: 'ws://lab:9090/', label: '' }]);
});

test('a workers.json that is there but wrong is an error that says what was expected', async () => {
  await assert.rejects(loadWorkers(answer(200, '<html>')),
    (error) => error instanceof WorkersError && /workers\.json: not JSON/.test(error.message)
      && error.message.includes('{"workers": ["/workers/0/", ...]}'));
  const wrong = [
    [{}, /no "workers" list/],
    [{ workers: '/workers/0/' }, /no "workers" list/],
    [{ workers: [] }, /empty/],
    [{ workers: ['ws://elsewhere:9090/'] },
      /"ws:\/\/elsewhere:9090\/" is not a path on this server/],
    [{ workers: ['//elsewhere/'] }, /not a path/],
    [{ workers: ['/workers/0/?token=x'] }, /not a path/],
    [{ workers: [7] }, /7 is not a path/],
    [{ workers: Array.from({ length: MAX_WORKERS + 1 }, (_, i) => `/workers/${i}/`) },
      new RegExp(`more than ${MAX_WORKERS}`)],
  ];
  for (const [document, reason] of wrong) {
    assert.throws(() => parseWorkers(document), (error) => error instanceof WorkersError
      && reason.test(error.message), JSON.stringify(document).slice(0, 60));
  }
});

test('each worker is its path on the page\'s own bridge, where the token may go', () => {
  const page = { protocol: 'http:', hostname: 'lab', host: 'lab:8080' };
  const root = rootWsUrl(page, 'ws://lab:9090/robots/alice'); // config.json: the bridge
  assert.equal(workerWsUrl(root, '/workers/1/'), 'ws://lab:9090/workers/1/');
  assert.equal(workerWsUrl(rootWsUrl({ ...page, protocol: 'https:' }), '/workers/0/'),
    'wss://lab:9090/workers/0/');
  assert.deepEqual(rootTargets(root, ['/workers/0/', '/workers/1/']), [
    { url: 'ws://lab:9090/workers/0/', label: 'Worker 0 (/workers/0/)' },
    { url: 'ws://lab:9090/workers/1/', label: 'Worker 1 (/workers/1/)' },
  ]);
});
