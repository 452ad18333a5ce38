// Drive forward at SPEED_MPS with one /cmd_vel message, record /odom for about a second, then
// publish a zero Twist. Prints {before, driving, after}: the /odom messages received before
// the first command, between the two commands, and after the stop.
'use strict';

const { ROSLIB, connect, record, run, waitFor } = require('./lib');

const DRIVE_S = 0.95;  // 19 ticks after the first move: 20 ticks of motion, 0.30 m at 0.3 m/s
const HALF_TICK_S = 0.025;  // stamps are wall-clock times of 50 ms ticks

function seconds(from, to) {
  const a = from.header.stamp;
  const b = to.header.stamp;
  return (b.sec - a.sec) + (b.nanosec - a.nanosec) * 1e-9;
}

run(async (url, speed = '0.3') => {
  const ros = await connect(url);
  const odomListener = new ROSLIB.Topic({
    ros: ros,
    name: '/odom',
    messageType: 'nav_msgs/msg/Odometry'
  });
  const odom = record(odomListener);
  const cmdVel = new ROSLIB.Topic({
    ros: ros,
    name: '/cmd_vel',
    messageType: 'geometry_msgs/msg/Twist'
  });
  const twist = (x) => new ROSLIB.Message({
    linear: { x: x, y: 0.0, z: 0.0 },
    angular: { x: 0.0, y: 0.0, z: 0.0 }
  });

  await waitFor(() => odom.length > 0, 2000, 'the first /odom');
  const go = odom.length;
  const restX = odom[go - 1].pose.pose.position.x;
  cmdVel.publish(twist(Number(speed)));

  const drivenFor = () => {
    const first = odom.slice(go).find((m) => m.pose.pose.position.x !== restX);
    return first ? seconds(first, odom[odom.length - 1]) : 0;
  };
  await waitFor(() => drivenFor() >= DRIVE_S - HALF_TICK_S, 5000, `${DRIVE_S} s of driving`);
  const stop = odom.length;
  cmdVel.publish(twist(0.0));
  await waitFor(() => odom.length >= stop + 10, 3000, '10 /odom after the stop');
  return { before: odom.slice(0, go), driving: odom.slice(go, stop), after: odom.slice(stop) };
});
