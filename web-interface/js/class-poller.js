// Polls every robot's status about every STATUS_PERIOD_MS, staggered: one robot every
// period / N, round the class, so a class of 40 costs the bridge a call every 50 ms rather than
// 40 at once every 2 s. A robot whose last call has not been answered is skipped, so a slow
// robot never piles calls up. Timers are passed in: the schedule is testable in Node.

/** Each robot's status is asked for about this often (ms). */
export const STATUS_PERIOD_MS = 2000;
/** The shortest time between two status calls (ms), however large the class. */
export const MIN_POLL_GAP_MS = 20;

/** Time between two calls (ms) for a class of `count`. */
export function pollGapMs(count, periodMs = STATUS_PERIOD_MS) {
  return Math.max(MIN_POLL_GAP_MS, periodMs / Math.max(1, count));
}

export class StatusPoller {
  /**
   * @param {{names: () => string[], poll: (name: string) => Promise<unknown>,
   *          periodMs?: number, timers?: {setTimeout: Function, clearTimeout: Function}}} options
   *   names: the robots now; poll: asks one robot (its answer and errors are the caller's)
   */
  constructor({ names, poll, periodMs = STATUS_PERIOD_MS, timers = globalThis }) {
    this.names = names;
    this.poll = poll;
    this.periodMs = periodMs;
    this.timers = timers;
    this.inFlight = new Set();
    this._cursor = 0;
    this._timer = null;
  }

  get running() {
    return this._timer !== null;
  }

  /** Starts (or restarts) the round at the first robot. */
  start() {
    this.stop();
    this._cursor = 0;
    this._schedule(0);
  }

  stop() {
    if (this._timer !== null) this.timers.clearTimeout(this._timer);
    this._timer = null;
  }

  /** Asks robot `name` now (after a command changed it), unless a call is already out. */
  pollNow(name) {
    if (this.inFlight.has(name)) return;
    this.inFlight.add(name);
    Promise.resolve()
      .then(() => this.poll(name))
      .catch(() => {}) // the caller's poll reports its own errors
      .finally(() => this.inFlight.delete(name));
  }

  _schedule(delayMs) {
    this._timer = this.timers.setTimeout(() => this._tick(), delayMs);
  }

  _tick() {
    const names = this.names();
    if (names.length === 0) {
      this._schedule(this.periodMs);
      return;
    }
    const name = names[this._cursor % names.length];
    this._cursor = (this._cursor + 1) % names.length;
    this.pollNow(name);
    this._schedule(pollGapMs(names.length, this.periodMs));
  }
}
