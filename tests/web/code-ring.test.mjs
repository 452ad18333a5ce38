// The ring a Python program's frames cross from the page to its worker (web-interface/js/
// code-ring.js): in order, whole, across the end of the buffer, cut into records when large,
// refused (never overwritten) when full, and a reader that waits only as long as it is told.
import assert from 'node:assert/strict';
import { test } from 'node:test';

import {
  CHUNK_BYTES, createRing, KIND, RingReader, RingWriter,
} from '../../web-interface/js/code-ring.js';

function pair(capacity) {
  const shared = createRing(capacity);
  return [new RingWriter(shared), new RingReader(shared)];
}

test('frames arrive in order and whole, also across the end of the buffer', () => {
  const [writer, reader] = pair(1024);
  const sent = [];
  for (let round = 0; round < 50; round += 1) { // 50 rounds of ~300 bytes: many wrap-arounds
    const batch = [];
    for (let index = 0; index < 3; index += 1) {
      const text = `{"op":"publish","n":${round * 3 + index},"pad":"${'é'.repeat(round % 40)}"}`;
      assert.equal(writer.write(writer.encode(KIND.MESSAGE, 7, text)), true);
      batch.push([7, 'message', text]);
    }
    sent.push(...batch);
    assert.deepEqual(reader.take(0).frames, batch);
  }
  assert.equal(sent.length, 150);
});

test('a frame larger than a record is cut and joined again', () => {
  const [writer, reader] = pair(1 << 21);
  const big = 'x'.repeat(CHUNK_BYTES * 2 + 12345);
  assert.equal(writer.write(writer.encode(KIND.MESSAGE, 1, big)), true);
  assert.equal(writer.write(writer.encode(KIND.OPEN, 2)), true);
  const { frames } = reader.take(0);
  assert.equal(frames.length, 2);
  assert.equal(frames[0][2].length, big.length);
  assert.deepEqual(frames[1], [2, 'open', '']);
});

test('a full ring refuses a frame, whole, and takes it once read', () => {
  const [writer, reader] = pair(256);
  const frame = writer.encode(KIND.MESSAGE, 1, 'y'.repeat(100));
  assert.equal(writer.write(frame), true);
  assert.equal(writer.write(frame), true);
  assert.equal(writer.write(frame), false); // 2 x 112 bytes written, 112 more do not fit
  writer.setPending(true);
  const { frames, pending } = reader.take(0);
  assert.equal(frames.length, 2);
  assert.equal(pending, true); // the page asked to be told: it is, once
  assert.equal(reader.take(0).pending, false);
  assert.equal(writer.write(frame), true);
  assert.equal(writer.fits(new Uint8Array(1000)), false); // never, however empty
});

test('a reader waits up to its timeout, and a wake ends the wait', () => {
  const [writer, reader] = pair(1024);
  let started = performance.now();
  assert.deepEqual(reader.take(50).frames, []);
  assert.ok(performance.now() - started >= 45);
  started = performance.now();
  let interrupted = false;
  writer.wake();
  interrupted = true;
  assert.deepEqual(reader.take(5000, () => interrupted).frames, []);
  assert.ok(performance.now() - started < 1000);
  assert.throws(() => createRing(1000), /power of two/);
});
