// The heading PID panel: gains and setpoint from the form, the controller (pid.js) run at 10 Hz
// in the browser, from the odometry's yaw to the velocity command's angular.z (linear 0); the
// topics are the robot description's (robot.json).

import { CONTROL_PERIOD_S, INITIAL_STATE, makeGains, pidStep } from './pid.js';
import { onCommand } from './state.js';
import { twist } from './ros-msgs.js';

/** Odometry older than this (ms) is not steered on: the panel commands zero and waits. */
const ODOM_STALE_MS = 500;

const DEG = Math.PI / 180;

/**
 * Events: 'start', 'stop'.
 * @param {object} robot the robot description (robot.js)
 * @param {object} elements {form, kp, ki, kd, setpoint, toggle, status, error, output}
 * @param {() => number} outputLimit the robot's max_angular_rps now
 */
export class PidPanel extends EventTarget {
  constructor(connection, state, robot, elements, outputLimit) {
    super();
    this.connection = connection;
    this.state = state;
    this.el = elements;
    this.outputLimit = outputLimit;
    this.odomTopic = robot.topics.odom.name;
    const { name, type } = robot.topics.cmd_vel;
    this.cmdVel = connection.publisher(name, type);
    this.timer = null;
    this.memory = INITIAL_STATE;
    this.formError = null;
    elements.form.addEventListener('submit', (event) => {
      event.preventDefault();
      if (this.running) this.stop(); else this.start();
    });
    for (const input of [elements.kp, elements.ki, elements.kd, elements.setpoint]) {
      input.addEventListener('input', () => {
        if (this.running) this._readForm();
      });
    }
    connection.addEventListener('beforeclose', () => this.stop());
    connection.addEventListener('disconnected', () => this.stop());
  }

  get running() {
    return this.timer !== null;
  }

  start() {
    if (!this._readForm()) return;
    this.memory = INITIAL_STATE;
    this.timer = setInterval(() => this._step(), CONTROL_PERIOD_S * 1000);
    this.el.toggle.textContent = 'Stop';
    this.el.toggle.setAttribute('aria-pressed', 'true');
    this.dispatchEvent(new Event('start'));
    this._step();
  }

  stop() {
    if (!this.running) return;
    clearInterval(this.timer);
    this.timer = null;
    this.state.setpointDeg = null;
    this._send(0);
    this.el.toggle.textContent = 'Start';
    this.el.toggle.setAttribute('aria-pressed', 'false');
    this.el.status.textContent = 'stopped';
    this.dispatchEvent(new Event('stop'));
  }

  _readForm() {
    try {
      this.gains = makeGains({
        kp: Number(this.el.kp.value),
        ki: Number(this.el.ki.value),
        kd: Number(this.el.kd.value),
        outputLimit: this.outputLimit(),
      });
      const setpointDeg = Number(this.el.setpoint.value);
      if (this.el.setpoint.value.trim() === '' || !Number.isFinite(setpointDeg)) {
        throw new RangeError('the setpoint must be a number of degrees');
      }
      this.setpointDeg = setpointDeg;
      if (this.running) this.state.setpointDeg = wrapDeg(setpointDeg);
      this.formError = null;
      this.el.status.textContent = this.running ? 'running' : 'ready';
      return true;
    } catch (error) {
      // While running, the last good gains stay in force; the status says what is wrong.
      this.formError = error.message;
      this.el.status.textContent = error.message;
      return false;
    }
  }

  _step() {
    this.state.setpointDeg = wrapDeg(this.setpointDeg);
    const odom = this.state.odom;
    if (!odom || performance.now() - this.state.odomAtMs > ODOM_STALE_MS) {
      this.memory = INITIAL_STATE;
      this._send(0);
      this.el.status.textContent = `waiting for ${this.odomTopic}`;
      return;
    }
    const step = pidStep(this.gains, this.memory, this.setpointDeg * DEG, odom.theta);
    this.memory = step.state;
    this._send(step.output);
    this.el.status.textContent = this.formError
      ?? (step.saturated ? 'running (saturated)' : 'running');
    this.el.error.value = (step.error / DEG).toFixed(1);
    this.el.output.value = step.output.toFixed(2);
  }

  _send(angular) {
    if (this.cmdVel.publish(twist(0, angular))) onCommand(this.state, 0, angular);
  }
}

/** Degrees wrapped into (-180, 180], as the heading plot shows them. */
function wrapDeg(deg) {
  const wrapped = deg - 360 * Math.round(deg / 360);
  return wrapped <= -180 ? wrapped + 360 : wrapped;
}
