// The dashboard's root connections, and which robot lives behind which. One process: one
// root, every robot behind it. Behind nginx (class-workers.js): one root per worker, each
// listing (/websim/robots) the robots that live on that worker. A robot's topics and calls go
// over the root of the worker that listed it, never another: a worker makes a robot when it
// is first asked for one, so asking the wrong worker would make a second robot of that name.
// Also here: the one badge and the one message the roots make together.

import { Connection, withoutToken } from './connection.js';
import { ClassCommands } from './class-commands.js';
import { explainClosed, explainWorkerClosed, observedRoslib } from './class-root-reasons.js';

const SEVERITY = Object.freeze({ ok: 0, info: 1, warn: 2, error: 3 });

/**
 * ClassCommands' per-robot calls (reset, pause, setMode, setPayload, token), each sent to the
 * ClassCommands `commandsOf(name)` gives; a name it throws for rejects.
 */
export function routedCommands(commandsOf) {
  const route = (method) => async (name, ...args) => commandsOf(name)[method](name, ...args);
  return Object.freeze(Object.fromEntries(['reset', 'pause', 'setMode', 'setPayload',
    'token'].map((method) => [method, route(method)])));
}

export class ClassRoots {
  /**
   * @param {object} ROSLIB the roslibjs namespace
   * @param {{url: string, label: string}[]} targets class-workers.js rootTargets()
   * @param {object} robot the robot description (robot.js)
   * @param {{token?: string}} [options] the instructor's token, sent to every root (each is
   *   a path on the page's own bridge: its tokenUrl)
   */
  constructor(ROSLIB, targets, robot, { token = '' } = {}) {
    /**
     * One per target: {url, label, connection, commands, lastClose (observedRoslib()'s last
     * report), opened (with the current token), listed (its robots came), failure ({close,
     * health}: why it did not open, for rootsMessage()), message ({kind, text} or null)}.
     */
    this.list = targets.map(({ url, label }) => {
      const root = {
        url, label, lastClose: null, opened: false, listed: false, failure: null, message: null,
      };
      root.connection = new Connection(observedRoslib(ROSLIB, (close) => {
        root.lastClose = close;
      }), { url, token, tokenUrl: url });
      root.connection.addEventListener('connected', () => {
        root.opened = true;
        root.failure = null;
      });
      root.commands = new ClassCommands(root.connection, robot);
      return root;
    });
    this._home = new Map(); // robot name -> the root it lives behind
    this.commands = routedCommands((name) => this.commandsOf(name));
  }

  /**
   * The names of `names` (listed by `root`) that no root held: now `root`'s, in order. A name
   * another root listed first stays with that one (two workers hold a name only after the
   * set of workers changed).
   */
  claim(root, names) {
    const claimed = [];
    for (const name of names) {
      if (this._home.has(name)) continue;
      this._home.set(name, root);
      claimed.push(name);
    }
    return claimed;
  }

  rootOf(name) {
    return this._home.get(name);
  }

  /** The ClassCommands of robot `name`'s root; throws for a robot no root listed. */
  commandsOf(name) {
    const root = this._home.get(name);
    if (!root) throw new Error(`no root connection lists robot ${name}`);
    return root.commands;
  }

  /** (Re)connects every root, with `token` (default: the current one). */
  connect(token) {
    for (const root of this.list) {
      if (token !== undefined) root.opened = false;
      root.connection.connect(root.url, token); // undefined: the connection's own
    }
  }

  close() {
    for (const root of this.list) root.connection.close();
  }
}

/**
 * The status badge of `list` (ClassRoots.list): {status, text, title}. One root: its own
 * status. Several: connected when all are, else `connected K/N` (status connecting) while
 * some are, else the first one's status; the title says each root's state.
 */
export function rootsBadge(list) {
  if (list.length === 1) {
    const { status, message } = list[0].connection;
    return { status, text: status, title: message };
  }
  const title = list.map((root) => `${root.label}: ${root.connection.message}`).join('\n');
  const connected = list.filter((root) => root.connection.isConnected).length;
  if (connected === list.length) return { status: 'connected', text: 'connected', title };
  if (connected > 0) {
    return { status: 'connecting', text: `connected ${connected}/${list.length}`, title };
  }
  const waiting = list.find((root) => root.connection.status === 'connecting') ?? list[0];
  const { status } = waiting.connection;
  return { status, text: status, title };
}

/**
 * What the dashboard says about its roots, plus `extra` (a {kind, text} about the class, or
 * null): {message: {kind, lines} or null, askToken}. A root that did not open is explained
 * by class-root-reasons.js: explainClosed() while no root has opened with this token, and,
 * with several roots, explainWorkerClosed() once one has (the token is right). The token is
 * asked for only when every root has failed. Lines of several roots start with their label;
 * kind is the gravest.
 */
export function rootsMessage(list, extra = null) {
  const tokenWorks = list.some((root) => root.opened);
  const allFailed = list.every((root) => root.failure);
  const entries = [];
  let askToken = false;
  for (const root of list) {
    let { message } = root;
    if (root.failure) {
      const url = withoutToken(root.url);
      message = tokenWorks && list.length > 1
        ? explainWorkerClosed({ url, close: root.failure.close })
        : explainClosed({ url, ...root.failure });
      askToken ||= message.askToken && allFailed;
    }
    if (message) {
      entries.push({
        kind: message.kind, text: root.label ? `${root.label}: ${message.text}` : message.text,
      });
    }
  }
  if (extra) entries.push(extra);
  if (entries.length === 0) return { message: null, askToken };
  const kind = entries.map((entry) => entry.kind)
    .reduce((worst, each) => ((SEVERITY[each] ?? 0) > (SEVERITY[worst] ?? 0) ? each : worst));
  return { message: { kind, lines: entries.map((entry) => entry.text) }, askToken };
}
