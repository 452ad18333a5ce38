// Runs the student's program in a Web Worker, against the robot of this page.
//
// Python (code-python-worker.js): Pyodide, loaded once when the Code panel opens and kept
// warm between runs. The program's WebSockets belong to this page's thread: it opens them (to
// the page's own bridge, with the page's token), writes what arrives into the ring the worker
// reads while the program waits (code-ring.js), and sends what the worker posts. Stop raises
// KeyboardInterrupt in the program through Pyodide's interrupt buffer; a program that does not
// end within STOP_GRACE_MS (it swallowed the interrupt) has its worker terminated.
// JavaScript (code-js-worker.js): a new worker per run, roslib inside it; Stop terminates it.
//
// Whatever way a program ends, its sockets close at once and the robot gets a zero /cmd_vel
// (`stopRobot`, the page's own teleop), so nothing keeps driving it.
//
// Events: 'state' {state, detail}, 'output' {lines: [[stream, text]], dropped}, 'ended'
// {status, code, text, line}, 'note' {text}.

import { createRing, KIND, RingWriter } from './code-ring.js';
import { withToken } from './connection.js';

/** The Python heap's cap: a program that allocates forever gets MemoryError at its line. */
export const PYTHON_MEMORY_BYTES = 512 * 1024 * 1024;

/** How long Stop waits for a Python program to end by KeyboardInterrupt before terminating. */
export const STOP_GRACE_MS = 1000;

/** Lines a program may have sent that the page has not shown yet; more are dropped, counted. */
export const OUTPUT_IN_FLIGHT = 2000;

/** Frames held on the page while the ring is full (a program busy in a callback): at most. */
export const PENDING_BYTES = 16 * 1024 * 1024;

const WORKERS = {
  python: new URL('./code-python-worker.js', import.meta.url).href,
  javascript: new URL('./code-js-worker.js', import.meta.url).href,
};
const ROSLIB_URL = new URL('../node_modules/roslib/build/roslib.min.js', import.meta.url).href;

/**
 * @param {{robot: () => {url: string, token: string}, stopRobot: () => void}} options
 *   robot(): the bridge the page talks to now and the token it may send there; stopRobot():
 *   a zero velocity command from the page.
 */
export class ProgramRunner extends EventTarget {
  constructor({ robot, stopRobot }) {
    super();
    this.robot = robot;
    this.stopRobot = stopRobot;
    this.state = 'idle';
    this.language = null;
    this.python = null; // {worker, ready: Promise, loadMs}
    this.run_ = null; // the current run: {language, worker, sockets, ring, pending, ...}
  }

  get running() {
    return this.run_ !== null;
  }

  /** Start loading Python (the Code panel opened): the first Run then starts at once. */
  preload() {
    this._python().catch(() => {}); // the failure is reported by run()
  }

  /** Runs a program: {language, source, filename, env}; stops the one running first. */
  async run({ language, source, filename, env }) {
    const previous = this.run_;
    if (previous) { // Restart: the old program must be over (its worker may be ended)
      this.stop();
      await previous.done;
    }
    const outputShared = new SharedArrayBuffer(8);
    const run = {
      language, sockets: new Map(), pending: [], pendingBytes: 0, dropped: 0, ended: false,
      startedMs: performance.now(), outputShared, output: new Int32Array(outputShared),
    };
    run.done = new Promise((resolve) => { run.resolveDone = resolve; });
    this.run_ = run;
    this.language = language;
    if (language === 'python') {
      this._setState('loading', 'Loading Python…');
      let python;
      try {
        python = await this._python();
      } catch (error) {
        if (this.run_ === run) this._finish(run, { status: 'failed', code: 1, text: error.message });
        return;
      }
      if (this.run_ !== run) return; // stopped while loading
      run.worker = python.worker;
      const shared = { ring: createRing(), interrupt: new SharedArrayBuffer(4) };
      run.ring = new RingWriter(shared.ring);
      run.interrupt = new Int32Array(shared.interrupt);
      shared.output = run.outputShared;
      shared.outputLimit = OUTPUT_IN_FLIGHT;
      run.listener = (event) => this._onPython(run, event.data);
      python.worker.addEventListener('message', run.listener);
      this._setState('running');
      python.worker.postMessage({
        type: 'run', source, filename, env, argv: [filename], shared,
      });
    } else {
      const worker = new Worker(WORKERS.javascript);
      run.worker = worker;
      worker.addEventListener('message', (event) => this._onJavascript(run, event.data));
      worker.addEventListener('error', (event) => {
        event.preventDefault();
        this._finish(run, { status: 'crashed', code: 1, text: event.message || 'the worker failed', line: null });
      });
      const { url, token } = this.robot();
      this._setState('running');
      worker.postMessage({
        type: 'run', source, filename, env, robotUrl: withToken(url, token), roslibUrl: ROSLIB_URL,
        output: run.outputShared, outputLimit: OUTPUT_IN_FLIGHT,
      });
    }
  }

  /** Stops the program now: its sockets close, the robot gets a zero command. */
  stop() {
    const run = this.run_;
    if (!run) return;
    this._closeSockets(run);
    this.stopRobot();
    if (run.language === 'python' && run.interrupt) {
      Atomics.store(run.interrupt, 0, 2); // SIGINT: KeyboardInterrupt in the program
      run.ring.wake();
      run.stopping = setTimeout(() => {
        if (run.ended) return;
        this._discardPython();
        this._finish(run, { status: 'stopped', code: 130, text: '', line: null });
      }, STOP_GRACE_MS);
      this._setState('stopping');
      run.stopRequested = true;
      return;
    }
    if (run.worker) run.worker.terminate();
    this._finish(run, { status: 'stopped', code: 130, text: '', line: null });
  }

  _python() {
    if (!this.python) {
      const worker = new Worker(WORKERS.python, { type: 'module' });
      const python = { worker, loadMs: null };
      python.ready = new Promise((resolve, reject) => {
        const onMessage = (event) => {
          if (event.data.type === 'ready') {
            python.loadMs = event.data.loadMs;
            worker.removeEventListener('message', onMessage);
            resolve(python);
          } else if (event.data.type === 'failed') {
            reject(new Error(`Python could not start: ${event.data.text}`));
          }
        };
        worker.addEventListener('message', onMessage);
        worker.addEventListener('error', (event) => {
          event.preventDefault();
          reject(new Error(`Python could not start: ${event.message || 'its worker failed'}`));
        });
      });
      python.ready.catch(() => {
        if (this.python === python) this.python = null; // the next Run tries again
      });
      worker.postMessage({ type: 'load', memoryBytes: PYTHON_MEMORY_BYTES });
      this.python = python;
    }
    return this.python.ready;
  }

  _discardPython() {
    if (!this.python) return;
    this.python.worker.terminate();
    this.python = null;
  }

  _onPython(run, message) {
    if (run.ended) return;
    switch (message.type) {
      case 'open': this._open(run, message.socket); break;
      case 'send': {
        const socket = run.sockets.get(message.socket);
        if (socket && socket.readyState === WebSocket.OPEN) socket.send(message.text);
        break;
      }
      case 'close': {
        const socket = run.sockets.get(message.socket);
        if (socket) socket.close();
        break;
      }
      case 'drained': this._flush(run); break;
      case 'output': this._output(run, message); break;
      case 'ended': this._finish(run, message); break;
      default: break;
    }
  }

  _onJavascript(run, message) {
    if (run.ended) return;
    if (message.type === 'output') this._output(run, message);
    else if (message.type === 'note') this.dispatchEvent(new CustomEvent('note', { detail: message }));
    else if (message.type === 'sockets') this._setState(message.open > 0 ? 'connected' : 'running');
    else if (message.type === 'ended') {
      run.worker.terminate();
      this._finish(run, message);
    }
  }

  _open(run, id) {
    const { url, token } = this.robot();
    let socket;
    try {
      socket = new WebSocket(withToken(url, token));
    } catch (error) {
      this._deliver(run, run.ring.encode(KIND.CLOSE, id, `cannot connect: ${error.message}`));
      return;
    }
    run.sockets.set(id, socket);
    socket.addEventListener('open', () => {
      this._deliver(run, run.ring.encode(KIND.OPEN, id));
      this._updateConnected(run);
    });
    socket.addEventListener('message', (event) => {
      if (typeof event.data === 'string') this._deliver(run, run.ring.encode(KIND.MESSAGE, id, event.data));
    });
    socket.addEventListener('close', (event) => {
      run.sockets.delete(id);
      this._deliver(run, run.ring.encode(KIND.CLOSE, id, event.reason || `closed (${event.code})`));
      this._updateConnected(run);
    });
  }

  _updateConnected(run) {
    if (run.ended || run.stopRequested) return;
    const open = [...run.sockets.values()].some((s) => s.readyState === WebSocket.OPEN);
    this._setState(open ? 'connected' : 'running');
  }

  /** Into the ring, or held (in order) until the worker has read enough. */
  _deliver(run, frame) {
    if (run.ended) return;
    if (!run.pending.length && run.ring.write(frame)) return;
    if (!run.ring.fits(frame.payload)) {
      run.dropped += 1; // larger than the whole ring: never deliverable
      return;
    }
    run.pending.push(frame);
    run.pendingBytes += frame.payload.length;
    while (run.pendingBytes > PENDING_BYTES && run.pending.length > 1) {
      const oldest = run.pending.findIndex((f) => f.kind === KIND.MESSAGE); // a message, never open/close
      if (oldest < 0) break;
      run.pendingBytes -= run.pending[oldest].payload.length;
      run.pending.splice(oldest, 1);
      run.dropped += 1;
    }
    run.ring.setPending(true);
  }

  _flush(run) {
    while (run.pending.length && run.ring.write(run.pending[0])) {
      run.pendingBytes -= run.pending[0].payload.length;
      run.pending.shift();
    }
    run.ring.setPending(run.pending.length > 0);
  }

  _output(run, message) {
    Atomics.sub(run.output, 0, message.lines.length);
    const dropped = Atomics.exchange(run.output, 1, 0);
    this.dispatchEvent(new CustomEvent('output', { detail: { lines: message.lines, dropped } }));
  }

  _closeSockets(run) {
    for (const socket of run.sockets.values()) socket.close();
    run.sockets.clear();
  }

  _finish(run, result) {
    if (run.ended) return;
    run.ended = true;
    clearTimeout(run.stopping);
    if (run.listener && run.worker) run.worker.removeEventListener('message', run.listener);
    this._closeSockets(run);
    const lost = Atomics.exchange(run.output, 1, 0); // lines dropped after the last shown
    if (lost) this.dispatchEvent(new CustomEvent('output', { detail: { lines: [], dropped: lost } }));
    if (result.status !== 'failed') this.stopRobot();
    const status = run.stopRequested && result.status !== 'crashed' ? 'stopped' : result.status;
    if (this.run_ === run) this.run_ = null;
    const detail = {
      ...result, status, dropped: run.dropped, seconds: (performance.now() - run.startedMs) / 1000,
    };
    this._setState(status, detail);
    this.dispatchEvent(new CustomEvent('ended', { detail }));
    run.resolveDone();
  }

  _setState(state, detail = null) {
    this.state = state;
    this.dispatchEvent(new CustomEvent('state', { detail: { state, detail } }));
  }
}
