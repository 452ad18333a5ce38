// The dashboard's root connections (web-interface/js/class-root-connections.js) on a fake
// roslibjs: one per worker, the token on each; a robot's subscriptions and calls over the root
// of the worker that listed it, never another; one badge and one message for them all.
import assert from 'node:assert/strict';
import { test } from 'node:test';

import {
  ClassRoots, rootsBadge, rootsMessage, routedCommands,
} from '../../web-interface/js/class-root-connections.js';
import { ClassFeed } from '../../web-interface/js/class-feed.js';
import { CLASS_SERVICES } from '../../web-interface/js/class-plan.js';
import { NEEDS_TOKEN } from '../../web-interface/js/class-root-reasons.js';
import { rootTargets } from '../../web-interface/js/class-workers.js';
import { fakeRoslib } from './fake-roslib.mjs';
import { robot } from './robot.mjs';

const ROOT = 'ws://lab:9090/';
const WORKERS = ['/workers/0/', '/workers/1/'];

/** ClassRoots over the two workers, with the sockets they opened. */
function twoWorkers(token = 'T') {
  const { ROSLIB, sockets } = fakeRoslib();
  const roots = new ClassRoots(ROSLIB, rootTargets(ROOT, WORKERS), robot, { token });
  roots.connect();
  return { roots, sockets };
}

test('one root connection per worker, each with the token, each its own tokenUrl', () => {
  const { roots, sockets } = twoWorkers('s3cret');
  assert.deepEqual(sockets.map((socket) => socket.url), [
    'ws://lab:9090/workers/0/?token=s3cret', 'ws://lab:9090/workers/1/?token=s3cret']);
  for (const root of roots.list) assert.equal(root.connection.sendsToken, true);
  assert.doesNotMatch(roots.list[1].connection.message, /s3cret/);
  roots.connect('new');
  assert.deepEqual(sockets.slice(2).map((socket) => socket.url), [
    'ws://lab:9090/workers/0/?token=new', 'ws://lab:9090/workers/1/?token=new']);
  roots.close();
});

test('a robot lives behind the root that listed it first; its calls go there only', async () => {
  const { roots, sockets } = twoWorkers();
  for (const socket of sockets) socket.emit('connection');
  const calls = [[], []];
  sockets.forEach((socket, index) => socket.on('call', (call) => {
    calls[index].push(call.name);
    call.ok({});
  }));
  const [first, second] = roots.list;
  assert.deepEqual(roots.claim(first, ['alice', 'bob']), ['alice', 'bob']);
  assert.deepEqual(roots.claim(second, ['bob', 'carol']), ['carol'], 'bob stays on worker 0');
  assert.equal(roots.rootOf('carol'), second);
  await roots.commands.reset('carol');
  await roots.commands.pause('alice', true);
  await roots.commands.token('bob');
  assert.deepEqual(calls, [
    [`/alice${CLASS_SERVICES.pause.name}`, `/bob${CLASS_SERVICES.token.name}`],
    [`/carol${robot.services.reset.name}`],
  ]);
  await assert.rejects(roots.commands.reset('dave'), /no root connection lists robot dave/);
  assert.equal(calls.flat().length, 3, 'an unknown robot is asked of no worker');
  roots.close();
});

test('each robot\'s topics are subscribed on its own worker\'s root', () => {
  const { roots, sockets } = twoWorkers();
  for (const socket of sockets) socket.emit('connection');
  const [first, second] = roots.list;
  const feed = new ClassFeed(first.connection, robot, { now: () => 0 });
  feed.addRobots(roots.claim(first, ['alice']), first.connection);
  feed.addRobots(roots.claim(second, ['carol']), second.connection);
  const topics = (socket) => socket.sent.filter((sent) => sent.op === 'subscribe')
    .map((sent) => sent.topic);
  assert.ok(topics(sockets[0]).length > 0);
  assert.ok(topics(sockets[0]).every((topic) => topic.startsWith('/alice/')));
  assert.ok(topics(sockets[1]).length > 0);
  assert.ok(topics(sockets[1]).every((topic) => topic.startsWith('/carol/')));
  feed.setScans(true);
  assert.ok(topics(sockets[1]).includes(`/carol${robot.topics.scan.name}`));
  assert.ok(!topics(sockets[0]).includes(`/carol${robot.topics.scan.name}`));
  roots.close();
});

test('routed commands pass every argument to the chosen commands', async () => {
  const seen = [];
  const commands = routedCommands(() => ({
    setMode: async (...args) => seen.push(['a', ...args]),
    setPayload: async (...args) => seen.push(['b', ...args]),
  }));
  await commands.setMode('alice', 'dynamic');
  await commands.setPayload('bob', 2);
  assert.deepEqual(seen, [['a', 'alice', 'dynamic'], ['b', 'bob', 2]]);
});

test('the badge: one root as it is; several: connected K/N until all are', () => {
  const { ROSLIB, sockets } = fakeRoslib();
  const single = new ClassRoots(ROSLIB, rootTargets(ROOT, null), robot, { token: 'T' });
  single.connect();
  assert.deepEqual(rootsBadge(single.list), {
    status: 'connecting', text: 'connecting', title: 'connecting to ws://lab:9090/…' });
  sockets[0].emit('connection');
  assert.equal(rootsBadge(single.list).text, 'connected');
  single.close();

  const { roots, sockets: two } = twoWorkers();
  assert.equal(rootsBadge(roots.list).text, 'connecting');
  two[1].emit('connection');
  const partial = rootsBadge(roots.list);
  assert.deepEqual([partial.status, partial.text], ['connecting', 'connected 1/2']);
  assert.ok(partial.title.startsWith(
    'Worker 0 (/workers/0/): connecting to ws://lab:9090/workers/0/…\nWorker 1'), partial.title);
  two[0].emit('connection');
  assert.equal(rootsBadge(roots.list).text, 'connected');
  roots.close();
});

const refused = { opened: false, code: 1006, reason: '' };
const classHealth = { status: 'ok', robot_count: 3 };

test('one root that is refused: the explanation as before, and the token asked for', () => {
  const { ROSLIB } = fakeRoslib();
  const roots = new ClassRoots(ROSLIB, rootTargets(ROOT, null), robot, { token: 'wrong' });
  roots.list[0].failure = { close: refused, health: classHealth };
  const { message, askToken } = rootsMessage(roots.list);
  assert.equal(askToken, true);
  assert.equal(message.kind, 'error');
  assert.equal(message.lines.length, 1);
  assert.ok(message.lines[0].startsWith('The class server refused the instructor\'s connection '
    + '(ws://lab:9090/).'));
  assert.ok(message.lines[0].includes(NEEDS_TOKEN));
  assert.deepEqual(rootsMessage(roots.list.map((root) => ({ ...root, failure: null })),
    { kind: 'info', text: 'The class has no robots yet.' }), {
    message: { kind: 'info', lines: ['The class has no robots yet.'] }, askToken: false });
});

test('a worker out of reach while another took the token: said so, the token not asked', () => {
  const { roots, sockets } = twoWorkers();
  sockets[0].emit('connection');
  const [, down] = roots.list;
  down.failure = { close: refused, health: classHealth };
  const { message, askToken } = rootsMessage(roots.list);
  assert.equal(askToken, false);
  assert.equal(message.kind, 'warn');
  assert.equal(message.lines.length, 1);
  assert.ok(message.lines[0].startsWith(
    'Worker 1 (/workers/1/): Cannot reach the class worker at ws://lab:9090/workers/1/: '));
  assert.match(message.lines[0], /the other workers' robots are shown/);
  roots.close();
});

test('several workers: the token is asked for only when every one has failed', () => {
  const { roots } = twoWorkers();
  const [first, second] = roots.list;
  first.failure = { close: refused, health: classHealth };
  assert.equal(rootsMessage(roots.list).askToken, false, 'worker 1 may still take it');
  second.failure = { close: refused, health: classHealth };
  const { message, askToken } = rootsMessage(roots.list, { kind: 'info', text: 'extra' });
  assert.equal(askToken, true);
  assert.equal(message.kind, 'error');
  assert.equal(message.lines.length, 3);
  assert.match(message.lines[0], /^Worker 0 .*refused the instructor's connection/);
  assert.match(message.lines[1], /^Worker 1 .*refused the instructor's connection/);
  assert.equal(message.lines[2], 'extra');
  roots.close();
});
