// The robot's runtime parameters through rcl_interfaces services, as ros2 param does it: the
// same calls work against websim serve and against a real rclpy node behind rosbridge. The
// services, their types and the ParameterType codes are the robot description's (robot.js).

import { parameterValue, valueOfParameter } from './ros-msgs.js';
import { LIMIT_PARAMETERS, parameterSpec, robotLimits } from './robot.js';

/** Values of `names` as {name: value}; a parameter the node does not have reads undefined. */
export async function getParameters(connection, robot, names) {
  const { name, type } = robot.services.get_parameters;
  const response = await connection.callService(name, type, { names });
  const values = response.values ?? [];
  return Object.fromEntries(
    names.map((key, i) => [key, valueOfParameter(robot.parameter_types, values[i])]));
}

/**
 * Sets {name: value}, each as its type in the robot's parameter table. Resolves with one
 * {name, successful, reason} per parameter; rejects when the call itself is refused (no admin
 * token) with the bridge's reason as the message, and before sending anything when a name is
 * not in the table or a value does not fit its type.
 */
export async function setParameters(connection, robot, values) {
  const names = Object.keys(values);
  const parameters = names.map((key) => {
    const spec = parameterSpec(robot, key);
    if (!spec) throw new TypeError(`${key} is not a parameter of ${robot.node}`);
    return { name: key, value: parameterValue(robot.parameter_types, spec.type, values[key]) };
  });
  const { name, type } = robot.services.set_parameters;
  const response = await connection.callService(name, type, { parameters });
  return (response.results ?? []).map((result, i) => ({ name: names[i], ...result }));
}

/**
 * The robot's speed limits {linear (m/s), angular (rad/s)}: its live max_linear_mps and
 * max_angular_rps when it has them, else robot.json's.
 */
export async function speedLimits(connection, robot) {
  const fallback = robotLimits(robot);
  try {
    const values = await getParameters(connection, robot, Object.values(LIMIT_PARAMETERS));
    return {
      linear: positiveOr(values[LIMIT_PARAMETERS.linear], fallback.linear),
      angular: positiveOr(values[LIMIT_PARAMETERS.angular], fallback.angular),
    };
  } catch (error) {
    console.info('websim: live speed limits unknown, using robot.json\'s:', error.message);
    return fallback;
  }
}

function positiveOr(value, fallback) {
  return typeof value === 'number' && Number.isFinite(value) && value > 0 ? value : fallback;
}
