// The dashboard's plan (web-interface/js/class-plan.js): the root connection's URL, the names
// under each robot's namespace, and which topics a class of N costs at which throttles.
import assert from 'node:assert/strict';
import { test } from 'node:test';

import {
  CLASS_SERVICES, namespaced, namespacedRobot, ODOM_THROTTLE_MS, POSE_BUDGET_HZ,
  POSE_THROTTLE_MAX_MS, POSE_THROTTLE_MIN_MS, poseThrottleMs, robotNames, robotStatuses,
  robotSubscriptions,
  rootWsUrl, SCAN_THROTTLE_MS, subscriptionPlan,
} from '../../web-interface/js/class-plan.js';
import { robot } from './robot.mjs';

const names = (count) => Array.from({ length: count }, (_, i) => `robot${String(i + 1).padStart(2, '0')}`);

test('the root connection is the page\'s own server at /, on config.json\'s port or 9090', () => {
  const page = { protocol: 'http:', hostname: 'lab', host: 'lab:8080', search: '?token=x' };
  assert.equal(rootWsUrl(page), 'ws://lab:9090/');
  assert.equal(rootWsUrl(page, null), 'ws://lab:9090/');
  assert.equal(rootWsUrl(page, 'ws://lab:9555'), 'ws://lab:9555/');
  assert.equal(rootWsUrl(page, 'ws://lab:9555/robots/alice'), 'ws://lab:9555/'); // the root
  assert.equal(rootWsUrl({ ...page, protocol: 'https:' }), 'wss://lab:9090/');
  assert.equal(rootWsUrl(page, 'not a url'), 'ws://lab:9090/');
  // ?ws= in the address is never the root: a link could name anybody's server.
  assert.equal(rootWsUrl({ ...page, search: '?ws=ws://evil:9090' }), 'ws://lab:9090/');
});

test('a robot\'s names are robot.json\'s under /NAME', () => {
  assert.equal(namespaced('alice', robot.topics.odom.name), `/alice${robot.topics.odom.name}`);
  assert.equal(namespaced('alice', 'odom'), '/alice/odom');
  const alice = namespacedRobot(robot, 'alice');
  for (const [key, entry] of Object.entries(robot.topics)) {
    assert.equal(alice.topics[key].name, `/alice${entry.name}`);
    assert.equal(alice.topics[key].type, entry.type);
  }
  assert.equal(alice.services.set_parameters.name, `/alice${robot.services.set_parameters.name}`);
  assert.equal(alice.parameters, robot.parameters);
  assert.equal(robot.topics.odom.name.startsWith('/alice'), false, 'the description is unchanged');
  assert.equal(namespaced('bob', CLASS_SERVICES.pause.name), '/bob/websim/pause');
});

test('ground truth shares a budget of pose messages; 40 robots get 200 ms each', () => {
  assert.equal(poseThrottleMs(40), 200);
  assert.equal(poseThrottleMs(40) * POSE_BUDGET_HZ / 1000, 40);
  assert.equal(poseThrottleMs(1), POSE_THROTTLE_MIN_MS);
  assert.equal(poseThrottleMs(12), POSE_THROTTLE_MIN_MS);
  assert.equal(poseThrottleMs(60), 300);
  assert.equal(poseThrottleMs(200), POSE_THROTTLE_MAX_MS);
  assert.equal(poseThrottleMs(0), POSE_THROTTLE_MIN_MS);
});

test('each robot: ground truth, slow odometry and its world once; scans only when asked', () => {
  const plan = robotSubscriptions('robot07', robot, 40);
  assert.deepEqual(plan.map((e) => [e.stream, e.topic, e.type, e.throttleMs, e.once]), [
    ['ground_truth', `/robot07${robot.topics.ground_truth.name}`, robot.topics.ground_truth.type,
      200, false],
    ['odom', `/robot07${robot.topics.odom.name}`, robot.topics.odom.type, ODOM_THROTTLE_MS,
      false],
    ['world', `/robot07${robot.topics.world.name}`, robot.topics.world.type, 0, true],
  ]);
  const scanning = robotSubscriptions('robot07', robot, 40, { scans: true });
  assert.deepEqual(scanning.slice(3).map((e) => [e.stream, e.topic, e.throttleMs, e.once]), [
    ['scan', `/robot07${robot.topics.scan.name}`, SCAN_THROTTLE_MS, false],
    ['tf_static', `/robot07${robot.topics.tf_static.name}`, 0, true],
  ]);
  assert.ok(scanning.every((e) => e.robot === 'robot07' && e.queueLength >= 1));
});

test('a class of N: 3 subscriptions per robot, 2 held once the latched world came', () => {
  for (const count of [1, 12, 40]) {
    const plan = subscriptionPlan(names(count), robot);
    assert.equal(plan.length, 3 * count);
    assert.equal(plan.filter((e) => !e.once).length, 2 * count);
    assert.equal(new Set(plan.map((e) => e.topic)).size, plan.length, 'no topic twice');
    const withScans = subscriptionPlan(names(count), robot, { scans: true });
    assert.equal(withScans.filter((e) => !e.once).length, 3 * count);
  }
  const forty = subscriptionPlan(names(40), robot);
  // What the grid costs the bridge per second: ground truth at its budget, odometry at 1 Hz.
  const rateHz = forty.filter((e) => !e.once)
    .reduce((sum, e) => sum + 1000 / e.throttleMs, 0);
  assert.equal(rateHz, POSE_BUDGET_HZ + 40 * (1000 / ODOM_THROTTLE_MS));
});

test('the robot list keeps roster names, each once, in the server\'s order', () => {
  assert.deepEqual(robotNames({ names: ['bob', 'alice', 'bob', 'carol-2', '', 7, '../x', null] }),
    ['bob', 'alice', 'carol-2']);
  assert.deepEqual(robotNames({ names: [] }), []);
  assert.throws(() => robotNames({}), /no names/);
  assert.throws(() => robotNames(null), /no names/);
});

test('a class status is each listed robot\'s status by name; odd entries are left out', () => {
  const statuses = robotStatuses({ robots: [
    { name: 'alice', last_driver: 'a:1' }, { name: '../x' }, null, { last_driver: 'b:2' },
    { name: 'bob', mode: 'dynamic' }] });
  assert.deepEqual([...statuses.keys()], ['alice', 'bob']);
  assert.equal(statuses.get('alice').last_driver, 'a:1');
  assert.equal(statuses.get('bob').mode, 'dynamic');
  assert.deepEqual([...robotStatuses({ robots: [] }).keys()], []);
  assert.throws(() => robotStatuses({ names: [] }), /no robots/);
  assert.throws(() => robotStatuses(null), /no robots/);
});
