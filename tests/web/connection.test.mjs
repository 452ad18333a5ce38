// The rosbridge connection (web-interface/js/connection.js): URLs, tokens, backoff, and the
// reconnect cycle against a fake roslibjs.
import assert from 'node:assert/strict';
import { test } from 'node:test';

import {
  Connection, defaultWsUrl, initialWsUrl, loadSiteConfig, resolveWsUrl, retryDelayMs,
  RETRY_MAX_MS, ServiceCallError, takeToken, TOKEN_KEY, withoutToken, withToken,
} from '../../web-interface/js/connection.js';
import { fakeRoslib } from './fake-roslib.mjs';

test('the default bridge is the page host on 9090; ?ws= overrides it', () => {
  assert.equal(defaultWsUrl({ protocol: 'http:', hostname: '192.168.1.7' }),
    'ws://192.168.1.7:9090');
  assert.equal(defaultWsUrl({ protocol: 'https:', hostname: 'sim.example' }),
    'wss://sim.example:9090');
  assert.equal(initialWsUrl({ protocol: 'http:', hostname: 'h', search: '' }), 'ws://h:9090');
  assert.equal(initialWsUrl({
    protocol: 'http:', hostname: 'h', search: '?ws=ws%3A%2F%2F192.168.1.100%3A9090',
  }), 'ws://192.168.1.100:9090');
});

test('config.json can name the bridge; a path means this server; ?ws= still wins', async () => {
  const page = { protocol: 'https:', hostname: 'lab', host: 'lab:8443', search: '' };
  assert.equal(resolveWsUrl('/rosbridge', page), 'wss://lab:8443/rosbridge');
  assert.equal(resolveWsUrl(' ws://robot:9090 ', page), 'ws://robot:9090');
  assert.equal(initialWsUrl(page, '/admin/rosbridge'), 'wss://lab:8443/admin/rosbridge');
  assert.equal(initialWsUrl(page, null), 'wss://lab:9090');
  assert.equal(initialWsUrl({ ...page, search: '?ws=ws://x:1' }, '/rosbridge'), 'ws://x:1');
  const answer = (ok, body) => async () => ({ ok, json: async () => body });
  assert.deepEqual(await loadSiteConfig(answer(true, { ws: '/rosbridge' })), { ws: '/rosbridge' });
  assert.deepEqual(await loadSiteConfig(answer(false, null)), {});
  assert.deepEqual(await loadSiteConfig(async () => { throw new TypeError('offline'); }), {});
});

test('the token is appended with ? or &, encoded, and can be taken out again', () => {
  assert.equal(withToken('ws://h:9090', 'abc'), 'ws://h:9090?token=abc');
  assert.equal(withToken('ws://h:9090/?x=1', 'a&b'), 'ws://h:9090/?x=1&token=a%26b');
  assert.equal(withToken('ws://h:9090', ''), 'ws://h:9090');
  assert.equal(withoutToken('ws://h:9090/?token=abc'), 'ws://h:9090/');
  assert.equal(withoutToken('ws://h:9090/?x=1&token=abc'), 'ws://h:9090/?x=1');
  assert.equal(withoutToken('ws://h:9090/?token=abc&x=1'), 'ws://h:9090/?x=1');
});

test('?token= is stored for the tab and removed from the address bar', () => {
  const stored = new Map();
  const storage = { getItem: (k) => stored.get(k) ?? null, setItem: (k, v) => stored.set(k, v) };
  const replaced = [];
  const history = { replaceState: (s, t, url) => replaced.push(String(url)) };
  const token = takeToken({ href: 'http://h:8080/admin?token=s3cret&ws=ws%3A%2F%2Fh%3A1' },
    history, storage);
  assert.equal(token, 's3cret');
  assert.equal(stored.get(TOKEN_KEY), 's3cret');
  assert.deepEqual(replaced, ['http://h:8080/admin?ws=ws%3A%2F%2Fh%3A1']);
  assert.equal(takeToken({ href: 'http://h:8080/admin' }, history, storage), 's3cret');
  assert.equal(replaced.length, 1);
});

test('backoff doubles from 0.5 s to at most 5 s, with +-20 % jitter', () => {
  const middle = () => 0.5;
  assert.deepEqual([0, 1, 2, 3, 4, 10].map((a) => retryDelayMs(a, middle)),
    [500, 1000, 2000, 4000, 5000, 5000]);
  assert.equal(retryDelayMs(0, () => 0), 400);
  assert.equal(retryDelayMs(20, () => 1), RETRY_MAX_MS * 1.2);
});

test('reconnects after a close, re-subscribes, and drops publishes while down', (t) => {
  t.mock.timers.enable({ apis: ['setTimeout'] });
  const { ROSLIB, sockets } = fakeRoslib();
  const connection = new Connection(ROSLIB, { url: 'ws://h:9090', token: 'tok' });
  const statuses = [];
  connection.addEventListener('status', (e) => statuses.push(e.detail.status));
  const received = [];
  connection.subscribe('/odom', 'nav_msgs/msg/Odometry', (m) => received.push(m));
  const cmdVel = connection.publisher('/cmd_vel', 'geometry_msgs/msg/Twist');
  assert.equal(connection.publisher('/cmd_vel', 'geometry_msgs/msg/Twist'), cmdVel);

  connection.connect();
  assert.equal(sockets[0].url, 'ws://h:9090?token=tok');
  assert.equal(cmdVel.publish({}), false); // not connected yet: dropped, not queued
  sockets[0].emit('connection');
  assert.deepEqual(sockets[0].sent, [
    { op: 'subscribe', topic: '/odom', type: 'nav_msgs/msg/Odometry' }]);
  sockets[0].emit('message:/odom', { n: 1 });
  assert.equal(cmdVel.publish({ linear: {} }), true);

  sockets[0].emit('close'); // the bridge went away
  assert.equal(connection.status, 'closed');
  assert.equal(cmdVel.publish({}), false);
  t.mock.timers.tick(RETRY_MAX_MS * 1.2);
  assert.equal(sockets.length, 2);
  sockets[1].emit('error', {});
  sockets[1].emit('close'); // still down: an error, and another retry
  assert.equal(connection.status, 'error');
  assert.match(connection.message, /Cannot reach the bridge at ws:\/\/h:9090\..*Retrying/);
  t.mock.timers.tick(RETRY_MAX_MS * 1.2);
  assert.equal(connection.status, 'connecting');
  assert.match(connection.message, /Cannot reach the bridge/); // no flicker while retrying
  sockets[2].emit('close');
  t.mock.timers.tick(RETRY_MAX_MS * 1.2);
  sockets[3].emit('connection');
  assert.equal(connection.status, 'connected');
  assert.deepEqual(sockets[3].sent, [
    { op: 'subscribe', topic: '/odom', type: 'nav_msgs/msg/Odometry' }]);
  sockets[3].emit('message:/odom', { n: 2 });
  assert.deepEqual(received, [{ n: 1 }, { n: 2 }]);
  assert.deepEqual(statuses, [
    'connecting', 'connected', 'closed', 'connecting', 'error', 'connecting', 'closed',
    'connecting', 'connected']);
});

test('close() says last words first and never reconnects', (t) => {
  t.mock.timers.enable({ apis: ['setTimeout'] });
  const { ROSLIB, sockets } = fakeRoslib();
  const connection = new Connection(ROSLIB, { url: 'ws://h:9090' });
  const cmdVel = connection.publisher('/cmd_vel', 'geometry_msgs/msg/Twist');
  connection.addEventListener('beforeclose', () => cmdVel.publish({ stop: true }));
  connection.connect();
  sockets[0].emit('connection');
  connection.close();
  assert.deepEqual(sockets[0].sent, [{ op: 'publish', topic: '/cmd_vel', msg: { stop: true } }]);
  assert.equal(sockets[0].closed, true);
  t.mock.timers.tick(60_000);
  assert.equal(sockets.length, 1);
  assert.equal(connection.status, 'closed');
});

test('a refused service call rejects with the bridge\'s reason', async () => {
  const { ROSLIB, sockets } = fakeRoslib();
  const connection = new Connection(ROSLIB, { url: 'ws://h:9090' });
  await assert.rejects(connection.callService('/s', 't'), /not connected/);
  connection.connect();
  sockets[0].emit('connection');
  sockets[0].on('call', ({ fail }) => fail('set_parameters needs admin rights'));
  await assert.rejects(connection.callService('/virtual_robot/set_parameters', 't', {}),
    (error) => error instanceof ServiceCallError && /needs admin rights/.test(error.message));
  connection.close();
});

test('a URL the browser cannot parse is an error, not a retry loop', () => {
  const { ROSLIB } = fakeRoslib();
  ROSLIB.Ros = function Broken() { throw new SyntaxError('invalid URL'); };
  const connection = new Connection(ROSLIB, { url: 'nonsense' });
  connection.connect();
  assert.equal(connection.status, 'error');
  assert.match(connection.message, /"nonsense" is not a WebSocket URL/);
});
