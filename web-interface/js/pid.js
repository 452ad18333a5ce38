// The course's heading PID (Module 2.4), one pure step at a time: no DOM, no clock, no I/O.
//
// Every dtS (0.1 s: the course's 10 Hz controller), from a measured heading to a yaw rate:
//
//   error      = wrap(setpoint - heading)                 shortest way round, in (-pi, pi]
//   derivative = -wrap(heading - previousHeading) / dt     on the measurement: no kick when
//                                                          the setpoint jumps
//   candidate  = integral + error * dt
//   output     = kp*error + ki*candidate + kd*derivative, clamped to +-outputLimit
//   integral   = candidate, unless the output is saturated and the error pushes further into
//                the saturation (conditional integration: anti-windup)
//
// physics/pid.py implements the same steps in Python. Angles in rad, rates in rad/s.

/** The course's PID node runs at 10 Hz. */
export const CONTROL_PERIOD_S = 0.1;

const TWO_PI = 2 * Math.PI;

/** `angleRad` wrapped into (-pi, pi]. */
export function wrapAngle(angleRad) {
  const wrapped = angleRad - TWO_PI * Math.round(angleRad / TWO_PI);
  return wrapped <= -Math.PI ? wrapped + TWO_PI : wrapped;
}

/**
 * Gains and limits, validated.
 * kp (rad/s per rad), ki (rad/s per rad s), kd (rad/s per rad/s): finite and >= 0;
 * outputLimit: the largest yaw rate command (rad/s), the robot's max_angular_rps; no default,
 * finite and > 0. Throws RangeError naming the bad field.
 */
export function makeGains({ kp = 2.0, ki = 0.0, kd = 0.0, outputLimit } = {}) {
  for (const [name, value] of Object.entries({ kp, ki, kd })) {
    if (!Number.isFinite(value) || value < 0) {
      throw new RangeError(`${name} must be a finite number >= 0, got ${value}`);
    }
  }
  if (!Number.isFinite(outputLimit) || outputLimit <= 0) {
    throw new RangeError(`outputLimit must be a finite number > 0, got ${outputLimit}`);
  }
  return Object.freeze({ kp, ki, kd, outputLimit });
}

/** What the controller remembers between steps: integral (rad s), previous heading (rad). */
export const INITIAL_STATE = Object.freeze({ integral: 0.0, previousHeading: null });

/**
 * Advances the heading PID by one period.
 * @param {{kp:number, ki:number, kd:number, outputLimit:number}} gains from makeGains()
 * @param {{integral:number, previousHeading:(number|null)}} state from the previous step
 * @param {number} setpointRad desired heading (rad)
 * @param {number} headingRad measured heading (rad)
 * @param {number} [dtS] the control period (s)
 * @returns {{output:number, error:number, saturated:boolean, state:object}} output: yaw rate
 *   command (rad/s); error: wrapped heading error (rad); state: for the next step.
 */
export function pidStep(gains, state, setpointRad, headingRad, dtS = CONTROL_PERIOD_S) {
  if (!Number.isFinite(setpointRad) || !Number.isFinite(headingRad)) {
    throw new RangeError(`setpoint and heading must be finite, got ${setpointRad}, ${headingRad}`);
  }
  if (!Number.isFinite(dtS) || dtS <= 0) {
    throw new RangeError(`dtS must be a finite number > 0, got ${dtS}`);
  }
  const error = wrapAngle(setpointRad - headingRad);
  const derivative = state.previousHeading === null
    ? 0.0 : -wrapAngle(headingRad - state.previousHeading) / dtS;
  const candidate = state.integral + error * dtS;
  const unclamped = gains.kp * error + gains.ki * candidate + gains.kd * derivative;
  const output = Math.max(-gains.outputLimit, Math.min(gains.outputLimit, unclamped));
  const saturated = output !== unclamped;
  const windingUp = saturated && error * unclamped > 0;
  const integral = windingUp ? state.integral : candidate;
  return { output, error, saturated, state: Object.freeze({ integral, previousHeading: headingRad }) };
}
