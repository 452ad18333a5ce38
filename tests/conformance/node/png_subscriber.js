// Subscribe to TOPIC (of TYPE) twice with roslibjs, on two connections: once with
// compression 'png' (rosbridge's {"op": "png"} frames, which roslibjs decodes with pngparse
// under Node) and once as plain JSON; print the two copies of one message (same stamp):
// `node png_subscriber.js WS_URL TOPIC TYPE`.
'use strict';

const { ROSLIB, connect, record, run, stampKey, waitFor } = require('../../node/lib');

const PAIR_TIMEOUT_MS = 10000;

run(async (url, name, messageType) => {
  const listener = async (compression) => record(new ROSLIB.Topic({
    ros: await connect(url), name, messageType, compression
  }));
  const png = await listener('png');
  const json = await listener('none');
  const pair = () => {
    for (const decoded of png) {
      const text = json.find((message) => stampKey(message) === stampKey(decoded));
      if (text) {
        return { png: decoded, json: text };
      }
    }
    return null;
  };
  return waitFor(pair, PAIR_TIMEOUT_MS, `a PNG and a JSON ${name} with one stamp`);
});
