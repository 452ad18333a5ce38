// The program's output pane (web-interface/js/code-output.js): bounded, the newest kept.
import assert from 'node:assert/strict';
import { test } from 'node:test';

import { MAX_LINES, OutputPane } from '../../web-interface/js/code-output.js';

test('the pane keeps the newest lines and counts what it let go and what never came', () => {
  const pane = new OutputPane({}, { schedule: () => {} }); // drawn by nobody here
  const lines = Array.from({ length: MAX_LINES + 500 }, (_, i) => ['stdout', `line ${i}`]);
  pane.add(lines.slice(0, 700));
  pane.add(lines.slice(700), 42);
  assert.equal(pane.lines.length, MAX_LINES);
  assert.equal(pane.dropped, 500);
  assert.equal(pane.skipped, 42);
  assert.deepEqual(pane.lines.at(-1), ['stdout', `line ${MAX_LINES + 499}`]);
  assert.deepEqual(pane.lines[0], ['stdout', 'line 500']);
  pane.clear();
  assert.deepEqual([pane.lines.length, pane.dropped, pane.skipped], [0, 0, 0]);
});
