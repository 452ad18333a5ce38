// The command-to-odometry latency (web-interface/js/latency.js).
import assert from 'node:assert/strict';
import { test } from 'node:test';

import {
  createLatency, LATENCY_SAMPLES, LATENCY_TIMEOUT_MS, latencyMs, noteCommandSent, noteOdometry,
} from '../../web-interface/js/latency.js';

test('a new command is timed to the first odometry showing its speeds', () => {
  const latency = createLatency();
  assert.equal(latencyMs(latency), null);
  noteCommandSent(latency, 0.2, 0, 1000);
  noteOdometry(latency, 0, 0, 1010); // the old speed: not yet
  noteOdometry(latency, 0.2, 0, 1030);
  noteOdometry(latency, 0.2, 0, 1080); // later ones do not count again
  assert.deepEqual(latency.samplesMs, [30]);
  noteCommandSent(latency, 0.2, 0, 1100); // a held key repeats it: not timed again
  noteOdometry(latency, 0.2, 0, 1110);
  assert.deepEqual(latency.samplesMs, [30]);
  noteCommandSent(latency, 0, 0, 1200); // the release: a change
  noteOdometry(latency, 0, 0, 1250);
  assert.deepEqual(latency.samplesMs, [30, 50]);
  assert.equal(latencyMs(latency), 40);
});

test('a command odometry never shows is given up; the median of the latest samples', () => {
  const latency = createLatency();
  noteCommandSent(latency, 9, 0, 0); // beyond the robot's limit: odometry shows the clamped speed
  noteOdometry(latency, 0.5, 0, LATENCY_TIMEOUT_MS + 1);
  assert.equal(latency.pending, null);
  assert.equal(latencyMs(latency), null);
  for (let i = 0; i < LATENCY_SAMPLES + 5; i += 1) {
    noteCommandSent(latency, i % 2 ? 0.1 : 0.2, 0, 10000 * i);
    noteOdometry(latency, i % 2 ? 0.1 : 0.2, 0, 10000 * i + (i < 5 ? 500 : 20));
  }
  assert.equal(latency.samplesMs.length, LATENCY_SAMPLES);
  assert.equal(latencyMs(latency), 20); // the five slow ones were the oldest
});
