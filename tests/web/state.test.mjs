// The page's state bookkeeping (web-interface/js/state.js): which pose is shown, the trail,
// plot history and message rates.
import assert from 'node:assert/strict';
import { test } from 'node:test';

import {
  createState, displayPose, historyCsv, HISTORY_S, lastStepS, noteLinkDown, noteLinkUp,
  noteOwnReset, notePose, onCommand, onGroundTruth, onOdometry, onWorld, POSE_HISTORY_S, poseAt,
  rateHz, RESET_SHOW_MS, resetByOther, shownAtMs, STEP_STEADY_S, TRUTH_STALE_MS, unwrapDeg,
} from '../../web-interface/js/state.js';

function odometry(x, y, stampS, frame = 'odom') {
  return {
    header: { stamp: { sec: Math.floor(stampS), nanosec: Math.round((stampS % 1) * 1e9) },
      frame_id: frame },
    pose: { pose: { position: { x, y, z: 0 }, orientation: { x: 0, y: 0, z: 0, w: 1 } } },
    twist: { twist: { linear: { x: 0.1 }, angular: { z: 0 } } },
  };
}

test('ground truth is shown while it flows, odometry after it stops (a real robot)', () => {
  const state = createState();
  assert.equal(displayPose(state, 0).pose, null);
  onOdometry(state, odometry(1, 0, 100), 0);
  assert.equal(displayPose(state, 0).frame, 'odom');
  onGroundTruth(state, odometry(2, 0, 100, 'map'), 10);
  assert.equal(displayPose(state, 20).frame, 'map');
  assert.equal(displayPose(state, 20).pose.x, 2);
  assert.equal(displayPose(state, 10 + TRUTH_STALE_MS + 1).frame, 'odom');
});

test('the trail skips sub-centimetre steps and breaks at a reset jump', () => {
  const state = createState();
  onOdometry(state, odometry(0, 0, 1), 0);
  onOdometry(state, odometry(0.005, 0, 1.05), 50);
  onOdometry(state, odometry(0.02, 0, 1.1), 100);
  onOdometry(state, odometry(2, 0, 1.15), 150);
  const points = state.trail.points;
  assert.deepEqual(points.map((p) => p.x), [0, 0.02, 2]);
  assert.deepEqual(points.map((p) => p.gap), [true, false, true]);
});

test('plot history keeps the last 20 s of stamps, one sample per /odom', () => {
  const state = createState();
  for (let i = 0; i <= 30 * 20; i += 1) onOdometry(state, odometry(0, 0, 1000 + i / 20), i * 50);
  const t = state.history.t;
  assert.ok(t.at(-1) - t[0] <= HISTORY_S);
  assert.ok(t.at(-1) - t[0] >= HISTORY_S - 0.051);
  assert.equal(state.history.vMeas.length, t.length);
  assert.equal(state.history.setpointDeg.at(-1), null);
});

test('message rates over the last two seconds', () => {
  const state = createState();
  for (let i = 0; i < 100; i += 1) onOdometry(state, odometry(0, 0, 1 + i / 20), i * 50);
  assert.equal(rateHz(state, 'odom', 99 * 50), 20.5); // 41 arrivals within 2000 ms inclusive
  assert.equal(rateHz(state, 'scan', 99 * 50), 0);
});

test('a world message bumps the version and the bounds', () => {
  const state = createState();
  onWorld(state, {
    markers: [{ ns: 'w', id: 0, type: 3, action: 0, scale: { x: 1 },
      pose: { position: { x: 2, y: 0 }, orientation: { w: 1 } } }],
  });
  assert.equal(state.worldVersion, 1);
  assert.deepEqual(state.worldBounds, { minX: 1.5, minY: -0.5, maxX: 2.5, maxY: 0.5 });
});

test('a scan is placed at the pose of its stamp, interpolated, the heading the short way', () => {
  const state = createState();
  assert.equal(poseAt(state, 'map', 10), null);
  notePose(state, 'map', { x: 0, y: 0, theta: 3.0, stampS: 10.0 });
  notePose(state, 'map', { x: 1, y: 2, theta: -3.0, stampS: 10.1 });  // across ±π
  const middle = poseAt(state, 'map', 10.05);
  assert.ok(Math.abs(middle.x - 0.5) < 1e-9 && Math.abs(middle.y - 1) < 1e-9);
  const turned = Math.atan2(Math.sin(middle.theta), Math.cos(middle.theta));
  assert.ok(Math.abs(Math.abs(turned) - Math.PI) < 1e-9, `${turned}`);  // not through 0
  assert.equal(poseAt(state, 'map', 9).stampS, 10.0);  // before the history: the oldest
  assert.equal(poseAt(state, 'map', 11).stampS, 10.1);  // after it: the newest
  assert.equal(poseAt(state, 'odom', 10.05), null);  // another frame's history
  notePose(state, 'map', { x: 0, y: 0, theta: 0, stampS: 20 });
  notePose(state, 'map', { x: 0, y: 0, theta: 0, stampS: 20 + POSE_HISTORY_S + 1 });
  assert.equal(state.poses.map.length, 2);  // older than POSE_HISTORY_S: dropped
  notePose(state, 'map', { x: 5, y: 5, theta: 0, stampS: 1 });  // time went back: restart
  assert.deepEqual(state.poses.map.map((p) => p.stampS), [1]);
  notePose(state, 'map', { x: 5, y: 5, theta: 0, stampS: null });  // no stamp: not kept
  assert.equal(state.poses.map.length, 1);
});

test('a jump of the shown pose breaks the trail and is announced unless the page asked', () => {
  const state = createState();
  onGroundTruth(state, odometry(1.5, 0, 10, 'map'), 1000);
  onGroundTruth(state, odometry(1.6, 0, 10.05, 'map'), 1050);
  assert.equal(resetByOther(state, 1060), false); // moving, no jump
  onGroundTruth(state, odometry(0, 0, 10.1, 'map'), 1100); // back at the start: a reset
  assert.equal(state.trail.points.at(-1).gap, true); // no line joins it to the old pose
  assert.equal(resetByOther(state, 1200), true);
  assert.equal(resetByOther(state, 1100 + RESET_SHOW_MS + 1), false); // said for a while
  noteOwnReset(state, 5000); // this page asked: its own reset is not another's
  onGroundTruth(state, odometry(1.2, 0, 12, 'map'), 5200);
  assert.equal(resetByOther(state, 5300), false);
});

test('the heading is unwrapped across ±180°, the setpoint on the heading\'s turn', () => {
  assert.equal(unwrapDeg(170, undefined), 170);
  assert.equal(unwrapDeg(-170, 170), 190); // crossed +180 going up: goes on
  assert.equal(unwrapDeg(170, 190), 170);
  assert.equal(unwrapDeg(-90, 700), 630); // two turns on
  const state = createState();
  const turning = [170, 179, -179, -170].map((deg, i) => ({
    header: { stamp: { sec: 10 + i, nanosec: 0 }, frame_id: 'odom' },
    pose: { pose: { position: { x: 0, y: 0, z: 0 }, orientation: {
      x: 0, y: 0, z: Math.sin((deg * Math.PI) / 360), w: Math.cos((deg * Math.PI) / 360) } } },
    twist: { twist: { linear: { x: 0 }, angular: { z: 0.5 } } },
  }));
  state.setpointDeg = -175; // the PID's, wrapped
  turning.forEach((msg, i) => onOdometry(state, msg, 1000 + i));
  const headings = state.history.headingDeg.map((d) => Math.round(d * 1e6) / 1e6);
  assert.deepEqual(headings, [170, 179, 181, 190]);
  assert.deepEqual(state.history.setpointDeg.map((d) => Math.round(d)), [185, 185, 185, 185]);
  const csv = historyCsv(state.history).trim().split('\n');
  assert.equal(csv[0], 'stamp_s,v_cmd_mps,v_mps,omega_cmd_rps,omega_rps,heading_deg,setpoint_deg,'
    + 'v_true_mps,omega_true_rps');
  assert.equal(csv.length, 5);
  assert.equal(csv[1].split(',')[0], '10');
});

test('while the bridge is down the picture stays as it was: ground truth, its map frame', () => {
  const state = createState();
  onOdometry(state, odometry(1, 0, 10), 0);
  onGroundTruth(state, odometry(1.1, 0, 10, 'map'), 0);
  noteLinkDown(state, 100);
  const later = 100 + 10 * TRUTH_STALE_MS;
  assert.equal(shownAtMs(state, later), 100);
  assert.equal(displayPose(state, shownAtMs(state, later)).frame, 'map');
  assert.equal(displayPose(state, later).frame, 'odom'); // what the view used to fall back to
  noteLinkUp(state);
  assert.equal(shownAtMs(state, later), later);
});

test('the last step of a command: a change after a steady command, not a PID\'s every tick', () => {
  const t = Array.from({ length: 40 }, (_, i) => i * 0.05);
  const keys = t.map((s) => (s < 0.5 ? 0 : s < 1.2 ? 0.3 : 0)); // press, release
  assert.equal(lastStepS({ t, v: keys }, 'v', 0.01), t[24]); // the release at 1.2 s
  const pid = t.map((s) => (s < 1 ? 0 : Math.cos(s * 7))); // starts at 1 s, changes each tick
  assert.equal(lastStepS({ t, v: pid }, 'v', 0.01), t[20]);
  const quick = t.map((s) => (s < 1 ? 0.3 : s < 1 + STEP_STEADY_S / 2 ? 0 : 0.3));
  assert.equal(lastStepS({ t, v: quick }, 'v', 0.01), t[20]); // the press after too short a rest
  assert.equal(lastStepS({ t, v: t.map(() => 0.2) }, 'v', 0.01), null);
  const setpoint = t.map((s) => (s < 1 ? null : 90)); // the PID started
  assert.equal(lastStepS({ t, v: setpoint }, 'v', 1), t[20]);
});

test('the true speed of the same stamp joins the /odom sample, whichever came first', () => {
  const state = createState();
  onCommand(state, 0.3, 0);
  const moving = (v, stampS, frame) => {
    const msg = odometry(0, 0, stampS, frame);
    msg.twist = { twist: { linear: { x: v, y: 0, z: 0 }, angular: { x: 0, y: 0, z: 0 } } };
    return msg;
  };
  onOdometry(state, moving(0.3, 10, 'odom'), 0); // odometry first: the wheels slip
  onGroundTruth(state, moving(0.125, 10, 'map'), 1);
  onGroundTruth(state, moving(0.25, 10.05, 'map'), 50); // ground truth first
  onOdometry(state, moving(0.3, 10.05, 'odom'), 51);
  assert.deepEqual(state.history.vMeas, [0.3, 0.3]);
  assert.deepEqual(state.history.vTrue, [0.125, 0.25]);
  assert.match(historyCsv(state.history).split('\n')[0], /,v_true_mps,omega_true_rps$/);
});
