// The robot the page drives, as its server describes it in robot.json next to the pages: speed
// limits, footprint, topic and service names and types, the ParameterType codes and the
// parameter table. `websim robot-json` writes the file from the one parameter table, `websim
// serve` serves it live, the Docker stack's nginx serves the committed copy. The page's
// modules take every robot fact from this description (passed in, never a global): none of
// them restates one.

/** Where the description is, relative to the page (like config.json). */
export const ROBOT_URL = 'robot.json';

/**
 * The keys of robot.json's `robot` section that are also the node's speed-limit parameters
 * (the live values, read with get_parameters, override the file's).
 */
export const LIMIT_PARAMETERS = Object.freeze({
  linear: 'max_linear_mps', angular: 'max_angular_rps',
});

const TOPICS_USED = ['cmd_vel', 'odom', 'ground_truth', 'scan', 'tf_static', 'world'];
const SERVICES_USED = ['reset', 'get_parameters', 'set_parameters'];
const PARAMETER_TYPES_USED = ['NOT_SET', 'BOOL', 'INTEGER', 'DOUBLE', 'STRING'];
const ROBOT_NUMBERS_USED = [
  ...Object.values(LIMIT_PARAMETERS), 'footprint_radius_m', 'wheelbase_m', 'wheel_radius_m'];

/** robot.json is missing, unreadable or lacks something the page needs. */
export class RobotDescriptionError extends Error {
  constructor(problem) {
    super(`Could not load the robot's description (${problem}). The page takes the robot's `
      + 'topics, limits and parameters from robot.json next to it: serve the pages with '
      + '"websim serve", or write the file with "python -m websim.cli robot-json", and reload.');
    this.name = 'RobotDescriptionError';
  }
}

/** Fetches, checks and returns robot.json; rejects with a RobotDescriptionError. */
export async function loadRobot(fetchImpl = globalThis.fetch) {
  let response;
  try {
    response = await fetchImpl(ROBOT_URL, { cache: 'no-cache' });
  } catch (error) {
    throw new RobotDescriptionError(`${ROBOT_URL}: ${error.message}`);
  }
  if (!response.ok) throw new RobotDescriptionError(`${ROBOT_URL}: HTTP ${response.status}`);
  let description;
  try {
    description = await response.json();
  } catch {
    throw new RobotDescriptionError(`${ROBOT_URL} is not JSON`);
  }
  return checkRobot(description);
}

/**
 * `description` itself when it holds everything the page reads (each entry the right type);
 * throws a RobotDescriptionError naming the first entry that is missing.
 */
export function checkRobot(description) {
  const isName = (v) => typeof v === 'string' && v.length > 0;
  const isNumber = (v) => typeof v === 'number' && Number.isFinite(v);
  const checks = [
    ['node', isName],
    ...TOPICS_USED.flatMap((k) => [[`topics.${k}.name`, isName], [`topics.${k}.type`, isName]]),
    ...SERVICES_USED.flatMap((k) => [
      [`services.${k}.name`, isName], [`services.${k}.type`, isName]]),
    ...PARAMETER_TYPES_USED.map((k) => [`parameter_types.${k}`, Number.isInteger]),
    ...ROBOT_NUMBERS_USED.map((k) => [`robot.${k}`, isNumber]),
    ['parameters', Array.isArray],
  ];
  for (const [path, valid] of checks) {
    const value = path.split('.').reduce((node, key) => node?.[key], description);
    if (!valid(value)) throw new RobotDescriptionError(`${ROBOT_URL} has no valid ${path}`);
  }
  for (const [i, parameter] of description.parameters.entries()) {
    if (!isName(parameter?.name) || !Number.isInteger(parameter.type)) {
      throw new RobotDescriptionError(`${ROBOT_URL}: parameters[${i}] needs a name and a type`);
    }
  }
  return description;
}

/** The speed limits {linear (m/s), angular (rad/s)} robot.json gives. */
export function robotLimits(robot) {
  return {
    linear: robot.robot[LIMIT_PARAMETERS.linear],
    angular: robot.robot[LIMIT_PARAMETERS.angular],
  };
}

/** The parameters that can change while the robot runs: the admin page's form. */
export function runtimeParameters(robot) {
  return robot.parameters.filter((parameter) => parameter.runtime);
}

/** The parameters[] entry named `name`, or undefined. */
export function parameterSpec(robot, name) {
  return robot.parameters.find((parameter) => parameter.name === name);
}
