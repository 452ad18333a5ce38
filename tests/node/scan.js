// Subscribe to /scan and /ground_truth and print {scan, ground_truth}: the first scan and the
// true pose published by the same tick (the same header stamp).
'use strict';

const { ROSLIB, connect, record, run, stampKey, waitFor } = require('./lib');

run(async (url) => {
  const ros = await connect(url);
  const scanListener = new ROSLIB.Topic({
    ros: ros,
    name: '/scan',
    messageType: 'sensor_msgs/msg/LaserScan'
  });
  const truthListener = new ROSLIB.Topic({
    ros: ros,
    name: '/ground_truth',
    messageType: 'nav_msgs/msg/Odometry'
  });
  const scans = record(scanListener);
  const truths = record(truthListener);

  const pair = () => {
    for (const scan of scans) {
      const truth = truths.find((t) => stampKey(t) === stampKey(scan));
      if (truth) {
        return { scan: scan, ground_truth: truth };
      }
    }
    return null;
  };
  return waitFor(pair, 3000, 'a /scan and a /ground_truth with the same stamp');
});
