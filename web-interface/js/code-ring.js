// The frames a Python program receives: a ring in a SharedArrayBuffer, written by the page's
// thread (which owns the program's WebSockets), read by the program's worker while the program
// waits (web-interface/python/websim_browser.py). A worker running Python has no event loop of
// its own, so nothing posted to it would arrive before the program ends; the ring is read
// inside time.sleep and the other waits, with Atomics.wait to block until a frame comes.
//
// One writer, one reader. Each record: a 12-byte header (payload bytes, kind, socket) and the
// UTF-8 payload, written contiguously modulo the capacity (a power of two). A frame larger than
// CHUNK_BYTES goes as several PART records and a last MESSAGE record, which the reader joins.
// The write and read positions count bytes modulo 2^30; WAKE is bumped (and notified) after
// every write, so a reader that saw the ring empty sleeps on WAKE without missing one.

export const KIND = Object.freeze({ OPEN: 1, MESSAGE: 2, PART: 3, CLOSE: 4 });
const KIND_NAMES = { 1: 'open', 2: 'message', 4: 'close' };

const WRITE = 0;
const READ = 1;
const WAKE = 2;
const PENDING = 3; // the page holds frames the ring had no room for: tell it when drained
const CONTROL_INTS = 4;
const HEADER_BYTES = 12;
const POSITION_MASK = (1 << 30) - 1;

/** Default capacity: 4 MiB, ten times the largest world's /map. */
export const RING_BYTES = 1 << 22;

/** A frame is cut into records of at most this many bytes. */
export const CHUNK_BYTES = 1 << 18;

/** The shared memory of a ring of `capacity` bytes (a power of two). */
export function createRing(capacity = RING_BYTES) {
  if (capacity & (capacity - 1)) throw new Error('the ring capacity must be a power of two');
  return {
    control: new SharedArrayBuffer(CONTROL_INTS * 4),
    data: new SharedArrayBuffer(capacity),
  };
}

function views(shared) {
  return { control: new Int32Array(shared.control), data: new Uint8Array(shared.data) };
}

function used(control) {
  return (Atomics.load(control, WRITE) - Atomics.load(control, READ)) & POSITION_MASK;
}

/** The page's side: writes records, or says it has no room (false) so the caller keeps them. */
export class RingWriter {
  constructor(shared) {
    Object.assign(this, views(shared));
    this.capacity = this.data.length;
    this.header = new DataView(new ArrayBuffer(HEADER_BYTES));
    this.encoder = new TextEncoder();
  }

  /** Bytes a frame of `text` takes in the ring (its records and headers). */
  bytesFor(payload) {
    const chunks = Math.max(1, Math.ceil(payload.length / CHUNK_BYTES));
    return payload.length + chunks * HEADER_BYTES;
  }

  /** Encode a frame: [kind, socket, UTF-8 bytes]. */
  encode(kind, socket, text = '') {
    return { kind, socket, payload: this.encoder.encode(text) };
  }

  /** Writes a whole encoded frame, or nothing and false when there is no room for it. */
  write({ kind, socket, payload }) {
    const need = this.bytesFor(payload);
    if (need > this.capacity - used(this.control)) return false;
    let offset = 0;
    do {
      const end = Math.min(payload.length, offset + CHUNK_BYTES);
      const last = end === payload.length;
      this._record(last ? kind : KIND.PART, socket, payload.subarray(offset, end));
      offset = end;
    } while (offset < payload.length);
    Atomics.add(this.control, WAKE, 1);
    Atomics.notify(this.control, WAKE);
    return true;
  }

  /** Whether a frame this large could ever fit (the ring empty). */
  fits(payload) {
    return this.bytesFor(payload) <= this.capacity;
  }

  /** Note that frames wait on the page (the reader then says when it drained the ring). */
  setPending(pending) {
    Atomics.store(this.control, PENDING, pending ? 1 : 0);
  }

  /** Wake a reader blocked in wait() (Stop: it then finds the interrupt). */
  wake() {
    Atomics.add(this.control, WAKE, 1);
    Atomics.notify(this.control, WAKE);
  }

  _record(kind, socket, bytes) {
    this.header.setUint32(0, bytes.length, true);
    this.header.setUint32(4, kind, true);
    this.header.setUint32(8, socket, true);
    let position = Atomics.load(this.control, WRITE);
    position = this._copy(position, new Uint8Array(this.header.buffer));
    position = this._copy(position, bytes);
    Atomics.store(this.control, WRITE, position);
  }

  _copy(position, bytes) {
    const at = position & (this.capacity - 1);
    const first = Math.min(bytes.length, this.capacity - at);
    this.data.set(bytes.subarray(0, first), at);
    if (first < bytes.length) this.data.set(bytes.subarray(first), 0);
    return (position + bytes.length) & POSITION_MASK;
  }
}

/** The worker's side: takes every frame written, blocking up to a timeout for the first. */
export class RingReader {
  constructor(shared) {
    Object.assign(this, views(shared));
    this.capacity = this.data.length;
    this.decoder = new TextDecoder();
    this.parts = new Map(); // socket -> [Uint8Array] of a frame still coming
  }

  /**
   * Frames as [socket, kind ('open', 'message', 'close'), text], waiting up to `timeoutMs`
   * for the first; `interrupted()` true ends the wait at once. Returns whether the page
   * asked to be told the ring has room again (PENDING), cleared.
   */
  take(timeoutMs, interrupted = () => false) {
    const frames = [];
    const deadline = performance.now() + Math.max(0, timeoutMs);
    for (;;) {
      const wake = Atomics.load(this.control, WAKE);
      this._drain(frames);
      if (frames.length || interrupted()) break;
      const left = deadline - performance.now();
      if (left <= 0) break;
      Atomics.wait(this.control, WAKE, wake, left);
    }
    const pending = Atomics.exchange(this.control, PENDING, 0) === 1;
    return { frames, pending };
  }

  _drain(frames) {
    let position = Atomics.load(this.control, READ);
    const end = Atomics.load(this.control, WRITE);
    while (position !== end) {
      const header = new DataView(this._bytes(position, HEADER_BYTES).buffer);
      const length = header.getUint32(0, true);
      const kind = header.getUint32(4, true);
      const socket = header.getUint32(8, true);
      const payload = this._bytes((position + HEADER_BYTES) & POSITION_MASK, length);
      position = (position + HEADER_BYTES + length) & POSITION_MASK;
      if (kind === KIND.PART) {
        if (!this.parts.has(socket)) this.parts.set(socket, []);
        this.parts.get(socket).push(payload);
        continue;
      }
      let bytes = payload;
      const before = this.parts.get(socket);
      if (before) {
        this.parts.delete(socket);
        bytes = joined([...before, payload]);
      }
      frames.push([socket, KIND_NAMES[kind] ?? 'close', this.decoder.decode(bytes)]);
    }
    Atomics.store(this.control, READ, position);
  }

  /** A copy (never a view of the shared memory: TextDecoder refuses those) of `length` bytes. */
  _bytes(position, length) {
    const out = new Uint8Array(length);
    const at = position & (this.capacity - 1);
    const first = Math.min(length, this.capacity - at);
    out.set(this.data.subarray(at, at + first));
    if (first < length) out.set(this.data.subarray(0, length - first), first);
    return out;
  }
}

function joined(chunks) {
  const out = new Uint8Array(chunks.reduce((sum, chunk) => sum + chunk.length, 0));
  let offset = 0;
  for (const chunk of chunks) {
    out.set(chunk, offset);
    offset += chunk.length;
  }
  return out;
}
