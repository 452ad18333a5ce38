// The robot's runtime parameters through rcl_interfaces services, as ros2 param does it: the
// same calls work against websim serve and against a real rclpy node behind rosbridge.

import { parameterValue, valueOfParameter } from './ros-msgs.js';
import { DEFAULT_LIMITS } from './teleop.js';

export const NODE = '/virtual_robot';

/** Values of `names` as {name: value}; a parameter the node does not have reads undefined. */
export async function getParameters(connection, names) {
  const response = await connection.callService(`${NODE}/get_parameters`,
    'rcl_interfaces/srv/GetParameters', { names });
  const values = response.values ?? [];
  return Object.fromEntries(names.map((name, i) => [name, valueOfParameter(values[i])]));
}

/**
 * Sets {name: value} (numbers as doubles, strings as strings). Resolves with one
 * {name, successful, reason} per parameter; rejects when the call itself is refused (no admin
 * token) with the bridge's reason as the message.
 */
export async function setParameters(connection, values) {
  const names = Object.keys(values);
  const response = await connection.callService(`${NODE}/set_parameters`,
    'rcl_interfaces/srv/SetParameters',
    { parameters: names.map((name) => ({ name, value: parameterValue(values[name]) })) });
  return (response.results ?? []).map((result, i) => ({ name: names[i], ...result }));
}

/**
 * The robot's speed limits {linear (m/s), angular (rad/s)}: its max_linear_mps and
 * max_angular_rps when it has them, else the course defaults.
 */
export async function speedLimits(connection) {
  try {
    const values = await getParameters(connection, ['max_linear_mps', 'max_angular_rps']);
    return {
      linear: positiveOr(values.max_linear_mps, DEFAULT_LIMITS.linear),
      angular: positiveOr(values.max_angular_rps, DEFAULT_LIMITS.angular),
    };
  } catch (error) {
    console.info('websim: robot speed limits unknown, using defaults:', error.message);
    return { ...DEFAULT_LIMITS };
  }
}

function positiveOr(value, fallback) {
  return typeof value === 'number' && Number.isFinite(value) && value > 0 ? value : fallback;
}
