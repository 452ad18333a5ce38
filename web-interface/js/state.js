// The page's live state: messages update it, the animation loop (view.js, plots.js) reads it.
//
// Pure functions over a plain object: no DOM and no clock (callers pass nowMs), so the
// bookkeeping (trail, plot history, message rates, which pose to show) is testable in Node.

import {
  applyMarkerArray, markerBounds, poseFromOdometry, robotsFromMarkers, scanPoints, transformFromTf,
} from './ros-msgs.js';
import { createDrivers } from './drivers.js';
import { createLatency, noteOdometry } from './latency.js';

/** Seconds of history the live plots show. */
export const HISTORY_S = 20;
/** Seconds of trajectory the view keeps, fading with age. */
export const TRAIL_S = 30;
/** A new trail point only after this much motion (m): a parked robot adds nothing. */
export const TRAIL_STEP_M = 0.01;
/** A pose jump larger than this (m) between two messages breaks the trail (a reset). */
export const TRAIL_BREAK_M = 0.5;
/** Ground truth older than this (ms) is gone (a real robot has none): show odometry. */
export const TRUTH_STALE_MS = 1000;
/** Message rates are counted over this window (ms). */
export const RATE_WINDOW_MS = 2000;
/** A reset another client made is announced this long (ms). */
export const RESET_SHOW_MS = 4000;
/** A jump this soon (ms) after the page's own reset request is that reset, not another's. */
export const OWN_RESET_MS = 3000;
/** Seconds of stamped poses kept per frame, to draw a scan where it was taken. */
export const POSE_HISTORY_S = 2;
/** A change of the command is a step when the command held this long (s) before it. */
export const STEP_STEADY_S = 0.3;

export function createState() {
  return {
    odom: null, // {x, y, theta, v, omega, stampS, frame} in the odom frame
    odomAtMs: -Infinity,
    truth: null, // the same, in the map frame (simulation only)
    truthAtMs: -Infinity,
    scan: null, // {points: Float32Array of x, y in the laser frame (m), frame, stampS}
    scanAtMs: -Infinity,
    laserMount: { x: 0, y: 0, yaw: 0 }, // laser pose in base_link, from /tf_static
    markers: new Map(), // the world's walls and discs (map frame), from /world
    worldBounds: null,
    worldVersion: 0, // bumped on every /world: view.js re-renders its wall layer
    entity: null, // this robot's name in its world (config.json): not among the others
    others: [], // the other robots of the world {name, x, y, yaw, radius} (map frame)
    othersAtMs: -Infinity, // when /world_robots last came
    trail: { frame: null, points: [] }, // points {x, y, tMs, gap}; gap: no line to it
    command: { linear: 0, angular: 0 }, // the latest /cmd_vel (m/s, rad/s)
    drivers: createDrivers(), // whose /cmd_vel that is: this page's or another client's
    setpointDeg: null, // the heading PID's setpoint while it runs
    history: { // per /odom: its stamp (s), the command, odometry's and ground truth's speeds
      t: [], vCmd: [], vMeas: [], wCmd: [], wMeas: [], headingDeg: [], setpointDeg: [],
      vTrue: [], wTrue: [],
    },
    arrivals: new Map(), // stream (robot.json's topic key: odom, scan...) -> arrival times (ms)
    poses: { map: [], odom: [] }, // per frame, the recent stamped poses, oldest first
    latency: createLatency(), // the page's commands until odometry shows them (latency.js)
    jumpAtMs: -Infinity, // when the shown pose last jumped (a reset): the trail breaks there
    ownResetAtMs: -Infinity, // when this page last asked for a reset
    linkDownAtMs: null, // when the bridge went away (null while connected): the view freezes
  };
}

/** The bridge went away at nowMs: what the page shows is as of then, and stale. */
export function noteLinkDown(state, nowMs) {
  state.linkDownAtMs = nowMs;
}

/** The bridge is back: the page shows live data again. */
export function noteLinkUp(state) {
  state.linkDownAtMs = null;
}

/**
 * The time (ms) the page's picture is of: now, or while the bridge is down the moment it
 * went away, so that the world, the pose and its frame stay as they were last seen instead
 * of ground truth going stale and the view falling back to odometry without walls.
 */
export function shownAtMs(state, nowMs) {
  return state.linkDownAtMs === null ? nowMs : Math.min(nowMs, state.linkDownAtMs);
}

/** Notes a stamped pose of `frame`; keeps the last POSE_HISTORY_S of them (by stamp). */
export function notePose(state, frame, pose) {
  if (!Number.isFinite(pose.stampS)) return;
  const poses = state.poses[frame];
  if (poses.length && pose.stampS < poses[poses.length - 1].stampS) poses.length = 0; // reset
  poses.push(pose);
  while (poses.length > 2 && poses[0].stampS < pose.stampS - POSE_HISTORY_S) poses.shift();
}

/**
 * The pose of `frame` at time `stampS` (s), interpolated between the two stamped poses around
 * it (the heading along the shorter arc), as rviz2 looks up TF at a message's stamp; the
 * nearest one outside the history; null without any. A scan is drawn at the pose it was
 * taken from, not where the robot is by the time it is drawn.
 */
export function poseAt(state, frame, stampS) {
  const poses = state.poses[frame] ?? [];
  if (!poses.length || !Number.isFinite(stampS)) return null;
  if (stampS <= poses[0].stampS) return poses[0];
  const last = poses[poses.length - 1];
  if (stampS >= last.stampS) return last;
  let i = poses.length - 1;
  while (poses[i - 1].stampS > stampS) i -= 1;
  const a = poses[i - 1];
  const b = poses[i];
  const f = (stampS - a.stampS) / (b.stampS - a.stampS);
  const turn = Math.atan2(Math.sin(b.theta - a.theta), Math.cos(b.theta - a.theta));
  return { ...b, x: a.x + f * (b.x - a.x), y: a.y + f * (b.y - a.y), theta: a.theta + f * turn,
    stampS };
}

/** Counts one message of `stream` (odom, scan, ground_truth: robot.json's topic keys). */
export function noteArrival(state, stream, nowMs) {
  let times = state.arrivals.get(stream);
  if (!times) {
    times = [];
    state.arrivals.set(stream, times);
  }
  times.push(nowMs);
  while (times.length && times[0] < nowMs - RATE_WINDOW_MS) times.shift();
}

/** Messages per second of `stream` over the last RATE_WINDOW_MS. */
export function rateHz(state, stream, nowMs) {
  const times = state.arrivals.get(stream) ?? [];
  const recent = times.filter((t) => t >= nowMs - RATE_WINDOW_MS);
  return recent.length / (RATE_WINDOW_MS / 1000);
}

/** The pose to draw and its frame: ground truth (map) while it flows, else odometry (odom). */
export function displayPose(state, nowMs) {
  if (state.truth && nowMs - state.truthAtMs <= TRUTH_STALE_MS) {
    return { pose: state.truth, frame: 'map' };
  }
  return state.odom ? { pose: state.odom, frame: 'odom' } : { pose: null, frame: null };
}

export function onOdometry(state, msg, nowMs) {
  const pose = poseFromOdometry(msg);
  if (!pose) return;
  state.odom = pose;
  state.odomAtMs = nowMs;
  notePose(state, 'odom', pose);
  noteOdometry(state.latency, pose.v, pose.omega, nowMs);
  noteArrival(state, 'odom', nowMs);
  recordHistory(state, pose);
  if (displayPose(state, nowMs).frame === 'odom') extendTrail(state, pose, 'odom', nowMs);
}

export function onGroundTruth(state, msg, nowMs) {
  const pose = poseFromOdometry(msg);
  if (!pose) return;
  state.truth = pose;
  state.truthAtMs = nowMs;
  notePose(state, 'map', pose);
  const h = state.history; // the same tick's /odom may have come first: its sample gets this
  const last = h.t.length - 1;
  if (last >= 0 && h.t[last] === pose.stampS) {
    h.vTrue[last] = pose.v;
    h.wTrue[last] = pose.omega;
  }
  noteArrival(state, 'ground_truth', nowMs);
  extendTrail(state, pose, 'map', nowMs);
}

export function onScan(state, msg, nowMs) {
  state.scan = {
    points: scanPoints(msg),
    frame: msg.header?.frame_id || 'laser',
    stampS: msg.header?.stamp ? msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9 : null,
  };
  state.scanAtMs = nowMs;
  noteArrival(state, 'scan', nowMs);
}

export function onTfStatic(state, msg) {
  const mount = transformFromTf(msg, 'base_link', state.scan?.frame || 'laser');
  if (mount) state.laserMount = mount;
}

export function onWorld(state, msg) {
  applyMarkerArray(state.markers, msg);
  state.worldBounds = markerBounds(state.markers);
  state.worldVersion += 1;
}

/** /world_robots: every robot of the world at a tick; the page keeps the others. */
export function onWorldRobots(state, msg, nowMs) {
  state.others = robotsFromMarkers(msg, state.entity);
  state.othersAtMs = nowMs;
}

export function onCommand(state, linear, angular) {
  state.command = { linear, angular };
}

/** The page asked for a reset at nowMs: the jump that follows is its own. */
export function noteOwnReset(state, nowMs) {
  state.ownResetAtMs = nowMs;
}

/** Whether to say another client reset the robot: a jump lately, not after our own request. */
export function resetByOther(state, nowMs) {
  const jumpAtMs = state.jumpAtMs;
  if (nowMs - jumpAtMs > RESET_SHOW_MS) return false;
  const sinceOwn = jumpAtMs - state.ownResetAtMs;
  return !(sinceOwn >= 0 && sinceOwn <= OWN_RESET_MS);
}

/** Forgets the trail (a new connection, or the user's "clear"). */
export function clearTrail(state) {
  state.trail = { frame: null, points: [] };
}

/** Forgets the past the page holds (a replay jumped in time): trail, plots' history, poses. */
export function forgetPast(state) {
  clearTrail(state);
  for (const values of Object.values(state.history)) values.length = 0;
  state.poses = { map: [], odom: [] };
}

function extendTrail(state, pose, frame, nowMs) {
  const trail = state.trail;
  if (trail.frame !== frame) {
    trail.frame = frame;
    trail.points = [];
  }
  const points = trail.points;
  const last = points[points.length - 1];
  const step = last ? Math.hypot(pose.x - last.x, pose.y - last.y) : Infinity;
  if (!last || step >= TRAIL_STEP_M) {
    const jumped = Boolean(last) && step > TRAIL_BREAK_M;
    if (jumped) state.jumpAtMs = nowMs;
    points.push({ x: pose.x, y: pose.y, tMs: nowMs, gap: !last || jumped });
  }
  while (points.length && points[0].tMs < nowMs - TRAIL_S * 1000) points.shift();
}

/**
 * `deg` moved by whole turns to lie within half a turn of `nearDeg` (undefined: as it is):
 * the heading plot continues across ±180° instead of jumping.
 */
export function unwrapDeg(deg, nearDeg) {
  if (nearDeg === undefined || nearDeg === null) return deg;
  return nearDeg + (((deg - nearDeg) % 360) + 540) % 360 - 180;
}

/**
 * The plotted history as CSV: one row per /odom, stamps in s, speeds in SI, angles in °; the
 * true speeds (ground truth, a simulation's) empty where there is none.
 */
export function historyCsv(history) {
  const columns = [['stamp_s', 't'], ['v_cmd_mps', 'vCmd'], ['v_mps', 'vMeas'],
    ['omega_cmd_rps', 'wCmd'], ['omega_rps', 'wMeas'], ['heading_deg', 'headingDeg'],
    ['setpoint_deg', 'setpointDeg'], ['v_true_mps', 'vTrue'], ['omega_true_rps', 'wTrue']];
  const rows = [columns.map(([name]) => name).join(',')];
  for (let i = 0; i < history.t.length; i += 1) {
    rows.push(columns.map(([, key]) => (history[key][i] ?? '')).join(','));
  }
  return `${rows.join('\n')}\n`;
}

/**
 * The stamp (s) of the last step of history[key] (vCmd, wCmd, setpointDeg): the last sample
 * that differs by at least `minChange` from the one before, when that one had held for
 * STEP_STEADY_S (a PID's or a joystick's ever-changing command steps only where it started);
 * null (no value) counts as its own level. Null when there is no such step.
 */
export function lastStepS(history, key, minChange, steadyS = STEP_STEADY_S) {
  const { t } = history;
  const values = history[key];
  const same = (a, b) => (a === null || b === null ? a === b : Math.abs(a - b) < minChange);
  for (let i = values.length - 1; i > 0; i -= 1) {
    if (same(values[i], values[i - 1])) continue;
    let steady = true;
    for (let j = i - 2; steady && j >= 0 && t[j] >= t[i] - steadyS; j -= 1) {
      steady = same(values[j], values[i - 1]);
    }
    if (steady) return t[i];
  }
  return null;
}

function recordHistory(state, pose) {
  const h = state.history;
  const t = pose.stampS;
  if (t === null) return;
  if (h.t.length && t < h.t[h.t.length - 1]) {
    for (const key of Object.keys(h)) h[key].length = 0; // clock went back: a new robot
  }
  h.t.push(t);
  h.vCmd.push(state.command.linear);
  h.vMeas.push(pose.v);
  h.wCmd.push(state.command.angular);
  h.wMeas.push(pose.omega);
  const truth = state.truth?.stampS === t ? state.truth : null; // else filled in when it comes
  h.vTrue.push(truth ? truth.v : null);
  h.wTrue.push(truth ? truth.omega : null);
  const headingDeg = unwrapDeg((pose.theta * 180) / Math.PI, h.headingDeg.at(-1));
  h.headingDeg.push(headingDeg);
  h.setpointDeg.push(state.setpointDeg === null ? null
    : unwrapDeg(state.setpointDeg, headingDeg)); // the setpoint's turn nearest the heading
  let drop = 0;
  while (drop < h.t.length && h.t[drop] < t - HISTORY_S) drop += 1;
  if (drop) for (const key of Object.keys(h)) h[key].splice(0, drop);
}
