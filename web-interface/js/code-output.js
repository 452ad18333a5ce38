// The program's output pane: print / console.log, errors, notes. Bounded: the newest
// MAX_LINES lines are kept (a program that prints forever costs the page a fixed amount), and
// the pane says how many earlier ones it dropped. Drawn at most once a frame.

/** Lines the pane keeps. */
export const MAX_LINES = 1000;

export class OutputPane {
  constructor(element, { maxLines = MAX_LINES, schedule = (fn) => requestAnimationFrame(fn) } = {}) {
    this.element = element;
    this.maxLines = maxLines;
    this.schedule = schedule;
    this.lines = []; // [kind, text]: stdout, stderr, note
    this.dropped = 0; // lines the pane let go of (the oldest)
    this.skipped = 0; // lines the program printed faster than the page took them
    this.pending = false;
  }

  /** Add lines ([[kind, text]]); `dropped`: lines the program printed that never got here. */
  add(lines, dropped = 0) {
    this.skipped += dropped;
    for (const line of lines) this.lines.push(line);
    if (this.lines.length > this.maxLines) {
      this.dropped += this.lines.length - this.maxLines;
      this.lines.splice(0, this.lines.length - this.maxLines);
    }
    this._draw();
  }

  note(text) {
    this.add([['note', text]]);
  }

  clear() {
    this.lines = [];
    this.dropped = 0;
    this.skipped = 0;
    this._draw();
  }

  /** All of the pane's text, as a test or a copy reads it. */
  text() {
    return this.lines.map(([, text]) => text).join('\n');
  }

  _draw() {
    if (this.pending) return;
    this.pending = true;
    this.schedule(() => {
      this.pending = false;
      const stick = this.element.scrollTop + this.element.clientHeight
        >= this.element.scrollHeight - 4;
      const fragment = document.createDocumentFragment();
      const missing = [];
      if (this.dropped) missing.push(`${this.dropped} earlier lines not shown`);
      if (this.skipped) missing.push(`${this.skipped} lines printed too fast to show`);
      if (missing.length) {
        const head = document.createElement('span');
        head.className = 'note';
        head.textContent = `… ${missing.join('; ')}\n`;
        fragment.append(head);
      }
      for (const [kind, text] of this.lines) {
        const span = document.createElement('span');
        span.className = kind;
        span.textContent = `${text}\n`;
        fragment.append(span);
      }
      this.element.replaceChildren(fragment);
      if (stick) this.element.scrollTop = this.element.scrollHeight;
    });
  }
}
