// A replay's player (websim replay): play, pause, seek and speed, through the replay's own
// service (config.json's `replay`: {name, type}), which answers every command with the
// player's status. The page asks for that status twice a second to move the seek bar; the
// controls act for every viewer of the replay at once. Pure helpers first (tested in Node),
// then the one class that touches the DOM.

/** How often the page asks the player's status (ms). */
export const STATUS_PERIOD_MS = 500;

/** The speeds the page offers (times as recorded). */
export const PLAYER_SPEEDS = Object.freeze([0.25, 0.5, 1, 2, 4, 8]);

const finite = (value) => (typeof value === 'number' && Number.isFinite(value) ? value : null);

/**
 * A status answer as the page reads it: {playing, positionS, durationS, speed, finished,
 * loop}; a field missing or of the wrong type reads null (false for the flags).
 */
export function parsePlayerStatus(values) {
  return {
    playing: values?.playing === true,
    positionS: finite(values?.position_s),
    durationS: finite(values?.duration_s),
    speed: finite(values?.speed),
    finished: values?.finished === true,
    loop: values?.loop === true,
  };
}

/** "1:05.3" for 65.3 s; "–" for nothing known. */
export function clockText(seconds) {
  if (seconds === null || seconds === undefined || !Number.isFinite(seconds)) return '–';
  const minutes = Math.floor(seconds / 60);
  const rest = seconds - 60 * minutes;
  return `${minutes}:${rest.toFixed(1).padStart(4, '0')}`;
}

/** What the play button says: Pause while playing, Play again at the end, else Play. */
export function playLabel(status) {
  if (status.playing) return 'Pause';
  return status.finished ? 'Play again' : 'Play';
}

/** The command the play button sends. */
export function playCommand(status) {
  return status.playing ? { command: 'pause' } : { command: 'play' };
}

export class Player {
  /**
   * @param {object} connection connection.js's Connection
   * @param {{name: string, type: string}} service the replay's service (config.json)
   * @param {{card: HTMLElement, toggle: HTMLButtonElement, seek: HTMLInputElement,
   *   time: HTMLElement, speed: HTMLSelectElement, message: HTMLElement}} elements
   * @param {{onSeek?: () => void}} [options] onSeek: the recording's time jumped (the page
   *   forgets its trail and plots)
   */
  constructor(connection, service, elements, { onSeek = () => {} } = {}) {
    this.connection = connection;
    this.service = service;
    this.el = elements;
    this.onSeek = onSeek;
    this.status = parsePlayerStatus(null);
    this.dragging = false; // the seek bar is held: the status does not move it meanwhile
    for (const speed of PLAYER_SPEEDS) {
      const option = document.createElement('option');
      option.value = String(speed);
      option.textContent = `${speed}×`;
      elements.speed.append(option);
    }
    elements.card.hidden = false;
    elements.toggle.addEventListener('click', () => this.send(playCommand(this.status)));
    elements.seek.addEventListener('input', () => {
      this.dragging = true;
      this._showTime(Number(elements.seek.value));
    });
    elements.seek.addEventListener('change', () => {
      this.dragging = false;
      this.send({ command: 'seek', position_s: Number(elements.seek.value) })
        .then(() => this.onSeek());
    });
    elements.speed.addEventListener('change', () => {
      this.send({ command: 'speed', speed: Number(elements.speed.value) });
    });
    connection.addEventListener('connected', () => this.refresh());
    this._timer = setInterval(() => {
      if (connection.isConnected) this.refresh();
    }, STATUS_PERIOD_MS);
  }

  /** Asks for the status (no command). */
  refresh() {
    return this.send({ command: 'status' });
  }

  /** Sends a command; shows the status it answers, or why it was refused. */
  async send(request) {
    try {
      const reply = await this.connection.callService(this.service.name, this.service.type,
        request);
      this.el.message.textContent = '';
      this.show(parsePlayerStatus(reply));
    } catch (error) {
      this.el.message.textContent = error.message;
    }
  }

  /** Brings the controls up to date with a status. */
  show(status) {
    this.status = status;
    const { toggle, seek, speed } = this.el;
    toggle.textContent = playLabel(status);
    toggle.setAttribute('aria-pressed', String(status.playing));
    if (status.durationS !== null) seek.max = String(status.durationS);
    if (!this.dragging && status.positionS !== null) {
      seek.value = String(status.positionS);
      this._showTime(status.positionS);
    }
    if (status.speed !== null && speed.value !== String(status.speed)) {
      if (![...speed.options].some((option) => option.value === String(status.speed))) {
        const option = document.createElement('option'); // a --speed the list lacks
        option.value = String(status.speed);
        option.textContent = `${status.speed}×`;
        speed.append(option);
      }
      speed.value = String(status.speed);
    }
  }

  _showTime(positionS) {
    this.el.time.textContent = `${clockText(positionS)} / ${clockText(this.status.durationS)}`;
  }
}
