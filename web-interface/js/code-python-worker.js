// The Python program's worker (a module worker): Pyodide, the browser's roslibpy, the program.
//
// 'load' fetches the runtime from this server (node_modules/pyodide: nothing from a CDN) and
// installs web-interface/python/*.py into Pyodide's file system; 'run' runs one program, as
// __main__, in a fresh namespace, blocking this worker until it ends. Meanwhile the page reaches
// it only through shared memory: the ring of frames (code-ring.js), read while the program
// waits, and Pyodide's interrupt buffer (Stop: KeyboardInterrupt). What the program sends and
// prints goes out with postMessage, which needs no event loop here.
//
// Served with its own Content-Security-Policy (websim/http_server.py): Pyodide compiles
// WebAssembly and runs its glue's eval(), which the page's policy forbids; the page keeps its.

import { RingReader } from './code-ring.js';

const PYODIDE_DIR = new URL('../node_modules/pyodide/', import.meta.url).href;
const SHIM_DIR = new URL('../python/', import.meta.url).href;
const SHIM_FILES = ['websim_browser.py', 'websim_worker.py', 'roslibpy/__init__.py',
  'roslibpy/core.py', 'roslibpy/ros2.py'];
const HOME = '/home/pyodide';

/** A longer line is cut (with a note of how much). */
const LINE_CHARS = 4000;

let pyodide = null;
let ring = null;
let interrupt = null;
let outputGate = null;
let nextSocket = 1;

function post(message) {
  self.postMessage(message);
}

/**
 * Each line goes to the page at once (a program that prints and then computes forever still
 * shows what it printed), unless the page has not read OUTPUT_IN_FLIGHT lines yet: then it is
 * dropped and counted (a print flood costs the page a bounded queue). outputGate: [lines
 * posted and not yet read, lines dropped], shared with the page (code-runner.js).
 */
function queueOutput(stream, text) {
  if (Atomics.load(outputGate, 0) >= outputGate.limit) {
    Atomics.add(outputGate, 1, 1);
    return;
  }
  const line = text.length > LINE_CHARS
    ? `${text.slice(0, LINE_CHARS)}… (${text.length - LINE_CHARS} more characters)` : text;
  Atomics.add(outputGate, 0, 1);
  post({ type: 'output', lines: [[stream, line]] });
}

/**
 * Cap the WebAssembly heap at `limitBytes`: growing beyond it fails, and Python raises
 * MemoryError at the program's line (instead of the tab growing to 4 GB and the browser
 * ending it). Pyodide's memory grows through emscripten_resize_heap, one of its imports.
 */
function capMemory(limitBytes) {
  for (const name of ['instantiate', 'instantiateStreaming']) {
    const original = WebAssembly[name];
    WebAssembly[name] = function instantiate(source, imports, ...rest) {
      const env = imports && imports.env;
      if (env && typeof env.emscripten_resize_heap === 'function') {
        const grow = env.emscripten_resize_heap;
        env.emscripten_resize_heap = (bytes) => ((bytes >>> 0) > limitBytes ? 0 : grow(bytes));
      }
      return original.call(this, source, imports, ...rest);
    };
  }
}

/** What Python's websim_worker.BrowserTransport calls: the program's sockets, via the page. */
const transport = {
  open(url) {
    const socket = nextSocket;
    nextSocket += 1;
    post({ type: 'open', socket, url });
    return socket;
  },
  send(socket, text) {
    post({ type: 'send', socket, text });
  },
  close(socket) {
    post({ type: 'close', socket });
  },
  wait(timeoutS) {
    const { frames, pending } = ring.take(timeoutS * 1000, () => interrupt[0] !== 0);
    if (pending) post({ type: 'drained' });
    if (interrupt[0] !== 0) pyodide.checkInterrupt(); // Stop: KeyboardInterrupt, now
    return frames;
  },
  pause(timeoutS) {
    Atomics.wait(new Int32Array(new SharedArrayBuffer(4)), 0, 0, timeoutS * 1000);
    if (interrupt[0] !== 0) pyodide.checkInterrupt();
  },
};

async function load({ memoryBytes }) {
  const started = performance.now();
  capMemory(memoryBytes);
  const { loadPyodide } = await import('../node_modules/pyodide/pyodide.mjs');
  pyodide = await loadPyodide({
    indexURL: PYODIDE_DIR,
    stdout: (text) => queueOutput('stdout', text),
    stderr: (text) => queueOutput('stderr', text),
  });
  pyodide.setStdin({ stdin: () => null }); // input(): end of file, at once
  pyodide.FS.mkdirTree(`${HOME}/roslibpy`);
  for (const name of SHIM_FILES) {
    const response = await fetch(SHIM_DIR + name, { cache: 'no-cache' });
    if (!response.ok) throw new Error(`${name}: HTTP ${response.status}`);
    pyodide.FS.writeFile(`${HOME}/${name}`, await response.text());
  }
  pyodide.registerJsModule('websim_transport', transport);
  pyodide.runPython(`import sys; sys.path.insert(0, ${JSON.stringify(HOME)})`);
  post({ type: 'ready', loadMs: performance.now() - started, version: pyodide.version });
}

function run({ source, filename, env, argv, shared }) {
  ring = new RingReader(shared.ring);
  interrupt = new Int32Array(shared.interrupt);
  outputGate = new Int32Array(shared.output);
  outputGate.limit = shared.outputLimit;
  pyodide.setInterruptBuffer(interrupt);
  nextSocket = 1;
  const runner = pyodide.pyimport('websim_worker');
  let result;
  try {
    result = runner.run_program(source, filename, pyodide.toPy(env), pyodide.toPy(argv))
      .toJs({ dict_converter: Object.fromEntries });
  } catch (error) { // the runner itself failed (it catches the program's own exceptions)
    result = { status: 'crashed', code: 1, text: String(error), line: null };
  } finally {
    runner.destroy();
  }
  post({ type: 'ended', ...result });
}

self.addEventListener('message', async (event) => {
  const message = event.data;
  try {
    if (message.type === 'load') await load(message);
    else if (message.type === 'run') run(message);
  } catch (error) {
    post({ type: 'failed', text: `${error.message || error}` });
  }
});
