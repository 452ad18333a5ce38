// The heading PID (web-interface/js/pid.js): hand-worked steps and closed-loop behaviour.
// Run by tests/test_page_modules.py as `node --test`.
import assert from 'node:assert/strict';
import { test } from 'node:test';

import {
  CONTROL_PERIOD_S, INITIAL_STATE, makeGains, pidStep, wrapAngle,
} from '../../web-interface/js/pid.js';
import { robot } from './robot.mjs';

const DEG = Math.PI / 180;
/** Gains with the robot's yaw-rate limit (robot.json), as the page's PID panel makes them. */
const withLimit = (fields = {}) => makeGains({
  outputLimit: robot.robot.max_angular_rps, ...fields,
});
const close = (actual, expected, tol = 1e-12) => assert.ok(
  Math.abs(actual - expected) <= tol, `${actual} is not within ${tol} of ${expected}`);

test('wrapAngle maps into (-pi, pi]', () => {
  close(wrapAngle(0), 0);
  close(wrapAngle(Math.PI), Math.PI);
  close(wrapAngle(-Math.PI), Math.PI);
  close(wrapAngle(3 * Math.PI), Math.PI);
  close(wrapAngle(1.5 * Math.PI), -0.5 * Math.PI);
  close(wrapAngle(-1.5 * Math.PI), 0.5 * Math.PI);
  close(wrapAngle(2 * Math.PI + 0.1), 0.1, 1e-12);
  close(wrapAngle(-20 * Math.PI - 0.1), -0.1, 1e-12);
});

test('proportional step: output = kp * error', () => {
  const step = pidStep(withLimit({ kp: 2 }), INITIAL_STATE, 0.5, 0.25);
  close(step.error, 0.25);
  close(step.output, 0.5);
  assert.equal(step.saturated, false);
  close(step.state.integral, 0.25 * CONTROL_PERIOD_S);
  assert.equal(step.state.previousHeading, 0.25);
});

test('the error takes the shortest way round', () => {
  // From -170 deg to 170 deg is 20 deg clockwise, not 340 deg counter-clockwise.
  const step = pidStep(withLimit({ kp: 1 }), INITIAL_STATE, 170 * DEG, -170 * DEG);
  close(step.error, -20 * DEG, 1e-12);
  assert.ok(step.output < 0);
});

test('the output is clamped to the limit and flagged saturated', () => {
  const step = pidStep(makeGains({ kp: 10, outputLimit: 2.5 }), INITIAL_STATE, 1, 0);
  assert.equal(step.output, 2.5);
  assert.equal(step.saturated, true);
  const back = pidStep(makeGains({ kp: 10, outputLimit: 2.5 }), INITIAL_STATE, -1, 0);
  assert.equal(back.output, -2.5);
});

test('anti-windup: no integration while saturated in the error direction', () => {
  const gains = makeGains({ kp: 10, ki: 1, outputLimit: 2.5 });
  let state = INITIAL_STATE;
  for (let i = 0; i < 50; i += 1) state = pidStep(gains, state, 1, 0).state;
  assert.equal(state.integral, 0); // five seconds saturated: nothing accumulated
  // Unsaturated, the integral grows by error * dt each step.
  const soft = makeGains({ kp: 0.1, ki: 0.1, outputLimit: 2.5 });
  const once = pidStep(soft, INITIAL_STATE, 1, 0);
  close(once.state.integral, 1 * CONTROL_PERIOD_S);
});

test('a wound-up integral still unwinds once the error turns', () => {
  // The integral alone saturates the output (+2.5) but the error is now negative
  // (overshoot): integrating reduces the saturation, so it goes on.
  const gains = makeGains({ kp: 1, ki: 1, outputLimit: 2.5 });
  const step = pidStep(gains, { integral: 5, previousHeading: 0.2 }, 0, 0.2);
  assert.equal(step.output, 2.5);
  close(step.state.integral, 5 - 0.2 * CONTROL_PERIOD_S);
});

test('derivative acts on the measurement: a setpoint jump gives no kick', () => {
  const gains = withLimit({ kp: 0, kd: 1 });
  const still = pidStep(gains, { integral: 0, previousHeading: 0.2 }, 1.5, 0.2);
  assert.equal(still.output, 0);
  // Heading rising 0.1 rad in 0.1 s: derivative term -kd * 1 rad/s.
  const moving = pidStep(gains, { integral: 0, previousHeading: 0.2 }, 1.5, 0.3);
  close(moving.output, -1, 1e-12);
  // Across the +-pi seam the motion is +2 deg, not -358 deg.
  const seam = pidStep(gains, { integral: 0, previousHeading: 179 * DEG }, 0, -179 * DEG);
  close(seam.output, -(2 * DEG) / CONTROL_PERIOD_S, 1e-9);
});

/** Heading of a robot that turns at the commanded rate plus `disturbance` (rad/s). */
function simulate(gains, setpoint, seconds, disturbance = 0) {
  let heading = 0;
  let state = INITIAL_STATE;
  const headings = [];
  for (let t = 0; t < seconds; t += CONTROL_PERIOD_S) {
    const step = pidStep(gains, state, setpoint, heading);
    state = step.state;
    heading = wrapAngle(heading + (step.output + disturbance) * CONTROL_PERIOD_S);
    headings.push(heading);
  }
  return headings;
}

test('closed loop, P only: 90 deg reached without overshoot', () => {
  const headings = simulate(withLimit({ kp: 2 }), 90 * DEG, 6);
  close(headings.at(-1), 90 * DEG, 0.5 * DEG);
  assert.ok(Math.max(...headings) <= 90 * DEG + 1e-9);
});

test('closed loop: the integral removes the steady-state error of a disturbance', () => {
  const disturbance = -0.2; // rad/s, e.g. a dragging wheel
  const p = simulate(withLimit({ kp: 2 }), 90 * DEG, 20, disturbance);
  close(p.at(-1), 90 * DEG + disturbance / 2, 1e-3); // P leaves d / kp
  const pi = simulate(withLimit({ kp: 2, ki: 1 }), 90 * DEG, 20, disturbance);
  close(pi.at(-1), 90 * DEG, 1e-3);
});

test('gains are validated', () => {
  assert.throws(() => withLimit({ kp: -1 }), /kp/);
  assert.throws(() => withLimit({ ki: Number.NaN }), /ki/);
  assert.throws(() => makeGains({ kp: 1 }), /outputLimit/); // no default: the robot's
  assert.throws(() => makeGains({ outputLimit: 0 }), /outputLimit/);
  assert.throws(() => pidStep(withLimit(), INITIAL_STATE, Number.NaN, 0), /finite/);
});
