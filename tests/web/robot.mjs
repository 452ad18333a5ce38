// The robot description the page loads (web-interface/robot.json, the committed file that
// `websim robot-json` writes), read through the page's own loader: tests never restate it.
import { readFile } from 'node:fs/promises';

import { loadRobot } from '../../web-interface/js/robot.js';

/** web-interface/robot.json. */
export const ROBOT_JSON = new URL('../../web-interface/robot.json', import.meta.url);

/** Its text, parsed and checked by robot.js's loadRobot (as the page does it). */
export const robot = await loadRobot(async () => ({
  ok: true,
  json: async () => JSON.parse(await readFile(ROBOT_JSON, 'utf8')),
}));
