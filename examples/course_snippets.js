// The course's roslibjs snippets (section 2.5.5) as one Node program.
//
//   node examples/course_snippets.js [ws://localhost:9090]
//
// Connects with new ROSLIB.Ros({url}), subscribes to /odom and /scan, drives the robot forward
// and into a left turn for two seconds by publishing geometry_msgs/msg/Twist on /cmd_vel,
// prints what it sees, stops the robot and exits (status 1 if the robot did not move: the bridge
// refused the commands). The same program runs unmodified against
// `websim serve` (ws://localhost:9090), the Docker stack (ws://HOST:9090) or the real robot's
// rosbridge: only the URL changes (section 2.5.6.3). In a class (`websim serve --class`) the URL
// is your robot's with its token, ws://HOST:9090/robots/NAME?token=TOKEN: without the token you
// may watch the robot but not drive it.
//
// This file needs roslib 1.4.1, the course text's version: copy it into a folder of your own
// and run `npm install roslib@1.4.1` there. (`npm install roslib` now installs roslib 2.x, an
// ES module only, where `require('roslib')` fails and ROSLIB.Message is gone; for 2.x run
// course_snippets.mjs instead: examples/README.md.) From this checkout, without a copy:
// NODE_PATH=web-interface/node_modules node examples/course_snippets.js
'use strict';

const ROSLIB = require('roslib');

const url = process.argv[2] || 'ws://localhost:9090';
const DRIVE_MS = 2000;
const TIMEOUT_MS = 10000;
const NOT_DRIVEN = 'the robot did not move: the bridge refused the commands. A class robot '
  + 'drives only with its token, ws://HOST:9090/robots/NAME?token=TOKEN (without it your code '
  + 'may watch the robot, not drive it).';

function yawOf(pose) {
  // A planar quaternion: yaw = 2 atan2(z, w).
  return 2 * Math.atan2(pose.orientation.z, pose.orientation.w);
}

function describe(odom) {
  const { position } = odom.pose.pose;
  return `x=${position.x.toFixed(3)} m y=${position.y.toFixed(3)} m ` +
    `yaw=${yawOf(odom.pose.pose).toFixed(3)} rad`;
}

// 2.5.5.1 WebSocket connection
const ros = new ROSLIB.Ros({ url });
ros.on('error', (error) => {
  console.error(`Error: ${error.message || error.type || error}`);
  process.exit(1);
});
ros.on('close', () => console.log('Connection closed'));

const giveUp = setTimeout(() => {
  console.error(`no /odom and /scan from ${url.split('?')[0]} within ${TIMEOUT_MS} ms`);
  process.exit(1);
}, TIMEOUT_MS);

ros.on('connection', () => {
  console.log(`Connected to ROS 2 at ${url.split('?')[0]}`); // never print a ?token=

  // 2.5.5.2 Publishing velocity commands
  const cmdVel = new ROSLIB.Topic({
    ros,
    name: '/cmd_vel',
    messageType: 'geometry_msgs/msg/Twist',
  });

  // 2.5.5.3 Subscribing to odometry (20 Hz)
  let firstOdom = null;
  let lastOdom = null;
  const odomListener = new ROSLIB.Topic({
    ros,
    name: '/odom',
    messageType: 'nav_msgs/msg/Odometry',
  });
  odomListener.subscribe((message) => {
    if (firstOdom === null) {
      firstOdom = message;
      console.log(`odom start: ${describe(message)}`);
    }
    lastOdom = message;
  });

  // 2.5.5.4 Subscribing to the laser scan (10 Hz)
  let scans = 0;
  const scanListener = new ROSLIB.Topic({
    ros,
    name: '/scan',
    messageType: 'sensor_msgs/msg/LaserScan',
  });
  scanListener.subscribe((message) => {
    scans += 1;
    if (scans === 1) {
      const valid = message.ranges.filter(
        (r) => r !== null && r >= message.range_min && r <= message.range_max);
      console.log(`scan: ${message.ranges.length} beams, nearest ` +
        `${Math.min(...valid).toFixed(3)} m, straight ahead ${Number(message.ranges[0]).toFixed(3)} m`);
    }
  });

  const stop = () => {
    cmdVel.publish(new ROSLIB.Message({
      linear: { x: 0.0, y: 0.0, z: 0.0 },
      angular: { x: 0.0, y: 0.0, z: 0.0 },
    }));
    console.log('stop: published a zero Twist');
  };

  const waitForData = setInterval(() => {
    if (firstOdom === null || scans === 0) {
      return;
    }
    clearInterval(waitForData);
    // Forward at 0.3 m/s while turning left at 0.5 rad/s (resent at 10 Hz, as a teleop does).
    const drive = () => cmdVel.publish(new ROSLIB.Message({
      linear: { x: 0.3, y: 0.0, z: 0.0 },
      angular: { x: 0.0, y: 0.0, z: 0.5 },
    }));
    drive();
    console.log('drive: linear.x=0.3 m/s angular.z=0.5 rad/s');
    const repeat = setInterval(drive, 100);
    setTimeout(() => {
      clearInterval(repeat);
      stop();
      console.log(`odom end: ${describe(lastOdom)}`);
      console.log(`received ${scans} scans`);
      if (describe(lastOdom) === describe(firstOdom)) { // it turned 1 rad if it drove
        console.error(NOT_DRIVEN);
        process.exitCode = 1;
      }
      clearTimeout(giveUp);
      odomListener.unsubscribe();
      scanListener.unsubscribe();
      // Give the stop command time to leave before closing the socket.
      setTimeout(() => ros.close(), 200);
    }, DRIVE_MS);
  }, 10);
});
