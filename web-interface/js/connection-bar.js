// The connection controls every page has: the bridge URL field, the status badge, the
// message over the view that says what is wrong when nothing can be shown, and the badge that
// says another client is driving the robot (drivers.js decides who).

import { resolveWsUrl } from './connection.js';
import { othersDriving } from './drivers.js';
import { resetByOther } from './state.js';

const WAITING_MS = 2000; // connected but no odometry for this long: say so

/**
 * @param {Connection} connection
 * @param {{form: HTMLFormElement, input: HTMLInputElement, status: HTMLElement,
 *          message: HTMLElement, otherDriver?: HTMLElement, resetNotice?: HTMLElement}}
 *   elements otherDriver: shown while another client's velocity commands arrive; resetNotice:
 *   shown for a while after a reset this page did not ask for
 * @param {object} robot the robot description (robot.js): the odometry topic it waits for
 * @returns {{update: (nowMs: number, state: object) => void}}
 */
export function bindConnectionBar(connection, {
  form, input, status, message, otherDriver = null, resetNotice = null,
}, robot) {
  const odomTopic = robot.topics.odom.name;
  let connectedAtMs = null;
  input.value = connection.url;
  form.addEventListener('submit', (event) => {
    event.preventDefault();
    if (!input.value.trim()) return;
    const url = resolveWsUrl(input.value, window.location);
    const address = new URL(window.location.href);
    address.searchParams.set('ws', url); // a reload keeps the chosen bridge
    window.history.replaceState(null, '', address);
    connection.connect(url);
  });
  connection.addEventListener('status', (event) => {
    const { status: value, message: text } = event.detail;
    status.textContent = value;
    status.dataset.status = value;
    status.title = text;
    connectedAtMs = value === 'connected' ? performance.now() : null;
  });
  const show = (text) => {
    if (message.textContent !== text) message.textContent = text;
    message.hidden = !text;
  };
  return {
    update(nowMs, state) {
      if (!connection.isConnected) {
        show(connection.message);
      } else if (nowMs - Math.max(connectedAtMs ?? 0, state.odomAtMs) > WAITING_MS) {
        show(`Connected to ${connection.url}, but no ${odomTopic} arrives: is the robot running?`);
      } else {
        show('');
      }
      const foreign = connection.isConnected && othersDriving(state.drivers, nowMs);
      if (otherDriver && otherDriver.hidden === foreign) otherDriver.hidden = !foreign;
      const reset = connection.isConnected && resetByOther(state, nowMs);
      if (resetNotice && resetNotice.hidden === reset) resetNotice.hidden = !reset;
    },
  };
}

/** Runs `draw(nowMs)` functions in the page's one requestAnimationFrame loop. */
export function runFrameLoop(...draws) {
  const frame = (nowMs) => {
    for (const draw of draws) {
      try {
        draw(nowMs);
      } catch (error) {
        console.error('websim: drawing failed:', error); // one bad frame must not stop the loop
      }
    }
    requestAnimationFrame(frame);
  };
  requestAnimationFrame(frame);
}
