// Subscribe with roslibjs to each TOPIC:TYPE (compression COMPRESSION: none or cbor), say
// "subscribed" on stderr once the server has the subscriptions, and print the first message of
// each topic, a typed array or byte string shown as {typed: its class, values}:
// `node first_messages.js WS_URL COMPRESSION TOPIC:TYPE...`.
'use strict';

const { ROSLIB, connect, run, waitFor } = require('../../node/lib');

const FIRST_MESSAGE_TIMEOUT_MS = 20000;

// `value` with every typed array (what roslibjs's CBOR decoder makes of RFC 8746 tags and
// byte strings) replaced by {typed, values}, so JSON.stringify keeps what it was.
function shown(value) {
  if (ArrayBuffer.isView(value)) {
    return { typed: value.constructor.name, values: Array.from(value, Number) };
  }
  if (Array.isArray(value)) {
    return value.map(shown);
  }
  if (value !== null && typeof value === 'object') {
    return Object.fromEntries(Object.entries(value).map(([key, item]) => [key, shown(item)]));
  }
  return value;
}

run(async (url, compression, ...topics) => {
  const ros = await connect(url);
  const first = {};
  for (const spec of topics) {
    const [name, messageType] = spec.split(':');
    const topic = new ROSLIB.Topic({ ros, name, messageType, compression });
    topic.subscribe((message) => {
      if (!(name in first)) {
        first[name] = shown(message);
      }
    });
  }
  let answered = false;  // ops are handled in order: once this is answered, so are the subscribes
  ros.getTopics(() => { answered = true; }, () => { answered = true; });
  await waitFor(() => answered, 5000, 'the answer of ros.getTopics');
  process.stderr.write('subscribed\n');
  await waitFor(() => Object.keys(first).length === topics.length, FIRST_MESSAGE_TIMEOUT_MS,
    `a first message on each of ${topics.join(', ')}`);
  return first;
});
