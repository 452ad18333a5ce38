// The class's status (web-interface/js/class-poller.js): one call per root, asked again a
// period after each answer, never two out at once, at once after a command; mocked timers.
import assert from 'node:assert/strict';
import { test } from 'node:test';

import { STATUS_PERIOD_MS, StatusPoller } from '../../web-interface/js/class-poller.js';

const flush = () => new Promise((resolve) => { setImmediate(resolve); });

/** A poller whose calls are recorded (at the mocked clock) and answered when `answer` says. */
function recorded(t, { answerAtOnce = true } = {}) {
  t.mock.timers.enable({ apis: ['setTimeout'] });
  const asked = [];
  const pending = [];
  let clock = 0;
  const poller = new StatusPoller({
    poll: () => {
      asked.push(clock);
      if (answerAtOnce) return Promise.resolve();
      return new Promise((resolve) => { pending.push(resolve); });
    },
  });
  const advance = async (ms) => {
    clock += ms;
    t.mock.timers.tick(ms);
    await flush();
  };
  return { poller, asked, pending, advance };
}

test('the class is asked at once, then a period after each answer: twice a second', async (t) => {
  const { poller, asked, advance } = recorded(t);
  poller.start();
  await flush();
  for (let i = 0; i < 20; i += 1) await advance(100);
  poller.stop();
  assert.equal(STATUS_PERIOD_MS, 500);
  assert.deepEqual(asked, [0, 500, 1000, 1500, 2000]);
  assert.equal(poller.running, false);
  await advance(2000);
  assert.equal(asked.length, 5, 'stopped: nothing more is asked');
});

test('never two calls out: a slow answer delays the next call, it does not pile up', async (t) => {
  const { poller, asked, pending, advance } = recorded(t, { answerAtOnce: false });
  poller.start();
  await flush();
  await advance(3000); // the first call is still out
  assert.deepEqual(asked, [0]);
  pending.shift()();
  await flush();
  await advance(STATUS_PERIOD_MS);
  assert.deepEqual(asked, [0, 3500]);
  poller.stop();
});

test('after a command the class is asked at once, or right after the call that is out',
  async (t) => {
    const { poller, asked, pending, advance } = recorded(t, { answerAtOnce: false });
    poller.start();
    await flush();
    pending.shift()(); // answered at 0: the next would be at 500
    await flush();
    await advance(100);
    poller.pollNow(); // at 100: asked now
    await flush();
    assert.deepEqual(asked, [0, 100]);
    poller.pollNow(); // the call is out: once more after it, however many commands
    poller.pollNow();
    await advance(50);
    assert.deepEqual(asked, [0, 100]);
    pending.shift()();
    await flush();
    assert.deepEqual(asked, [0, 100, 150]);
    pending.shift()();
    await flush();
    await advance(STATUS_PERIOD_MS);
    assert.deepEqual(asked, [0, 100, 150, 650]);
    poller.stop();
    poller.pollNow(); // stopped (the root is down): nothing
    await advance(STATUS_PERIOD_MS);
    assert.equal(asked.length, 4);
  });

test('a failing call does not stop the polling; a restart ends the old round', async (t) => {
  t.mock.timers.enable({ apis: ['setTimeout'] });
  let calls = 0;
  const poller = new StatusPoller({ poll: async () => { calls += 1; throw new Error('refused'); } });
  poller.start();
  await flush();
  for (let i = 0; i < 2; i += 1) {
    t.mock.timers.tick(STATUS_PERIOD_MS);
    await flush();
  }
  assert.equal(calls, 3);
  poller.start(); // a reconnect: asked at once, one round only
  await flush();
  assert.equal(calls, 4);
  t.mock.timers.tick(STATUS_PERIOD_MS);
  await flush();
  assert.equal(calls, 5);
  poller.stop();
});
