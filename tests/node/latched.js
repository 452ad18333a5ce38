// Subscribe to the latched topics /tf_static and /world and print the first message of each,
// with how long after subscribing both had arrived (ms).
'use strict';

const { ROSLIB, connect, record, run, waitFor } = require('./lib');

const LATCHED_WITHIN_MS = 2000;

run(async (url) => {
  const ros = await connect(url);
  const tfStatic = record(new ROSLIB.Topic({
    ros: ros,
    name: '/tf_static',
    messageType: 'tf2_msgs/msg/TFMessage'
  }));
  const world = record(new ROSLIB.Topic({
    ros: ros,
    name: '/world',
    messageType: 'visualization_msgs/msg/MarkerArray'
  }));
  const start = Date.now();
  await waitFor(() => tfStatic.length > 0 && world.length > 0, LATCHED_WITHIN_MS,
    '/tf_static and /world');
  return { tf_static: tfStatic[0], world: world[0], waited_ms: Date.now() - start };
});
