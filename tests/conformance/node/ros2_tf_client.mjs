// roslib 2.x's ROSLIB.ROS2TFClient (the action /tf2_web_republisher) as a page would use it,
// run by tests/test_viewers_tf.py. roslib 1.4.1 has no ROS 2 actions; 2.x (tests/node/roslib2/,
// installed by scripts/test.sh) does.
//
//   node ros2_tf_client.mjs WS_URL FIXED_FRAME FRAME [FRAME...]
//       subscribes the first FRAME at once and each next one 300 ms later (each makes the
//       client cancel its goal and send a new one, as a page adding objects does), and prints
//       one JSON line per transform the client hands its callbacks:
//       {"frame", "translation": {x, y, z}, "rotation": {x, y, z, w}}. Runs until killed.
//
// An error or a closed connection ends the program with exit 1.
import * as ROSLIB from '../../node/roslib2/node_modules/roslib/dist/RosLib.js';

function fail(reason) {
  process.stderr.write(`${reason}\n`);
  process.exit(1);
}

function print(value) {
  process.stdout.write(`${JSON.stringify(value)}\n`);
}

const [url, fixedFrame, ...frames] = process.argv.slice(2);
if (!url || !fixedFrame || frames.length === 0) {
  fail('usage: node ros2_tf_client.mjs WS_URL FIXED_FRAME FRAME [FRAME...]');
}

const ros = new ROSLIB.Ros({ url });
ros.on('error', (error) => fail(`${url}: ${error.message || error}`));
ros.on('close', () => fail(`${url}: connection closed by the server`));
ros.on('connection', () => {
  // Thresholds as small as roslib lets them be (0 is taken as "use the default").
  const tfClient = new ROSLIB.ROS2TFClient({
    ros, fixedFrame, angularThres: 1e-6, transThres: 1e-6, rate: 20,
  });
  frames.forEach((frame, index) => {
    setTimeout(() => {
      tfClient.subscribe(frame, (transform) => {
        print({ frame, translation: transform.translation, rotation: transform.rotation });
      });
    }, 300 * index);
  });
});
