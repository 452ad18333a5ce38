// /admin: the payload perturbation page. Shows and changes the robot's runtime parameters
// (mass, inertia, mode, the speed and force limits...: robot.json's table) through the node's
// get_parameters and set_parameters services, resets the simulation, and shows the effect in
// the same view and velocity plots as the student page.
//
// The admin token rides in the WebSocket URL (?token=...). It is asked for once per tab and
// kept in sessionStorage; the banner's /admin?token=TOKEN link is accepted and the token is
// then removed from the address bar. It is sent only to the page's own bridge (config.json's
// adminWs or ws, else ws://<page host>:9090), never to one that ?ws= or the Bridge field
// names: a link could name anybody's.

import { ROSLIB } from './vendor.js';
import {
  Connection, initialWsUrl, loadSiteConfig, ownWsUrl, sameBridge, TOKEN_KEY, takeToken,
  withoutToken,
} from './connection.js';
import { bindConnectionBar, runFrameLoop } from './connection-bar.js';
import { createState, noteOwnReset } from './state.js';
import { LivePlots } from './plots.js';
import { Readouts } from './readouts.js';
import { ParametersPanel } from './params-panel.js';
import {
  $, closeWithPage, createView, keepBridgeOnNavigation, librariesLoaded, robotDescription,
  showFatal, subscribeRobot,
} from './page.js';
import { bindKeys, Teleop } from './teleop.js';

/**
 * The token card: the token form, what the page does with the token, and a warning while the
 * bridge is not the page's own (the token is not sent there: see Connection.sendsToken).
 */
function bindTokenCard(connection, storage, params) {
  const form = $('#token-form');
  const input = $('#token-input');
  const status = $('#token-state');
  const forget = $('#token-forget');
  $('#token-own-bridge').textContent = connection.tokenUrl;
  $('#ws-url').title = 'The admin token is only sent to this page\'s own bridge, '
    + `${connection.tokenUrl}`;
  let refusedAt = null; // the bridge that refused the token, until the token or bridge changes
  const show = () => {
    const has = Boolean(connection.token);
    const refused = has && refusedAt === connection.url;
    form.hidden = has && !refused;
    forget.hidden = !has;
    if (!sameBridge(connection.url, connection.tokenUrl)) {
      status.dataset.kind = 'warn';
      status.textContent = `Connected to ${withoutToken(connection.url)} from the link or the `
        + 'Bridge field; your admin token is only sent to this page\'s own server '
        + `(${connection.tokenUrl}), so this bridge treats you as any non-admin client.`;
    } else if (refused) {
      status.dataset.kind = 'error';
      status.textContent = 'The bridge refused this token: check it against the websim serve '
        + 'banner (admin: http://HOST:8080/admin?token=...).';
    } else {
      status.dataset.kind = has ? 'ok' : 'info';
      status.textContent = has
        ? 'Token set for this tab: changes are sent with it (the bridge checks it).'
        : 'No token set: websim serve refuses changes without one (its banner prints the '
          + 'admin link, /admin?token=...).';
    }
  };
  params.addEventListener('refused', () => {
    refusedAt = connection.url;
    show();
  });
  connection.addEventListener('status', show); // another bridge: say what it gets
  form.addEventListener('submit', (event) => {
    event.preventDefault();
    const token = input.value.trim();
    if (!token) return;
    storage.setItem(TOKEN_KEY, token);
    input.value = '';
    refusedAt = null;
    connection.connect(connection.url, token); // sent only if this is the page's own bridge
  });
  forget.addEventListener('click', () => {
    storage.removeItem(TOKEN_KEY);
    refusedAt = null;
    connection.connect(connection.url, '');
    input.focus();
  });
  show();
}

async function main() {
  if (!librariesLoaded()) return;
  const storage = window.sessionStorage;
  const token = takeToken(window.location, window.history, storage);
  const [config, robot] = await Promise.all([loadSiteConfig(), robotDescription()]);
  if (!robot) return;
  const configured = config.adminWs ?? config.ws;
  const connection = new Connection(ROSLIB, {
    url: initialWsUrl(window.location, configured),
    token,
    tokenUrl: ownWsUrl(window.location, configured),
  });
  const bar = bindConnectionBar(connection, {
    form: $('#connect-form'), input: $('#ws-url'), status: $('#conn-status'),
    message: $('#view-message'), otherDriver: $('#other-driver'),
    resetNotice: $('#reset-notice'),
  }, robot);
  const state = createState();
  state.entity = config.entity ?? null; // this robot's name in its world: not drawn twice
  subscribeRobot(connection, state, robot);
  const view = createView(state, robot);
  const teleop = new Teleop(connection, state, robot);
  bindKeys(teleop);
  const plots = new LivePlots($('#plots'), state, ['linear', 'angular'],
    { tools: $('#plots-tools') });
  const readouts = new Readouts(connection, state, $('#readouts'), robot);
  const params = new ParametersPanel(connection, robot, {
    form: $('#params-form'), fields: $('#params-fields'), notice: $('#params-notice'),
    reload: $('#params-reload'), reset: $('#reset-sim'),
  });
  bindTokenCard(connection, storage, params);
  // Our own reset is announced by the panel; the jump it makes is not another client's.
  $('#reset-sim').addEventListener('click', () => noteOwnReset(state, performance.now()));
  closeWithPage(connection);
  keepBridgeOnNavigation();
  runFrameLoop((now) => view.draw(now), (now) => plots.update(now),
    (now) => readouts.update(now), (now) => bar.update(now, state));
  connection.connect();
  window.websim = { connection, robot, state, view, teleop, params }; // for the console
}

main().catch((error) => showFatal(`The page could not start: ${error.message}`));
