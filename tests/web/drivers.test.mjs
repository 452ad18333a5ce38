// Who else drives (web-interface/js/drivers.js): the page's own echoes are not foreign, any
// other Twist is, and the page says so for FOREIGN_SHOW_MS after the last one.
import assert from 'node:assert/strict';
import { test } from 'node:test';

import {
  createDrivers, FOREIGN_SHOW_MS, noteCommand, noteOwnCommand, OWN_ECHO_MS, othersDriving,
  sameTwist, twistFields,
} from '../../web-interface/js/drivers.js';
import { twist } from '../../web-interface/js/ros-msgs.js';

/** What the bridge relays: every field filled, as floats (JSON cannot tell 0 from 0.0). */
function canonical(msg) {
  return JSON.parse(JSON.stringify({
    linear: { x: 0, y: 0, z: 0, ...msg.linear },
    angular: { x: 0, y: 0, z: 0, ...msg.angular },
  }));
}

test('Twists are compared field by field, within a small tolerance', () => {
  assert.deepEqual(twistFields(twist(0.3, -1)), [0.3, 0, 0, 0, 0, -1]);
  assert.deepEqual(twistFields({ linear: { x: 1 } }), [1, 0, 0, 0, 0, 0]); // missing reads 0
  assert.ok(sameTwist(twist(0.3, 0), { linear: { x: 0.1 + 0.2, y: 0, z: 0 },
    angular: { x: 0, y: 0, z: 0 } }));
  assert.ok(sameTwist(twist(0, 0), canonical({})));
  assert.ok(!sameTwist(twist(0.3, 0), twist(0.3, 0.01)));
  assert.ok(!sameTwist(twist(0, 0), { linear: { x: 0, y: 0, z: 0.5 }, angular: {} }));
  assert.ok(!sameTwist(twist(0, 0), { linear: { x: null }, angular: {} })); // JSON's NaN
});

test('the echo of the page\'s own command is not foreign', () => {
  const drivers = createDrivers();
  for (let t = 0; t < 1000; t += 100) {
    noteOwnCommand(drivers, twist(0.3, 0), t);
    assert.equal(noteCommand(drivers, canonical(twist(0.3, 0)), t + 15), false);
    assert.equal(othersDriving(drivers, t + 15), false);
  }
  noteOwnCommand(drivers, twist(0, 0), 1000); // the zero on release
  assert.equal(noteCommand(drivers, canonical(twist(0, 0)), 1020), false);
  assert.equal(othersDriving(drivers, 1020), false);
});

test('an echo may come late, and after later sends', () => {
  const drivers = createDrivers();
  noteOwnCommand(drivers, twist(0.3, 0), 0);
  noteOwnCommand(drivers, twist(0.3, 0.5), 100);
  noteOwnCommand(drivers, twist(0, 0), 200);
  assert.equal(noteCommand(drivers, canonical(twist(0.3, 0)), OWN_ECHO_MS - 1), false);
  assert.equal(noteCommand(drivers, canonical(twist(0, 0)), OWN_ECHO_MS), false);
  assert.equal(noteCommand(drivers, canonical(twist(0.3, 0.5)), OWN_ECHO_MS + 50), false);
  assert.equal(othersDriving(drivers, OWN_ECHO_MS + 50), false);
});

test('a Twist the page did not send is foreign', () => {
  const drivers = createDrivers();
  noteOwnCommand(drivers, twist(0.3, 0), 0);
  assert.equal(noteCommand(drivers, canonical(twist(0.2, 0)), 10), true);
  assert.equal(othersDriving(drivers, 10), true);
  assert.equal(noteCommand(drivers, canonical(twist(0.3, 0)), 20), false); // ours still is ours
});

test('each own command explains one echo: an equal Twist from another tab is foreign', () => {
  const drivers = createDrivers();
  noteOwnCommand(drivers, twist(0.3, 0), 0);
  assert.equal(noteCommand(drivers, canonical(twist(0.3, 0)), 10), false);
  assert.equal(noteCommand(drivers, canonical(twist(0.3, 0)), 30), true);
});

test('an own command older than OWN_ECHO_MS explains nothing', () => {
  const drivers = createDrivers();
  noteOwnCommand(drivers, twist(0.3, 0), 0);
  assert.equal(noteCommand(drivers, canonical(twist(0.3, 0)), OWN_ECHO_MS + 1), true);
  assert.equal(drivers.own.length, 0);
});

test('a zero Twist from another client while the page is idle is foreign', () => {
  const drivers = createDrivers();
  assert.equal(othersDriving(drivers, 0), false);
  assert.equal(noteCommand(drivers, canonical(twist(0, 0)), 5000), true);
  assert.equal(othersDriving(drivers, 5000), true);
});

test('the foreign badge lasts FOREIGN_SHOW_MS after the last foreign command', () => {
  const drivers = createDrivers();
  for (let t = 0; t <= 500; t += 100) noteCommand(drivers, canonical(twist(0.1, 0)), t);
  assert.equal(othersDriving(drivers, 500 + FOREIGN_SHOW_MS - 1), true);
  assert.equal(othersDriving(drivers, 500 + FOREIGN_SHOW_MS), false);
  // The page's own driving afterwards does not bring it back.
  noteOwnCommand(drivers, twist(0.3, 0), 3000);
  noteCommand(drivers, canonical(twist(0.3, 0)), 3010);
  assert.equal(othersDriving(drivers, 3010), false);
});

test('the page\'s own commands are not kept longer than OWN_ECHO_MS', () => {
  const drivers = createDrivers();
  for (let t = 0; t <= 10_000; t += 100) noteOwnCommand(drivers, twist(0.3, 0), t);
  assert.ok(drivers.own.length <= OWN_ECHO_MS / 100 + 1);
});
