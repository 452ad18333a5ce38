// A Fibonacci action server or client through roslib 2.x's ROSLIB.Action (ROS 2 actions),
// run by tests/conformance/test_actions.py. roslib 1.4.1 (web-interface/) has no ROS 2
// Action: only 2.x (tests/node/roslib2/, installed by scripts/test.sh) does.
//
//   node fibonacci.mjs server WS_URL ACTION STEP_MS
//       advertises ACTION (example_interfaces/action/Fibonacci); each goal {order} gets one
//       feedback {sequence} per step, STEP_MS apart, then setSucceeded({sequence}); a cancel
//       ends it with setCanceled. Prints one JSON line per event: {"ready": true} once a goal
//       it sent itself came back (the advertisement is in force), {"goal": ..., "id": ...},
//       {"cancel": id}. Runs until killed.
//   node fibonacci.mjs client WS_URL ACTION ORDER
//       sends one goal and prints {"ok": true, "result", "feedback"} or {"ok": false,
//       "reason", "feedback"}, then exits.
//
// Every wait has a timeout; an error or a closed connection ends the program with exit 1.
import * as ROSLIB from '../../node/roslib2/node_modules/roslib/dist/RosLib.js';

const TYPE = 'example_interfaces/action/Fibonacci';
const TIMEOUT_MS = 20000;

function fail(reason) {
  process.stderr.write(`${reason}\n`);
  process.exit(1);
}

function print(value) {
  process.stdout.write(`${JSON.stringify(value)}\n`);
}

function connect(url) {
  const ros = new ROSLIB.Ros({ url });
  ros.on('error', (error) => fail(`${url}: ${error.message || error}`));
  ros.on('close', () => fail(`${url}: connection closed by the server`));
  return new Promise((resolve) => ros.on('connection', () => resolve(ros)));
}

function sendGoal(ros, name, order) {
  const action = new ROSLIB.Action({ ros, name, actionType: TYPE });
  const feedback = [];
  return new Promise((resolve) => {
    action.sendGoal({ order },
      (result) => resolve({ ok: true, result, feedback }),
      (values) => feedback.push(values),
      (reason) => resolve({ ok: false, reason, feedback }));
  });
}

async function serve(url, name, stepMs) {
  const ros = await connect(url);
  const action = new ROSLIB.Action({ ros, name, actionType: TYPE });
  const canceled = new Set();
  action.advertise((goal, id) => {
    print({ goal, id });
    const sequence = [0, 1];
    const step = () => {
      if (canceled.has(id)) {
        action.setCanceled(id, { sequence });
        return;
      }
      if (sequence.length > goal.order) {
        action.setSucceeded(id, { sequence });
        return;
      }
      sequence.push(sequence[sequence.length - 1] + sequence[sequence.length - 2]);
      action.sendFeedback(id, { sequence: [...sequence] });
      setTimeout(step, stepMs);
    };
    setTimeout(step, stepMs);
  }, (id) => {
    print({ cancel: id });
    canceled.add(id);
  });
  const probe = await sendGoal(ros, name, 1);
  if (!probe.ok) {
    fail(`the server's own probe goal failed: ${probe.reason}`);
  }
  print({ ready: true });
}

async function client(url, name, order) {
  const ros = await connect(url);
  const answer = await sendGoal(ros, name, order);
  process.stdout.write(`${JSON.stringify(answer)}\n`, () => process.exit(0));
}

const [mode, url, name, number] = process.argv.slice(2);
if (!['server', 'client'].includes(mode) || !url || !name || number === undefined) {
  fail('usage: node fibonacci.mjs server|client WS_URL ACTION STEP_MS|ORDER');
}
if (mode === 'client') {
  setTimeout(() => fail(`no answer to the goal within ${TIMEOUT_MS} ms`), TIMEOUT_MS).unref();
  client(url, name, Number(number)).catch((error) => fail(error.stack || String(error)));
} else {
  serve(url, name, Number(number)).catch((error) => fail(error.stack || String(error)));
}
