// A button whose action takes a second click: the first one asks (the button says what will
// happen), the second within a few seconds acts; otherwise the button goes back as it was.

/** How long the button waits for the second click (ms). */
export const CONFIRM_WINDOW_MS = 4000;

export class Confirmation {
  /**
   * @param {{textContent: string, dataset: object}} button the button (its text is the prompt
   *   while armed)
   * @param {() => string} prompt what the armed button says ("Reset all 30 robots? Click again")
   * @param {{windowMs?: number, setTimer?: Function, clearTimer?: Function}} options
   */
  constructor(button, prompt, {
    windowMs = CONFIRM_WINDOW_MS,
    setTimer = (fn, ms) => setTimeout(fn, ms), // called unbound: the window's own would throw
    clearTimer = (id) => clearTimeout(id),
  } = {}) {
    this.button = button;
    this.prompt = prompt;
    this.windowMs = windowMs;
    this._setTimer = setTimer;
    this._clearTimer = clearTimer;
    this._label = button.textContent;
    this._timer = null;
  }

  /** Whether this click is the confirming one; the first click arms the button instead. */
  confirmed() {
    if (this._timer !== null) {
      this.disarm();
      return true;
    }
    this.button.textContent = this.prompt();
    this.button.dataset.armed = 'true';
    this._timer = this._setTimer(() => this.disarm(), this.windowMs);
    return false;
  }

  /** Back to the button's own label, nothing pending. */
  disarm() {
    if (this._timer !== null) this._clearTimer(this._timer);
    this._timer = null;
    this.button.textContent = this._label;
    delete this.button.dataset.armed;
  }
}
