// Whose robot a class page is, and the URL a student's code uses (web-interface/js/your-robot.js).
import assert from 'node:assert/strict';
import { test } from 'node:test';

import {
  codeUrl, robotNameOf, yourRobotText,
} from '../../web-interface/js/your-robot.js';

test('a class page names its robot; a single robot page does not', () => {
  assert.equal(robotNameOf({ ws: 'ws://h:9090/robots/alice', robot: 'alice' }), 'alice');
  assert.equal(robotNameOf({ ws: 'ws://h:9090/' }), null);
  assert.equal(robotNameOf({ robot: '' }), null);
  assert.equal(robotNameOf(null), null);
});

test("the code's URL carries the token, encoded; the line never shows it", () => {
  const url = 'ws://h:9090/robots/alice';
  assert.equal(codeUrl(url, 'a+b/c'), `${url}?token=a%2Bb%2Fc`);
  assert.equal(codeUrl(url, null), url);
  const line = yourRobotText('alice', url, 'Secret-Token-123');
  assert.equal(line, `Your robot: alice \u2014 your code connects to ${url}?token=\u2026`);
  assert.ok(!line.includes('Secret-Token-123'));
});

test('without a token the line says the page watches and how the code connects', () => {
  const line = yourRobotText('bob', 'ws://h:9090/robots/bob', null);
  assert.match(line, /^Your robot: bob\. This page only watches/);
  assert.match(line, /ws:\/\/h:9090\/robots\/bob\?token=YOUR_TOKEN/);
});
