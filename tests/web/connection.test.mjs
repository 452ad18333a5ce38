// The rosbridge connection (web-interface/js/connection.js): URLs, tokens (and which bridge may
// get one), backoff, and the reconnect cycle against a fake roslibjs.
import assert from 'node:assert/strict';
import { test } from 'node:test';

import {
  Connection, defaultWsUrl, initialWsUrl, linkedWsUrl, loadSiteConfig, ownWsUrl, resolveWsUrl,
  retryDelayMs, RETRY_MAX_MS, sameBridge, ServiceCallError, takeToken, tokenFor, TOKEN_KEY,
  withoutToken, withPageBridge, withToken, keepRobotToken, ROBOT_TOKEN_PREFIX, takeRobotToken,
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

test('the own bridge is config.json\'s or the default, never the address bar\'s ?ws=', () => {
  const page = { protocol: 'http:', hostname: 'lab', host: 'lab:8080', search: '' };
  const linked = { ...page, search: '?ws=ws%3A%2F%2Fevil%3A9090&token=t' };
  assert.equal(ownWsUrl(page), 'ws://lab:9090');
  assert.equal(ownWsUrl(linked), 'ws://lab:9090');
  assert.equal(ownWsUrl(linked, '/admin/rosbridge'), 'ws://lab:8080/admin/rosbridge');
  assert.equal(ownWsUrl(page, '  '), 'ws://lab:9090');
  assert.equal(linkedWsUrl(page), null);
  assert.equal(linkedWsUrl(linked), 'ws://evil:9090');
  assert.equal(linkedWsUrl({ ...page, search: '?ws=/rosbridge' }), 'ws://lab:8080/rosbridge');
  assert.equal(initialWsUrl(linked, '/admin/rosbridge'), 'ws://evil:9090');
});

test('links to the other page carry this page\'s ?ws=, and nothing else of its query', () => {
  const page = { href: 'http://lab:8080/?ws=ws%3A%2F%2Flab%3A9091%2F&token=t', search:
    '?ws=ws%3A%2F%2Flab%3A9091%2F&token=t' };
  assert.equal(withPageBridge('admin', page), '/admin?ws=ws%3A%2F%2Flab%3A9091%2F');
  const admin = { href: 'http://lab:8080/admin?ws=%2Frosbridge', search: '?ws=%2Frosbridge' };
  assert.equal(withPageBridge('./', admin), '/?ws=%2Frosbridge');
  const plain = { href: 'http://lab:8080/', search: '' };
  assert.equal(withPageBridge('admin', plain), 'admin');
  const robot = { href: 'http://lab:8080/robots/alice/?ws=ws%3A%2F%2Fx', search: '?ws=ws%3A%2F%2Fx' };
  assert.equal(withPageBridge('admin', robot), '/robots/alice/admin?ws=ws%3A%2F%2Fx');
});

test('the same bridge: equal once parsed, trailing slash and fragment aside', () => {
  assert.equal(sameBridge('ws://h:9090', 'ws://h:9090/'), true);
  assert.equal(sameBridge('ws://H:9090/#x', 'ws://h:9090'), true);
  assert.equal(sameBridge('ws://h:80/', 'ws://h'), true); // the default port
  assert.equal(sameBridge('wss://h:9090', 'ws://h:9090'), false);
  assert.equal(sameBridge('ws://h:9091', 'ws://h:9090'), false);
  assert.equal(sameBridge('ws://h:9090/admin', 'ws://h:9090/'), false);
  assert.equal(sameBridge('ws://h:9090/?a=1', 'ws://h:9090/'), false);
  assert.equal(sameBridge('ws://user@h:9090', 'ws://h:9090'), false);
  assert.equal(sameBridge('ws://h.evil:9090', 'ws://h:9090'), false);
  assert.equal(sameBridge('ws://localhost:9090', 'ws://127.0.0.1:9090'), false); // as typed
  assert.equal(sameBridge('nonsense', 'nonsense'), false);
  assert.equal(sameBridge('ws://h:9090', null), false);
});

test('the admin token goes only to the page\'s own bridge', () => {
  const own = 'ws://lab:9090';
  assert.equal(tokenFor('ws://lab:9090/', own, 's3cret'), 's3cret');
  assert.equal(tokenFor('ws://elsewhere:9090', own, 's3cret'), '');
  assert.equal(tokenFor('ws://lab:9091', own, 's3cret'), '');
  assert.equal(tokenFor('ws://lab:9090', null, 's3cret'), ''); // no own bridge: nobody
  assert.equal(tokenFor('ws://lab:9090', own, ''), '');
});

test('a Connection withholds the token from any other bridge, typed or linked', () => {
  const { ROSLIB, sockets } = fakeRoslib();
  const own = 'ws://lab:9090';
  const linked = new Connection(ROSLIB, { url: 'ws://evil:9090', token: 'tok', tokenUrl: own });
  assert.equal(linked.sendsToken, false);
  linked.connect();
  linked.connect(linked.url, 'typed-token'); // a token typed into the form
  assert.deepEqual(sockets.map((s) => s.url), ['ws://evil:9090', 'ws://evil:9090']);
  linked.connect('ws://lab:9090/'); // the Bridge field: the page's own bridge, typed
  assert.equal(linked.sendsToken, true);
  linked.connect('ws://lab:9091'); // a near miss
  assert.equal(linked.sendsToken, false);
  assert.deepEqual(sockets.slice(2).map((s) => s.url),
    ['ws://lab:9090/?token=typed-token', 'ws://lab:9091']);
  const noOwn = new Connection(ROSLIB, { url: own, token: 'tok' });
  noOwn.connect();
  assert.equal(sockets.at(-1).url, own); // without tokenUrl the token goes nowhere
  linked.close();
  noOwn.close();
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
  const connection = new Connection(ROSLIB, {
    url: 'ws://h:9090', token: 'tok', tokenUrl: 'ws://h:9090',
  });
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

test('what the page\'s publishers send is announced as published; dropped messages are not',
  () => {
    const { ROSLIB, sockets } = fakeRoslib();
    const connection = new Connection(ROSLIB, { url: 'ws://h:9090' });
    const published = [];
    connection.addEventListener('published', (e) => published.push(e.detail));
    const cmdVel = connection.publisher('/cmd_vel', 'geometry_msgs/msg/Twist');
    connection.connect();
    cmdVel.publish({ n: 1 }); // not connected yet: dropped
    sockets[0].emit('connection');
    cmdVel.publish({ n: 2 });
    assert.deepEqual(published, [{ topic: '/cmd_vel', msg: { n: 2 } }]);
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

test('a robot page keeps its #token= per robot, out of the address bar; ?token= too', () => {
  const stored = new Map();
  const storage = { setItem: (k, v) => stored.set(k, v), getItem: (k) => stored.get(k) ?? null };
  const replaced = [];
  const history = { replaceState: (s, t, url) => replaced.push(String(url)) };
  const alice = 'http://h:8080/robots/alice/';
  assert.equal(takeRobotToken({ href: `${alice}#token=Abc-123` }, history, storage), 'Abc-123');
  assert.equal(stored.get(`${ROBOT_TOKEN_PREFIX}/robots/alice/`), 'Abc-123');
  assert.deepEqual(replaced, [alice]);
  assert.equal(takeRobotToken({ href: alice }, history, storage), 'Abc-123');
  assert.equal(replaced.length, 1, 'nothing to strip: the address bar is left alone');
  assert.equal(takeRobotToken({ href: 'http://h:8080/robots/bob/' }, history, storage), '',
    "alice's token is not bob's");
  assert.equal(takeRobotToken({ href: 'http://h:8080/robots/bob/?token=B0b&ws=x' }, history,
    storage), 'B0b');
  assert.equal(replaced.at(-1), 'http://h:8080/robots/bob/?ws=x');
  keepRobotToken({ href: 'http://h:8080/robots/dave/' }, storage, 'D4ve');
  assert.equal(takeRobotToken({ href: 'http://h:8080/robots/dave/' }, history, storage), 'D4ve');
});
