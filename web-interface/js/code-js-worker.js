// The JavaScript program's worker (a classic worker, one per run): roslib 1.4.1 and the program.
//
// The program is the file a student runs with `node file.js` on a laptop (npm install
// roslib@1.4.1), unchanged: `require('roslib')` gives the global ROSLIB the classic build
// defines, `process.env` holds what `websim grade` would give it (WEBSIM_URL and the
// assignment's WEBSIM_<NAME>), `process.exit()` and `process.exitCode` end it, console.*
// prints to the page. Every WebSocket it opens (roslib's `new ROSLIB.Ros({url})`) goes to the
// robot of the page that runs it, with that page's token, whatever URL it names. Like Node, it
// ends when nothing is left to wait for (no timer, no open socket), or at an uncaught error.
//
// Served with its own Content-Security-Policy (websim/http_server.py): the program is loaded
// from a blob: URL, which the page's policy does not allow.

/* eslint-disable no-restricted-globals */

(function setUpWorker() {
  'use strict';

  const LINE_CHARS = 4000;

  let outputGate = null; // [lines posted, not yet read by the page; lines dropped] (shared)
  const timers = new Set();
  const sockets = new Set();
  const openSockets = new Set();
  let started = false;
  let ended = false;
  let program = { filename: 'main.js', blobUrl: '' };

  function post(message) {
    self.postMessage(message);
  }

  /** Each line to the page at once, unless it has too many unread: then counted, dropped
   *  (the same rule as the Python worker's). */
  function print(stream, args) {
    const text = args.map((value) => (typeof value === 'string' ? value : describe(value)))
      .join(' ');
    for (const piece of text.split('\n')) {
      if (Atomics.load(outputGate, 0) >= outputGate.limit) {
        Atomics.add(outputGate, 1, 1);
        continue;
      }
      const line = piece.length > LINE_CHARS
        ? `${piece.slice(0, LINE_CHARS)}… (${piece.length - LINE_CHARS} more characters)` : piece;
      Atomics.add(outputGate, 0, 1);
      post({ type: 'output', lines: [[stream, line]] });
    }
  }

  function describe(value) {
    if (value instanceof Error) return value.stack || String(value);
    try {
      const text = JSON.stringify(value);
      return text === undefined ? String(value) : text;
    } catch {
      return String(value);
    }
  }

  /** Where in the program an error comes from: its line in the student's file, if any. */
  function lineOf(error) {
    const stack = (error && error.stack) || '';
    for (const frame of stack.split('\n')) {
      const at = program.blobUrl ? frame.indexOf(program.blobUrl) : -1;
      if (at >= 0) {
        const match = frame.slice(at + program.blobUrl.length).match(/^:(\d+):\d+/);
        if (match) return Number(match[1]);
      }
    }
    return null;
  }

  function readable(text) {
    return program.blobUrl ? String(text).split(program.blobUrl).join(program.filename)
      : String(text);
  }

  function end(status, code, text = '', line = null) {
    if (ended) return;
    ended = true;
    post({ type: 'ended', status, code, text: readable(text), line });
  }

  /** Node's rule: the program is over when it waits for nothing any more. */
  function checkIdle() {
    if (started && !ended && timers.size === 0 && sockets.size === 0) {
      end('exited', self.process.exitCode || 0);
    }
  }

  const originalSetTimeout = self.setTimeout.bind(self);
  const originalClearTimeout = self.clearTimeout.bind(self);
  const originalSetInterval = self.setInterval.bind(self);
  const originalClearInterval = self.clearInterval.bind(self);

  function guarded(callback) {
    return (...args) => {
      if (ended) return undefined;
      try {
        return callback(...args);
      } catch (error) {
        crash(error);
        return undefined;
      }
    };
  }

  function crash(error) {
    end('crashed', 1, (error && error.stack) || String(error), lineOf(error));
  }

  self.setTimeout = (callback, delay, ...args) => {
    const id = originalSetTimeout(() => {
      timers.delete(id);
      guarded(callback)(...args);
      checkIdle();
    }, delay);
    timers.add(id);
    return id;
  };
  self.clearTimeout = (id) => {
    timers.delete(id);
    originalClearTimeout(id);
    originalSetTimeout(checkIdle, 0);
  };
  self.setInterval = (callback, delay, ...args) => {
    const id = originalSetInterval(() => {
      guarded(callback)(...args);
      checkIdle();
    }, delay);
    timers.add(id);
    return id;
  };
  self.clearInterval = (id) => {
    timers.delete(id);
    originalClearInterval(id);
    originalSetTimeout(checkIdle, 0);
  };

  function robotSocketClass(url) {
    const Native = self.WebSocket;
    return class RobotSocket extends Native {
      constructor(asked, protocols) {
        super(url, protocols);
        if (String(asked).split('?')[0] !== url.split('?')[0]) {
          post({ type: 'note', text: `new WebSocket(${JSON.stringify(String(asked).split('?')[0])}): `
            + 'in the browser, this page\'s robot' });
        }
        sockets.add(this);
        this.addEventListener('open', () => {
          openSockets.add(this);
          post({ type: 'sockets', open: openSockets.size });
        });
        this.addEventListener('close', () => {
          sockets.delete(this);
          openSockets.delete(this);
          post({ type: 'sockets', open: openSockets.size });
          originalSetTimeout(checkIdle, 0);
        });
      }
    };
  }

  function installNode(env, filename) {
    self.process = {
      env: { ...env },
      argv: ['node', filename],
      exitCode: undefined,
      platform: 'browser',
      exit(code) {
        const status = code === undefined ? (self.process.exitCode || 0) : Number(code) || 0;
        end('exited', status);
        throw new ProgramExit(); // ends the handler that called it, as exit() would
      },
      on() { return self.process; },
    };
    self.global = self;
    self.require = (name) => {
      // self.ROSLIB, not ROSLIB: the program's own `const ROSLIB = require(...)` is a global
      // binding, not yet initialized while this runs
      if (name === 'roslib') return self.roslibNamespace;
      throw new Error(`require('${name}'): in the browser only require('roslib') is available `
        + '(roslib 1.4.1)');
    };
    self.module = { exports: {} };
    self.exports = self.module.exports;
    self.__filename = filename;
    self.__dirname = '.';
    for (const [method, stream] of [['log', 'stdout'], ['info', 'stdout'], ['debug', 'stdout'],
      ['warn', 'stderr'], ['error', 'stderr']]) {
      console[method] = (...args) => print(stream, args);
    }
  }

  class ProgramExit extends Error {}

  self.addEventListener('error', (event) => {
    event.preventDefault();
    if (event.error instanceof ProgramExit) return;
    end('crashed', 1, event.error ? (event.error.stack || String(event.error)) : event.message,
      event.error ? lineOf(event.error) : (String(event.filename).startsWith('blob:')
        ? event.lineno : null));
  });
  self.addEventListener('unhandledrejection', (event) => {
    event.preventDefault();
    if (event.reason instanceof ProgramExit) return;
    crash(event.reason);
  });

  self.addEventListener('message', (event) => {
    const message = event.data;
    if (message.type !== 'run' || started) return;
    program = { filename: message.filename, blobUrl: '' };
    outputGate = new Int32Array(message.output);
    outputGate.limit = message.outputLimit;
    self.WebSocket = robotSocketClass(message.robotUrl);
    self.window = self; // roslib's browser build reads window.WebSocket, window.DOMParser...
    importScripts(message.roslibUrl); // roslib binds its WebSocket now: the robot's
    self.roslibNamespace = self.ROSLIB;
    installNode(message.env, message.filename); // after: roslib's bundle calls a global require
    program.blobUrl = URL.createObjectURL(new Blob([message.source],
      { type: 'text/javascript' }));
    started = true;
    try {
      importScripts(program.blobUrl);
    } catch (error) {
      if (!(error instanceof ProgramExit)) crash(error);
      return;
    }
    originalSetTimeout(checkIdle, 0);
  });
}());
