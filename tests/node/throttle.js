// Subscribe to /odom on two connections, one with throttle_rate THROTTLE_MS and one without,
// for WINDOW_MS. Prints {throttled, unthrottled}: the header stamps each received.
'use strict';

const { ROSLIB, connect, record, run, sleep } = require('./lib');

const WINDOW_MS = 2500;

function odomStamps(ros, throttleMs) {
  const messages = record(new ROSLIB.Topic({
    ros: ros,
    name: '/odom',
    messageType: 'nav_msgs/msg/Odometry',
    throttle_rate: throttleMs
  }));
  return () => messages.map((m) => m.header.stamp);
}

run(async (url, throttleMs = '200') => {
  const throttled = odomStamps(await connect(url), Number(throttleMs));
  const unthrottled = odomStamps(await connect(url), 0);
  await sleep(WINDOW_MS);
  return { throttled: throttled(), unthrottled: unthrottled() };
});
