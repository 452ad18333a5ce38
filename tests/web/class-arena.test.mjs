// The dashboard's arena map (web-interface/js/class-arena.js): its state from /world and
// /world_robots, on hand-made messages.
import assert from 'node:assert/strict';
import { test } from 'node:test';

import { createArenaState, onArenaRobots, onArenaWorld } from '../../web-interface/js/class-arena.js';
import { MARKER } from '../../web-interface/js/ros-msgs.js';

const robotMarker = (text, x, y) => ({
  ns: 'world_robots', id: 0, type: MARKER.CYLINDER, action: MARKER.ADD, text,
  pose: { position: { x, y, z: 0.06 }, orientation: { x: 0, y: 0, z: 0, w: 1 } },
  scale: { x: 0.22, y: 0.22, z: 0.12 },
});

test('the arena keeps its walls and every robot, none left out as the page\'s own', () => {
  const state = createArenaState();
  onArenaWorld(state, { markers: [{ ns: 'world', id: 0, type: MARKER.LINE_LIST,
    action: MARKER.ADD, pose: { position: { x: 0, y: 0 } },
    points: [{ x: -3, y: -3 }, { x: 3, y: -3 }], scale: { x: 0.02 } }] });
  assert.deepEqual(state.bounds, { minX: -3, minY: -3, maxX: 3, maxY: -3 });
  const before = state.version;
  onArenaRobots(state, { markers: [robotMarker('alice', -1, 0), robotMarker('bob', 1, 0)] });
  assert.deepEqual(state.robots.map((robot) => robot.name), ['alice', 'bob']);
  assert.equal(state.robots[1].radius, 0.11);
  assert.ok(state.version > before, 'a new picture to draw');
});
