// ROS message conversions (web-interface/js/ros-msgs.js) on hand-made messages.
import assert from 'node:assert/strict';
import { test } from 'node:test';

import {
  applyMarkerArray, composePose, markerBounds, MARKER, parameterValue, poseFromOdometry,
  robotsFromMarkers, scanPoints, stampSeconds, transformFromTf, twist, valueOfParameter,
  yawFromQuaternion,
} from '../../web-interface/js/ros-msgs.js';
import { robot } from './robot.mjs';

const close = (actual, expected, tol = 1e-9) => assert.ok(
  Math.abs(actual - expected) <= tol, `${actual} is not within ${tol} of ${expected}`);
const yawQuaternion = (yaw) => ({ x: 0, y: 0, z: Math.sin(yaw / 2), w: Math.cos(yaw / 2) });

test('yaw from a planar quaternion, both signs and past 90 degrees', () => {
  for (const yaw of [0, 1, -1, 2.5, -3]) close(yawFromQuaternion(yawQuaternion(yaw)), yaw);
});

test('odometry pose, twist and stamp', () => {
  const pose = poseFromOdometry({
    header: { stamp: { sec: 10, nanosec: 500_000_000 }, frame_id: 'odom' },
    pose: { pose: { position: { x: 1, y: -2, z: 0 }, orientation: yawQuaternion(0.5) } },
    twist: { twist: { linear: { x: 0.3 }, angular: { z: null } } },
  });
  close(pose.x, 1);
  close(pose.y, -2);
  close(pose.theta, 0.5);
  close(pose.v, 0.3);
  assert.equal(pose.omega, 0); // JSON null (non-finite) reads as no motion
  close(pose.stampS, 10.5);
  assert.equal(pose.frame, 'odom');
  assert.equal(poseFromOdometry({ pose: { pose: { position: { x: null, y: 0 } } } }), null);
  assert.equal(stampSeconds(undefined), null);
});

test('a Twist for a planar robot', () => {
  assert.deepEqual(twist(0.2, -1), {
    linear: { x: 0.2, y: 0, z: 0 }, angular: { x: 0, y: 0, z: -1 },
  });
});

test('scan returns: null, range_max and below range_min are not drawn', () => {
  const points = scanPoints({
    angle_min: 0,
    angle_increment: Math.PI / 2,
    range_min: 0.12,
    range_max: 3.5,
    ranges: [1, null, 3.5, 0.05, 2, 0.12],
  });
  // Beams 0 (1 m at 0), 4 (2 m at 2 pi) and 5 (0.12 m at 5 pi / 2) have returns.
  assert.equal(points.length, 6);
  close(points[0], 1, 1e-6);
  close(points[1], 0, 1e-6);
  close(points[2], 2, 1e-6);
  close(points[3], 0, 1e-5);
  close(points[4], 0, 1e-6);
  close(points[5], 0.12, 1e-6);
});

test('the laser mount comes from the direct base_link -> laser transform', () => {
  const msg = {
    transforms: [{
      header: { frame_id: 'base_link' },
      child_frame_id: 'laser',
      transform: { translation: { x: 0.05, y: 0, z: 0.1 }, rotation: yawQuaternion(Math.PI) },
    }],
  };
  const mount = transformFromTf(msg, 'base_link', 'laser');
  close(mount.x, 0.05);
  close(mount.yaw, Math.PI);
  assert.equal(transformFromTf(msg, 'odom', 'base_link'), null);
  // A laser mounted 0.05 m ahead of a robot at (1, 1) facing +y is at (1, 1.05).
  const laser = composePose({ x: 1, y: 1, yaw: Math.PI / 2 }, { x: 0.05, y: 0, yaw: 0 });
  close(laser.x, 1);
  close(laser.y, 1.05);
});

test('world markers: LINE_LIST point pairs are walls, CYLINDERs are discs', () => {
  const markers = new Map();
  const identity = { position: { x: 0, y: 0, z: 0 }, orientation: yawQuaternion(0) };
  applyMarkerArray(markers, {
    markers: [
      {
        ns: 'world', id: 0, type: MARKER.LINE_LIST, action: MARKER.ADD, pose: identity,
        scale: { x: 0.02 },
        points: [{ x: -3, y: -3 }, { x: 3, y: -3 }, { x: 3, y: -3 }, { x: 3, y: 3 }],
      },
      {
        ns: 'world', id: 1, type: MARKER.CYLINDER, action: MARKER.ADD,
        pose: { position: { x: 1, y: 2, z: 0 }, orientation: yawQuaternion(0) },
        scale: { x: 0.5, y: 0.5, z: 0.3 },
      },
    ],
  });
  assert.deepEqual(markers.get('world/0').segments, [[-3, -3, 3, -3], [3, -3, 3, 3]]);
  assert.deepEqual(markers.get('world/1'), { kind: 'disc', x: 1, y: 2, radius: 0.25 });
  assert.deepEqual(markerBounds(markers), { minX: -3, minY: -3, maxX: 3, maxY: 3 });
  applyMarkerArray(markers, { markers: [{ ns: 'world', id: 1, action: MARKER.DELETE }] });
  assert.equal(markers.size, 1);
  applyMarkerArray(markers, { markers: [{ action: MARKER.DELETEALL }] });
  assert.equal(markers.size, 0);
  assert.equal(markerBounds(markers), null);
});

test('world markers: a CUBE is a box, its corners turned by its yaw', () => {
  const markers = new Map();
  applyMarkerArray(markers, {
    markers: [{
      ns: 'world', id: 2, type: MARKER.CUBE, action: MARKER.ADD,
      pose: { position: { x: 2, y: 1, z: 0 }, orientation: yawQuaternion(Math.PI / 2) },
      scale: { x: 0.4, y: 0.2, z: 0.3 },
    }],
  });
  const box = markers.get('world/2');
  assert.equal(box.kind, 'polygon');
  const expected = [[2.1, 0.8], [2.1, 1.2], [1.9, 1.2], [1.9, 0.8]]; // 0.4 along y once turned
  box.corners.forEach(([x, y], i) => {
    close(x, expected[i][0]);
    close(y, expected[i][1]);
  });
  const bounds = markerBounds(markers);
  close(bounds.minX, 1.9);
  close(bounds.maxY, 1.2);
});

test('a marker pose moves and turns its points', () => {
  const markers = applyMarkerArray(new Map(), {
    markers: [{
      ns: 'n', id: 3, type: MARKER.LINE_LIST, action: MARKER.ADD,
      pose: { position: { x: 1, y: 0, z: 0 }, orientation: yawQuaternion(Math.PI / 2) },
      scale: { x: 0.05 }, points: [{ x: 0, y: 0 }, { x: 1, y: 0 }],
    }],
  });
  const [[x1, y1, x2, y2]] = markers.get('n/3').segments;
  close(x1, 1);
  close(y1, 0);
  close(x2, 1);
  close(y2, 1);
});

test('ParameterValue both ways, by robot.json\'s type codes', () => {
  const types = robot.parameter_types;
  assert.deepEqual(parameterValue(types, types.DOUBLE, 2.5),
    { type: types.DOUBLE, double_value: 2.5 });
  assert.deepEqual(parameterValue(types, types.STRING, 'dynamic'),
    { type: types.STRING, string_value: 'dynamic' });
  assert.deepEqual(parameterValue(types, types.INTEGER, 7),
    { type: types.INTEGER, integer_value: 7 });
  assert.deepEqual(parameterValue(types, types.BOOL, false),
    { type: types.BOOL, bool_value: false });
  assert.equal(valueOfParameter(types, { type: types.DOUBLE, double_value: 1.2, string_value: '' }),
    1.2);
  assert.equal(valueOfParameter(types,
    { type: types.STRING, double_value: 0, string_value: 'kinematic' }), 'kinematic');
  assert.equal(valueOfParameter(types, { type: types.NOT_SET }), undefined);
  assert.equal(valueOfParameter(types, { type: 99 }), undefined);
  assert.throws(() => parameterValue(types, types.DOUBLE, null), TypeError);
  assert.throws(() => parameterValue(types, types.INTEGER, 1.5), TypeError);
  assert.throws(() => parameterValue(types, types.NOT_SET, 1), TypeError);
});

test('the world\'s other robots from /world_robots, the page\'s own left out', () => {
  const cylinder = (text, x, y, yaw, diameter) => ({
    ns: 'world_robots', id: 0, type: MARKER.CYLINDER, action: MARKER.ADD, text,
    pose: { position: { x, y, z: 0.06 }, orientation: yawQuaternion(yaw) },
    scale: { x: diameter, y: diameter, z: 0.12 },
  });
  const msg = { markers: [cylinder('alice', 1, 2, 0.5, 0.22), cylinder('bob', -1, 0, -2, 0.3),
    cylinder('lost', null, 0, 0, 0.22)] };
  const others = robotsFromMarkers(msg, 'bob');
  assert.equal(others.length, 1); // bob is this page's robot; lost's pose is not finite
  assert.equal(others[0].name, 'alice');
  close(others[0].x, 1);
  close(others[0].y, 2);
  close(others[0].yaw, 0.5);
  close(others[0].radius, 0.11);
  assert.equal(robotsFromMarkers(msg).length, 2); // no name of its own: every robot
  assert.deepEqual(robotsFromMarkers(undefined), []);
});
