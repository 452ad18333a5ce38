// Subscribe to /scan twice, on two connections: once as JSON and once with CBOR compression.
// Print the ranges of the two copies of one scan (same stamp), and what type the CBOR copy's
// ranges decoded to.
'use strict';

const { ROSLIB, connect, record, run, stampKey, waitFor } = require('./lib');

function scanListener(ros, compression) {
  return new ROSLIB.Topic({
    ros: ros,
    name: '/scan',
    messageType: 'sensor_msgs/msg/LaserScan',
    compression: compression
  });
}

run(async (url) => {
  const json = record(scanListener(await connect(url), 'none'));
  const cbor = record(scanListener(await connect(url), 'cbor'));

  const pair = () => {
    for (const binary of cbor) {
      const text = json.find((m) => stampKey(m) === stampKey(binary));
      if (text) {
        return { binary: binary, text: text };
      }
    }
    return null;
  };
  const { binary, text } = await waitFor(pair, 3000, 'a JSON and a CBOR /scan with one stamp');
  return {
    stamp: binary.header.stamp,
    cbor_ranges_type: Object.prototype.toString.call(binary.ranges),
    cbor_ranges_is_float32array: binary.ranges instanceof Float32Array,
    cbor_ranges: Array.from(binary.ranges),
    json_ranges: text.ranges
  };
});
