// What the instructor does to robots: reset, pause and resume, the motion model and the
// payload, each a service call on the root connection under the robot's namespace (the
// class's status is one call at the root: classStatus), and
// the "for all" fan-out over the class. Rejections carry the server's reason (a
// ServiceCallError from connection.js, or an Error naming the refused parameter).

import {
  CLASS_SERVICES, namespaced, namespacedRobot, robotNames, robotStatuses,
} from './class-plan.js';
import { setParameters } from './params.js';
import { parameterSpec } from './robot.js';

/** The robot parameters the dashboard changes (names in robot.json's parameter table). */
export const PARAMETERS = Object.freeze({
  mode: 'mode', mass: 'mass_kg', inertia: 'inertia_kg_m2',
});

/** The payloads offered: robot.json's mass and inertia times each factor. */
export const PAYLOAD_FACTORS = Object.freeze([1, 2]);

/** Relative difference under which a mass or inertia counts as default times a factor. */
const PAYLOAD_TOLERANCE = 1e-6;

/** "For all" calls in flight at once: a class of 40 does not land on the bridge in one burst. */
export const FAN_OUT_CONCURRENCY = 8;

/** The default payload, robot.json's: {massKg, inertiaKgM2}. */
export function payloadDefaults(robot) {
  return {
    massKg: parameterSpec(robot, PARAMETERS.mass).default,
    inertiaKgM2: parameterSpec(robot, PARAMETERS.inertia).default,
  };
}

/** The parameter values of payload `factor` (x1, x2): {mass_kg, inertia_kg_m2}. */
export function payloadValues(robot, factor) {
  const { massKg, inertiaKgM2 } = payloadDefaults(robot);
  return { [PARAMETERS.mass]: massKg * factor, [PARAMETERS.inertia]: inertiaKgM2 * factor };
}

/**
 * Which of PAYLOAD_FACTORS a status (class-state.js parseStatus) shows: mass and inertia both
 * that factor times the default; null for another payload, undefined when not known yet.
 */
export function payloadFactor(status, robot) {
  if (!status || status.massKg === null || status.inertiaKgM2 === null) return undefined;
  const { massKg, inertiaKgM2 } = payloadDefaults(robot);
  const near = (value, target) => Math.abs(value - target) <= PAYLOAD_TOLERANCE * target;
  return PAYLOAD_FACTORS.find((factor) => near(status.massKg, massKg * factor)
    && near(status.inertiaKgM2, inertiaKgM2 * factor)) ?? null;
}

/** The motion models robot.json's `mode` parameter offers (kinematic, dynamic). */
export function modeChoices(robot) {
  return parameterSpec(robot, PARAMETERS.mode).choices;
}

/** The model after `mode` in modeChoices(): what the card's toggle switches to. */
export function otherMode(robot, mode) {
  const choices = modeChoices(robot);
  return choices[(choices.indexOf(mode) + 1) % choices.length];
}

/** The instructor's calls, on the root Connection (connection.js). */
export class ClassCommands {
  constructor(connection, robot) {
    this.connection = connection;
    this.robot = robot;
  }

  /** The class's robot names (/websim/robots on the root). */
  async robots() {
    const { name, type } = CLASS_SERVICES.robots;
    return robotNames(await this.connection.callService(name, type, {}));
  }

  /**
   * Every robot's status behind this root (/websim/class_status on the root): a Map of name
   * -> status values (parse them with class-state.js parseStatus).
   */
  async classStatus() {
    const { name, type } = CLASS_SERVICES.classStatus;
    return robotStatuses(await this.connection.callService(name, type, {}));
  }

  /** Robot `name`'s own token, to hand to its student (an open class's newly enrolled too). */
  async token(name) {
    const reply = await this._call(name, CLASS_SERVICES.token, {});
    return reply.token;
  }

  /** Back to the spawn pose, command zeroed (the robot's /reset_simulation). */
  reset(name) {
    return this._call(name, this.robot.services.reset, {});
  }

  /** Holds the robot (paused true) or lets it run; resolves with {paused}. */
  pause(name, paused) {
    return this._call(name, CLASS_SERVICES.pause, { paused });
  }

  /** Sets the robot's motion model (one of modeChoices()). */
  setMode(name, mode) {
    return this._set(name, { [PARAMETERS.mode]: mode });
  }

  /** Sets the robot's mass and inertia to `factor` times robot.json's. */
  setPayload(name, factor) {
    return this._set(name, payloadValues(this.robot, factor));
  }

  _call(robotName, service, args) {
    return this.connection.callService(namespaced(robotName, service.name), service.type, args);
  }

  async _set(robotName, values) {
    const results = await setParameters(
      this.connection, namespacedRobot(this.robot, robotName), values);
    const refused = results.filter((result) => !result.successful);
    if (refused.length) {
      throw new Error(refused.map((result) => `${result.name}: ${result.reason}`).join('; '));
    }
    return results;
  }
}

/**
 * Runs `action(name)` for every name, at most `concurrency` at once; never rejects. Resolves
 * with one {name, ok, value} or {name, ok: false, error} per name, in the names' order.
 */
export async function forAll(names, action, { concurrency = FAN_OUT_CONCURRENCY } = {}) {
  const results = new Array(names.length);
  let next = 0;
  const worker = async () => {
    while (next < names.length) {
      const i = next;
      next += 1;
      try {
        results[i] = { name: names[i], ok: true, value: await action(names[i]) };
      } catch (error) {
        results[i] = { name: names[i], ok: false, error };
      }
    }
  };
  await Promise.all(Array.from({ length: Math.min(concurrency, names.length) }, worker));
  return results;
}

/** One line for a fan-out's results: "reset 40 robots" or "paused 38 of 40; 2 refused". */
export function fanOutSummary(verb, results) {
  const done = results.filter((result) => result.ok).length;
  if (done === results.length) return `${verb} ${done} robot${done === 1 ? '' : 's'}`;
  return `${verb} ${done} of ${results.length}; ${results.length - done} refused (see their cards)`;
}
