// Status polling (web-interface/js/class-poller.js): every robot about every 2 s, staggered,
// never two calls out for one robot, against mocked timers.
import assert from 'node:assert/strict';
import { test } from 'node:test';

import {
  MIN_POLL_GAP_MS, pollGapMs, STATUS_PERIOD_MS, StatusPoller,
} from '../../web-interface/js/class-poller.js';

const flush = () => new Promise((resolve) => { setImmediate(resolve); });

test('the gap between calls is the period shared by the class, never below the minimum', () => {
  assert.equal(pollGapMs(4), STATUS_PERIOD_MS / 4);
  assert.equal(pollGapMs(40), 50);
  assert.equal(pollGapMs(1000), MIN_POLL_GAP_MS);
  assert.equal(pollGapMs(0), STATUS_PERIOD_MS);
});

test('each robot is asked once per period, at evenly spaced times', async (t) => {
  t.mock.timers.enable({ apis: ['setTimeout'] });
  const asked = [];
  let clock = 0;
  const poller = new StatusPoller({
    names: () => ['a', 'b', 'c', 'd'],
    poll: async (name) => { asked.push([name, clock]); },
    timers: globalThis,
  });
  poller.start();
  for (clock = 0; clock <= 2 * STATUS_PERIOD_MS; clock += 100) {
    t.mock.timers.tick(clock === 0 ? 0 : 100);
    await flush();
  }
  poller.stop();
  assert.deepEqual(asked.slice(0, 5), [['a', 0], ['b', 500], ['c', 1000], ['d', 1500], ['a', 2000]]);
  assert.equal(asked.length, 9); // 0 to 4000 ms inclusive, one every 500 ms
  assert.equal(poller.running, false);
});

test('a robot whose call is still out is skipped; it is asked again once answered', async (t) => {
  t.mock.timers.enable({ apis: ['setTimeout'] });
  const asked = [];
  let release;
  const poller = new StatusPoller({
    names: () => ['slow', 'fast'],
    poll: (name) => {
      asked.push(name);
      return name === 'slow' ? new Promise((resolve) => { release = resolve; }) : Promise.resolve();
    },
  });
  poller.start();
  for (let i = 0; i < 4; i += 1) { // 0, 1000, 2000, 3000 ms: slow, fast, (slow out), fast
    t.mock.timers.tick(i === 0 ? 0 : pollGapMs(2));
    await flush();
  }
  assert.deepEqual(asked, ['slow', 'fast', 'fast']);
  release();
  await flush();
  t.mock.timers.tick(pollGapMs(2));
  await flush();
  assert.deepEqual(asked, ['slow', 'fast', 'fast', 'slow']);
  poller.pollNow('fast'); // after a command: at once
  await flush();
  assert.deepEqual(asked.at(-1), 'fast');
  poller.stop();
});

test('robots that join later are polled; an empty class waits a period', async (t) => {
  t.mock.timers.enable({ apis: ['setTimeout'] });
  const names = [];
  const asked = [];
  const poller = new StatusPoller({ names: () => names, poll: async (n) => { asked.push(n); } });
  poller.start();
  t.mock.timers.tick(0);
  await flush();
  assert.deepEqual(asked, []);
  names.push('late');
  t.mock.timers.tick(STATUS_PERIOD_MS);
  await flush();
  assert.deepEqual(asked, ['late']);
  poller.stop();
});

test('a failing poll does not stop the round', async (t) => {
  t.mock.timers.enable({ apis: ['setTimeout'] });
  const asked = [];
  const poller = new StatusPoller({
    names: () => ['x'],
    poll: async (name) => { asked.push(name); throw new Error('refused'); },
  });
  poller.start();
  for (let i = 0; i < 3; i += 1) {
    t.mock.timers.tick(i === 0 ? 0 : STATUS_PERIOD_MS);
    await flush();
  }
  assert.deepEqual(asked, ['x', 'x', 'x']);
  poller.stop();
});
