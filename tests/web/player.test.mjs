// A replay's player (web-interface/js/player.js): the status as the page reads it, the time,
// and what the play button says and sends.
import assert from 'node:assert/strict';
import { test } from 'node:test';

import {
  clockText, parsePlayerStatus, playCommand, playLabel, PLAYER_SPEEDS,
} from '../../web-interface/js/player.js';

test('a status answer is read field by field; what is missing reads null or false', () => {
  assert.deepEqual(parsePlayerStatus({
    playing: true, position_s: 12.5, duration_s: 60, speed: 2, finished: false, loop: true,
  }), { playing: true, positionS: 12.5, durationS: 60, speed: 2, finished: false, loop: true });
  assert.deepEqual(parsePlayerStatus({ playing: 'yes', position_s: 'x', speed: NaN }),
    { playing: false, positionS: null, durationS: null, speed: null, finished: false,
      loop: false });
});

test('times read as minutes and tenths of seconds', () => {
  assert.equal(clockText(0), '0:00.0');
  assert.equal(clockText(65.34), '1:05.3');
  assert.equal(clockText(null), '–');
  assert.equal(clockText(Infinity), '–');
});

test('the play button pauses while playing, plays again at the end', () => {
  const status = (playing, finished) => parsePlayerStatus({ playing, finished });
  assert.equal(playLabel(status(true, false)), 'Pause');
  assert.deepEqual(playCommand(status(true, false)), { command: 'pause' });
  assert.equal(playLabel(status(false, false)), 'Play');
  assert.equal(playLabel(status(false, true)), 'Play again');
  assert.deepEqual(playCommand(status(false, true)), { command: 'play' });
  assert.ok(PLAYER_SPEEDS.includes(1));
});
