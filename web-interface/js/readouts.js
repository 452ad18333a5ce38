// The numbers under the view: pose, velocities, stamp time, message rates, the command-to-
// odometry latency and the bridge's round trip.

import { rateHz } from './state.js';
import { latencyMs } from './latency.js';

const REFRESH_MS = 100;
/** How often the round trip is timed: a cheap service call, answered by the bridge itself. */
const LATENCY_PERIOD_MS = 2000;

export class Readouts {
  /**
   * @param {HTMLElement} root holds <output data-readout="NAME"> elements: x, y, theta, v,
   *   omega, time, odomRate, scanRate, cmdLatency, roundTrip (any may be absent)
   * @param {object} robot the robot description (robot.js): the topic the round trip asks about
   */
  constructor(connection, state, root, robot) {
    this.connection = connection;
    this.state = state;
    this.probeTopic = robot.topics.odom.name;
    this.out = Object.fromEntries(
      [...root.querySelectorAll('[data-readout]')].map((el) => [el.dataset.readout, el]));
    this.roundTripMs = null;
    this.lastMs = -Infinity;
    setInterval(() => this._timeRoundTrip(), LATENCY_PERIOD_MS);
    connection.addEventListener('connected', () => this._timeRoundTrip());
    connection.addEventListener('disconnected', () => { this.roundTripMs = null; });
  }

  update(nowMs) {
    if (nowMs - this.lastMs < REFRESH_MS) return;
    this.lastMs = nowMs;
    const odom = this.state.odom;
    const fresh = odom && this.connection.isConnected;
    // Units are in the labels (x (m), θ (°), ...): the values stay short.
    this._set('x', fresh ? odom.x.toFixed(3) : '–');
    this._set('y', fresh ? odom.y.toFixed(3) : '–');
    this._set('theta', fresh ? ((odom.theta * 180) / Math.PI).toFixed(1) : '–');
    this._set('v', fresh ? odom.v.toFixed(2) : '–');
    this._set('omega', fresh ? odom.omega.toFixed(2) : '–');
    this._set('time', fresh && odom.stampS !== null ? clock(odom.stampS) : '–');
    this._set('odomRate', rateHz(this.state, 'odom', nowMs).toFixed(0));
    this._set('scanRate', rateHz(this.state, 'scan', nowMs).toFixed(0));
    const commandMs = latencyMs(this.state.latency);
    this._set('cmdLatency', commandMs === null ? '–' : commandMs.toFixed(0));
    this._set('roundTrip', this.roundTripMs === null ? '–' : this.roundTripMs.toFixed(0));
  }

  _set(name, text) {
    const el = this.out[name];
    if (el && el.textContent !== text) el.textContent = text;
  }

  async _timeRoundTrip() {
    if (!this.connection.isConnected) return;
    const start = performance.now();
    try {
      await this.connection.callService('/rosapi/topic_type', 'rosapi_msgs/srv/TopicType',
        { topic: this.probeTopic }, LATENCY_PERIOD_MS);
      this.roundTripMs = performance.now() - start;
    } catch {
      this.roundTripMs = null; // no rosapi on this bridge: nothing to show
    }
  }
}

/** A stamp (s since the epoch) as the local time of day, to the tenth of a second. */
function clock(stampS) {
  const date = new Date(stampS * 1000);
  const pad = (n, w = 2) => String(n).padStart(w, '0');
  return `${pad(date.getHours())}:${pad(date.getMinutes())}:${pad(date.getSeconds())}.`
    + `${Math.floor(date.getMilliseconds() / 100)}`;
}
