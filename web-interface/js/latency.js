// Command-to-odometry latency: from the page publishing a velocity command to the first
// odometry that shows the robot moving at it (what a key press costs before the robot is seen
// to obey), the figure benchmarks/bench_server.py measures.
//
// Pure functions over a plain object, like state.js: no DOM and no clock (callers pass nowMs).

/** A command whose odometry has not come within this long (ms) is given up (clamped, say). */
export const LATENCY_TIMEOUT_MS = 1000;
/** The readout is the median of this many recent samples. */
export const LATENCY_SAMPLES = 15;
/** Odometry shows a command when both speeds are within this of it (m/s, rad/s). */
export const SPEED_TOLERANCE = 1e-3;

export function createLatency() {
  return {
    pending: null, // {linear, angular, atMs}: the command being timed
    last: null, // the last command sent: a repeat (a held key) is not timed again
    samplesMs: [],
  };
}

/** The page published a command (m/s, rad/s) at nowMs; a change starts a measurement. */
export function noteCommandSent(latency, linear, angular, nowMs) {
  const last = latency.last;
  latency.last = { linear, angular };
  if (last && last.linear === linear && last.angular === angular) return;
  latency.pending = { linear, angular, atMs: nowMs };
}

/** An odometry message showing speeds (v, omega) arrived at nowMs. */
export function noteOdometry(latency, v, omega, nowMs) {
  const pending = latency.pending;
  if (!pending) return;
  if (nowMs - pending.atMs > LATENCY_TIMEOUT_MS) {
    latency.pending = null;
    return;
  }
  if (Math.abs(v - pending.linear) <= SPEED_TOLERANCE
      && Math.abs(omega - pending.angular) <= SPEED_TOLERANCE) {
    latency.samplesMs.push(nowMs - pending.atMs);
    if (latency.samplesMs.length > LATENCY_SAMPLES) latency.samplesMs.shift();
    latency.pending = null;
  }
}

/** The median of the recent samples (ms), or null before the first. */
export function latencyMs(latency) {
  const sorted = [...latency.samplesMs].sort((a, b) => a - b);
  if (!sorted.length) return null;
  const middle = Math.floor(sorted.length / 2);
  return sorted.length % 2 ? sorted[middle] : (sorted[middle - 1] + sorted[middle]) / 2;
}
