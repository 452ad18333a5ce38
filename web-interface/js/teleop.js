// Teleoperation: keys, on-screen buttons and a touch joystick drive the robot's velocity
// command topic (robot.json's topics.cmd_vel).
//
// Each input is a "source" holding a demand in [-1, 1] for linear and angular speed; the
// command is their sum, clamped, times the speed sliders. While any source is active the
// command goes out at 10 Hz (the robot keeps the last command it got, so a page that stops
// talking must say zero first): a zero Twist follows every release, a lost focus, a hidden tab
// and a disconnect the page asks for.

import { onCommand } from './state.js';
import { twist } from './ros-msgs.js';
import { robotLimits } from './robot.js';

/** The course's teleop rate. */
export const PUBLISH_PERIOD_MS = 100;

/** event.key -> [linear, angular] demand; letters are matched in lower case. */
export const KEY_DEMANDS = Object.freeze({
  ArrowUp: [1, 0], w: [1, 0],
  ArrowDown: [-1, 0], s: [-1, 0],
  ArrowLeft: [0, 1], a: [0, 1],
  ArrowRight: [0, -1], d: [0, -1],
});

/** The speeds teleop starts with, as a fraction of the robot's limits. */
export const START_SPEED_FRACTION = 0.6;

/** Inputs that keep the keys for themselves: typing, or arrows moving a slider. */
export function keysBelongToElement(element) {
  if (!element) return false;
  if (element.isContentEditable) return true;
  const tag = element.tagName;
  if (tag === 'TEXTAREA' || tag === 'SELECT') return true;
  return tag === 'INPUT'
    && !['button', 'submit', 'reset', 'checkbox', 'radio'].includes(element.type);
}

/** Inputs where a space is typed: Space stops the robot everywhere else (a slider too). */
export function spaceBelongsToElement(element) {
  return keysBelongToElement(element) && !(element.tagName === 'INPUT' && element.type === 'range');
}

/** The [linear, angular] demand of held keys (a Set of event.key values), each in [-1, 1]. */
export function keyDemand(heldKeys) {
  let linear = 0;
  let angular = 0;
  for (const key of heldKeys) {
    const demand = KEY_DEMANDS[key];
    if (demand) {
      linear += demand[0];
      angular += demand[1];
    }
  }
  return [clampUnit(linear), clampUnit(angular)];
}

/**
 * The velocity-command side of teleoperation. Events: 'drive' when driving starts and 'halt'
 * when the user stops (Space, the Stop button): the PID panel stops then; 'command' with
 * detail {linear, angular} on every publish.
 * @param {object} robot the robot description (robot.js): its cmd_vel topic and limits
 */
export class Teleop extends EventTarget {
  constructor(connection, state, robot) {
    super();
    this.connection = connection;
    this.state = state;
    const { name, type } = robot.topics.cmd_vel;
    this.cmdVel = connection.publisher(name, type);
    this.sources = new Map(); // name -> [linear, angular] demand
    const limits = robotLimits(robot);
    this.speed = { // what full demand means (m/s, rad/s): the sliders set it
      linear: START_SPEED_FRACTION * limits.linear,
      angular: START_SPEED_FRACTION * limits.angular,
    };
    this.timer = null;
    connection.addEventListener('beforeclose', () => this.stop());
    connection.addEventListener('disconnected', () => this._clear());
  }

  get active() {
    return this.sources.size > 0;
  }

  /** Sets a source's demand; all-zero releases it. */
  set(source, linear, angular) {
    const wasActive = this.active;
    if (linear === 0 && angular === 0) {
      this.sources.delete(source);
    } else {
      this.sources.set(source, [clampUnit(linear), clampUnit(angular)]);
    }
    if (!wasActive && this.active) {
      this.dispatchEvent(new Event('drive'));
      this._publish();
      this.timer = setInterval(() => this._publish(), PUBLISH_PERIOD_MS);
    } else if (wasActive && !this.active) {
      this._clear();
      this._send(0, 0);
    }
  }

  /** Releases every source and sends a zero Twist (blur, hidden tab, disconnect). */
  stop() {
    this._clear();
    this._send(0, 0);
  }

  /** The user's stop (Space, the Stop button): stop() and a 'halt' for whatever else drives. */
  halt() {
    this.stop();
    this.dispatchEvent(new Event('halt'));
  }

  /** The command (m/s, rad/s) the held sources ask for now. */
  command() {
    let linear = 0;
    let angular = 0;
    for (const [l, a] of this.sources.values()) {
      linear += l;
      angular += a;
    }
    return [clampUnit(linear) * this.speed.linear, clampUnit(angular) * this.speed.angular];
  }

  _publish() {
    const [linear, angular] = this.command();
    this._send(linear, angular);
  }

  _send(linear, angular) {
    if (this.cmdVel.publish(twist(linear, angular))) {
      onCommand(this.state, linear, angular);
      this.dispatchEvent(new CustomEvent('command', { detail: { linear, angular } }));
    }
  }

  _clear() {
    clearInterval(this.timer);
    this.timer = null;
    this.sources.clear();
  }
}

/**
 * Arrow keys and WASD drive while held, Space stops; not while a text field has focus. The
 * keys the page uses never act on a focused control as well: Space on the PID's Stop button
 * would otherwise press it again and restart the PID (Enter still presses a button).
 */
export function bindKeys(teleop, target = window) {
  const held = new Set();
  const update = () => {
    const [linear, angular] = keyDemand(held);
    teleop.set('keys', linear, angular);
  };
  const pageKey = (event) => {
    if (event.ctrlKey || event.metaKey || event.altKey) return null;
    const key = event.key.length === 1 ? event.key.toLowerCase() : event.key;
    if (key === ' ') return spaceBelongsToElement(event.target) ? null : key;
    return key in KEY_DEMANDS && !keysBelongToElement(event.target) ? key : null;
  };
  target.addEventListener('keydown', (event) => {
    const key = pageKey(event);
    if (key === null) return;
    event.preventDefault(); // no scrolling, no pressing or toggling the focused control
    if (key === ' ') {
      held.clear();
      teleop.halt();
    } else {
      held.add(key);
      update();
    }
  });
  target.addEventListener('keyup', (event) => {
    const key = event.key.length === 1 ? event.key.toLowerCase() : event.key;
    if (pageKey(event) !== null) event.preventDefault(); // a button clicks on Space's keyup
    if (held.delete(key)) update();
  });
  const stopAll = () => {
    held.clear();
    teleop.stop();
  };
  window.addEventListener('blur', stopAll);
  document.addEventListener('visibilitychange', () => {
    if (document.visibilityState === 'hidden') stopAll();
  });
}

/** Buttons with data-drive="forward|back|left|right" drive while pressed; data-drive="stop". */
export function bindButtons(teleop, root) {
  const demands = { forward: [1, 0], back: [-1, 0], left: [0, 1], right: [0, -1] };
  for (const button of root.querySelectorAll('[data-drive]')) {
    const name = button.dataset.drive;
    if (name === 'stop') {
      button.addEventListener('click', () => teleop.halt());
      continue;
    }
    const source = `button:${name}`;
    button.addEventListener('pointerdown', (event) => {
      button.setPointerCapture(event.pointerId);
      button.classList.add('held');
      teleop.set(source, ...demands[name]);
    });
    const release = () => {
      button.classList.remove('held');
      teleop.set(source, 0, 0);
    };
    for (const type of ['pointerup', 'pointercancel', 'lostpointercapture']) {
      button.addEventListener(type, release);
    }
    button.addEventListener('contextmenu', (event) => event.preventDefault()); // long press
  }
}

/** The joystick's diameter (CSS px) where its zone has room for it. */
const JOYSTICK_SIZE_PX = 150;
/** The joystick keeps at least this much (CSS px) between its rim and its zone's edges. */
const JOYSTICK_MARGIN_PX = 10;

/**
 * A nipplejs joystick in `zone`: up drives forward, sideways turns; its deflection (0 at the
 * centre, 1 at the rim) scales the speed. It is as large as fits inside the zone's narrower
 * side (style.css shapes the zone: a wide strip upright, a column beside the view sideways).
 */
export function bindJoystick(teleop, zone, nipplejs) {
  const room = Math.min(zone.clientWidth, zone.clientHeight) - 2 * JOYSTICK_MARGIN_PX;
  const manager = nipplejs.create({
    zone,
    mode: 'static',
    position: { left: '50%', top: '50%' },
    size: room > 0 ? Math.min(JOYSTICK_SIZE_PX, room) : JOYSTICK_SIZE_PX,
    color: { front: '#2563eb', back: 'rgba(37, 99, 235, 0.15)' },
    restOpacity: 0.8,
  });
  manager.on('move', (event) => {
    const { x, y } = event.data.vector; // y up, each in [-1, 1] of the radius
    teleop.set('joystick', y, -x);
  });
  manager.on('end', () => teleop.set('joystick', 0, 0));
  return manager;
}

/**
 * Speed sliders (range inputs) set teleop.speed; they start at teleop's speed, bounded by
 * `limits` {linear (m/s), angular (rad/s)}, and setLimits() moves the bounds.
 */
export function bindSpeedSliders(teleop, { linear, angular, linearOut, angularOut }, limits) {
  const show = () => {
    teleop.speed = { linear: Number(linear.value), angular: Number(angular.value) };
    linearOut.value = `${teleop.speed.linear.toFixed(2)} m/s`;
    angularOut.value = `${teleop.speed.angular.toFixed(1)} rad/s`;
  };
  const setLimits = (bounds) => {
    linear.max = String(bounds.linear);
    angular.max = String(bounds.angular);
    linear.value = String(Math.min(Number(linear.value), bounds.linear));
    angular.value = String(Math.min(Number(angular.value), bounds.angular));
    show();
  };
  linear.addEventListener('input', show);
  angular.addEventListener('input', show);
  linear.value = String(teleop.speed.linear); // the page sets no max: nothing clamps these
  angular.value = String(teleop.speed.angular);
  setLimits(limits);
  /** Bounds the sliders by the robot's limits (m/s, rad/s), keeping the values inside. */
  return { setLimits };
}

function clampUnit(value) {
  return Math.max(-1, Math.min(1, value));
}
