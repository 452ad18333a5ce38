// Shared by the roslibjs test programs in this folder (run by tests/test_roslibjs.py).
//
// Each program is `node <program>.js WS_URL [ARGS...]`: it talks to a websim server through
// roslibjs as the course's browser code does, prints one JSON result on stdout and exits 0,
// or prints the reason on stderr and exits 1. Every wait has a timeout.
'use strict';

const path = require('path');
const { createRequire } = require('module');

// roslib is installed (from web-interface/package-lock.json) for the web interface.
const ROSLIB = createRequire(path.join(__dirname, '..', '..', 'web-interface', 'package.json'))(
  'roslib');

const CONNECT_TIMEOUT_MS = 5000;
const POLL_MS = 5;

function fail(reason) {
  process.stderr.write(`${reason}\n`);
  process.exit(1);
}

// Resolves with the first truthy value of `condition()`; rejects after `timeoutMs`.
function waitFor(condition, timeoutMs, what) {
  const deadline = Date.now() + timeoutMs;
  return new Promise((resolve, reject) => {
    const poll = () => {
      const value = condition();
      if (value) {
        resolve(value);
      } else if (Date.now() > deadline) {
        reject(new Error(`timed out after ${timeoutMs} ms waiting for ${what}`));
      } else {
        setTimeout(poll, POLL_MS);
      }
    };
    poll();
  });
}

function sleep(ms) {
  return new Promise((resolve) => setTimeout(resolve, ms));
}

// A connected ROSLIB.Ros; any later error or close from the server ends the program.
async function connect(url) {
  const ros = new ROSLIB.Ros({ url });
  let connected = false;
  ros.on('connection', () => { connected = true; });
  ros.on('error', (error) => fail(`${url}: ${error.message || error}`));
  ros.on('close', () => fail(`${url}: connection closed by the server`));
  await waitFor(() => connected, CONNECT_TIMEOUT_MS, `a connection to ${url}`);
  return ros;
}

// Subscribes to `topic` and returns the array every message is appended to.
function record(topic) {
  const messages = [];
  topic.subscribe((message) => { messages.push(message); });
  return messages;
}

// Calls a ROSLIB.Service; resolves with {ok: true, values} or {ok: false, reason}.
function callService(service, request, timeoutMs) {
  let answer = null;
  service.callService(new ROSLIB.ServiceRequest(request),
    (values) => { answer = { ok: true, values }; },
    (reason) => { answer = { ok: false, reason }; });
  return waitFor(() => answer, timeoutMs, `the answer of ${service.name}`);
}

function stampKey(message) {
  const { sec, nanosec } = message.header.stamp;
  return `${sec}.${nanosec}`;
}

// Runs `program(url, ...args)` and prints what it resolves with as JSON.
function run(program) {
  const [url, ...args] = process.argv.slice(2);
  if (!url) {
    fail(`usage: node ${path.basename(process.argv[1])} WS_URL [ARGS...]`);
  }
  program(url, ...args).then(
    (result) => process.stdout.write(`${JSON.stringify(result)}\n`, () => process.exit(0)),
    (error) => fail(error.stack || String(error)));
}

module.exports = { ROSLIB, callService, connect, record, run, sleep, stampKey, waitFor };
