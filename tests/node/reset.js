// Drive forward until /odom has moved 0.1 m, call /reset_simulation (std_srvs/srv/Empty), and
// print {driven, reset, after}: the last /odom before the call, the call's answer, and the
// /odom messages received after the answer.
'use strict';

const { ROSLIB, callService, connect, record, run, waitFor } = require('./lib');

const DRIVE_M = 0.1;

run(async (url) => {
  const ros = await connect(url);
  const odom = record(new ROSLIB.Topic({
    ros: ros,
    name: '/odom',
    messageType: 'nav_msgs/msg/Odometry'
  }));
  const cmdVel = new ROSLIB.Topic({
    ros: ros,
    name: '/cmd_vel',
    messageType: 'geometry_msgs/msg/Twist'
  });
  const resetSimulation = new ROSLIB.Service({
    ros: ros,
    name: '/reset_simulation',
    serviceType: 'std_srvs/srv/Empty'
  });

  await waitFor(() => odom.length > 0, 2000, 'the first /odom');
  const start = odom[odom.length - 1].pose.pose.position;
  cmdVel.publish(new ROSLIB.Message({
    linear: { x: 0.3, y: 0.0, z: 0.0 },
    angular: { x: 0.0, y: 0.0, z: 0.0 }
  }));
  const moved = () => {
    const now = odom[odom.length - 1].pose.pose.position;
    return Math.hypot(now.x - start.x, now.y - start.y) > DRIVE_M;
  };
  await waitFor(moved, 3000, `/odom to move ${DRIVE_M} m`);

  const driven = odom[odom.length - 1];
  const reset = await callService(resetSimulation, {}, 3000);
  const answered = odom.length;
  await waitFor(() => odom.length >= answered + 10, 3000, '10 /odom after the reset');
  return { driven: driven, reset: reset, after: odom.slice(answered) };
});
