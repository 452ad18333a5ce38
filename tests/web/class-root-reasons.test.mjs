// Why the instructor's root connection would not open (web-interface/js/class-root-reasons.js)
// and its token (class-token.js): the token taken once and sent only to the root, how each
// socket closed, and what the page says when the root does not open.
import assert from 'node:assert/strict';
import { test } from 'node:test';

import { Connection, TOKEN_KEY } from '../../web-interface/js/connection.js';
import {
  explainClosed, explainNoRobots, NEEDS_TOKEN, observedRoslib, probeHealth, tokenRefused,
  WRONG_TOKEN,
} from '../../web-interface/js/class-root-reasons.js';
import { forgetToken, instructorToken, storeToken } from '../../web-interface/js/class-token.js';
import { rootWsUrl } from '../../web-interface/js/class-plan.js';
import { fakeRoslib } from './fake-roslib.mjs';

function memoryStorage() {
  const stored = new Map();
  return {
    stored,
    getItem: (key) => stored.get(key) ?? null,
    setItem: (key, value) => stored.set(key, value),
    removeItem: (key) => stored.delete(key),
  };
}

test('?token= is kept for the tab and stripped from the address; a typed one is trimmed', () => {
  const storage = memoryStorage();
  const replaced = [];
  const history = { replaceState: (s, t, url) => replaced.push(String(url)) };
  assert.equal(instructorToken({ href: 'http://lab:8080/class?token=T0k' }, history, storage), 'T0k');
  assert.deepEqual(replaced, ['http://lab:8080/class']);
  assert.equal(storage.stored.get(TOKEN_KEY), 'T0k');
  assert.equal(instructorToken({ href: 'http://lab:8080/class' }, history, storage), 'T0k');
  assert.equal(storeToken(storage, '  typed \n'), 'typed');
  assert.equal(storage.stored.get(TOKEN_KEY), 'typed');
  assert.equal(storeToken(storage, '   '), '');
  assert.equal(storage.stored.get(TOKEN_KEY), 'typed', 'a blank entry keeps the token');
  forgetToken(storage);
  assert.equal(instructorToken({ href: 'http://lab:8080/class' }, history, storage), '');
});

test('the token rides only on the root connection of the page\'s own server', () => {
  const { ROSLIB, sockets } = fakeRoslib();
  const url = rootWsUrl({ protocol: 'http:', hostname: 'lab', host: 'lab:8080' }, null);
  const connection = new Connection(observedRoslib(ROSLIB, () => {}),
    { url, token: 's3cret', tokenUrl: url });
  connection.connect();
  assert.deepEqual(sockets.map((s) => s.url), ['ws://lab:9090/?token=s3cret']);
  assert.doesNotMatch(connection.message, /s3cret/);
  connection.close();
});

test('each socket says whether it opened and how it closed', () => {
  const { ROSLIB, sockets } = fakeRoslib();
  const closes = [];
  const Observed = observedRoslib(ROSLIB, (close) => closes.push(close));
  assert.equal(Observed.Topic, ROSLIB.Topic, 'the rest is roslibjs\'s own');
  const connection = new Connection(Observed, { url: 'ws://h:1/' });
  connection.connect();
  sockets[0].emit('close', { code: 1006, reason: '' }); // refused at the handshake
  connection.connect();
  sockets[1].emit('connection');
  sockets[1].emit('close', { code: 1008, reason: 'rate limit' });
  assert.deepEqual(closes, [
    { opened: false, code: 1006, reason: '' },
    { opened: true, code: 1008, reason: 'rate limit' },
  ]);
  connection.close();
});

test('a refusal the server explains is shown as it is', () => {
  const shown = explainClosed({ url: 'ws://h:9090/', close: { opened: false, code: 1008,
    reason: 'this dashboard needs the instructor\'s token' }, health: null });
  assert.equal(shown.text,
    'The server closed ws://h:9090/: this dashboard needs the instructor\'s token');
  assert.equal(shown.askToken, true);
});

test('a silent refusal: unreachable, a single robot, or a class that wants the token', () => {
  const close = { opened: false, code: 1006, reason: '' };
  const down = explainClosed({ url: 'ws://h:9090/', close, health: null });
  assert.match(down.text, /Cannot reach the server at ws:\/\/h:9090\/\. Is websim serve running/);
  assert.equal(down.askToken, false);
  const single = explainClosed({ url: 'ws://h:9090/', close, health: { status: 'ok' } });
  assert.match(single.text, /single robot, not a class/);
  const refused = explainClosed({ url: 'ws://h:9090/', close,
    health: { status: 'ok', robot_count: 12 } }); // a server that does not say
  assert.equal(refused.kind, 'error');
  assert.equal(refused.askToken, true);
  assert.ok(refused.text.includes(NEEDS_TOKEN));
  assert.match(NEEDS_TOKEN, /needs the instructor's token/);
  const wrong = explainClosed({ url: 'ws://h:9090/', close,
    health: { status: 'ok', robot_count: 12, token_accepted: false } });
  assert.deepEqual(wrong, { kind: 'error', askToken: true, text: WRONG_TOKEN });
  assert.match(WRONG_TOKEN, /it is not the instructor's token/);
  const taken = explainClosed({ url: 'ws://h:9090/', close,
    health: { status: 'ok', robot_count: 12, token_accepted: true } });
  assert.equal(taken.askToken, false, 'the token is right: asking for it again would not help');
  assert.match(taken.text, /takes the token but refused ws:\/\/h:9090\/: most likely this page's origin/);
  assert.match(explainNoRobots('unknown service /websim/robots').text,
    /\/websim\/robots: unknown service \/websim\/robots/);
});

test('the health probe reads the page server\'s /healthz, or says null', async () => {
  const asked = [];
  const answer = (body) => async (url) => {
    asked.push(url);
    return { ok: true, json: async () => body };
  };
  const health = await probeHealth('', answer({ status: 'ok', robot_count: 3 }));
  assert.deepEqual(health, { status: 'ok', robot_count: 3 });
  await probeHealth('T k&n', answer({}));
  assert.deepEqual(asked, ['healthz', 'healthz?token=T%20k%26n']);
  assert.equal(await probeHealth('', async () => ({ ok: false })), null);
  assert.equal(await probeHealth('', async () => { throw new TypeError('offline'); }), null);
  assert.equal(await probeHealth('', async () => ({ ok: true, json: async () => 'x' })), null);
});

test('a token is refused only when a class server says it does not take it', () => {
  assert.equal(tokenRefused({ status: 'ok', robot_count: 3, token_accepted: false }), true);
  assert.equal(tokenRefused({ status: 'ok', robot_count: 3, token_accepted: true }), false);
  assert.equal(tokenRefused({ status: 'ok', robot_count: 3 }), false, 'a server that does not say');
  assert.equal(tokenRefused({ status: 'ok', token_accepted: false }), false, 'a single robot');
  assert.equal(tokenRefused({ status: 'ok' }), false, 'nginx\'s own /healthz');
  assert.equal(tokenRefused(null), false, 'no answer: out of reach, not a wrong token');
});
