// What both pages share: the robot's subscriptions, the view with its buttons, teleop with its
// controls, and the page-wide error banner. The pages (main.js, admin.js) only wire them.

import { missingLibraries, nipplejs } from './vendor.js';
import {
  clearTrail, onCommand, onGroundTruth, onOdometry, onScan, onTfStatic, onWorld,
} from './state.js';
import { twistValues } from './ros-msgs.js';
import { View } from './view.js';
import {
  bindButtons, bindJoystick, bindKeys, bindSpeedSliders, DEFAULT_LIMITS, Teleop,
} from './teleop.js';
import { speedLimits } from './params.js';

export const $ = (selector) => document.querySelector(selector);

/** Subscribes the state to the robot's topics; absent ones (a real robot) simply stay quiet. */
export function subscribeRobot(connection, state) {
  const now = () => performance.now();
  connection.subscribe('/odom', 'nav_msgs/msg/Odometry', (m) => onOdometry(state, m, now()));
  connection.subscribe('/ground_truth', 'nav_msgs/msg/Odometry',
    (m) => onGroundTruth(state, m, now()));
  connection.subscribe('/scan', 'sensor_msgs/msg/LaserScan', (m) => onScan(state, m, now()));
  connection.subscribe('/tf_static', 'tf2_msgs/msg/TFMessage', (m) => onTfStatic(state, m),
    { queueLength: 10 });
  connection.subscribe('/world', 'visualization_msgs/msg/MarkerArray', (m) => onWorld(state, m));
  connection.subscribe('/cmd_vel', 'geometry_msgs/msg/Twist', (m) => {
    const { linear, angular } = twistValues(m); // any client's command: what the robot obeys
    onCommand(state, linear, angular);
  });
  connection.addEventListener('connected', () => clearTrail(state));
}

/** A view with its follow and reset buttons. */
export function createView(state) {
  const follow = $('#follow');
  const view = new View($('#view'), state, {
    onFollowChange: (on) => follow.setAttribute('aria-pressed', String(on)),
  });
  follow.addEventListener('click', () => view.setFollow(!view.follow));
  $('#reset-view').addEventListener('click', () => view.resetView());
  return view;
}

/** Teleop with keys, buttons, sliders and (on touch screens) the joystick. */
export function createTeleop(connection, state) {
  const teleop = new Teleop(connection, state);
  bindKeys(teleop);
  bindButtons(teleop, $('#drive-pad'));
  const zone = $('#joystick');
  if (zone && window.matchMedia('(pointer: coarse)').matches) {
    zone.hidden = false;
    bindJoystick(teleop, zone, nipplejs);
  }
  const sliders = bindSpeedSliders(teleop, {
    linear: $('#speed-linear'),
    angular: $('#speed-angular'),
    linearOut: $('#speed-linear-value'),
    angularOut: $('#speed-angular-value'),
  });
  const limits = { ...DEFAULT_LIMITS };
  connection.addEventListener('connected', async () => {
    Object.assign(limits, await speedLimits(connection));
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

/** True when the npm libraries loaded; otherwise says on the page how to install them. */
export function librariesLoaded() {
  const missing = missingLibraries();
  if (missing.length) {
    showFatal(`Could not load ${missing.join(' and ')} from web-interface/node_modules: run `
      + '"npm ci" in web-interface/ (or "bash scripts/test.sh") and reload.');
  }
  return missing.length === 0;
}

/** Closes the connection (a zero /cmd_vel first) when the page goes, reopens it on return. */
export function closeWithPage(connection) {
  window.addEventListener('pagehide', () => connection.close());
  window.addEventListener('pageshow', (event) => {
    if (event.persisted) connection.connect();
  });
}
