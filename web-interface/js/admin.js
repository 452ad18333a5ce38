// /admin: the payload perturbation page. Shows and changes mass, inertia, mode (and the speed
// and force limits) through /virtual_robot/get_parameters and set_parameters, resets the
// simulation, and shows the effect in the same view and velocity plots as the student page.
//
// The admin token rides in the WebSocket URL (?token=...). It is asked for once per tab and
// kept in sessionStorage; the banner's /admin?token=TOKEN link is accepted and the token is
// then removed from the address bar.

import { ROSLIB } from './vendor.js';
import {
  Connection, initialWsUrl, loadSiteConfig, ServiceCallError, TOKEN_KEY, takeToken,
} from './connection.js';
import { bindConnectionBar, runFrameLoop } from './connection-bar.js';
import { createState } from './state.js';
import { LivePlots } from './plots.js';
import { Readouts } from './readouts.js';
import { getParameters, setParameters } from './params.js';
import {
  $, closeWithPage, createView, librariesLoaded, showFatal, subscribeRobot,
} from './page.js';
import { bindKeys, Teleop } from './teleop.js';

/** The parameter form. Events: 'refused' when the bridge refuses a set_parameters call. */
class ParametersPanel extends EventTarget {
  constructor(connection) {
    super();
    this.connection = connection;
    this.form = $('#params-form');
    this.inputs = [...this.form.querySelectorAll('[data-param]')];
    this.notice = $('#params-notice');
    this.loaded = {}; // the values last read from the robot
    this.form.addEventListener('submit', (event) => {
      event.preventDefault();
      this.apply();
    });
    $('#params-reload').addEventListener('click', () => this.load());
    $('#reset-sim').addEventListener('click', () => this.reset());
    connection.addEventListener('connected', () => this.load());
  }

  async load() {
    try {
      const values = await getParameters(this.connection, this.inputs.map((i) => i.dataset.param));
      this.loaded = values;
      for (const input of this.inputs) {
        const value = values[input.dataset.param];
        input.disabled = value === undefined; // a robot without that parameter
        input.value = value === undefined ? '' : String(value);
      }
      this.form.dataset.loaded = 'true';
    } catch (error) {
      this.say('error', `Could not read the parameters: ${error.message}`);
    }
  }

  /** Sends the fields that differ from the robot's values, then shows what it said. */
  async apply() {
    const changes = {};
    for (const input of this.inputs) {
      const name = input.dataset.param;
      if (input.disabled) continue;
      const value = input.tagName === 'SELECT' ? input.value : Number(input.value);
      if (input.tagName !== 'SELECT' && (input.value.trim() === '' || !Number.isFinite(value))) {
        this.say('error', `${name}: "${input.value}" is not a number`);
        input.focus();
        return;
      }
      if (value !== this.loaded[name]) changes[name] = value;
    }
    if (!Object.keys(changes).length) {
      this.say('info', 'Nothing to apply: every field shows the robot\'s current value.');
      return;
    }
    try {
      const results = await setParameters(this.connection, changes);
      const refused = results.filter((r) => !r.successful);
      if (refused.length) {
        this.say('error', refused.map((r) => `${r.name} refused: ${r.reason}`).join('; '));
      } else {
        this.say('ok', `Applied: ${Object.entries(changes).map(([n, v]) => `${n} = ${v}`).join(', ')}`);
      }
    } catch (error) {
      if (error instanceof ServiceCallError) {
        this.say('error', `Refused: ${error.message}`);
        this.dispatchEvent(new Event('refused'));
      } else {
        this.say('error', `Not applied: ${error.message}`);
      }
    }
    await this.load();
  }

  async reset() {
    try {
      await this.connection.callService('/reset_simulation', 'std_srvs/srv/Empty', {});
      this.say('ok', 'Simulation reset: the robot is back at its start.');
    } catch (error) {
      this.say('error', `Reset failed: ${error.message}`);
    }
  }

  say(kind, text) {
    this.notice.dataset.kind = kind;
    this.notice.textContent = text;
    this.notice.hidden = false;
  }
}

function bindTokenCard(connection, storage, params) {
  const form = $('#token-form');
  const input = $('#token-input');
  const status = $('#token-state');
  const forget = $('#token-forget');
  const show = (refused = false) => {
    const has = Boolean(connection.token);
    form.hidden = has && !refused;
    forget.hidden = !has;
    if (refused && has) {
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
  params.addEventListener('refused', () => show(true));
  form.addEventListener('submit', (event) => {
    event.preventDefault();
    const token = input.value.trim();
    if (!token) return;
    storage.setItem(TOKEN_KEY, token);
    input.value = '';
    connection.connect(connection.url, token);
    show();
  });
  forget.addEventListener('click', () => {
    storage.removeItem(TOKEN_KEY);
    connection.connect(connection.url, '');
    show();
    input.focus();
  });
  show();
}

async function main() {
  if (!librariesLoaded()) return;
  const storage = window.sessionStorage;
  const token = takeToken(window.location, window.history, storage);
  const config = await loadSiteConfig();
  const state = createState();
  const connection = new Connection(ROSLIB, {
    url: initialWsUrl(window.location, config.adminWs ?? config.ws), token,
  });
  const bar = bindConnectionBar(connection, {
    form: $('#connect-form'), input: $('#ws-url'), status: $('#conn-status'),
    message: $('#view-message'),
  });
  subscribeRobot(connection, state);
  const view = createView(state);
  const teleop = new Teleop(connection, state);
  bindKeys(teleop);
  const plots = new LivePlots($('#plots'), state, ['linear', 'angular']);
  const readouts = new Readouts(connection, state, $('#readouts'));
  const params = new ParametersPanel(connection);
  bindTokenCard(connection, storage, params);
  closeWithPage(connection);
  runFrameLoop((now) => view.draw(now), (now) => plots.update(now),
    (now) => readouts.update(now), (now) => bar.update(now, state));
  connection.connect();
  window.websim = { connection, state, view, teleop, params }; // for the browser's console
}

main().catch((error) => showFatal(`The page could not start: ${error.message}`));
