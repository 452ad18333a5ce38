// /class: the instructor's dashboard. Every robot of a class live in one grid, on ONE
// WebSocket: the instructor's root connection (class-root.js), where robot NAME's topics and
// services are under /NAME. This module only wires the others: the token (class-token.js),
// the robots' topics (class-feed.js), their status (class-poller.js), the commands
// (class-commands.js) and the grid (class-grid.js), drawn in one animation loop.

import { ROSLIB } from './vendor.js';
import { Connection, loadSiteConfig, withoutToken } from './connection.js';
import { runFrameLoop } from './connection-bar.js';
import { loadRobot, parameterSpec } from './robot.js';
import { rootWsUrl } from './class-plan.js';
import {
  explainClosed, explainNoRobots, NEEDS_TOKEN, observedRoslib, probeHealth,
} from './class-root.js';
import { bindTokenCard, instructorToken } from './class-token.js';
import { ClassFeed } from './class-feed.js';
import { StatusPoller } from './class-poller.js';
import {
  ClassCommands, fanOutSummary, forAll, modeChoices, otherMode, PAYLOAD_FACTORS, payloadFactor,
  PARAMETERS,
} from './class-commands.js';
import { classSummary, isHeld, onStatus, onStatusError } from './class-state.js';
import { ClassGrid } from './class-grid.js';

/** The class's robot list is asked for again this often (ms): an open class enrols students. */
const ROBOTS_REFRESH_MS = 10000;

const $ = (selector) => document.querySelector(selector);

function showFatal(text) {
  const banner = $('#fatal');
  banner.textContent = text;
  banner.hidden = false;
}

/** The message over the grid: {kind, text}, or null to hide it. */
function showMessage(message) {
  const element = $('#class-message');
  element.hidden = !message;
  if (!message) return;
  element.dataset.kind = message.kind;
  element.textContent = message.text;
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
  try {
    [config, robot] = await Promise.all([loadSiteConfig(), loadRobot()]);
  } catch (error) { // robot.json: the dashboard guesses no topic names
    showFatal(error.message);
    return;
  }
  const url = rootWsUrl(window.location, config.ws);
  let lastClose = null;
  const connection = new Connection(observedRoslib(ROSLIB, (close) => { lastClose = close; }),
    { url, token, tokenUrl: url });
  const commands = new ClassCommands(connection, robot);
  const feed = new ClassFeed(connection, robot);
  const stateOf = (name) => feed.states.get(name);
  const poller = new StatusPoller({
    names: () => feed.names,
    poll: async (name) => {
      try {
        onStatus(stateOf(name), await commands.status(name), performance.now());
      } catch (error) {
        onStatusError(stateOf(name), `status: ${error.message}`);
      }
    },
  });

  // One robot's actions, the card's buttons and the "for all" buttons alike.
  const defaultMode = parameterSpec(robot, PARAMETERS.mode).default;
  const actions = {
    reset: (name) => commands.reset(name),
    pause: (name) => commands.pause(name, !isHeld(stateOf(name))),
    mode: (name) => commands.setMode(name, otherMode(robot, stateOf(name).status?.mode
      ?? defaultMode)),
    payload: (name) => commands.setPayload(name,
      payloadFactor(stateOf(name).status, robot) === PAYLOAD_FACTORS.at(-1)
        ? PAYLOAD_FACTORS[0] : PAYLOAD_FACTORS.at(-1)),
  };
  const act = (name, action, call = () => actions[action](name)) => runAction(
    stateOf(name), action, call).finally(() => poller.pollNow(name));

  const grid = new ClassGrid($('#class-grid'), $('#robot-card'), robot, {
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
  bindAll($('#all-reset'), 'reset', 'reset', (name) => commands.reset(name));
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

  // The robots: listed when the root connection opens, and again now and then.
  let robotsTimer = null;
  const loadRobots = async () => {
    try {
      const added = feed.addRobots(await commands.robots());
      grid.add(added.map(stateOf));
      if (feed.names.length === 0) {
        showMessage({ kind: 'info', text: 'The class has no robots yet.' });
      } else {
        showMessage(null);
      }
    } catch (error) {
      showMessage(explainNoRobots(error.message));
    }
  };

  const badge = $('#conn-status');
  const tokenCard = bindTokenCard({
    card: $('#token-card'), form: $('#token-form'), input: $('#token-input'),
    forget: $('#token-forget'),
  }, {
    storage,
    onToken: (newToken) => {
      token = newToken;
      if (token) {
        connection.connect(url, token);
      } else {
        connection.close();
        badge.textContent = 'no token';
        showMessage({ kind: 'info', text: NEEDS_TOKEN });
      }
    },
  });

  connection.addEventListener('status', async (event) => {
    const { status, message } = event.detail;
    badge.textContent = status;
    badge.dataset.status = status;
    badge.title = message;
    if (status === 'connecting' || status === 'connected' || !token) return;
    const close = lastClose;
    if (close?.opened) {
      showMessage({ kind: 'warn', text: message }); // lost: Connection reconnects
      return;
    }
    const health = await probeHealth();
    const explained = explainClosed({ url: withoutToken(url), close, health });
    if (connection.isConnected) return; // it opened while the server was asked
    showMessage(explained);
    tokenCard.ask(explained.askToken);
  });
  connection.addEventListener('connected', () => {
    tokenCard.ask(false);
    showMessage({ kind: 'info', text: 'Connected; asking for the class\'s robots…' });
    loadRobots();
    poller.start();
    clearInterval(robotsTimer);
    robotsTimer = setInterval(loadRobots, ROBOTS_REFRESH_MS);
  });
  connection.addEventListener('disconnected', () => {
    poller.stop();
    clearInterval(robotsTimer);
  });

  runFrameLoop((now) => grid.update(now), (now) => {
    const summary = classSummary(feed.states.values(), now);
    const text = `${summary.robots} robots · ${summary.driving} driving · ${summary.held} paused`;
    const element = $('#class-summary');
    if (element.textContent !== text) element.textContent = text;
  });
  window.addEventListener('pagehide', () => connection.close());
  window.addEventListener('pageshow', (event) => {
    if (event.persisted && token) connection.connect();
  });
  window.websim = { connection, robot, feed, grid, poller, commands }; // for the console

  if (token) {
    connection.connect();
  } else {
    badge.textContent = 'no token';
    badge.dataset.status = 'closed';
    showMessage({ kind: 'info', text: NEEDS_TOKEN });
    tokenCard.ask(true);
  }
}

main().catch((error) => showFatal(`The dashboard could not start: ${error.message}`));
