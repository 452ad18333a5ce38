// A button that takes a second click (web-interface/js/confirm.js): "Reset all" asks first.
import assert from 'node:assert/strict';
import { test } from 'node:test';

import { Confirmation } from '../../web-interface/js/confirm.js';

function fakeTimers() {
  const pending = new Map();
  let next = 1;
  return {
    pending,
    setTimer: (fn) => { pending.set(next, fn); return next++; },
    clearTimer: (id) => pending.delete(id),
    fire: () => { for (const [id, fn] of [...pending]) { pending.delete(id); fn(); } },
  };
}

test('the first click asks, the second acts', () => {
  const timers = fakeTimers();
  const button = { textContent: 'Reset all', dataset: {} };
  const confirm = new Confirmation(button, () => 'Reset all 30 robots? Click again', timers);
  assert.equal(confirm.confirmed(), false);
  assert.equal(button.textContent, 'Reset all 30 robots? Click again');
  assert.equal(button.dataset.armed, 'true');
  assert.equal(confirm.confirmed(), true);
  assert.equal(button.textContent, 'Reset all');
  assert.equal(button.dataset.armed, undefined);
  assert.equal(timers.pending.size, 0);
});

test('a second click too late asks again', () => {
  const timers = fakeTimers();
  const button = { textContent: 'Reset all', dataset: {} };
  const confirm = new Confirmation(button, () => 'sure?', timers);
  assert.equal(confirm.confirmed(), false);
  timers.fire(); // the window closed
  assert.equal(button.textContent, 'Reset all');
  assert.equal(confirm.confirmed(), false); // asks again, does not act
});
