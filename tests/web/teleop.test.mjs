// Teleop (web-interface/js/teleop.js): key demands, which elements keep the keys, and the
// /cmd_vel rhythm: at once on press, 10 Hz while held, zero on release and on stop.
import assert from 'node:assert/strict';
import { test } from 'node:test';

import {
  keyDemand, keysBelongToElement, PUBLISH_PERIOD_MS, spaceBelongsToElement, Teleop,
} from '../../web-interface/js/teleop.js';
import { createState } from '../../web-interface/js/state.js';
import { robot } from './robot.mjs';

test('arrow keys and WASD: forward, back, turn left (+z), turn right (-z), combined', () => {
  assert.deepEqual(keyDemand(new Set(['ArrowUp'])), [1, 0]);
  assert.deepEqual(keyDemand(new Set(['s'])), [-1, 0]);
  assert.deepEqual(keyDemand(new Set(['a'])), [0, 1]);
  assert.deepEqual(keyDemand(new Set(['ArrowRight'])), [0, -1]);
  assert.deepEqual(keyDemand(new Set(['w', 'ArrowUp', 'd'])), [1, -1]); // clamped to 1
  assert.deepEqual(keyDemand(new Set(['w', 's'])), [0, 0]);
  assert.deepEqual(keyDemand(new Set(['x'])), [0, 0]);
});

test('text fields, selects and sliders keep the keys; buttons do not', () => {
  assert.equal(keysBelongToElement({ tagName: 'INPUT', type: 'text' }), true);
  assert.equal(keysBelongToElement({ tagName: 'INPUT', type: 'number' }), true);
  assert.equal(keysBelongToElement({ tagName: 'INPUT', type: 'range' }), true);
  assert.equal(keysBelongToElement({ tagName: 'TEXTAREA' }), true);
  assert.equal(keysBelongToElement({ tagName: 'DIV', isContentEditable: true }), true);
  assert.equal(keysBelongToElement({ tagName: 'INPUT', type: 'checkbox' }), false);
  assert.equal(keysBelongToElement({ tagName: 'BUTTON' }), false);
  assert.equal(keysBelongToElement({ tagName: 'BODY' }), false);
  assert.equal(keysBelongToElement(null), false);
});

test('a space is typed into text fields only: on a slider, a button or a checkbox it stops', () => {
  assert.equal(spaceBelongsToElement({ tagName: 'INPUT', type: 'text' }), true);
  assert.equal(spaceBelongsToElement({ tagName: 'TEXTAREA' }), true);
  assert.equal(spaceBelongsToElement({ tagName: 'INPUT', type: 'range' }), false);
  assert.equal(spaceBelongsToElement({ tagName: 'INPUT', type: 'checkbox' }), false);
  assert.equal(spaceBelongsToElement({ tagName: 'BUTTON' }), false);
  assert.equal(spaceBelongsToElement(null), false);
});

function fakeConnection() {
  const sent = [];
  const publishers = [];
  const connection = new EventTarget();
  connection.publisher = (topic, type) => {
    publishers.push([topic, type]);
    return {
      publish: (msg) => {
        sent.push([msg.linear.x, msg.angular.z]);
        return true;
      },
    };
  };
  return { connection, sent, publishers };
}

test('teleop publishes on robot.json\'s cmd_vel and starts below its limits', () => {
  const { connection, publishers } = fakeConnection();
  const teleop = new Teleop(connection, createState(), robot);
  assert.deepEqual(publishers, [[robot.topics.cmd_vel.name, robot.topics.cmd_vel.type]]);
  assert.ok(teleop.speed.linear > 0 && teleop.speed.linear < robot.robot.max_linear_mps);
  assert.ok(teleop.speed.angular > 0 && teleop.speed.angular < robot.robot.max_angular_rps);
});

test('publishes at once, every 100 ms while held, and a zero on release', (t) => {
  t.mock.timers.enable({ apis: ['setInterval'] });
  const { connection, sent } = fakeConnection();
  const state = createState();
  const teleop = new Teleop(connection, state, robot);
  teleop.speed = { linear: 0.4, angular: 2 };
  let drives = 0;
  teleop.addEventListener('drive', () => { drives += 1; });
  teleop.set('keys', 1, 0);
  assert.deepEqual(sent, [[0.4, 0]]);
  t.mock.timers.tick(PUBLISH_PERIOD_MS * 3);
  assert.equal(sent.length, 4);
  teleop.set('joystick', 0.5, -0.5); // two sources add up, clamped to the unit square
  t.mock.timers.tick(PUBLISH_PERIOD_MS);
  assert.deepEqual(sent.at(-1), [0.4, -1]);
  teleop.set('keys', 0, 0);
  t.mock.timers.tick(PUBLISH_PERIOD_MS);
  assert.deepEqual(sent.at(-1), [0.2, -1]);
  teleop.set('joystick', 0, 0);
  assert.deepEqual(sent.at(-1), [0, 0]);
  const count = sent.length;
  t.mock.timers.tick(PUBLISH_PERIOD_MS * 5);
  assert.equal(sent.length, count); // released: quiet
  assert.equal(drives, 1);
  assert.deepEqual(state.command, { linear: 0, angular: 0 });
});

test('stop and a disconnect the page asks for send a zero Twist', (t) => {
  t.mock.timers.enable({ apis: ['setInterval'] });
  const { connection, sent } = fakeConnection();
  const teleop = new Teleop(connection, createState(), robot);
  teleop.set('keys', 1, 0);
  teleop.stop();
  assert.deepEqual(sent.at(-1), [0, 0]);
  assert.equal(teleop.active, false);
  teleop.set('button:forward', 1, 0);
  connection.dispatchEvent(new Event('beforeclose'));
  assert.deepEqual(sent.at(-1), [0, 0]);
  const count = sent.length;
  t.mock.timers.tick(PUBLISH_PERIOD_MS * 5);
  assert.equal(sent.length, count);
});
