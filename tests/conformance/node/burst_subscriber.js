// Subscribe to TOPIC (std_msgs/msg/String) with roslibjs's defaults (queue_length 0, no
// throttle), say "subscribed" on stderr once the server has it, and print every message's
// data that arrives until COUNT have or IDLE_MS pass without one:
// `node burst_subscriber.js WS_URL TOPIC COUNT IDLE_MS`.
'use strict';

const { ROSLIB, connect, run, sleep, waitFor } = require('../../node/lib');

run(async (url, topicName, count, idleMs) => {
  const ros = await connect(url);
  const received = [];
  let lastAt = Date.now();
  const topic = new ROSLIB.Topic({ ros, name: topicName, messageType: 'std_msgs/msg/String' });
  topic.subscribe((message) => { received.push(message.data); lastAt = Date.now(); });
  let answered = false;  // ops are handled in order: once this is answered, so is subscribe
  ros.getTopics(() => { answered = true; }, () => { answered = true; });
  await waitFor(() => answered, 5000, 'the answer of ros.getTopics');
  process.stderr.write('subscribed\n');
  await waitFor(() => received.length > 0, 20000, `a first message on ${topicName}`);
  while (received.length < Number(count) && Date.now() - lastAt < Number(idleMs)) {
    await sleep(10);
  }
  return received;
});
