// The instructor's view of a class, as names and rates: where the root connection is, which
// services it offers, and which of every robot's topics the dashboard subscribes at which
// throttle. Pure functions: no DOM, no connection.
//
// On the root connection (ws://HOST:PORT/?token=INSTRUCTOR) robot NAME's topics and services
// are its own under /NAME, as in a ROS 2 multi-robot graph: /alice/odom, /alice/reset_simulation.
// The un-namespaced names are robot.json's (every robot of a class shares them).

import { defaultWsUrl, ownWsUrl } from './connection.js';

/** Services of the root connection and, under each robot's namespace, of each robot. */
export const CLASS_SERVICES = Object.freeze({
  robots: Object.freeze({ name: '/websim/robots', type: 'websim/srv/Robots' }), // root: names
  // root: every robot's status at once, {robots: [{name, ...status}]}
  classStatus: Object.freeze({ name: '/websim/class_status', type: 'websim/srv/ClassStatus' }),
  pause: Object.freeze({ name: '/websim/pause', type: 'websim/srv/Pause' }), // per robot
  token: Object.freeze({ name: '/websim/token', type: 'websim/srv/RobotToken' }), // per robot
});

/** Pose messages per second the whole grid may cost (ground truth; the server's 20 Hz each). */
export const POSE_BUDGET_HZ = 200;
/** Fastest pose throttle: 10 Hz is smooth on a thumbnail. */
export const POSE_THROTTLE_MIN_MS = 100;
/** Slowest pose throttle, however large the class: 2 Hz still shows where a robot goes. */
export const POSE_THROTTLE_MAX_MS = 500;
/** Odometry only stands in for a robot whose ground truth does not flow: 1 Hz is enough. */
export const ODOM_THROTTLE_MS = 1000;
/** Scans are the costly stream (360 ranges; the server casts them only when subscribed). */
export const SCAN_THROTTLE_MS = 500;
/** Latched /tf_static may come as several messages: keep them all until the laser's is seen. */
const TF_STATIC_QUEUE = 10;

/** `name` (a robot.json topic or service name) under robot `robotName`'s namespace. */
export function namespaced(robotName, name) {
  return `/${robotName}${name.startsWith('/') ? name : `/${name}`}`;
}

/**
 * The instructor's root connection on the page's own server: the scheme, host and port of
 * the page's own bridge (config.json's `ws`, else ws://<page host>:9090), at path `/`. The
 * token is added by the Connection (withToken), never here, so this URL may be shown.
 */
export function rootWsUrl(location, configured = null) {
  let url;
  try {
    url = new URL(ownWsUrl(location, configured));
  } catch {
    url = new URL(defaultWsUrl(location)); // config.json named something that is not a URL
  }
  return `${url.protocol}//${url.host}/`;
}

/** Throttle (ms) of each robot's ground truth for a class of `count` robots. */
export function poseThrottleMs(count) {
  const evenShare = Math.round((Math.max(1, count) * 1000) / POSE_BUDGET_HZ);
  return Math.min(POSE_THROTTLE_MAX_MS, Math.max(POSE_THROTTLE_MIN_MS, evenShare));
}

/**
 * What the dashboard subscribes for robot `robotName` in a class of `count`: entries
 * {robot, stream, topic, type, throttleMs, queueLength, once}. `stream` is robot.json's topic
 * key; `once` entries are latched (the world, the laser mount): unsubscribed when they came.
 * Scans only with `scans`.
 */
export function robotSubscriptions(robotName, robot, count, { scans = false } = {}) {
  const entry = (stream, throttleMs, { queueLength = 1, once = false } = {}) => ({
    robot: robotName,
    stream,
    topic: namespaced(robotName, robot.topics[stream].name),
    type: robot.topics[stream].type,
    throttleMs,
    queueLength,
    once,
  });
  const plan = [
    entry('ground_truth', poseThrottleMs(count)),
    entry('odom', ODOM_THROTTLE_MS),
    entry('world', 0, { once: true }),
  ];
  if (scans) {
    plan.push(entry('scan', SCAN_THROTTLE_MS));
    plan.push(entry('tf_static', 0, { queueLength: TF_STATIC_QUEUE, once: true }));
  }
  return plan;
}

/** robotSubscriptions() of every robot of `names`, in their order. */
export function subscriptionPlan(names, robot, options = {}) {
  return names.flatMap((name) => robotSubscriptions(name, robot, names.length, options));
}

/**
 * The robot description as robot `robotName` looks on the root connection: every topic and
 * service name under its namespace, the rest as it is. params.js's helpers take it as they
 * take the plain description.
 */
export function namespacedRobot(robot, robotName) {
  const under = (table) => Object.fromEntries(Object.entries(table).map(
    ([key, entry]) => [key, { ...entry, name: namespaced(robotName, entry.name) }]));
  return { ...robot, topics: under(robot.topics), services: under(robot.services) };
}

/** A roster name (classroom.py's ROBOT_NAME, upper case aside): one path segment. */
const ROBOT_NAME = /^[A-Za-z0-9_-]{1,32}$/;

/** The robot names of a /websim/robots answer: roster names, each once, in the given order. */
export function robotNames(response) {
  const names = response?.names;
  if (!Array.isArray(names)) throw new TypeError('the robot list has no names');
  const valid = names.filter((name) => typeof name === 'string' && ROBOT_NAME.test(name));
  return [...new Set(valid)];
}

/**
 * The statuses of a /websim/class_status answer: a Map of robot name -> its status values
 * (class-state.js parseStatus reads them), for the entries with a valid name.
 */
export function robotStatuses(response) {
  const robots = response?.robots;
  if (!Array.isArray(robots)) throw new TypeError('the class status has no robots');
  return new Map(robots
    .filter((entry) => typeof entry?.name === 'string' && ROBOT_NAME.test(entry.name))
    .map((entry) => [entry.name, entry]));
}
