// A robot's thumbnail (web-interface/js/class-view.js): the world fits inside the padded
// canvas with y up, and a canvas is redrawn only when its robot changed.
import assert from 'node:assert/strict';
import { test } from 'node:test';

import { fitCamera, RobotThumb } from '../../web-interface/js/class-view.js';
import { createRobotState, onPose } from '../../web-interface/js/class-state.js';
import { robot } from './robot.mjs';

/** A canvas whose 2D context records the calls that draw (drawImage, arc, fillRect...). */
function recordingCanvas() {
  const calls = [];
  const ctx = new Proxy({}, {
    get: (target, key) => (key in target ? target[key] : (...args) => calls.push([key, ...args])),
    set: (target, key, value) => { target[key] = value; return true; },
  });
  return { calls, canvas: { width: 0, height: 0, getContext: () => ctx } };
}

const PAD = { top: 20, right: 5, bottom: 5, left: 5 };

test('a world fits the padded canvas, its centre in the padded area\'s centre, y up', () => {
  const bounds = { minX: -3, minY: -3, maxX: 3, maxY: 3 };
  const { canvas } = recordingCanvas();
  const thumb = new RobotThumb(canvas, robot);
  thumb.setSize(240, 180, 1);
  thumb.camera = fitCamera(bounds, 240, 180, PAD);
  assert.equal(thumb.camera.scale, (180 - 25) / 6); // height limits a square world in 4:3
  const [left, top] = thumb.worldToScreen(-3, 3);
  const [right, bottom] = thumb.worldToScreen(3, -3);
  assert.ok(Math.abs(top - PAD.top) < 1e-9 && Math.abs(bottom - (180 - PAD.bottom)) < 1e-9);
  assert.ok(Math.abs((left + right) / 2 - (PAD.left + (240 - 10) / 2)) < 1e-9);
  const [, upY] = thumb.worldToScreen(0, 1);
  const [, originY] = thumb.worldToScreen(0, 0);
  assert.ok(upY < originY, '+y is up the screen');
});

test('the canvas is drawn when its robot changed, and not again until it changes', () => {
  const { canvas, calls } = recordingCanvas();
  const thumb = new RobotThumb(canvas, robot);
  const state = createRobotState('alice');
  assert.equal(thumb.draw(state), false, 'no size yet: nothing to draw on');
  thumb.setSize(200, 150, 2);
  assert.deepEqual([canvas.width, canvas.height], [400, 300], 'device pixels');
  thumb._renderLayer = () => ({}); // the offscreen layer needs a DOM
  assert.equal(thumb.draw(state), true);
  assert.equal(thumb.draw(state), false);
  onPose(state, 'odom', { pose: { pose: { position: { x: 1, y: 0 }, orientation: { w: 1 } } },
    header: { frame_id: 'odom' } }, 20);
  const before = calls.length;
  assert.equal(thumb.draw(state), true);
  assert.ok(calls.slice(before).some(([name]) => name === 'arc'), 'the robot is drawn');
  assert.equal(thumb.draw(state), false);
});
