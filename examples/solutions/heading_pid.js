// Reference solution, the heading PID (assignment 2.4), with roslibjs (roslib 1.4.1, Node).
//
//   websim grade heading_pid -- node heading_pid.js
//
// The same controller as heading_pid.py: turns in place to WEBSIM_SETPOINT_RAD (rad, relative
// to the heading at the start: the odom frame) and holds it, answering every /odom with one
// /cmd_vel (a callback, not a timer), so `websim grade` can run it in deterministic mode.
// WEBSIM_SETPOINT_RAD_CHANGES (`at_s:value` pairs) applies at the first /odom whose time since
// the start reaches it; WEBSIM_KP overrides the gain (default 4 rad/s per rad). `websim grade`
// gives it roslib 1.4.1; elsewhere, `npm install roslib@1.4.1` in its folder.
'use strict';

const ROSLIB = require('roslib');

const TICK_S = 0.05; // the simulator's tick: the first /odom comes one tick after the start
const MAX_ANGULAR_RPS = 2.5;

function wrap(angle) {
  return angle - 2 * Math.PI * Math.round(angle / (2 * Math.PI));
}

const kp = Number(process.env.WEBSIM_KP || '4.0');
let setpoint = Number(process.env.WEBSIM_SETPOINT_RAD);
const changes = (process.env.WEBSIM_SETPOINT_RAD_CHANGES || '').split(',').filter(Boolean)
  .map((item) => item.split(':').map(Number));
let firstStamp = null;

const ros = new ROSLIB.Ros({ url: process.env.WEBSIM_URL || 'ws://localhost:9090' });
const cmd = new ROSLIB.Topic({ ros, name: '/cmd_vel', messageType: 'geometry_msgs/msg/Twist' });
const odom = new ROSLIB.Topic({ ros, name: '/odom', messageType: 'nav_msgs/msg/Odometry' });

odom.subscribe((msg) => {
  const now = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9;
  if (firstStamp === null) firstStamp = now - TICK_S;
  while (changes.length && now - firstStamp >= changes[0][0] - 1e-6) setpoint = changes.shift()[1];
  const q = msg.pose.pose.orientation;
  const yaw = 2 * Math.atan2(q.z, q.w);
  const angular = Math.max(-MAX_ANGULAR_RPS, Math.min(MAX_ANGULAR_RPS, kp * wrap(setpoint - yaw)));
  cmd.publish(new ROSLIB.Message({ linear: { x: 0, y: 0, z: 0 }, angular: { x: 0, y: 0, z: angular } }));
});
ros.on('close', () => process.exit(0));
ros.on('error', (error) => { console.error('websocket error:', error.message || error); });
