// The class's status, asked of one root connection twice a second: one call,
// /websim/class_status, answers for every robot behind that root, so a class of 30 or 100 is
// as fresh as a class of one. (The dashboard used to ask each robot in turn, a round of about
// 2 s: a robot's last command aged past the 2 s "driving" window between two of its calls, so
// of 30 robots driven at 10 Hz only 19 to 29 counted as driving, and "driving ... (1.9 s ago)"
// lagged by up to the round.) Never two calls out at once: the next is asked STATUS_PERIOD_MS
// after the answer, and pollNow() (after a command) asks at once, or right after the call
// that is out. Timers are passed in: the schedule is testable in Node.

/** The class's status is asked for this long after the last answer (ms). */
export const STATUS_PERIOD_MS = 500;

export class StatusPoller {
  /**
   * @param {{poll: () => Promise<unknown>, periodMs?: number,
   *          timers?: {setTimeout: Function, clearTimeout: Function}}} options
   *   poll: asks once (its answer and its errors are the caller's)
   */
  constructor({ poll, periodMs = STATUS_PERIOD_MS, timers = globalThis }) {
    this.poll = poll;
    this.periodMs = periodMs;
    this.timers = timers;
    this.inFlight = false;
    this._again = false; // pollNow() while a call was out: ask again once it is answered
    this._round = 0; // start() and stop() end the rounds before them
    this._running = false;
    this._timer = null;
  }

  get running() {
    return this._running;
  }

  /** Asks now, then every period after each answer. */
  start() {
    this.stop();
    this._running = true;
    this._ask(this._round);
  }

  stop() {
    this.timers.clearTimeout(this._timer);
    this._timer = null;
    this._running = false;
    this.inFlight = false; // a call still out is the ended round's: its answer is not waited for
    this._again = false;
    this._round += 1;
  }

  /** Asks now (after a command changed a robot), or right after the call that is out. */
  pollNow() {
    if (!this._running) return;
    if (this.inFlight) {
      this._again = true;
      return;
    }
    this.timers.clearTimeout(this._timer);
    this._ask(this._round);
  }

  _ask(round) {
    this._timer = null;
    this.inFlight = true;
    Promise.resolve()
      .then(() => this.poll())
      .catch(() => {}) // the caller's poll reports its own errors
      .finally(() => {
        if (round !== this._round) return; // stopped, or started again, meanwhile
        this.inFlight = false;
        if (this._again) {
          this._again = false;
          this._ask(round);
        } else {
          this._timer = this.timers.setTimeout(() => this._ask(round), this.periodMs);
        }
      });
  }
}
