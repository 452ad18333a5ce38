// Who else drives the robot: tells the velocity commands this page published from those of
// other clients (a second tab, another student, a ROS node).
//
// The bridge relays every velocity command to every subscriber, its publisher included, in
// canonical form (every Twist field filled, integers as floats). So a Twist the page receives
// is either the echo of one it sent in the last OWN_ECHO_MS, or someone else's. Each of the
// page's publications accounts for one echo only: a second equal Twist (another tab holding
// the same key at the same speed) is foreign too.
//
// Pure functions over a plain object, like state.js: no DOM and no clock (callers pass nowMs).

/** The page's own publications are remembered this long (ms): their echoes come back sooner. */
export const OWN_ECHO_MS = 2000;
/** After another client's last command, the page says so for this long (ms). */
export const FOREIGN_SHOW_MS = 1000;
/** Twist fields closer than this are equal (JSON and the canonical form round numbers). */
export const TWIST_TOLERANCE = 1e-6;

const VECTORS = ['linear', 'angular'];
const AXES = ['x', 'y', 'z'];

export function createDrivers() {
  return {
    own: [], // {twist, atMs}: the page's publications whose echo has not come back, oldest first
    foreignAtMs: -Infinity, // when another client's command last arrived
  };
}

/**
 * A Twist's six numbers (linear x, y, z, angular x, y, z); a missing field reads 0 (ROS's
 * default), a null or non-finite one NaN, equal to nothing.
 */
export function twistFields(msg) {
  const fields = [];
  for (const vector of VECTORS) {
    for (const axis of AXES) {
      const value = msg?.[vector]?.[axis] === undefined ? 0 : msg[vector][axis];
      fields.push(typeof value === 'number' && Number.isFinite(value) ? value : NaN);
    }
  }
  return fields;
}

/** True when the Twists `a` and `b` agree on every field within `tolerance`. */
export function sameTwist(a, b, tolerance = TWIST_TOLERANCE) {
  const fa = twistFields(a);
  const fb = twistFields(b);
  return fa.every((value, i) => Math.abs(value - fb[i]) <= tolerance);
}

/** The page published `msg` (a Twist) at nowMs. */
export function noteOwnCommand(drivers, msg, nowMs) {
  forgetOld(drivers, nowMs);
  drivers.own.push({ twist: msg, atMs: nowMs });
}

/**
 * A Twist arrived on the command topic at nowMs: the echo of one of the page's own recent
 * publications (which it then uses up), or another client's. Returns true when foreign.
 */
export function noteCommand(drivers, msg, nowMs) {
  forgetOld(drivers, nowMs);
  const echoOf = drivers.own.findIndex((sent) => sameTwist(sent.twist, msg));
  if (echoOf >= 0) {
    drivers.own.splice(echoOf, 1);
    return false;
  }
  drivers.foreignAtMs = nowMs;
  return true;
}

/** True while another client's command arrived less than FOREIGN_SHOW_MS before nowMs. */
export function othersDriving(drivers, nowMs) {
  return nowMs - drivers.foreignAtMs < FOREIGN_SHOW_MS;
}

function forgetOld(drivers, nowMs) {
  const own = drivers.own;
  while (own.length && own[0].atMs < nowMs - OWN_ECHO_MS) own.shift();
}
