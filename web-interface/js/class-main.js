// /class: the instructor's dashboard. Every robot of a class live in one grid, on the
// instructor's root connections (class-root-connections.js; why one would not open:
// class-root-reasons.js), where robot NAME's topics and services are under /NAME: ONE
// WebSocket to a single process, or one per worker for a class spread over workers behind
// nginx (class-workers.js). This module only wires the others:
// the token (class-token.js), the robots' topics (class-feed.js), their status (one call per
// root twice a second: class-poller.js), the commands (class-commands.js) and the grid
// (class-grid.js), drawn in one animation loop.

import { ROSLIB } from './vendor.js';
import { loadSiteConfig } from './connection.js';
import { runFrameLoop } from './connection-bar.js';
import { loadRobot, parameterSpec } from './robot.js';
import { rootWsUrl } from './class-plan.js';
import {
  explainNoRobots, NEEDS_TOKEN, probeHealth, tokenRefused, WRONG_TOKEN,
} from './class-root-reasons.js';
import { loadWorkers, rootTargets } from './class-workers.js';
import { ClassRoots, rootsBadge, rootsMessage } from './class-root-connections.js';
import { bindTokenCard, forgetToken, instructorToken } from './class-token.js';
import { ClassFeed } from './class-feed.js';
import { StatusPoller } from './class-poller.js';
import {
  fanOutSummary, forAll, modeChoices, otherMode, PAYLOAD_FACTORS, payloadFactor, PARAMETERS,
} from './class-commands.js';
import { classSummary, isHeld, onStatus, onStatusError } from './class-state.js';
import { ClassGrid } from './class-grid.js';
import { ArenaMap } from './class-arena.js';
import { Confirmation } from './confirm.js';

/** The class's robot list is asked for again this often (ms): an open class enrols students. */
const ROBOTS_REFRESH_MS = 10000;

const $ = (selector) => document.querySelector(selector);

function showFatal(text) {
  const banner = $('#fatal');
  banner.textContent = text;
  banner.hidden = false;
}

/** The message over the grid: {kind, text} or {kind, lines} (one line each), or null. */
function showMessage(message) {
  const element = $('#class-message');
  element.hidden = !message;
  if (!message) return;
  element.dataset.kind = message.kind;
  const lines = message.lines ?? [message.text];
  element.replaceChildren(...lines.flatMap(
    (line, i) => (i === 0 ? [line] : [document.createElement('br'), line])));
}

/** Runs one card's action; a refusal lands in its card with the server's reason. */
async function runAction(state, action, call) {
  state.busy.add(action);
  try {
    const value = await call();
    state.commandError = '';
    return value;
  } catch (error) {
    state.commandError = `${action}: ${error.message}`;
    throw error;
  } finally {
    state.busy.delete(action);
  }
}

async function main() {
  if (!ROSLIB) {
    showFatal('Could not load roslib from web-interface/node_modules: run "npm ci" in '
      + 'web-interface/ (or "bash scripts/test.sh") and reload.');
    return;
  }
  const storage = window.sessionStorage;
  let token = instructorToken(window.location, window.history, storage);
  let config;
  let robot;
  let workers;
  try {
    [config, robot, workers] = await Promise.all([loadSiteConfig(), loadRobot(), loadWorkers()]);
  } catch (error) { // robot.json: the dashboard guesses no topic names; a broken workers.json
    showFatal(error.message);
    return;
  }
  // One root (a single process), or one per worker behind nginx; the token goes to each.
  const roots = new ClassRoots(ROSLIB, rootTargets(rootWsUrl(window.location, config.ws),
    workers), robot, { token });
  const { commands } = roots; // each robot's calls, over the root it lives behind
  const feed = new ClassFeed(roots.list[0].connection, robot);
  const stateOf = (name) => feed.states.get(name);
  // Each root's robots' statuses, all in one call per root (/websim/class_status).
  const pollers = new Map(roots.list.map((root) => [root, new StatusPoller({
    poll: async () => {
      const names = feed.names.filter((name) => roots.rootOf(name) === root);
      try {
        const statuses = await root.commands.classStatus();
        const nowMs = performance.now();
        for (const name of names) {
          const values = statuses.get(name);
          if (values) onStatus(stateOf(name), values, nowMs);
          else onStatusError(stateOf(name), `status: ${name} is no longer listed`);
        }
      } catch (error) {
        for (const name of names) onStatusError(stateOf(name), `status: ${error.message}`);
      }
    },
  })]));

  // One robot's actions, the card's buttons and the "for all" buttons alike.
  const defaultMode = parameterSpec(robot, PARAMETERS.mode).default;
  const actions = {
    reset: (name) => commands.reset(name),
    // shown on request only (a dashboard may be on a projector), in a box it can be copied from
    token: (name) => commands.token(name).then((token) => {
      window.prompt(`${name}'s token, for its student only (their page: `
        + `/robots/${name}/#token=TOKEN; their code: ws://HOST:9090/robots/${name}?token=TOKEN)`,
      token);
    }),
    pause: (name) => commands.pause(name, !isHeld(stateOf(name))),
    mode: (name) => commands.setMode(name, otherMode(robot, stateOf(name).status?.mode
      ?? defaultMode)),
    payload: (name) => commands.setPayload(name,
      payloadFactor(stateOf(name).status, robot) === PAYLOAD_FACTORS.at(-1)
        ? PAYLOAD_FACTORS[0] : PAYLOAD_FACTORS.at(-1)),
  };
  const act = (name, action, call = () => actions[action](name)) => runAction(
    stateOf(name), action, call).finally(() => pollers.get(roots.rootOf(name))?.pollNow());

  const grid = new ClassGrid($('#class-grid'), $('#robot-card'), robot, {
    robotsPath: config.robotsPath,
    onAction: (name, action) => act(name, action).catch(() => {}), // shown in its card
  });

  // "For all": the same calls fanned out over the class; each refusal in its robot's card.
  const allNotice = $('#all-notice');
  const forEveryRobot = async (button, verb, action, call) => {
    const buttons = document.querySelectorAll('#all-actions button');
    for (const each of buttons) each.disabled = true;
    allNotice.dataset.kind = 'info';
    allNotice.textContent = `${verb}…`;
    allNotice.hidden = false;
    try {
      const results = await forAll(feed.names, (name) => act(name, action, () => call(name)));
      allNotice.dataset.kind = results.every((result) => result.ok) ? 'ok' : 'error';
      allNotice.textContent = fanOutSummary(verb, results);
    } finally {
      for (const each of buttons) each.disabled = false;
      button.focus();
    }
  };
  const bindAll = (button, verb, action, call) => button.addEventListener(
    'click', () => forEveryRobot(button, verb, action, call));
  // Resetting every robot throws away every student's run: it takes a second click.
  const resetAll = $('#all-reset');
  const confirmation = new Confirmation(resetAll, () => `Reset all ${feed.names.length} `
    + 'robots? Click again');
  resetAll.addEventListener('click', () => {
    if (confirmation.confirmed()) {
      forEveryRobot(resetAll, 'reset', 'reset', (name) => commands.reset(name));
    }
  });
  bindAll($('#all-pause'), 'paused', 'pause', (name) => commands.pause(name, true));
  bindAll($('#all-resume'), 'resumed', 'pause', (name) => commands.pause(name, false));
  for (const mode of modeChoices(robot)) {
    const button = document.createElement('button');
    button.type = 'button';
    button.id = `all-mode-${mode}`;
    button.textContent = `All ${mode}`;
    $('#all-actions').append(button);
    bindAll(button, `set ${mode} on`, 'mode', (name) => commands.setMode(name, mode));
  }

  $('#scans').addEventListener('change', (event) => feed.setScans(event.target.checked));

  // What the page says: each root's state, and one line about the class.
  const badge = $('#conn-status');
  let classMessage = null;
  let tokenCard = null;
  const render = () => {
    const shown = rootsBadge(roots.list);
    badge.textContent = shown.text;
    badge.dataset.status = shown.status;
    badge.title = shown.title;
    if (!token) return; // the badge says "no token"; the message NEEDS_TOKEN
    const { message, askToken } = rootsMessage(roots.list, classMessage);
    showMessage(message);
    tokenCard?.ask(askToken);
  };
  const noToken = () => {
    badge.textContent = 'no token';
    badge.dataset.status = 'closed';
    showMessage({ kind: 'info', text: NEEDS_TOKEN });
  };
  // The class server does not take the token: nothing is retried with it, it is not kept,
  // and it is asked for again at once.
  const refuseToken = () => {
    token = ''; // first: the roots' status listeners leave the closes below alone
    forgetToken(storage);
    roots.close();
    for (const root of roots.list) {
      root.failure = null;
      root.message = null;
    }
    badge.textContent = 'wrong token';
    badge.dataset.status = 'error';
    badge.title = WRONG_TOKEN;
    showMessage({ kind: 'error', text: WRONG_TOKEN });
    tokenCard.ask(true);
  };
  // A token is checked with the page's own server before a socket carries it: a refused
  // handshake is, in a browser, a close without a reason, as a server out of reach is.
  const connectWith = async (checked) => {
    const health = await probeHealth(checked);
    if (checked !== token) return; // another token was entered meanwhile
    if (tokenRefused(health)) refuseToken();
    else roots.connect(checked);
  };

  // The robots: listed by each root when it opens, and again now and then.
  let arena = null; // the arena's map (class-arena.js), once a robot of it is known
  const noRobots = roots.list.length === 1 ? 'The class has no robots yet.'
    : 'No worker hosts a robot yet: a worker makes a robot when its student first connects.';
  const loadRobots = async (root) => {
    try {
      const added = feed.addRobots(roots.claim(root, await root.commands.robots()),
        root.connection);
      grid.add(added.map(stateOf));
      if (config.arena && !arena && added.length) { // one world: one map of it, too
        arena = new ArenaMap($('#arena canvas'), root.connection, robot, added[0]);
        $('#arena').hidden = false;
      }
      if (added.length) pollers.get(root).pollNow(); // their first status now, not in a period
      root.listed = true;
      root.message = null;
      classMessage = feed.names.length === 0 ? { kind: 'info', text: noRobots } : null;
    } catch (error) {
      root.message = explainNoRobots(error.message);
    }
    render();
  };
  tokenCard = bindTokenCard({
    card: $('#token-card'), form: $('#token-form'), input: $('#token-input'),
    forget: $('#token-forget'),
  }, {
    storage,
    onToken: (newToken) => {
      token = newToken;
      for (const root of roots.list) {
        root.failure = null;
        root.message = null;
      }
      if (token) {
        connectWith(token);
      } else {
        roots.close();
        noToken();
      }
    },
  });

  for (const root of roots.list) {
    const { connection } = root;
    let robotsTimer = null;
    connection.addEventListener('status', async (event) => {
      const { status, message } = event.detail;
      render();
      if (status === 'connecting' || status === 'connected' || !token) return;
      const close = root.lastClose;
      if (close?.opened) {
        root.message = { kind: 'warn', text: message }; // lost: Connection reconnects
        render();
        return;
      }
      const health = await probeHealth(token);
      if (connection.isConnected || !token) return; // it opened while the server was asked
      if (tokenRefused(health)) { // the server no longer takes it (restarted with another)
        refuseToken();
        return;
      }
      root.failure = { close, health };
      root.message = null;
      render();
    });
    connection.addEventListener('connected', () => {
      root.message = { kind: 'info', text: 'Connected; asking for the class\'s robots…' };
      render();
      loadRobots(root);
      pollers.get(root).start();
      clearInterval(robotsTimer);
      robotsTimer = setInterval(() => loadRobots(root), ROBOTS_REFRESH_MS);
    });
    connection.addEventListener('disconnected', () => {
      pollers.get(root).stop();
      clearInterval(robotsTimer);
    });
  }

  runFrameLoop((now) => grid.update(now), () => arena?.draw(), (now) => {
    const summary = classSummary(feed.states.values(), now);
    const text = `${summary.robots} robots · ${summary.driving} driving · ${summary.held} paused`;
    const element = $('#class-summary');
    if (element.textContent !== text) element.textContent = text;
  });
  window.addEventListener('pagehide', () => roots.close());
  window.addEventListener('pageshow', (event) => {
    if (event.persisted && token) roots.connect();
  });
  window.websim = { // for the console
    roots, robot, feed, grid, pollers, commands, get arena() { return arena; },
  };

  if (token) {
    connectWith(token);
  } else {
    noToken();
    tokenCard.ask(true);
  }
}

main().catch((error) => showFatal(`The dashboard could not start: ${error.message}`));
