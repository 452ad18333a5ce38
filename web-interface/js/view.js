// The 2D view: a canvas showing the world, the robot, its scan and trail, with pan and zoom.
//
// Coordinates: the world is in metres, ROS convention (x right, y up); the canvas is in CSS
// pixels (y down). worldToScreen() is the one place that scales and flips y. The backing
// store has devicePixelRatio pixels per CSS pixel so lines stay crisp on HiDPI screens. Static
// walls are drawn once into an offscreen layer (again only when the world or the zoom changes)
// and copied each frame. While the bridge is down the view keeps the last picture (frame,
// walls, zoom) and its stale note says how old it is.

import { displayPose, poseAt, shownAtMs, TRAIL_S } from './state.js';
import { composePose } from './ros-msgs.js';

const WHEEL_WIDTH_M = 0.025; // drawn only: the model has no wheel width

export const COLORS = Object.freeze({
  background: '#f8fafc',
  grid: '#e2e8f0',
  gridAxis: '#cbd5e1',
  wall: '#1e293b',
  disc: '#475569',
  scan: '#e11d48',
  robotFill: 'rgba(37, 99, 235, 0.16)',
  robot: '#2563eb',
  otherFill: 'rgba(100, 116, 139, 0.22)',
  other: '#64748b',
  heading: '#1e3a8a',
  wheel: '#334155',
  trail: '37, 99, 235',
  xAxis: '#dc2626',
  yAxis: '#16a34a',
  text: '#334155',
});

const SCAN_DOT_PX = 3;
const MIN_SCALE = 5; // px per m
const MAX_SCALE = 3000;
const OTHERS_STALE_MS = 1000; // /world_robots older than this: the others are not shown
const DEFAULT_SPAN_M = 4; // what the view shows around the robot when there is no world
const FIT_MARGIN = 0.04;
const FIT_PAD_PX = 44; // room for the buttons above and the scale bar below a fitted world
const LAYER_MAX_PX = 4096; // larger wall layers are not cached: the walls are drawn directly
const NICE_LENGTHS_M = [0.05, 0.1, 0.2, 0.5, 1, 2, 5, 10, 20, 50, 100];

export class View {
  /**
   * @param {HTMLCanvasElement} canvas
   * @param {object} state from state.js
   * @param {object} robot the robot description (robot.js): footprint, wheelbase, wheels
   * @param {{onFollowChange?: (follow: boolean) => void, staleNote?: HTMLElement}} [options]
   *   staleNote: shown, saying how old the picture is, while the bridge is down
   */
  constructor(canvas, state, robot, { onFollowChange = () => {}, staleNote = null } = {}) {
    this.canvas = canvas;
    this.ctx = canvas.getContext('2d');
    this.state = state;
    this.body = { // the robot's drawing (m)
      radius: robot.robot.footprint_radius_m,
      track: robot.robot.wheelbase_m,
      wheelDiameter: 2 * robot.robot.wheel_radius_m,
    };
    this.onFollowChange = onFollowChange;
    this.staleNote = staleNote;
    this.camera = { x: 0, y: 0, scale: 80 }; // world point at the centre; px per m
    this.follow = false;
    this.userMoved = false; // until the user pans or zooms, the view fits the world itself
    this.cssWidth = 0;
    this.cssHeight = 0;
    this.dpr = 1;
    this.layer = null; // {canvas, key, originX, originY}: the pre-rendered walls
    this.pointers = new Map();
    this._resize();
    new ResizeObserver(() => this._resize()).observe(canvas);
    this._bindInput();
  }

  /** CSS pixel position of the world point (x, y) in metres: scale, then flip y. */
  worldToScreen(x, y) {
    const { camera } = this;
    return [
      this.cssWidth / 2 + (x - camera.x) * camera.scale,
      this.cssHeight / 2 - (y - camera.y) * camera.scale,
    ];
  }

  /** The world point (m) under the CSS pixel (sx, sy). */
  screenToWorld(sx, sy) {
    const { camera } = this;
    return [
      camera.x + (sx - this.cssWidth / 2) / camera.scale,
      camera.y - (sy - this.cssHeight / 2) / camera.scale,
    ];
  }

  setFollow(follow) {
    this.follow = follow;
    if (follow) this.userMoved = true;
    this.onFollowChange(follow);
  }

  /** Shows the whole world (or the robot's surroundings) and stops following. */
  resetView(nowMs = performance.now()) {
    this.userMoved = false;
    this.setFollow(false);
    this._fit(nowMs);
  }

  /** Draws the latest state; called by the page's one animation loop. */
  draw(nowMs) {
    this._resize();
    const { ctx, state } = this;
    const atMs = shownAtMs(state, nowMs); // while the bridge is down: as it was last seen
    const stale = atMs < nowMs;
    const { pose, frame } = displayPose(state, atMs);
    if (this.follow && pose) {
      this.camera.x = pose.x;
      this.camera.y = pose.y;
    } else if (!this.userMoved) {
      this._fit(atMs);
    }
    ctx.setTransform(this.dpr, 0, 0, this.dpr, 0, 0);
    ctx.fillStyle = COLORS.background;
    ctx.fillRect(0, 0, this.cssWidth, this.cssHeight);
    this._drawGrid();
    if (frame !== 'odom') this._drawWalls(); // walls are in map: they need ground truth
    this._drawAxes();
    this._drawTrail(atMs);
    if (frame === 'map') this._drawOthers(atMs); // the world's other robots are in map
    if (pose) {
      this._drawScan(poseAt(state, frame, state.scan?.stampS) ?? pose);
      this._drawRobot(pose);
    }
    this._drawScaleBar();
    this._drawFrameLabel(frame);
    this._showStale(stale && (pose || state.worldBounds) ? nowMs - atMs : null);
  }

  /** The stale note: how old the picture is (ms), or null to hide it. Whole seconds. */
  _showStale(ageMs) {
    const note = this.staleNote;
    if (!note) return;
    const text = ageMs === null ? ''
      : `Stale: the last picture from the bridge, ${Math.floor(ageMs / 1000)} s old`;
    if (note.textContent !== text) note.textContent = text;
    if (note.hidden !== !text) note.hidden = !text;
  }

  _fit(nowMs) {
    const bounds = this.state.worldBounds;
    const { pose, frame } = displayPose(this.state, nowMs);
    if (bounds && (!pose || frame === 'map')) { // walls are in map: fit them
      const spanX = (bounds.maxX - bounds.minX) * (1 + 2 * FIT_MARGIN) || DEFAULT_SPAN_M;
      const spanY = (bounds.maxY - bounds.minY) * (1 + 2 * FIT_MARGIN) || DEFAULT_SPAN_M;
      this.camera = {
        x: (bounds.minX + bounds.maxX) / 2,
        y: (bounds.minY + bounds.maxY) / 2,
        scale: clampScale(Math.min((this.cssWidth - 2 * FIT_PAD_PX) / spanX,
          (this.cssHeight - 2 * FIT_PAD_PX) / spanY)),
      };
    } else {
      this.camera = {
        x: pose ? pose.x : 0,
        y: pose ? pose.y : 0,
        scale: clampScale(Math.min(this.cssWidth, this.cssHeight) / DEFAULT_SPAN_M),
      };
    }
  }

  _resize() {
    const rect = this.canvas.getBoundingClientRect();
    const dpr = window.devicePixelRatio || 1;
    if (rect.width === this.cssWidth && rect.height === this.cssHeight && dpr === this.dpr) return;
    this.cssWidth = rect.width;
    this.cssHeight = rect.height;
    this.dpr = dpr;
    this.canvas.width = Math.max(1, Math.round(rect.width * dpr));
    this.canvas.height = Math.max(1, Math.round(rect.height * dpr));
  }

  _drawGrid() {
    const { ctx, camera } = this;
    const stepM = camera.scale >= 12 ? 1 : 10;
    const [x0, y1] = this.screenToWorld(0, 0);
    const [x1, y0] = this.screenToWorld(this.cssWidth, this.cssHeight);
    ctx.lineWidth = 1;
    ctx.strokeStyle = COLORS.grid;
    ctx.beginPath();
    for (let x = Math.ceil(x0 / stepM) * stepM; x <= x1; x += stepM) {
      const sx = crisp(this.worldToScreen(x, 0)[0], this.dpr);
      ctx.moveTo(sx, 0);
      ctx.lineTo(sx, this.cssHeight);
    }
    for (let y = Math.ceil(y0 / stepM) * stepM; y <= y1; y += stepM) {
      const sy = crisp(this.worldToScreen(0, y)[1], this.dpr);
      ctx.moveTo(0, sy);
      ctx.lineTo(this.cssWidth, sy);
    }
    ctx.stroke();
  }

  _drawAxes() {
    // The frame's origin, RViz colours: x red, y green, 0.3 m long.
    const { ctx } = this;
    const [ox, oy] = this.worldToScreen(0, 0);
    const [xx, xy] = this.worldToScreen(0.3, 0);
    const [yx, yy] = this.worldToScreen(0, 0.3);
    ctx.lineWidth = 2;
    ctx.lineCap = 'round';
    for (const [color, ex, ey] of [[COLORS.xAxis, xx, xy], [COLORS.yAxis, yx, yy]]) {
      ctx.strokeStyle = color;
      ctx.beginPath();
      ctx.moveTo(ox, oy);
      ctx.lineTo(ex, ey);
      ctx.stroke();
    }
  }

  _drawWalls() {
    const { state, ctx } = this;
    const bounds = state.worldBounds;
    if (!bounds) return;
    const marginM = 0.5;
    const key = `${state.worldVersion}:${this.camera.scale}:${this.dpr}`;
    const widthPx = (bounds.maxX - bounds.minX + 2 * marginM) * this.camera.scale * this.dpr;
    const heightPx = (bounds.maxY - bounds.minY + 2 * marginM) * this.camera.scale * this.dpr;
    if (widthPx > LAYER_MAX_PX || heightPx > LAYER_MAX_PX) {
      paintWalls(ctx, state.markers, (x, y) => this.worldToScreen(x, y), this.camera.scale);
      return;
    }
    if (!this.layer || this.layer.key !== key) {
      const layer = document.createElement('canvas');
      layer.width = Math.ceil(widthPx);
      layer.height = Math.ceil(heightPx);
      const layerCtx = layer.getContext('2d');
      const originX = bounds.minX - marginM;
      const originY = bounds.maxY + marginM;
      const scale = this.camera.scale;
      layerCtx.setTransform(this.dpr, 0, 0, this.dpr, 0, 0);
      paintWalls(layerCtx, state.markers,
        (x, y) => [(x - originX) * scale, (originY - y) * scale], scale);
      this.layer = { canvas: layer, key, originX, originY };
    }
    const [sx, sy] = this.worldToScreen(this.layer.originX, this.layer.originY);
    ctx.save();
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.drawImage(this.layer.canvas, Math.round(sx * this.dpr), Math.round(sy * this.dpr));
    ctx.restore();
  }

  _drawTrail(nowMs) {
    const { ctx } = this;
    const points = this.state.trail.points;
    if (points.length < 2) return;
    const BUCKETS = 8; // segments grouped by age: one stroke per shade
    const paths = Array.from({ length: BUCKETS }, () => new Path2D());
    for (let i = 1; i < points.length; i += 1) {
      if (points[i].gap) continue;
      const age = (nowMs - points[i].tMs) / (TRAIL_S * 1000);
      const bucket = Math.min(BUCKETS - 1, Math.max(0, Math.floor(age * BUCKETS)));
      const [ax, ay] = this.worldToScreen(points[i - 1].x, points[i - 1].y);
      const [bx, by] = this.worldToScreen(points[i].x, points[i].y);
      paths[bucket].moveTo(ax, ay);
      paths[bucket].lineTo(bx, by);
    }
    ctx.lineWidth = 2;
    ctx.lineCap = 'round';
    paths.forEach((path, bucket) => {
      ctx.strokeStyle = `rgba(${COLORS.trail}, ${(0.7 * (1 - bucket / BUCKETS)).toFixed(2)})`;
      ctx.stroke(path);
    });
  }

  /** The scan, from the laser at `pose`: the robot's pose when the scan was taken. */
  _drawScan(pose) {
    const { ctx, state } = this;
    if (!state.scan) return;
    const laser = composePose({ x: pose.x, y: pose.y, yaw: pose.theta }, state.laserMount);
    const c = Math.cos(laser.yaw);
    const s = Math.sin(laser.yaw);
    const points = state.scan.points;
    ctx.fillStyle = COLORS.scan;
    const half = SCAN_DOT_PX / 2;
    for (let i = 0; i < points.length; i += 2) {
      const x = laser.x + c * points[i] - s * points[i + 1];
      const y = laser.y + s * points[i] + c * points[i + 1];
      const [sx, sy] = this.worldToScreen(x, y);
      ctx.fillRect(sx - half, sy - half, SCAN_DOT_PX, SCAN_DOT_PX);
    }
  }

  _drawRobot(pose) {
    const { ctx } = this;
    const scale = this.camera.scale;
    const [cx, cy] = this.worldToScreen(pose.x, pose.y);
    ctx.save();
    ctx.translate(cx, cy);
    ctx.rotate(-pose.theta); // canvas angles turn clockwise: the y-flip reverses them
    const { radius, track, wheelDiameter } = this.body;
    const r = Math.max(radius * scale, 4);
    ctx.fillStyle = COLORS.wheel;
    for (const side of [-1, 1]) {
      ctx.fillRect((-wheelDiameter / 2) * scale, (side * track) / 2 * scale
        - (WHEEL_WIDTH_M / 2) * scale, wheelDiameter * scale, WHEEL_WIDTH_M * scale);
    }
    ctx.beginPath();
    ctx.arc(0, 0, r, 0, 2 * Math.PI);
    ctx.fillStyle = COLORS.robotFill;
    ctx.fill();
    ctx.lineWidth = 2;
    ctx.strokeStyle = COLORS.robot;
    ctx.stroke();
    ctx.beginPath(); // heading: a wedge pointing at the front of the robot
    ctx.moveTo(r * 0.95, 0);
    ctx.lineTo(-r * 0.35, -r * 0.5);
    ctx.lineTo(-r * 0.1, 0);
    ctx.lineTo(-r * 0.35, r * 0.5);
    ctx.closePath();
    ctx.fillStyle = COLORS.heading;
    ctx.fill();
    ctx.restore();
  }

  /** The world's other robots (/world_robots): a disc, a heading line and the name each. */
  _drawOthers(atMs) {
    const { ctx, state } = this;
    if (!state.others.length || atMs - state.othersAtMs > OTHERS_STALE_MS) return;
    const scale = this.camera.scale;
    ctx.save();
    ctx.font = '11px system-ui, sans-serif';
    ctx.textAlign = 'center';
    ctx.lineWidth = 2;
    for (const other of state.others) {
      const [cx, cy] = this.worldToScreen(other.x, other.y);
      const r = Math.max(other.radius * scale, 3);
      ctx.beginPath();
      ctx.arc(cx, cy, r, 0, 2 * Math.PI);
      ctx.fillStyle = COLORS.otherFill;
      ctx.fill();
      ctx.strokeStyle = COLORS.other;
      ctx.stroke();
      ctx.beginPath(); // heading: canvas y points down, so the yaw turns the other way
      ctx.moveTo(cx, cy);
      ctx.lineTo(cx + r * Math.cos(other.yaw), cy - r * Math.sin(other.yaw));
      ctx.stroke();
      ctx.fillStyle = COLORS.text;
      ctx.fillText(other.name, cx, cy - r - 4);
    }
    ctx.restore();
  }

  _drawScaleBar() {
    const { ctx } = this;
    const scale = this.camera.scale;
    const lengthM = NICE_LENGTHS_M.find((m) => m * scale >= 60) ?? NICE_LENGTHS_M.at(-1);
    const lengthPx = lengthM * scale;
    const x = 14;
    const y = this.cssHeight - 16;
    ctx.fillStyle = 'rgba(248, 250, 252, 0.85)';
    ctx.fillRect(x - 6, y - 22, lengthPx + 12, 30);
    ctx.strokeStyle = COLORS.text;
    ctx.lineWidth = 2;
    ctx.lineCap = 'butt';
    ctx.beginPath();
    ctx.moveTo(x, y - 5);
    ctx.lineTo(x, y);
    ctx.lineTo(x + lengthPx, y);
    ctx.lineTo(x + lengthPx, y - 5);
    ctx.stroke();
    ctx.fillStyle = COLORS.text;
    ctx.font = '12px system-ui, sans-serif';
    ctx.textAlign = 'center';
    ctx.textBaseline = 'bottom';
    const label = lengthM < 1 ? `${Math.round(lengthM * 100)} cm` : `${lengthM} m`;
    ctx.fillText(label, x + lengthPx / 2, y - 6);
  }

  _drawFrameLabel(frame) {
    if (!frame) return;
    const { ctx } = this;
    ctx.font = '12px system-ui, sans-serif';
    ctx.textAlign = 'right';
    ctx.textBaseline = 'bottom';
    ctx.fillStyle = COLORS.text;
    const text = frame === 'map' ? 'frame: map (ground truth)' : 'frame: odom (odometry)';
    ctx.fillText(text, this.cssWidth - 10, this.cssHeight - 8);
  }

  _zoomAt(factor, sx, sy) {
    const [wx, wy] = this.screenToWorld(sx, sy);
    this.camera.scale = clampScale(this.camera.scale * factor);
    if (this.follow) return; // the robot stays in the middle
    const [nx, ny] = this.screenToWorld(sx, sy);
    this.camera.x += wx - nx;
    this.camera.y += wy - ny;
  }

  _panBy(dxPx, dyPx) {
    this.camera.x -= dxPx / this.camera.scale;
    this.camera.y += dyPx / this.camera.scale;
    if (this.follow) this.setFollow(false);
  }

  _bindInput() {
    const { canvas } = this;
    canvas.addEventListener('wheel', (event) => {
      event.preventDefault();
      const lines = event.deltaMode === WheelEvent.DOM_DELTA_LINE ? 16 : 1;
      const rect = canvas.getBoundingClientRect();
      this.userMoved = true;
      this._zoomAt(Math.exp(-event.deltaY * lines * 0.0015),
        event.clientX - rect.left, event.clientY - rect.top);
    }, { passive: false });
    canvas.addEventListener('pointerdown', (event) => {
      if (event.pointerType === 'mouse' && event.button !== 0) return;
      canvas.setPointerCapture(event.pointerId);
      this.pointers.set(event.pointerId, { x: event.clientX, y: event.clientY });
      this.userMoved = true;
    });
    canvas.addEventListener('pointermove', (event) => {
      const previous = this.pointers.get(event.pointerId);
      if (!previous) return;
      const rect = canvas.getBoundingClientRect();
      if (this.pointers.size === 2) { // pinch: zoom about the fingers' midpoint, and pan
        const [other] = [...this.pointers].filter(([id]) => id !== event.pointerId);
        const o = other[1];
        const before = Math.hypot(previous.x - o.x, previous.y - o.y);
        const after = Math.hypot(event.clientX - o.x, event.clientY - o.y);
        if (before > 0 && after > 0) {
          this._zoomAt(after / before, (event.clientX + o.x) / 2 - rect.left,
            (event.clientY + o.y) / 2 - rect.top);
        }
        this._panBy((event.clientX - previous.x) / 2, (event.clientY - previous.y) / 2);
      } else if (this.pointers.size === 1) {
        this._panBy(event.clientX - previous.x, event.clientY - previous.y);
      }
      this.pointers.set(event.pointerId, { x: event.clientX, y: event.clientY });
    });
    for (const type of ['pointerup', 'pointercancel']) {
      canvas.addEventListener(type, (event) => this.pointers.delete(event.pointerId));
    }
  }
}

/**
 * The world's walls, discs and boxes (ros-msgs.js applyMarkerArray shapes) at `scale` px/m; walls are
 * at least `minWidthPx` wide. Also the dashboard's (class-view.js), with thinner walls.
 */
export function paintWalls(ctx, markers, toScreen, scale, minWidthPx = 2) {
  ctx.lineCap = 'round';
  ctx.strokeStyle = COLORS.wall;
  ctx.fillStyle = COLORS.disc;
  for (const shape of markers.values()) {
    if (shape.kind === 'segments') {
      ctx.lineWidth = Math.max(minWidthPx, shape.width * scale);
      ctx.beginPath();
      for (const [x1, y1, x2, y2] of shape.segments) {
        ctx.moveTo(...toScreen(x1, y1));
        ctx.lineTo(...toScreen(x2, y2));
      }
      ctx.stroke();
    } else if (shape.kind === 'polygon') { // a box: solid, as the world file says
      ctx.beginPath();
      shape.corners.forEach(([x, y], i) => (i ? ctx.lineTo(...toScreen(x, y))
        : ctx.moveTo(...toScreen(x, y))));
      ctx.closePath();
      ctx.fill();
    } else {
      const [sx, sy] = toScreen(shape.x, shape.y);
      ctx.beginPath();
      ctx.arc(sx, sy, shape.radius * scale, 0, 2 * Math.PI);
      ctx.fill();
    }
  }
}

function clampScale(scale) {
  return Math.min(MAX_SCALE, Math.max(MIN_SCALE, scale));
}

/** A coordinate on the device pixel grid's centre line: 1 px lines that are not blurred. */
function crisp(value, dpr) {
  return (Math.floor(value * dpr) + 0.5) / dpr;
}
