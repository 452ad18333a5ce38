// What Lichtblick's RosbridgePlayer (packages/suite-base/src/players/RosbridgePlayer.ts) does
// on the wire, with Lichtblick's own packages from npm (tests/node/lichtblick/, installed by
// scripts/test.sh): its roslibjs fork asks rosapi for every topic with its type and full
// definition (Ros.getTopicsAndRawTypes, again every 500 ms until the topics wanted are
// listed), takes ROS 2 when rcl_interfaces/msg/Log is among the types, parses each definition
// (@lichtblick/rosmsg, ros2: true), subscribes with compression "cbor-raw" and no type, and
// reads each message's CDR with @lichtblick/rosmsg2-serialization's MessageReader. Run by
// tests/test_viewers_lichtblick.py.
//
//   node rosbridge_player.js WS_URL TOPIC [TOPIC...]
//       prints {"subscribed": TOPIC, "schema": TYPE} once per topic, then one line per message
//       {"topic", "message"} (the decoded message; bigint as a number), until killed.
//
// An error, a closed connection or a message that does not decode ends it with exit 1.
'use strict';

const path = require('path');
const { createRequire } = require('module');

const lichtblick = createRequire(path.join(__dirname, '..', '..', 'node', 'lichtblick',
  'package.json'));
// The fork is a browser bundle that takes the page's WebSocket (Lichtblick opens it in a web
// worker, "workersocket": the same frames); Node 20 has no global one, so ws stands in.
globalThis.WebSocket = lichtblick('ws');
const roslib = lichtblick('@lichtblick/roslibjs');
const { parse: parseMessageDefinition } = lichtblick('@lichtblick/rosmsg');
const { MessageReader } = lichtblick('@lichtblick/rosmsg2-serialization');

const POLL_MS = 500;

function fail(reason) {
  process.stderr.write(`${reason}\n`);
  process.exit(1);
}

function print(value) {
  process.stdout.write(`${JSON.stringify(value, (key, item) =>
    (typeof item === 'bigint' ? Number(item) : item))}\n`);
}

const [url, ...wanted] = process.argv.slice(2);
if (!url || wanted.length === 0) {
  fail('usage: node rosbridge_player.js WS_URL TOPIC [TOPIC...]');
}

const ros = new roslib.Ros({ url });
ros.on('error', (error) => fail(`${url}: ${error.message || error}`));
ros.on('close', () => fail(`${url}: connection closed by the server`));

const subscribed = new Set();

function requestTopics() {
  ros.getTopicsAndRawTypes((result) => {
    if (!result.types.includes('rcl_interfaces/msg/Log')) {
      fail(`not a ROS 2 rosbridge: no rcl_interfaces/msg/Log among ${result.types}`);
    }
    result.topics.forEach((topicName, index) => {
      if (!wanted.includes(topicName) || subscribed.has(topicName)) {
        return;
      }
      const schemaName = result.types[index];
      const reader = new MessageReader(parseMessageDefinition(result.typedefs_full_text[index],
        { ros2: true }));
      const topic = new roslib.Topic({ ros, name: topicName, compression: 'cbor-raw' });
      topic.subscribe((message) => {
        try {
          print({ topic: topicName, message: reader.readMessage(new Uint8Array(message.bytes)) });
        } catch (error) {
          fail(`Failed to parse message on ${topicName}: ${error.stack || error}`);
        }
      });
      subscribed.add(topicName);
      print({ subscribed: topicName, schema: schemaName });
    });
    if (subscribed.size < wanted.length) {
      setTimeout(requestTopics, POLL_MS);
    }
  }, (error) => fail(`getTopicsAndRawTypes: ${error}`));
}

ros.on('connection', requestTopics);
