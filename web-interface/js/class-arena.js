// The dashboard's arena: a class whose robots share one world (websim serve --arena) is also
// shown as one map, every robot at its place, named. Fed by one robot's /NAME/world (the walls,
// once) and /NAME/world_robots (every robot of the world, 10 Hz) on the root connection: the
// world's message is the same whichever robot publishes it. Coordinates and colours as the
// thumbnails' (class-view.js, view.js).

import { applyMarkerArray, markerBounds, robotsFromMarkers } from './ros-msgs.js';
import { namespaced } from './class-plan.js';
import { fitCamera, paintRobot } from './class-view.js';
import { COLORS, paintWalls } from './view.js';

const ROBOTS_THROTTLE_MS = 100;
const PAD_PX = Object.freeze({ top: 8, right: 8, bottom: 8, left: 8 });
const LABEL_GAP_PX = 4;

/** The arena's state: its walls and its robots, as the messages left them. */
export function createArenaState() {
  return { markers: new Map(), bounds: null, robots: [], version: 0 };
}

/** /world: the walls of the arena. */
export function onArenaWorld(state, msg) {
  applyMarkerArray(state.markers, msg);
  state.bounds = markerBounds(state.markers);
  state.version += 1;
}

/** /world_robots: every robot of the arena now (none is "this page's"). */
export function onArenaRobots(state, msg) {
  state.robots = robotsFromMarkers(msg);
  state.version += 1;
}

export class ArenaMap {
  /**
   * @param {HTMLCanvasElement} canvas
   * @param {Connection} connection the root connection (connection.js) robot `name` is on
   * @param {object} robot the robot description (robot.js): the topics' names and types
   * @param {string} name a robot of the arena: whose copy of the world's messages to read
   */
  constructor(canvas, connection, robot, name) {
    this.canvas = canvas;
    this.ctx = canvas.getContext('2d');
    this.state = createArenaState();
    this.drawn = -1;
    const on = (key, handler, options) => connection.subscribe(
      namespaced(name, robot.topics[key].name), robot.topics[key].type, handler, options);
    on('world', (msg) => onArenaWorld(this.state, msg));
    on('world_robots', (msg) => onArenaRobots(this.state, msg),
      { throttleMs: ROBOTS_THROTTLE_MS });
  }

  /** Draws the arena if it changed since the last time (the animation loop calls it). */
  draw() {
    const { canvas, state } = this;
    const rect = canvas.getBoundingClientRect();
    const dpr = window.devicePixelRatio || 1;
    const width = Math.max(1, Math.round(rect.width * dpr));
    const height = Math.max(1, Math.round(rect.height * dpr));
    if (canvas.width !== width || canvas.height !== height) {
      canvas.width = width;
      canvas.height = height;
      this.drawn = -1;
    }
    if (this.drawn === state.version || !state.bounds) return;
    this.drawn = state.version;
    const camera = fitCamera(state.bounds, rect.width, rect.height, PAD_PX);
    const toScreen = (x, y) => [rect.width / 2 + (x - camera.x) * camera.scale,
      rect.height / 2 - (y - camera.y) * camera.scale];
    const { ctx } = this;
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    ctx.fillStyle = COLORS.background;
    ctx.fillRect(0, 0, rect.width, rect.height);
    paintWalls(ctx, state.markers, toScreen, camera.scale, 1);
    ctx.font = '12px system-ui, sans-serif';
    ctx.textAlign = 'center';
    for (const other of state.robots) {
      const [cx, cy] = toScreen(other.x, other.y);
      const r = paintRobot(ctx, cx, cy, other.radius * camera.scale, other.yaw);
      ctx.fillStyle = COLORS.text;
      ctx.fillText(other.name, cx, cy - r - LABEL_GAP_PX);
    }
  }
}
