// The class's topics into the robots' states: subscribes class-plan.js's plan on the root
// Connection (which re-subscribes by itself after a reconnect) and routes each message to its
// robot's state (class-state.js). Latched streams (the world, the laser mount) are dropped
// once they have come: a class of 40 holds two subscriptions per robot, not five. A class
// spread over workers has a root connection per worker: each robot is subscribed on its own.

import { robotSubscriptions } from './class-plan.js';
import {
  clearScan, createRobotState, onPose, onScan, onTfStatic, onWorld,
} from './class-state.js';

const SCAN_STREAMS = new Set(['scan', 'tf_static']);

export class ClassFeed {
  /**
   * @param {Connection} connection the root connection (connection.js): addRobots' default
   * @param {object} robot the robot description (robot.js)
   * @param {{now?: () => number}} [options] the clock (ms) messages are stamped with
   */
  constructor(connection, robot, { now = () => performance.now() } = {}) {
    this.connection = connection;
    this.robot = robot;
    this.now = now;
    this.states = new Map(); // robot name -> state, in the class's order
    this.scans = false;
    this._unsubscribe = new Map(); // robot name -> Map(stream -> unsubscribe)
    this._connections = new Map(); // robot name -> the root connection it is subscribed on
  }

  get names() {
    return [...this.states.keys()];
  }

  /**
   * Adds the robots of `names` not yet known (an open class enrols more), subscribed on
   * `connection` (the root of the worker they live on); returns the new.
   */
  addRobots(names, connection = this.connection) {
    const added = names.filter((name) => !this.states.has(name));
    const count = this.states.size + added.length;
    for (const name of added) {
      this.states.set(name, createRobotState(name));
      this._unsubscribe.set(name, new Map());
      this._connections.set(name, connection);
      this._subscribe(name, count, (entry) => this.scans || !SCAN_STREAMS.has(entry.stream));
    }
    return added;
  }

  /** Scans on (every robot's /scan, and its laser mount) or off (unsubscribed, cleared). */
  setScans(on) {
    if (on === this.scans) return;
    this.scans = on;
    for (const [name, state] of this.states) {
      if (on) {
        this._subscribe(name, this.states.size, (entry) => SCAN_STREAMS.has(entry.stream));
      } else {
        const held = this._unsubscribe.get(name);
        for (const stream of SCAN_STREAMS) {
          held.get(stream)?.();
          held.delete(stream);
        }
        clearScan(state);
      }
    }
  }

  _subscribe(name, count, wanted) {
    const state = this.states.get(name);
    const held = this._unsubscribe.get(name);
    const connection = this._connections.get(name);
    for (const entry of robotSubscriptions(name, this.robot, count, { scans: true })) {
      if (!wanted(entry)) continue;
      const drop = () => {
        held.get(entry.stream)?.();
        held.delete(entry.stream);
      };
      const handle = this._handler(entry.stream, state, drop);
      held.set(entry.stream, connection.subscribe(entry.topic, entry.type, handle, {
        throttleMs: entry.throttleMs, queueLength: entry.queueLength,
      }));
    }
  }

  _handler(stream, state, drop) {
    switch (stream) {
      case 'ground_truth':
      case 'odom':
        return (msg) => onPose(state, stream, msg, this.now());
      case 'scan':
        return (msg) => onScan(state, msg);
      case 'world':
        return (msg) => {
          onWorld(state, msg);
          drop(); // latched: it does not change while the server runs
        };
      case 'tf_static':
        return (msg) => {
          if (onTfStatic(state, msg)) drop();
        };
      default:
        return (msg) => console.info(`websim: ${stream} message not used`, msg);
    }
  }
}
