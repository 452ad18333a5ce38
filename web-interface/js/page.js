// What both pages share: the robot's subscriptions, the view with its buttons, teleop with its
// controls, and the page-wide error banner. The pages (main.js, admin.js) only wire them. The
// robot's topics and limits come from its description (robot.js), passed in as `robot`.

import { missingLibraries, nipplejs } from './vendor.js';
import {
  clearTrail, noteLinkDown, noteLinkUp, onCommand, onGroundTruth, onOdometry, onScan, onTfStatic,
  onWorld, onWorldRobots,
} from './state.js';
import { twistValues } from './ros-msgs.js';
import { noteCommand, noteOwnCommand } from './drivers.js';
import { noteCommandSent } from './latency.js';
import { View } from './view.js';
import {
  bindButtons, bindJoystick, bindKeys, bindSpeedSliders, Teleop,
} from './teleop.js';
import { speedLimits } from './params.js';
import { loadRobot, robotLimits } from './robot.js';
import { withPageBridge } from './connection.js';

export const $ = (selector) => document.querySelector(selector);

/** Subscribes the state to the robot's topics; absent ones (a real robot) simply stay quiet. */
export function subscribeRobot(connection, state, robot) {
  const now = () => performance.now();
  const on = (key, onMessage, options) => {
    const { name, type } = robot.topics[key];
    connection.subscribe(name, type, onMessage, options);
  };
  on('odom', (m) => onOdometry(state, m, now()));
  on('ground_truth', (m) => onGroundTruth(state, m, now()));
  on('scan', (m) => onScan(state, m, now()));
  on('tf_static', (m) => onTfStatic(state, m), { queueLength: 10 });
  on('world', (m) => onWorld(state, m));
  if (robot.topics.world_robots) { // the world's other robots (an arena), at 10 Hz
    on('world_robots', (m) => onWorldRobots(state, m, now()), { throttleMs: 100 });
  }
  on('cmd_vel', (m) => {
    const { linear, angular } = twistValues(m); // any client's command: what the robot obeys
    onCommand(state, linear, angular);
    noteCommand(state.drivers, m, now()); // ours come back too: drivers.js tells them apart
  });
  connection.addEventListener('published', (event) => { // teleop, joystick, PID, stop
    const { topic, msg } = event.detail;
    if (topic !== robot.topics.cmd_vel.name) return;
    noteOwnCommand(state.drivers, msg, now());
    const { linear, angular } = twistValues(msg);
    noteCommandSent(state.latency, linear, angular, now());
  });
  connection.addEventListener('connected', () => {
    clearTrail(state);
    noteLinkUp(state);
  });
  connection.addEventListener('disconnected', () => noteLinkDown(state, now()));
}

/** A view with its follow and reset buttons, and its note that the picture is stale. */
export function createView(state, robot) {
  const follow = $('#follow');
  const view = new View($('#view'), state, robot, {
    onFollowChange: (on) => follow.setAttribute('aria-pressed', String(on)),
    staleNote: $('#view-stale'),
  });
  follow.addEventListener('click', () => view.setFollow(!view.follow));
  $('#reset-view').addEventListener('click', () => view.resetView());
  return view;
}

/**
 * Teleop with keys, buttons, sliders and (on touch screens) the joystick. Returns {teleop,
 * limits}: limits are the robot's speed limits now, robot.json's until the live parameters
 * arrive on connecting.
 */
export function createTeleop(connection, state, robot) {
  const teleop = new Teleop(connection, state, robot);
  bindKeys(teleop);
  bindButtons(teleop, $('#drive-pad'));
  const zone = $('#joystick');
  if (zone && window.matchMedia('(pointer: coarse)').matches) {
    zone.hidden = false;
    bindJoystick(teleop, zone, nipplejs);
  }
  const limits = robotLimits(robot);
  const sliders = bindSpeedSliders(teleop, {
    linear: $('#speed-linear'),
    angular: $('#speed-angular'),
    linearOut: $('#speed-linear-value'),
    angularOut: $('#speed-angular-value'),
  }, limits);
  connection.addEventListener('connected', async () => {
    Object.assign(limits, await speedLimits(connection, robot));
    sliders.setLimits(limits);
  });
  return { teleop, limits };
}

/** Shows a page-wide error instead of a blank page. */
export function showFatal(text) {
  const banner = $('#fatal');
  banner.textContent = text;
  banner.hidden = false;
}

/**
 * The robot's description from robot.json (robot.js), or null after saying on the page why
 * it could not be loaded: the page never guesses the robot's topics or limits.
 */
export async function robotDescription() {
  try {
    return await loadRobot();
  } catch (error) {
    showFatal(error.message);
    return null;
  }
}

/** True when the npm libraries loaded; otherwise says on the page how to install them. */
export function librariesLoaded() {
  const missing = missingLibraries();
  if (missing.length) {
    showFatal(`Could not load ${missing.join(' and ')} from web-interface/node_modules: run `
      + '"npm ci" in web-interface/ (or "bash scripts/test.sh") and reload.');
  }
  return missing.length === 0;
}

/** Closes the connection (a zero velocity command first) when the page goes; reopens it. */
/**
 * Make the page's navigation links (`nav a`) carry its ?ws= when followed: the bridge chosen
 * on one page (in the address, or since, with the Bridge field) is the other page's too.
 */
export function keepBridgeOnNavigation(root = document, location = window.location) {
  for (const anchor of root.querySelectorAll('nav a')) {
    const href = anchor.getAttribute('href');
    const follow = () => { anchor.setAttribute('href', withPageBridge(href, location)); };
    anchor.addEventListener('click', follow);
    anchor.addEventListener('auxclick', follow);
  }
}

export function closeWithPage(connection) {
  window.addEventListener('pagehide', () => connection.close());
  window.addEventListener('pageshow', (event) => {
    if (event.persisted) connection.connect();
  });
}
