// The dashboard's grid: one card per robot (its thumbnail, readouts, badges and buttons), made
// from the page's <template> and brought up to date by the one animation loop: a card's text
// is written only when it changed, and its canvas redrawn only when its robot moved and it is
// on screen. Buttons report to one listener: onAction(robotName, action).

import { modeChoices, PAYLOAD_FACTORS, payloadFactor } from './class-commands.js';
import {
  displayPose, driverLine, fixed, isHeld, speedMps, statusStale,
} from './class-state.js';
import { RobotThumb } from './class-view.js';

const RAD_TO_DEG = 180 / Math.PI;
const HEAVY = PAYLOAD_FACTORS.at(-1); // the payload toggle is pressed at the heavier payload

/** "dynamic" as a button says it: "Dynamic". */
export function capitalized(text) {
  return text.charAt(0).toUpperCase() + text.slice(1);
}

/** A robot's page on this server: robotsPath (config.json's, "/robots/") + NAME + "/". */
export function robotPageUrl(robotsPath, name) {
  return `${robotsPath}${encodeURIComponent(name)}/`;
}

/** Robot names in the order people read them: robot2 before robot10, case aside. */
export function byName(a, b) {
  return a.localeCompare(b, undefined, { numeric: true, sensitivity: 'base' });
}

/**
 * The clients line of a status: the students' clients, the instructor's (this dashboard is
 * one) left out: "2", or "2 (owner)" when the robot's own page or code (its token) is among
 * them, "3 (owner ×2)" with two.
 */
export function clientsText(status) {
  if (!status || status.students === null) return '–';
  const { students, owners } = status;
  if (!owners) return `${students}`;
  return owners === 1 ? `${students} (owner)` : `${students} (owner ×${owners})`;
}

/** The payload badge: ×1, ×2 (robot.json's mass and inertia times that), else the mass. */
export function payloadText(status, robot) {
  const factor = payloadFactor(status, robot);
  if (factor === undefined) return 'payload –';
  return factor === null ? `payload ${fixed(status.massKg, 2)} kg` : `payload ×${factor}`;
}

/** The card's pause badge: paused (by the instructor), idle (nobody connected), or none. */
export function pauseBadge(status) {
  if (status?.held) return 'paused';
  return status?.paused ? 'idle' : '';
}

export class ClassGrid {
  /**
   * @param {HTMLElement} container where the cards go
   * @param {HTMLTemplateElement} template one card
   * @param {object} robot the robot description (robot.js)
   * @param {{onAction: (name: string, action: string) => void}} options
   */
  constructor(container, template, robot, { robotsPath, onAction }) {
    this.robotsPath = robotsPath;
    this.container = container;
    this.template = template;
    this.robot = robot;
    this.cards = new Map(); // robot name -> card
    this._cardOf = new WeakMap(); // its canvas or element -> card, for the observers
    this.dpr = window.devicePixelRatio || 1;
    const [kinematic, dynamic] = modeChoices(robot);
    this.pressedMode = dynamic; // the mode toggle is pressed in the second model (dynamic)
    this.releasedMode = kinematic;
    this._resizes = new ResizeObserver((entries) => {
      for (const entry of entries) {
        const card = this._cardOf.get(entry.target);
        card.thumb.setSize(entry.contentRect.width, entry.contentRect.height, this.dpr);
      }
    });
    this._visibility = new IntersectionObserver((entries) => {
      for (const entry of entries) {
        this._cardOf.get(entry.target).visible = entry.isIntersecting;
      }
    });
    container.addEventListener('click', (event) => {
      const button = event.target.closest('button[data-action]');
      const element = button?.closest('[data-robot]');
      if (button && element && !button.disabled) {
        onAction(element.dataset.robot, button.dataset.action);
      }
    });
  }

  /** Adds a card for each state (class-state.js) not shown yet, in order. */
  add(states) {
    for (const state of states) {
      if (this.cards.has(state.name)) continue;
      const element = this.template.content.firstElementChild.cloneNode(true);
      element.dataset.robot = state.name;
      const field = (name) => element.querySelector(`[data-field="${name}"]`);
      const action = (name) => element.querySelector(`[data-action="${name}"]`);
      field('name').textContent = state.name;
      const link = field('open');
      link.href = robotPageUrl(this.robotsPath, state.name);
      link.title = `Open ${state.name}'s page in a new tab`;
      action('mode').textContent = capitalized(this.pressedMode);
      action('mode').title = `Motion model: pressed is ${this.pressedMode}, released `
        + `${this.releasedMode}`;
      action('payload').textContent = `Payload ×${HEAVY}`;
      action('payload').title = `Mass and inertia ×${HEAVY} (pressed) or as robot.json says`;
      const canvas = element.querySelector('canvas');
      canvas.setAttribute('aria-label', `${state.name}: walls, robot and scan`);
      const card = {
        state, element, visible: true, shown: new Map(),
        thumb: new RobotThumb(canvas, this.robot),
        fields: Object.fromEntries(['speed', 'pose', 'clients', 'collisions', 'driver', 'error',
          'held', 'mode', 'payload', 'recording'].map((name) => [name, field(name)])),
        buttons: Object.fromEntries(['reset', 'pause', 'mode', 'payload']
          .map((name) => [name, action(name)])),
      };
      this._cardOf.set(canvas, card);
      this._cardOf.set(element, card);
      // By name, whichever worker's root named the robot first (behind nginx: several).
      const next = [...this.cards.values()].find((other) => byName(state.name,
        other.state.name) < 0);
      this.cards.set(state.name, card);
      this.container.insertBefore(element, next ? next.element : null);
      this._resizes.observe(canvas);
      this._visibility.observe(element);
    }
  }

  /** Brings every card up to date; called once per animation frame. */
  update(nowMs) {
    const dpr = window.devicePixelRatio || 1;
    if (dpr !== this.dpr) { // zoomed, or moved to another screen: re-measure every canvas
      this.dpr = dpr;
      for (const card of this.cards.values()) {
        const { canvas } = card.thumb;
        card.thumb.setSize(canvas.clientWidth, canvas.clientHeight, dpr);
      }
    }
    for (const card of this.cards.values()) {
      this._updateText(card, nowMs);
      if (card.visible) card.thumb.draw(card.state);
    }
  }

  _updateText(card, nowMs) {
    const { state, fields, buttons } = card;
    const { status } = state;
    const set = (key, element, apply, value) => { // writes only what changed
      if (card.shown.get(key) === value) return;
      card.shown.set(key, value);
      apply(element, value);
    };
    const text = (name, value) => set(name, fields[name], (el, v) => {
      el.textContent = v;
    }, value);
    const attr = (key, element, name, value) => set(key, element, (el, v) => {
      if (v === null) el.removeAttribute(name);
      else el.setAttribute(name, v);
    }, value);

    const speed = speedMps(state);
    text('speed', speed === null ? '–' : fixed(speed, 2));
    const { pose } = displayPose(state);
    text('pose', pose
      ? `${fixed(pose.x, 2)}, ${fixed(pose.y, 2)}, ${fixed(pose.theta * RAD_TO_DEG, 0)}°` : '–');
    text('clients', clientsText(status));
    text('collisions', status?.collisions === null || !status ? '–' : String(status.collisions));
    const driver = driverLine(state, nowMs);
    text('driver', driver.text);
    attr('driver-kind', fields.driver, 'data-kind', driver.kind);
    text('mode', status?.mode ?? 'mode –');
    text('payload', payloadText(status, this.robot));
    const badge = pauseBadge(status);
    text('held', badge);
    attr('held-hidden', fields.held, 'hidden', badge ? null : '');
    const error = state.commandError || state.statusError;
    text('error', error);
    attr('error-hidden', fields.error, 'hidden', error ? null : '');
    const recording = status?.recording ?? '';
    text('recording', recording);
    attr('recording-hidden', fields.recording, 'hidden', recording ? null : '');
    attr('stale', card.element, 'data-stale', statusStale(state, nowMs) ? '' : null);
    attr('held-card', card.element, 'data-held', isHeld(state) ? '' : null);

    const held = isHeld(state);
    attr('pause-pressed', buttons.pause, 'aria-pressed', String(Boolean(held)));
    attr('pause-title', buttons.pause, 'title',
      held ? 'Paused: press to let it run' : 'Hold the robot');
    attr('mode-pressed', buttons.mode, 'aria-pressed', String(status?.mode === this.pressedMode));
    attr('payload-pressed', buttons.payload, 'aria-pressed',
      String(payloadFactor(status, this.robot) === HEAVY));
    for (const [name, button] of Object.entries(buttons)) {
      attr(`${name}-busy`, button, 'disabled', state.busy.has(name) ? '' : null);
    }
  }
}
