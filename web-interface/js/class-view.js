// One robot's thumbnail on the dashboard: its world's walls, the robot's pose and heading, and
// (when scans are on) its scan points, in a small canvas.
//
// Coordinates: the world in metres, ROS convention (x right, y up); the canvas in CSS pixels
// (y down). worldToScreen() is the one place that scales and flips y. The thumbnail fits its
// world (or, without one, follows the robot); the background and walls are pre-rendered once
// into an offscreen layer per world and canvas size, and copied each time the robot moved.
// Colours are the main view's (view.js COLORS).

import { composePose } from './ros-msgs.js';
import { displayPose } from './class-state.js';
import { COLORS, paintWalls } from './view.js';

/** Room (CSS px) between the world's bounds and the canvas's edges; the top holds the chips. */
const FIT_PAD_PX = Object.freeze({ top: 22, right: 6, bottom: 6, left: 6 });
const NO_WORLD_SPAN_M = 4; // what a thumbnail shows around a robot without walls
const MIN_ROBOT_PX = 4; // a robot is never drawn smaller than this (its radius)
const SCAN_DOT_PX = 2;
const MIN_WALL_PX = 1;
const OUTLINE_PX = 1.25; // the robot's outline; its heading line is thicker
const HEADING_PX = 2;

/**
 * The camera {x, y (m), scale (px per m)} that shows `bounds` in a canvas of `width` x `height`
 * CSS px, inside `pad` px ({top, right, bottom, left}) of the edges.
 */
export function fitCamera(bounds, width, height, pad = FIT_PAD_PX) {
  const spanX = Math.max(bounds.maxX - bounds.minX, 1e-3);
  const spanY = Math.max(bounds.maxY - bounds.minY, 1e-3);
  const innerWidth = Math.max(1, width - pad.left - pad.right);
  const innerHeight = Math.max(1, height - pad.top - pad.bottom);
  const scale = Math.min(innerWidth / spanX, innerHeight / spanY);
  // The bounds' centre goes to the centre of the padded area, not of the canvas.
  const areaX = pad.left + innerWidth / 2 - width / 2;
  const areaY = pad.top + innerHeight / 2 - height / 2;
  return {
    x: (bounds.minX + bounds.maxX) / 2 - areaX / scale,
    y: (bounds.minY + bounds.maxY) / 2 + areaY / scale, // y up: down the screen is -y
    scale,
  };
}

export class RobotThumb {
  /**
   * @param {HTMLCanvasElement} canvas
   * @param {object} robot the robot description (robot.js): its footprint
   */
  constructor(canvas, robot) {
    this.canvas = canvas;
    this.ctx = canvas.getContext('2d');
    this.radiusM = robot.robot.footprint_radius_m;
    this.cssWidth = 0;
    this.cssHeight = 0;
    this.dpr = 1;
    this.camera = { x: 0, y: 0, scale: 1 };
    this.layer = null; // {canvas, key}: background and walls
    this.drawn = null; // what the canvas shows: `${state.version}:${layer key}:${frame}`
  }

  /** The canvas's CSS size (from a ResizeObserver) and the screen's pixel ratio. */
  setSize(cssWidth, cssHeight, dpr) {
    if (cssWidth === this.cssWidth && cssHeight === this.cssHeight && dpr === this.dpr) return;
    this.cssWidth = cssWidth;
    this.cssHeight = cssHeight;
    this.dpr = dpr;
    this.canvas.width = Math.max(1, Math.round(cssWidth * dpr));
    this.canvas.height = Math.max(1, Math.round(cssHeight * dpr));
    this.layer = null;
    this.drawn = null;
  }

  /** CSS pixel position of the world point (x, y) in metres: scale, then flip y. */
  worldToScreen(x, y) {
    const { camera } = this;
    return [
      this.cssWidth / 2 + (x - camera.x) * camera.scale,
      this.cssHeight / 2 - (y - camera.y) * camera.scale,
    ];
  }

  /** Draws `state` (class-state.js) if it changed since the last draw; true when it drew. */
  draw(state) {
    if (this.cssWidth === 0 || this.cssHeight === 0) return false;
    const { pose, frame } = displayPose(state);
    const withWalls = Boolean(state.worldBounds) && frame !== 'odom'; // walls are in map
    const key = withWalls ? `${state.worldVersion}` : 'none';
    const drawn = `${state.version}:${key}:${frame}`;
    if (drawn === this.drawn && this.layer?.key === key) return false;
    if (withWalls) {
      this.camera = fitCamera(state.worldBounds, this.cssWidth, this.cssHeight);
    } else {
      this.camera = {
        x: pose ? pose.x : 0, y: pose ? pose.y : 0,
        scale: Math.min(this.cssWidth, this.cssHeight) / NO_WORLD_SPAN_M,
      };
    }
    if (this.layer?.key !== key) this.layer = { key, canvas: this._renderLayer(state, withWalls) };
    const { ctx } = this;
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.drawImage(this.layer.canvas, 0, 0);
    ctx.setTransform(this.dpr, 0, 0, this.dpr, 0, 0);
    if (pose) {
      if (state.scan) this._drawScan(state, pose);
      this._drawRobot(pose);
    }
    this.drawn = drawn;
    return true;
  }

  _renderLayer(state, withWalls) {
    const layer = document.createElement('canvas');
    layer.width = this.canvas.width;
    layer.height = this.canvas.height;
    const ctx = layer.getContext('2d');
    ctx.setTransform(this.dpr, 0, 0, this.dpr, 0, 0);
    ctx.fillStyle = COLORS.background;
    ctx.fillRect(0, 0, this.cssWidth, this.cssHeight);
    if (withWalls) {
      paintWalls(ctx, state.markers, (x, y) => this.worldToScreen(x, y), this.camera.scale,
        MIN_WALL_PX);
    }
    return layer;
  }

  _drawScan(state, pose) {
    const { ctx } = this;
    const laser = composePose({ x: pose.x, y: pose.y, yaw: pose.theta }, state.laserMount);
    const c = Math.cos(laser.yaw);
    const s = Math.sin(laser.yaw);
    const { points } = state.scan;
    const half = SCAN_DOT_PX / 2;
    ctx.fillStyle = COLORS.scan;
    for (let i = 0; i < points.length; i += 2) {
      const [sx, sy] = this.worldToScreen(laser.x + c * points[i] - s * points[i + 1],
        laser.y + s * points[i] + c * points[i + 1]);
      ctx.fillRect(sx - half, sy - half, SCAN_DOT_PX, SCAN_DOT_PX);
    }
  }

  _drawRobot(pose) {
    const [cx, cy] = this.worldToScreen(pose.x, pose.y);
    paintRobot(this.ctx, cx, cy, this.radiusM * this.camera.scale, pose.theta);
  }
}

/**
 * A robot at CSS pixel (cx, cy): its footprint of `radiusPx` (never under MIN_ROBOT_PX) and a
 * heading line from its centre to its front at `yaw` (rad, map frame), longer than the body
 * on tiny scales. The thumbnails' and the arena map's (class-arena.js).
 */
export function paintRobot(ctx, cx, cy, radiusPx, yaw) {
  const r = Math.max(radiusPx, MIN_ROBOT_PX);
  ctx.beginPath();
  ctx.arc(cx, cy, r, 0, 2 * Math.PI);
  ctx.fillStyle = COLORS.robotFill;
  ctx.fill();
  ctx.lineWidth = OUTLINE_PX;
  ctx.strokeStyle = COLORS.robot;
  ctx.stroke();
  ctx.beginPath();
  ctx.moveTo(cx, cy);
  const reach = Math.max(r, 2 * MIN_ROBOT_PX);
  ctx.lineTo(cx + reach * Math.cos(yaw), cy - reach * Math.sin(yaw)); // y flips
  ctx.lineWidth = HEADING_PX;
  ctx.lineCap = 'round';
  ctx.strokeStyle = COLORS.heading;
  ctx.stroke();
  return r;
}

