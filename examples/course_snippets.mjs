// The course's roslibjs snippets (section 2.5.5) as one Node program, for roslib 2.x.
//
//   npm install roslib                 # roslib 2.x, next to this file (Node >= 20)
//   node course_snippets.mjs [ws://localhost:9090]
//
// The same program as course_snippets.js (which is for roslib 1.4.1, the course text's
// version): connects with new ROSLIB.Ros({url}), subscribes to /odom and /scan, drives the
// robot forward and into a left turn for two seconds by publishing geometry_msgs/msg/Twist on
// /cmd_vel, prints what it sees, stops the robot and exits (status 1 if the robot did not move:
// the bridge refused the commands). It runs unmodified against
// `websim serve` (ws://localhost:9090), the Docker stack (ws://HOST:9090) or the real robot's
// rosbridge: only the URL changes (section 2.5.6.3). In a class (`websim serve --class`) the URL
// is your robot's with its token, ws://HOST:9090/robots/NAME?token=TOKEN: without the token you
// may watch the robot but not drive it.
//
// roslib 2.x is an ES module only: `require('roslib')` fails, so this file is .mjs and says
// `import * as ROSLIB from 'roslib'`. Node finds `roslib` in the node_modules folder next to
// this file or above it (NODE_PATH does not apply to `import`). roslib 2.x has no
// ROSLIB.Message or ROSLIB.ServiceRequest: publish and call with plain objects. Ros, Topic,
// subscribe, publish and the 'connection', 'error' and 'close' events are as in 1.4.1.
import * as ROSLIB from 'roslib';

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

// A geometry_msgs/msg/Twist: linear.x (m/s) and angular.z (rad/s). In 1.4.1 this object is
// wrapped in new ROSLIB.Message(...); 2.x publishes it as it is.
function twist(linearMps, angularRps) {
  return {
    linear: { x: linearMps, y: 0.0, z: 0.0 },
    angular: { x: 0.0, y: 0.0, z: angularRps },
  };
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
    cmdVel.publish(twist(0.0, 0.0));
    console.log('stop: published a zero Twist');
  };

  const waitForData = setInterval(() => {
    if (firstOdom === null || scans === 0) {
      return;
    }
    clearInterval(waitForData);
    // Forward at 0.3 m/s while turning left at 0.5 rad/s (resent at 10 Hz, as a teleop does).
    const drive = () => cmdVel.publish(twist(0.3, 0.5));
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
