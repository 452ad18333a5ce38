// The student page: the view, teleop, readouts, live plots and the heading PID panel.

import { ROSLIB } from './vendor.js';
import {
  Connection, initialWsUrl, keepRobotToken, loadSiteConfig, ownWsUrl, takeRobotToken,
} from './connection.js';
import { bindConnectionBar, runFrameLoop } from './connection-bar.js';
import { createState, forgetPast } from './state.js';
import { LivePlots } from './plots.js';
import { PidPanel } from './pid-panel.js';
import { Readouts } from './readouts.js';
import { showYourRobot } from './your-robot.js';
import { Player } from './player.js';
import { bindCodeCard } from './code-card.js';
import {
  $, closeWithPage, createTeleop, createView, keepBridgeOnNavigation, librariesLoaded,
  robotDescription, showFatal, subscribeRobot,
} from './page.js';

async function main() {
  if (!librariesLoaded()) return;
  const [config, robot] = await Promise.all([loadSiteConfig(), robotDescription()]);
  if (!robot) return;
  const state = createState();
  state.entity = config.entity ?? null; // this robot's name in its world: not drawn twice
  // A class robot's token (the links file's #token=, or what an open class handed this page):
  // kept in localStorage, sent only to the page's own bridge, never shown.
  const token = takeRobotToken(window.location, window.history, window.localStorage);
  const connection = new Connection(ROSLIB, {
    url: initialWsUrl(window.location, config.ws), token,
    tokenUrl: ownWsUrl(window.location, config.ws),
  });
  // A class robot's page: whose robot, and the URL the student's own code uses.
  const showOwner = showYourRobot({
    box: $('#your-robot'), text: $('#your-robot-text'), copy: $('#your-robot-copy'),
  }, config, ownWsUrl(window.location, config.ws), () => connection.token);
  if (!token && config.robotToken) {
    // An open class: the first connection to a new name is handed its robot. Ask once.
    connection.addEventListener('connected', () => {
      if (connection.token) return;
      connection.callService(config.robotToken.name, config.robotToken.type).then((reply) => {
        if (reply && typeof reply.token === 'string' && reply.token) {
          keepRobotToken(window.location, window.localStorage, reply.token);
          connection.token = reply.token; // sent from the next (re)connection on
          showOwner?.();
        }
      }).catch(() => {}); // not this page's robot: it watches
    });
  }
  if (config.replay) { // websim replay: a player, nothing to drive
    replayPage(connection, state, robot, config.replay);
    return;
  }
  const bar = bindConnectionBar(connection, {
    form: $('#connect-form'), input: $('#ws-url'), status: $('#conn-status'),
    message: $('#view-message'), otherDriver: $('#other-driver'),
    resetNotice: $('#reset-notice'),
  }, robot);
  subscribeRobot(connection, state, robot);
  const view = createView(state, robot);
  const { teleop, limits } = createTeleop(connection, state, robot);
  const plots = new LivePlots($('#plots'), state, ['linear', 'angular'],
    { tools: $('#plots-tools') });
  const headingPlot = new LivePlots($('#heading-plot'), state, ['heading']);
  const readouts = new Readouts(connection, state, $('#readouts'), robot);
  const pid = new PidPanel(connection, state, robot, {
    form: $('#pid-form'), kp: $('#pid-kp'), ki: $('#pid-ki'), kd: $('#pid-kd'),
    setpoint: $('#pid-setpoint'), toggle: $('#pid-toggle'), status: $('#pid-status'),
    error: $('#pid-error'), output: $('#pid-output'),
  }, () => limits.angular);
  teleop.addEventListener('drive', () => pid.stop()); // the student takes over
  teleop.addEventListener('halt', () => pid.stop()); // Space or Stop: nothing drives on
  pid.addEventListener('start', () => teleop.stop());
  const code = bindCodeCard(codeElements(), { // the Code panel: loads nothing until opened
    connection, robot, stopRobot: () => teleop.stop(), onRun: () => { pid.stop(); teleop.stop(); },
  });
  closeWithPage(connection);
  keepBridgeOnNavigation();
  runFrameLoop((now) => view.draw(now), (now) => plots.update(now),
    (now) => headingPlot.update(now),
    (now) => readouts.update(now), (now) => bar.update(now, state));
  connection.connect();
  window.websim = { connection, robot, state, view, teleop, pid, plots, headingPlot, code }; // console
}

function codeElements() {
  const ids = {
    open: 'code-open', intro: 'code-intro', panel: 'code-panel', state: 'code-state',
    nav: 'code-nav-state', navState: 'code-nav-state', language: 'code-language',
    assignment: 'code-assignment', scenario: 'code-scenario',
    scenarioLabel: 'code-scenario-label', load: 'code-load', run: 'code-run', stop: 'code-stop',
    restart: 'code-restart', download: 'code-download', filename: 'code-filename',
    submit: 'code-submit', saveStatus: 'code-save-status', laptop: 'code-laptop',
    laptopText: 'code-laptop-text', laptopCopy: 'code-laptop-copy', editor: 'code-editor',
    output: 'code-output', clear: 'code-clear', grade: 'code-grade',
    submitNote: 'code-submit-note',
  };
  return Object.fromEntries(Object.entries(ids).map(([key, id]) => [key, $(`#${id}`)]));
}

/**
 * The page of a replay (websim replay): the view, readouts and plots of the recording, and a
 * player (play, pause, seek, speed) instead of the drive pad, the PID panel and the notices of
 * other drivers: a recording is not driven.
 */
function replayPage(connection, state, robot, service) {
  document.body.dataset.mode = 'replay';
  document.title = 'websim — replay';
  $('.brand-sub').textContent = 'replay of a recording';
  const bar = bindConnectionBar(connection, {
    form: $('#connect-form'), input: $('#ws-url'), status: $('#conn-status'),
    message: $('#view-message'),
  }, robot);
  subscribeRobot(connection, state, robot);
  const view = createView(state, robot);
  const plots = new LivePlots($('#plots'), state, ['linear', 'angular'],
    { tools: $('#plots-tools') });
  const readouts = new Readouts(connection, state, $('#readouts'), robot);
  const player = new Player(connection, service, {
    card: $('#player'), toggle: $('#player-toggle'), seek: $('#player-seek'),
    time: $('#player-time'), speed: $('#player-speed'), message: $('#player-message'),
  }, { onSeek: () => forgetPast(state) });
  closeWithPage(connection);
  runFrameLoop((now) => view.draw(now), (now) => plots.update(now),
    (now) => readouts.update(now), (now) => bar.update(now, state));
  connection.connect();
  window.websim = { connection, robot, state, view, plots, player }; // console
}

main().catch((error) => showFatal(`The page could not start: ${error.message}`));
