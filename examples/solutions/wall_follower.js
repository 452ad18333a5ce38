// Reference solution, wall following (after MIT RSS's wall follower lab), with roslibjs
// (roslib 1.4.1, Node).
//
//   websim grade wall_following_suite -- node wall_follower.js
//
// The same controller as wall_follower.py: follows the wall on side WEBSIM_SIDE (left or
// right) at WEBSIM_DESIRED_DISTANCE_M (m), driving at WEBSIM_SPEED_MPS (m/s), keeping the
// nearest LiDAR hit on its side at the desired distance and abeam (90°),
//
//   angular = side k_d (d - d*) + k_a (bearing - side pi/2),   side = +1 left, -1 right
//
// from the latest /scan, answering every /odom with one /cmd_vel (a callback, not a timer).
// `websim grade` gives it roslib 1.4.1; elsewhere, `npm install roslib@1.4.1` in its folder.
'use strict';

const ROSLIB = require('roslib');

const K_DISTANCE = 3.0; // rad/s per m of distance error
const K_BEARING = 2.0; // rad/s per rad of bearing error
const MAX_ANGULAR_RPS = 2.5;

function wrap(angle) {
  return angle - 2 * Math.PI * Math.round(angle / (2 * Math.PI));
}

const side = process.env.WEBSIM_SIDE === 'left' ? 1.0 : -1.0;
const desired = Number(process.env.WEBSIM_DESIRED_DISTANCE_M);
const speed = Number(process.env.WEBSIM_SPEED_MPS);
let latest = null;

function command(scan) {
  let nearest = Infinity;
  let bearing = 0.0;
  scan.ranges.forEach((distance, index) => {
    if (distance === null || !(scan.range_min <= distance && distance < scan.range_max)) return;
    const angle = wrap(scan.angle_min + index * scan.angle_increment);
    if (side * angle >= 0.0 && distance < nearest) {
      nearest = distance;
      bearing = angle;
    }
  });
  if (!Number.isFinite(nearest)) return [speed, side]; // no wall on its side: turn to it
  const angular = side * K_DISTANCE * (nearest - desired) + K_BEARING * (bearing - side * Math.PI / 2);
  return [speed, Math.max(-MAX_ANGULAR_RPS, Math.min(MAX_ANGULAR_RPS, angular))];
}

const ros = new ROSLIB.Ros({ url: process.env.WEBSIM_URL || 'ws://localhost:9090' });
const cmd = new ROSLIB.Topic({ ros, name: '/cmd_vel', messageType: 'geometry_msgs/msg/Twist' });
new ROSLIB.Topic({ ros, name: '/scan', messageType: 'sensor_msgs/msg/LaserScan' })
  .subscribe((scan) => { latest = scan; });
new ROSLIB.Topic({ ros, name: '/odom', messageType: 'nav_msgs/msg/Odometry' }).subscribe(() => {
  const [linear, angular] = latest === null ? [0.0, 0.0] : command(latest);
  cmd.publish(new ROSLIB.Message({ linear: { x: linear, y: 0, z: 0 }, angular: { x: 0, y: 0, z: angular } }));
});
ros.on('close', () => process.exit(0));
ros.on('error', (error) => { console.error('websocket error:', error.message || error); });
