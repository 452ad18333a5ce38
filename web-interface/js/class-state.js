// The dashboard's live state of one robot of the class: messages and status answers update it,
// the one animation loop (class-grid.js, class-view.js) reads it. Pure functions over a plain
// object: no DOM and no clock (callers pass nowMs), so all of it is testable in Node.
//
// The pose to draw is ground truth (map frame), else odometry, as on the student page; but a
// robot the instructor paused sends neither, so here ground truth goes stale only when
// odometry still flows without it (state.js's displayPose would drop a paused robot's walls).

import {
  applyMarkerArray, markerBounds, poseFromOdometry, scanPoints, transformFromTf,
} from './ros-msgs.js';
import { TRUTH_STALE_MS } from './state.js';

/** A command this recent (s) means somebody is driving the robot now (so does moving). */
export const DRIVING_RECENT_S = 2;
/** Below these the robot stands still (m/s, rad/s): the simulator's zero is exact. */
const STILL_MPS = 1e-3;
const STILL_RPS = 1e-3;
/** A status answer older than this (ms) is stale: the card says so. */
export const STATUS_STALE_MS = 6000;

export function createRobotState(name) {
  return {
    name,
    odom: null, // {x, y, theta, v, omega, stampS, frame} (ros-msgs.js), odom frame
    odomAtMs: -Infinity,
    truth: null, // the same, map frame
    truthAtMs: -Infinity,
    scan: null, // {points: Float32Array of x, y in the laser frame (m)}
    laserMount: { x: 0, y: 0, yaw: 0 }, // laser pose in base_link, from /tf_static
    markers: new Map(), // the world's walls and discs (map frame)
    worldBounds: null,
    worldVersion: 0, // bumped on every /world: the view re-renders its wall layer
    status: null, // parseStatus() of the latest /websim/status answer
    statusAtMs: -Infinity,
    statusError: '', // why the latest status call failed ('' when it did not)
    commandError: '', // why the latest command on this robot was refused
    busy: new Set(), // actions in flight (reset, pause, mode, payload): their buttons wait
    version: 0, // bumped on every change the canvas shows: the loop redraws only then
  };
}

/** A pose message of `stream` (robot.json's key: ground_truth or odom) arrived. */
export function onPose(state, stream, msg, nowMs) {
  const pose = poseFromOdometry(msg);
  if (!pose) return;
  if (stream === 'ground_truth') {
    state.truth = pose;
    state.truthAtMs = nowMs;
  } else {
    state.odom = pose;
    state.odomAtMs = nowMs;
  }
  state.version += 1;
}

export function onScan(state, msg) {
  state.scan = { points: scanPoints(msg) };
  state.version += 1;
}

/** Scans stop (the toggle is off): none is drawn. */
export function clearScan(state) {
  state.scan = null;
  state.version += 1;
}

/** A /tf_static message; true when it held the laser's mount (then it is not needed again). */
export function onTfStatic(state, msg, laserFrame = 'laser') {
  const mount = transformFromTf(msg, 'base_link', laserFrame);
  if (!mount) return false;
  state.laserMount = mount;
  state.version += 1;
  return true;
}

export function onWorld(state, msg) {
  applyMarkerArray(state.markers, msg);
  state.worldBounds = markerBounds(state.markers);
  state.worldVersion += 1;
  state.version += 1;
}

const finiteOrNull = (value) => (Number.isFinite(value) ? value : null);
const boolOrNull = (value) => (typeof value === 'boolean' ? value : null);
const textOrNull = (value) => (typeof value === 'string' && value ? value : null);

/** A count: a non-negative integer, else null. */
const countOrNull = (value) => (Number.isInteger(value) && value >= 0 ? value : null);

/**
 * A robot's status (an entry of /websim/class_status, or a /websim/status answer) as the
 * dashboard reads it: {clientCount, admins, owners, instructors, students, recording,
 * lastDriver, lastDriveAgeS, collisions, mode, massKg, inertiaKgM2, paused, held, speedMps}.
 * A field that is missing or of the wrong type reads null. `admins` are the clients with the
 * robot's or the instructor's token; of them `owners` have the robot's own (its student's
 * page and code) and `instructors` the instructor's (the dashboard is one). `students` are
 * every client but the instructor's: the owner's page is a student's, not an admin's (a server
 * that does not count instructors apart: every client but the admins, as before).
 * `recording`: what is wrong with the robot's recording, if anything. `held` is the
 * instructor's pause; a server that does not tell it apart from `paused` (an idle robot
 * pauses too) gets `paused` for it.
 */
export function parseStatus(values) {
  const clientCount = countOrNull(values?.client_count);
  const admins = countOrNull(values?.admin_count);
  const instructors = countOrNull(values?.instructor_count);
  const paused = boolOrNull(values?.paused);
  const notStudents = instructors ?? admins;
  return {
    clientCount,
    admins,
    owners: countOrNull(values?.owner_count),
    instructors,
    students: clientCount === null || notStudents === null ? null
      : Math.max(0, clientCount - notStudents),
    recording: textOrNull(values?.recording),
    lastDriver: textOrNull(values?.last_driver),
    lastDriveAgeS: finiteOrNull(values?.last_drive_age_s),
    collisions: Number.isInteger(values?.collisions) ? values.collisions : null,
    mode: textOrNull(values?.mode),
    massKg: finiteOrNull(values?.mass_kg),
    inertiaKgM2: finiteOrNull(values?.inertia_kg_m2),
    paused,
    held: boolOrNull(values?.held) ?? paused,
    speedMps: finiteOrNull(values?.speed_mps),
  };
}

export function onStatus(state, values, nowMs) {
  state.status = parseStatus(values);
  state.statusAtMs = nowMs;
  state.statusError = '';
}

export function onStatusError(state, reason) {
  state.statusError = String(reason);
}

/**
 * The pose to draw and its frame: {pose, frame} with frame map (ground truth, unless odometry
 * arrived more than TRUTH_STALE_MS after it) or odom; {pose: null, frame: null} before either.
 */
export function displayPose(state) {
  if (state.truth && state.truthAtMs >= state.odomAtMs - TRUTH_STALE_MS) {
    return { pose: state.truth, frame: 'map' };
  }
  return state.odom ? { pose: state.odom, frame: 'odom' } : { pose: null, frame: null };
}

/** The robot's speed (m/s) now: the drawn pose's, else the last status's, else null. */
export function speedMps(state) {
  const { pose } = displayPose(state);
  if (pose) return pose.v;
  return state.status?.speedMps ?? null;
}

/** Whether the robot moves (drives or turns), by its latest pose or status. */
export function isMoving(state) {
  const { pose } = displayPose(state);
  if (pose) return Math.abs(pose.v) > STILL_MPS || Math.abs(pose.omega) > STILL_RPS;
  return Math.abs(state.status?.speedMps ?? 0) > STILL_MPS;
}

/** Whether the instructor has paused the robot (null: not known yet). */
export function isHeld(state) {
  return state.status?.held ?? null;
}

/** True when the status is missing or older than STATUS_STALE_MS. */
export function statusStale(state, nowMs) {
  return nowMs - state.statusAtMs > STATUS_STALE_MS;
}

/** The last driver's command age (s) now: the status's age plus the time since it came. */
export function driveAgeS(state, nowMs) {
  const age = state.status?.lastDriveAgeS;
  return age === null || age === undefined ? null : age + (nowMs - state.statusAtMs) / 1000;
}

/**
 * Who drives the robot: {kind, text}. kind none (nobody ever), recent (a command in the last
 * DRIVING_RECENT_S, or the robot still moves on its last command: it keeps it) or past. The
 * status is asked for twice a second (class-poller.js), so a robot driven at 10 Hz reads
 * well under a second ago and never leaves the window between two answers.
 */
export function driverLine(state, nowMs) {
  const driver = state.status?.lastDriver;
  if (!driver) return { kind: 'none', text: 'driving: none' };
  const age = driveAgeS(state, nowMs);
  const ago = age === null ? '' : ` (${formatAge(age)} ago)`;
  return (age !== null && age <= DRIVING_RECENT_S) || isMoving(state)
    ? { kind: 'recent', text: `driving: ${driver}${ago}` }
    : { kind: 'past', text: `last driver: ${driver}${ago}` };
}

/** An age in s as people say it: 0.4 s, 42 s, 3 min, 2 h. */
export function formatAge(seconds) {
  const s = Math.max(0, seconds);
  if (s < 10) return `${s.toFixed(1)} s`;
  if (s < 120) return `${Math.round(s)} s`;
  if (s < 7200) return `${Math.round(s / 60)} min`;
  return `${Math.round(s / 3600)} h`;
}

/** A number with `digits` decimals, never "-0.00". */
export function fixed(value, digits) {
  const text = value.toFixed(digits);
  return Number(text) === 0 ? (0).toFixed(digits) : text;
}

/** The whole class at a glance (any iterable of states): {robots, driving, held, students}. */
export function classSummary(states, nowMs) {
  let robots = 0;
  let driving = 0;
  let held = 0;
  let students = 0;
  for (const state of states) {
    robots += 1;
    if (driverLine(state, nowMs).kind === 'recent') driving += 1;
    if (isHeld(state)) held += 1;
    students += state.status?.students ?? 0;
  }
  return { robots, driving, held, students };
}
