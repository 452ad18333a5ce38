// The class's topics into the robots' states (web-interface/js/class-feed.js): what a class of
// N subscribes on the root connection, latched streams dropped once they came, scans on and
// off, and each message reaching its own robot only.
import assert from 'node:assert/strict';
import { test } from 'node:test';

import { ClassFeed } from '../../web-interface/js/class-feed.js';
import { poseThrottleMs, SCAN_THROTTLE_MS } from '../../web-interface/js/class-plan.js';
import { robot } from './robot.mjs';

/** A Connection's subscribe() that records what is held: topic -> {type, options, deliver}. */
function recordingConnection() {
  const held = new Map();
  const log = [];
  return {
    held,
    log,
    subscribe(topic, type, onMessage, options) {
      assert.equal(held.has(topic), false, `${topic} subscribed twice`);
      held.set(topic, { type, options, deliver: onMessage });
      log.push(`+${topic}`);
      return () => {
        held.delete(topic);
        log.push(`-${topic}`);
      };
    },
  };
}

const odometry = (x) => ({
  header: { frame_id: 'map' },
  pose: { pose: { position: { x, y: 0 }, orientation: { w: 1 } } },
  twist: { twist: { linear: { x: 0.2 }, angular: { z: 0 } } },
});
const topic = (name, key) => `/${name}${robot.topics[key].name}`;
const names = (count) => Array.from({ length: count }, (_, i) => `r${i}`);

test('a class of 40: ground truth, odometry and the world per robot, throttled', () => {
  const connection = recordingConnection();
  const feed = new ClassFeed(connection, robot, { now: () => 0 });
  assert.deepEqual(feed.addRobots(names(40)), names(40));
  assert.equal(connection.held.size, 120);
  const truth = connection.held.get(topic('r7', 'ground_truth'));
  assert.deepEqual(truth.options, { throttleMs: poseThrottleMs(40), queueLength: 1 });
  assert.equal(truth.type, robot.topics.ground_truth.type);
  assert.equal(connection.held.has(topic('r7', 'scan')), false, 'no scans unless asked');
  assert.deepEqual(feed.addRobots(['r3', 'r40']), ['r40'], 'known robots are not added again');
  assert.deepEqual(feed.names.slice(-2), ['r39', 'r40']);
});

test('the latched world is dropped once it came; messages reach their own robot', () => {
  const connection = recordingConnection();
  let now = 100;
  const feed = new ClassFeed(connection, robot, { now: () => now });
  feed.addRobots(['alice', 'bob']);
  connection.held.get(topic('alice', 'world')).deliver({ markers: [{ ns: 'w', id: 0, type: 5,
    action: 0, pose: { position: {}, orientation: { w: 1 } }, scale: { x: 0.05 },
    points: [{ x: 0, y: 0 }, { x: 1, y: 0 }] }] });
  assert.equal(connection.held.has(topic('alice', 'world')), false);
  assert.equal(connection.held.has(topic('bob', 'world')), true);
  assert.equal(connection.held.size, 5); // two robots' poses, bob's world
  now = 250;
  connection.held.get(topic('bob', 'ground_truth')).deliver(odometry(1.5));
  const alice = feed.states.get('alice');
  const bob = feed.states.get('bob');
  assert.equal(alice.worldVersion, 1);
  assert.equal(alice.truth, null);
  assert.equal(bob.truth.x, 1.5);
  assert.equal(bob.truthAtMs, 250);
  assert.equal(bob.worldVersion, 0);
});

test('scans on subscribes every robot\'s scan and laser mount; off drops and clears them', () => {
  const connection = recordingConnection();
  const feed = new ClassFeed(connection, robot, { now: () => 0 });
  feed.addRobots(['alice', 'bob']);
  feed.setScans(true);
  feed.setScans(true); // twice is once
  const scan = connection.held.get(topic('bob', 'scan'));
  assert.deepEqual(scan.options, { throttleMs: SCAN_THROTTLE_MS, queueLength: 1 });
  scan.deliver({ ranges: [1], angle_min: 0, angle_increment: 0.1, range_min: 0.1, range_max: 3 });
  assert.equal(feed.states.get('bob').scan.points.length, 2);
  connection.held.get(topic('bob', 'tf_static')).deliver({ transforms: [{
    header: { frame_id: 'base_link' }, child_frame_id: 'laser',
    transform: { translation: { x: 0.02, y: 0 }, rotation: { w: 1 } } }] });
  assert.equal(connection.held.has(topic('bob', 'tf_static')), false, 'mount found: dropped');
  assert.equal(connection.held.has(topic('alice', 'tf_static')), true);
  feed.addRobots(['carol']);
  assert.equal(connection.held.has(topic('carol', 'scan')), true, 'a robot that joins later');
  feed.setScans(false);
  assert.equal(connection.held.has(topic('bob', 'scan')), false);
  assert.equal(connection.held.has(topic('alice', 'tf_static')), false);
  assert.equal(connection.held.has(topic('carol', 'scan')), false);
  assert.equal(feed.states.get('bob').scan, null);
  assert.deepEqual([...connection.held.keys()].filter((t) => t.includes('/bob/')).sort(),
    [topic('bob', 'ground_truth'), topic('bob', 'odom'), topic('bob', 'world')].sort());
});
