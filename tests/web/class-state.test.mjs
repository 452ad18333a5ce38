// One robot's dashboard state (web-interface/js/class-state.js): poses, world, scans, and the
// status of /websim/class_status as the cards read it (who drives, how long ago, paused or idle).
import assert from 'node:assert/strict';
import { test } from 'node:test';

import {
  classSummary, clearScan, createRobotState, displayPose, DRIVING_RECENT_S, driverLine,
  driveAgeS, fixed, formatAge, isHeld, isMoving, onPose, onScan, onStatus, onStatusError,
  onTfStatic, onWorld, parseStatus, speedMps, STATUS_STALE_MS, statusStale,
} from '../../web-interface/js/class-state.js';
import { TRUTH_STALE_MS } from '../../web-interface/js/state.js';

const odometry = (x, v, frame) => ({
  header: { frame_id: frame, stamp: { sec: 1, nanosec: 0 } },
  pose: { pose: { position: { x, y: 0, z: 0 }, orientation: { x: 0, y: 0, z: 0, w: 1 } } },
  twist: { twist: { linear: { x: v, y: 0, z: 0 }, angular: { x: 0, y: 0, z: 0 } } },
});

const STATUS = {
  name: 'alice',
  client_count: 3,
  admin_count: 2,
  owner_count: 1,
  instructor_count: 1,
  recording: 'recording stopped: it reached its size limit (1000 MB)',
  last_driver: '10.0.0.5:51234',
  last_drive_age_s: 0.4,
  collisions: 3,
  mode: 'kinematic',
  mass_kg: 1.2,
  inertia_kg_m2: 0.0066,
  paused: false,
  speed_mps: 0.2,
};

test('a status answer is read field by field; what is missing or ill-typed reads null', () => {
  assert.deepEqual(parseStatus(STATUS), {
    clientCount: 3,
    admins: 2,
    owners: 1,
    instructors: 1,
    students: 2,
    recording: 'recording stopped: it reached its size limit (1000 MB)',
    lastDriver: '10.0.0.5:51234',
    lastDriveAgeS: 0.4,
    collisions: 3,
    mode: 'kinematic',
    massKg: 1.2,
    inertiaKgM2: 0.0066,
    paused: false,
    held: false,
    speedMps: 0.2,
  });
  const odd = parseStatus({
    client_count: -1, admin_count: 1.5, last_driver: null, last_drive_age_s: null,
    collisions: 1.5, mode: '', mass_kg: 'heavy', paused: 'yes', speed_mps: null,
  });
  for (const key of ['clientCount', 'admins', 'owners', 'instructors', 'students',
    'recording', 'lastDriver', 'lastDriveAgeS',
    'collisions', 'mode', 'massKg', 'inertiaKgM2', 'paused', 'held', 'speedMps']) {
    assert.equal(odd[key], null, key);
  }
  assert.equal(parseStatus(undefined).clientCount, null);
});

test('held is the instructor\'s pause; a server that only says paused means that', () => {
  assert.equal(parseStatus({ paused: true }).held, true);
  const idle = parseStatus({ paused: true, held: false }); // nobody connected: idle, not held
  assert.equal(idle.held, false);
  assert.equal(idle.paused, true);
  const state = createRobotState('alice');
  assert.equal(isHeld(state), null);
  onStatus(state, { paused: true, held: true }, 0);
  assert.equal(isHeld(state), true);
});

test('who drives: none, recent with the age counted on, then past once it stands', () => {
  const state = createRobotState('alice');
  assert.deepEqual(driverLine(state, 0), { kind: 'none', text: 'driving: none' });
  onStatus(state, STATUS, 1000);
  assert.deepEqual(driverLine(state, 1000),
    { kind: 'recent', text: 'driving: 10.0.0.5:51234 (0.4 s ago)' });
  assert.equal(driveAgeS(state, 2500), 0.4 + 1.5);
  assert.equal(driverLine(state, 2500).text, 'driving: 10.0.0.5:51234 (1.9 s ago)');
  const later = 1000 + (DRIVING_RECENT_S + 1) * 1000;
  assert.equal(driverLine(state, later).kind, 'recent', 'it still moves on that command');
  onPose(state, 'ground_truth', odometry(0, 0, 'map'), 1000);
  assert.deepEqual(driverLine(state, later),
    { kind: 'past', text: 'last driver: 10.0.0.5:51234 (3.4 s ago)' });
  onStatus(state, { ...STATUS, last_drive_age_s: null }, 0);
  assert.equal(driverLine(state, 0).text, 'last driver: 10.0.0.5:51234');
  onStatus(state, { ...STATUS, last_driver: null }, 0);
  assert.equal(driverLine(state, 0).kind, 'none');
});

test('ages read as people say them; numbers never show -0', () => {
  assert.deepEqual([0.04, 9.96, 42.4, 150, 7300, -1].map(formatAge),
    ['0.0 s', '10.0 s', '42 s', '3 min', '2 h', '0.0 s']);
  assert.equal(fixed(-0.001, 2), '0.00');
  assert.equal(fixed(-0.2, 2), '-0.20');
  assert.equal(fixed(0.199, 2), '0.20');
});

test('the pose and speed: ground truth, odometry without it, the status before either', () => {
  const state = createRobotState('alice');
  assert.equal(speedMps(state), null);
  assert.deepEqual(displayPose(state), { pose: null, frame: null });
  onStatus(state, STATUS, 0);
  assert.equal(speedMps(state), 0.2);
  assert.equal(isMoving(state), true);
  const version = state.version;
  onPose(state, 'odom', odometry(1, 0.1, 'odom'), 100);
  assert.equal(speedMps(state), 0.1);
  assert.equal(displayPose(state).frame, 'odom');
  onPose(state, 'ground_truth', odometry(2, 0.3, 'map'), 200);
  assert.equal(speedMps(state), 0.3);
  assert.equal(displayPose(state).frame, 'map');
  assert.equal(state.version, version + 2, 'each pose is a change to draw');
  onPose(state, 'odom', odometry(1, 0.1, 'odom'), 200 + TRUTH_STALE_MS);
  assert.equal(displayPose(state).frame, 'map', 'odometry just as old: still ground truth');
  onPose(state, 'odom', odometry(1, 0.1, 'odom'), 201 + TRUTH_STALE_MS);
  assert.equal(displayPose(state).frame, 'odom', 'odometry flows without ground truth');
  onPose(state, 'odom', { pose: { pose: { position: { x: null, y: 0 } } } }, 300);
  assert.equal(state.version, version + 4, 'a pose that is not finite is not used');
});

test('a paused robot sends nothing: its last ground truth (and walls) stay drawn', () => {
  const state = createRobotState('alice');
  onPose(state, 'odom', odometry(1, 0, 'odom'), 0);
  onPose(state, 'ground_truth', odometry(1, 0, 'map'), 10);
  assert.equal(displayPose(state).frame, 'map'); // whatever the time now: no clock here
  assert.equal(isMoving(state), false);
});

test('the world, the scan and the laser mount update the state and its version', () => {
  const state = createRobotState('alice');
  onWorld(state, { markers: [{ ns: 'walls', id: 0, type: 5, action: 0, scale: { x: 0.05 },
    pose: { position: { x: 0, y: 0 }, orientation: { w: 1 } },
    points: [{ x: -3, y: -3 }, { x: 3, y: -3 }] }] });
  assert.deepEqual(state.worldBounds, { minX: -3, minY: -3, maxX: 3, maxY: -3 });
  assert.equal(state.worldVersion, 1);
  onScan(state, { ranges: [1, null, 2], angle_min: 0, angle_increment: Math.PI / 2,
    range_min: 0.1, range_max: 3.5 });
  assert.equal(state.scan.points.length, 4); // two returns, x and y each
  assert.equal(onTfStatic(state, { transforms: [] }), false);
  assert.equal(onTfStatic(state, { transforms: [{ header: { frame_id: 'base_link' },
    child_frame_id: 'laser', transform: { translation: { x: 0.05, y: 0 },
      rotation: { x: 0, y: 0, z: 0, w: 1 } } }] }), true);
  assert.deepEqual(state.laserMount, { x: 0.05, y: 0, yaw: 0 });
  clearScan(state);
  assert.equal(state.scan, null);
  assert.equal(state.version, 4);
});

test('a status is stale after a while; a failed call keeps its reason until the next answer', () => {
  const state = createRobotState('alice');
  assert.equal(statusStale(state, 0), true);
  onStatus(state, STATUS, 1000);
  assert.equal(statusStale(state, 1000 + STATUS_STALE_MS), false);
  assert.equal(statusStale(state, 1001 + STATUS_STALE_MS), true);
  onStatusError(state, 'status: /alice/websim/status needs admin rights');
  assert.equal(state.statusError, 'status: /alice/websim/status needs admin rights');
  onStatus(state, STATUS, 2000);
  assert.equal(state.statusError, '');
});

test('the class at a glance counts robots, drivers, paused robots and students', () => {
  const states = ['a', 'b', 'c'].map(createRobotState);
  onStatus(states[0], STATUS, 0);
  onStatus(states[1], { ...STATUS, last_drive_age_s: 60, paused: true, speed_mps: 0 }, 0);
  assert.deepEqual(classSummary(new Set(states).values(), 0),
    { robots: 3, driving: 1, held: 1, students: 4 });
});
