// Reference solution, go to a goal, with roslibjs (roslib 1.4.1, Node): plan on /map, follow
// the plan on /odom.
//
//   websim grade go_to_goal -- node go_to_goal.js
//
// The same controller as go_to_goal.py: reads the goal (WEBSIM_GOAL_X_M, WEBSIM_GOAL_Y_M,
// WEBSIM_GOAL_RADIUS_M; map frame, the odom frame where the robot starts at the map's origin
// facing x), plans a path on the robot's /map (latched occupancy grid: breadth-first search,
// 8-connected, over the cells at least CLEARANCE_M from any wall), then follows it (pure
// pursuit: steer at the path point LOOKAHEAD_M ahead), answering every /odom with one
// /cmd_vel. `websim grade` gives it roslib 1.4.1; elsewhere, `npm install roslib@1.4.1` here.
'use strict';

const ROSLIB = require('roslib');

const CLEARANCE_M = 0.3; // centre to wall: the footprint's 0.11 m and a margin
const LOOKAHEAD_M = 0.35;
const SPEED_MPS = 0.3;
const K_HEADING = 3.0;
const MAX_ANGULAR_RPS = 2.5;

function wrap(angle) {
  return angle - 2 * Math.PI * Math.round(angle / (2 * Math.PI));
}

function plan(grid, start, goal) {
  const { width, height, resolution } = grid.info;
  const ox = grid.info.origin.position.x;
  const oy = grid.info.origin.position.y;
  const reach = Math.ceil(CLEARANCE_M / resolution);
  const offsets = [];
  for (let dx = -reach; dx <= reach; dx += 1) {
    for (let dy = -reach; dy <= reach; dy += 1) if (dx * dx + dy * dy <= reach * reach) offsets.push([dx, dy]);
  }
  const blocked = new Uint8Array(width * height);
  grid.data.forEach((value, index) => {
    if (value === 0) return; // a wall (100) or unknown (-1)
    const cx = index % width;
    const cy = Math.floor(index / width);
    for (const [dx, dy] of offsets) {
      const x = cx + dx;
      const y = cy + dy;
      if (x >= 0 && x < width && y >= 0 && y < height) blocked[y * width + x] = 1;
    }
  });
  const cell = ([px, py]) => Math.trunc((py - oy) / resolution) * width + Math.trunc((px - ox) / resolution);
  const source = cell(start);
  const target = cell(goal);
  const came = new Map([[source, source]]);
  const queue = [source];
  for (let head = 0; head < queue.length && !came.has(target); head += 1) {
    const here = queue[head];
    const hx = here % width;
    const hy = Math.floor(here / width);
    for (const [dx, dy] of [[1, 0], [-1, 0], [0, 1], [0, -1], [1, 1], [1, -1], [-1, 1], [-1, -1]]) {
      const x = hx + dx;
      const y = hy + dy;
      const there = y * width + x;
      if (x >= 0 && x < width && y >= 0 && y < height && !blocked[there] && !came.has(there)) {
        came.set(there, here);
        queue.push(there);
      }
    }
  }
  if (!came.has(target)) return [goal];
  const path = [];
  for (let here = target; here !== source; here = came.get(here)) {
    path.push([((here % width) + 0.5) * resolution + ox, (Math.floor(here / width) + 0.5) * resolution + oy]);
  }
  path.reverse();
  path.push(goal);
  return path;
}

const goal = [Number(process.env.WEBSIM_GOAL_X_M), Number(process.env.WEBSIM_GOAL_Y_M)];
const radius = Number(process.env.WEBSIM_GOAL_RADIUS_M || '0.25');
let path = null;
const dist = (a, b) => Math.hypot(a[0] - b[0], a[1] - b[1]);

const ros = new ROSLIB.Ros({ url: process.env.WEBSIM_URL || 'ws://localhost:9090' });
const cmd = new ROSLIB.Topic({ ros, name: '/cmd_vel', messageType: 'geometry_msgs/msg/Twist' });
new ROSLIB.Topic({ ros, name: '/map', messageType: 'nav_msgs/msg/OccupancyGrid' }).subscribe((grid) => {
  if (path === null) path = plan(grid, [0.0, 0.0], goal);
});
new ROSLIB.Topic({ ros, name: '/odom', messageType: 'nav_msgs/msg/Odometry' }).subscribe((odom) => {
  const { position, orientation } = odom.pose.pose;
  const here = [position.x, position.y];
  const yaw = 2 * Math.atan2(orientation.z, orientation.w);
  let linear = 0.0;
  let angular = 0.0;
  if (path && dist(here, goal) > radius * 0.5) {
    let nearest = 0;
    path.forEach((point, i) => { if (dist(point, here) < dist(path[nearest], here)) nearest = i; });
    path.splice(0, nearest); // never steer back to where it has been
    const target = path.find((point) => dist(point, here) >= LOOKAHEAD_M) || path[path.length - 1];
    const error = wrap(Math.atan2(target[1] - here[1], target[0] - here[0]) - yaw);
    angular = Math.max(-MAX_ANGULAR_RPS, Math.min(MAX_ANGULAR_RPS, K_HEADING * error));
    linear = SPEED_MPS * Math.max(0.0, Math.cos(error)) ** 4;
  }
  cmd.publish(new ROSLIB.Message({ linear: { x: linear, y: 0, z: 0 }, angular: { x: 0, y: 0, z: angular } }));
});
ros.on('close', () => process.exit(0));
ros.on('error', (error) => { console.error('websocket error:', error.message || error); });
