// The Code panel: write a controller, run it in this browser against this robot, save it,
// download it, submit it for grading. The editor is code-editor.js, the run code-runner.js,
// the output code-output.js, the keeping and the server's routes code-store.js. What the
// assignments are (their WEBSIM_* values, topics, starters) and what the server offers comes
// from the server (`code/starters.json`, websim/code_starters.py), never retyped here.

import { createEditor } from './code-editor.js';
import { OutputPane } from './code-output.js';
import { ProgramRunner } from './code-runner.js';
import {
  CodeServer, loadLocal, localKey, saveLocal, utf8Bytes,
} from './code-store.js';
import { copyText } from './your-robot.js';

/** The program's state, in words, as the badges say it. */
export const STATE_TEXT = {
  idle: 'not running',
  loading: 'loading Python…',
  running: 'running, not connected',
  connected: 'running, connected',
  stopping: 'stopping…',
  stopped: 'stopped',
  exited: 'ended',
  crashed: 'crashed',
  failed: 'could not start',
};

const EXTENSIONS = { python: 'py', javascript: 'js' };
const LOCAL_SAVE_DELAY_MS = 500;
const SERVER_SAVE_DELAY_MS = 3000;
const POLL_MS = 1500;
const CRASH_KEY_PREFIX = 'websim.codeRunning:';

export class CodePanel {
  constructor(elements, {
    robotLink, pageToken, robot, stopRobot, onRun, storage, location,
  }) {
    this.el = elements;
    this.robotLink = robotLink;
    this.pageToken = pageToken;
    this.robot = robot;
    this.onRun = onRun;
    this.storage = storage;
    this.location = location;
    this.server = new CodeServer('code/', pageToken());
    this.info = null; // code/starters.json
    this.language = 'python';
    this.editor = null;
    this.output = new OutputPane(elements.output);
    this.runner = new ProgramRunner({ robot: robotLink, stopRobot });
    this.localTimer = null;
    this.serverTimer = null;
    this.pollTimer = null;
    this.filename = 'controller.py';
    this.tracebackLine = null;
  }

  async open() {
    const { el } = this;
    el.panel.hidden = false;
    el.nav.hidden = false;
    this.runner.addEventListener('state', (event) => this._showState(event.detail));
    this.runner.addEventListener('output', (event) => this._onOutput(event.detail));
    this.runner.addEventListener('note', (event) => this.output.note(event.detail.text));
    this.runner.addEventListener('ended', (event) => this._onEnded(event.detail));
    this.runner.preload();
    try {
      this.info = await this.server.starters();
    } catch (error) {
      this.output.note(`The server's assignments could not be loaded: ${error.message}`);
    }
    this._fillAssignments();
    this.language = this.storage.getItem(this._key('language')) || 'python';
    el.language.value = this.language;
    const text = await this._restore(this.language);
    this.editor = createEditor(el.editor, {
      text,
      language: this.language,
      label: 'Program',
      onChange: () => this._changed(),
      onRun: () => this.run(),
    });
    this._bind();
    this._updateFilename();
    this._showState({ state: 'idle' });
    this._reportLastCrash();
    this._showSubmit();
    if (this.info && this.info.submitting && this.info.submitting.enabled) this._poll(true);
  }

  _key(what) {
    return `websim.code.${what}:${new URL(this.location.href).pathname}`;
  }

  _bind() {
    const { el } = this;
    el.language.addEventListener('change', () => this._switchLanguage(el.language.value));
    el.assignment.addEventListener('change', () => {
      this.storage.setItem(this._key('assignment'), el.assignment.value);
      this._fillScenarios();
      this._updateFilename();
      this._showSubmit();
    });
    el.load.addEventListener('change', () => this._load(el.load.value));
    el.run.addEventListener('click', () => this.run());
    el.stop.addEventListener('click', () => this.runner.stop());
    el.restart.addEventListener('click', () => this.run());
    el.download.addEventListener('click', () => this.download());
    el.submit.addEventListener('click', () => this.submit());
    el.clear.addEventListener('click', () => this.output.clear());
  }

  // --- assignments, starters, examples -------------------------------------------------------

  _assignments() {
    return (this.info && this.info.assignments) || [];
  }

  _assignment() {
    return this._assignments().find((a) => a.name === this.el.assignment.value) || null;
  }

  _fillAssignments() {
    const { el } = this;
    const options = this._assignments().map((a) => new Option(`${a.name}: ${a.description}`, a.name));
    el.assignment.replaceChildren(...options);
    el.assignment.disabled = options.length === 0;
    const kept = this.storage.getItem(this._key('assignment'));
    if (kept && this._assignments().some((a) => a.name === kept)) el.assignment.value = kept;
    this._fillScenarios();
    const groups = [];
    if (this._assignments().length) {
      const starters = document.createElement('optgroup');
      starters.label = 'Starters (replace the editor\u2019s text)';
      for (const a of this._assignments()) starters.append(new Option(`${a.name} starter`, `starter:${a.name}`));
      groups.push(starters);
    }
    const examples = (this.info && this.info.examples) || [];
    if (examples.length) {
      const group = document.createElement('optgroup');
      group.label = 'Examples';
      for (const example of examples) group.append(new Option(example.title, `example:${example.name}`));
      groups.push(group);
    }
    el.load.replaceChildren(new Option('Load a starter or an example…', ''), ...groups);
    el.load.disabled = groups.length === 0;
  }

  _fillScenarios() {
    const assignment = this._assignment();
    const scenarios = assignment ? assignment.scenarios : [];
    this.el.scenario.replaceChildren(...scenarios.map((s) => new Option(s.name, s.name)));
    this.el.scenarioLabel.hidden = scenarios.length < 2;
  }

  _scenario() {
    const assignment = this._assignment();
    if (!assignment) return null;
    return assignment.scenarios.find((s) => s.name === this.el.scenario.value)
      || assignment.scenarios[0];
  }

  _load(choice) {
    this.el.load.value = '';
    if (!choice) return;
    const [kind, name] = choice.split(/:(.*)/s);
    let text = null;
    if (kind === 'starter') {
      const assignment = this._assignments().find((a) => a.name === name);
      text = assignment && assignment.starters[this.language];
      if (assignment) {
        this.el.assignment.value = name;
        this._fillScenarios();
      }
    } else {
      const example = this.info.examples.find((e) => e.name === name);
      if (example && example.language !== this.language) {
        this.language = example.language;
        this.el.language.value = this.language;
        this.editor.setLanguage(this.language);
        this.storage.setItem(this._key('language'), this.language);
      }
      text = example && example.text;
    }
    if (typeof text !== 'string') return;
    this.editor.setText(text);
    this._updateFilename();
    this.output.note(`Loaded ${kind === 'starter' ? `the ${name} starter` : name}. `
      + 'Ctrl+Z (Cmd+Z) brings back what was there.');
  }

  _updateFilename() {
    const assignment = this._assignment();
    const stem = assignment ? assignment.name : 'controller';
    this.filename = `${stem}.${EXTENSIONS[this.language]}`;
    this.el.filename.textContent = this.filename;
  }

  // --- keeping the program -------------------------------------------------------------------

  async _restore(language) {
    const local = loadLocal(this.storage, localKey(this.location, language));
    let text = local ? local.text : null;
    let savedAt = local ? local.savedAt : 0;
    if (this._savesOnServer()) {
      try {
        const { versions } = await this.server.saved();
        const newest = versions.find((v) => v.language === language);
        if (newest && newest.saved_at * 1000 > savedAt) {
          text = newest.text;
          savedAt = newest.saved_at * 1000;
        }
      } catch (error) {
        this.output.note(`Your saved program could not be read from the server: ${error.message}`);
      }
    }
    if (text === null) {
      const assignment = this._assignment();
      text = assignment ? assignment.starters[language] : '';
    }
    if (savedAt) this._saved(`Saved ${new Date(savedAt).toLocaleTimeString()}`);
    return text;
  }

  _savesOnServer() {
    return Boolean(this.info && this.info.saving && this.pageToken());
  }

  _changed() {
    clearTimeout(this.localTimer);
    this.localTimer = setTimeout(() => this._saveLocal(), LOCAL_SAVE_DELAY_MS);
    if (this._savesOnServer()) {
      clearTimeout(this.serverTimer);
      this.serverTimer = setTimeout(() => this._saveServer('autosave'), SERVER_SAVE_DELAY_MS);
    }
  }

  _saveLocal() {
    clearTimeout(this.localTimer);
    try {
      saveLocal(this.storage, localKey(this.location, this.language), this.editor.text());
      if (!this._savesOnServer()) this._saved(`Saved in this browser ${new Date().toLocaleTimeString()}`);
    } catch (error) {
      this._saved(`Not saved in this browser: ${error.message}`, true);
    }
  }

  async _saveServer(reason) {
    clearTimeout(this.serverTimer);
    if (!this._savesOnServer()) return true;
    const text = this.editor.text();
    const limit = this.info.limits.code_bytes;
    if (utf8Bytes(text) > limit) {
      this._saved(`Not saved on the server: the program is larger than ${limit} bytes`, true);
      return false;
    }
    this.server.token = this.pageToken();
    try {
      const answer = await this.server.save(this.language, text, reason);
      this._saved(`Saved on the server ${new Date(answer.saved_at * 1000).toLocaleTimeString()}`
        + ` (version ${answer.version})`);
      return true;
    } catch (error) {
      this._saved(`Not saved on the server: ${error.message}`, true);
      return false;
    }
  }

  _saved(text, problem = false) {
    this.el.saveStatus.textContent = text;
    this.el.saveStatus.dataset.problem = String(problem);
  }

  async _switchLanguage(language) {
    this._saveLocal();
    await this._saveServer('autosave');
    if (this.runner.running) this.runner.stop();
    this.language = language;
    this.storage.setItem(this._key('language'), language);
    const text = await this._restore(language);
    this.editor.setLanguage(language);
    this.editor.setText(text);
    this.editor.showProblems([]);
    this._updateFilename();
    this._showSubmit();
  }

  // --- running -------------------------------------------------------------------------------

  async run() {
    if (!this.editor) return;
    this._saveLocal();
    this._saveServer('run');
    this.editor.showProblems([]);
    this.tracebackLine = null;
    const link = this.robotLink();
    const scenario = this._scenario();
    const env = { WEBSIM_URL: link.shownUrl, ...(scenario ? scenario.env : {}) };
    this.output.note(`Run ${this.filename} against ${link.shownUrl}`
      + (scenario ? ` with the values of ${scenario.name}` : ''));
    this.storage.setItem(CRASH_KEY_PREFIX + this.location.pathname, this.language);
    if (this.onRun) this.onRun();
    await this.runner.run({
      language: this.language, source: this.editor.text(), filename: this.filename, env,
    });
  }

  _onOutput({ lines, dropped }) {
    this.output.add(lines, dropped);
    for (const [stream, text] of lines) { // a callback's exception: its line, as a warning
      if (stream !== 'stderr') continue;
      const frame = text.match(/^\s*File "([^"]+)", line (\d+)/);
      if (frame && frame[1] === this.filename) this.tracebackLine = Number(frame[2]);
      else if (this.tracebackLine && /^[A-Za-z_][\w.]*(Error|Exception|Exit|Interrupt)\b/.test(text)) {
        this.editor.showProblems([{ line: this.tracebackLine, message: text, severity: 'warning' }]);
        this.tracebackLine = null;
      }
    }
  }

  _onEnded(result) {
    this.storage.removeItem(CRASH_KEY_PREFIX + this.location.pathname);
    if (result.status === 'crashed') {
      if (result.text) this.output.add(result.text.split('\n').map((t) => ['stderr', t]));
      const lines = (result.text || '').trim().split('\n');
      const last = this.language === 'python' ? lines.pop() : lines[0];
      if (!result.line && /SyntaxError/.test(result.text || '')) { // the browser did not say where
        result.line = this.editor.firstSyntaxError();
      }
      if (result.line) this.editor.showProblems([{ line: result.line, message: last }]);
      this.output.note(`Crashed${result.line ? ` at line ${result.line}` : ''}; the robot was sent a stop.`);
    } else if (result.status === 'failed') {
      this.output.add([['stderr', result.text]]);
    } else if (result.status === 'stopped') {
      this.output.note('Stopped; the robot was sent a stop.');
    } else {
      this.output.note(`Ended (exit status ${result.code}) after ${result.seconds.toFixed(1)} s; the robot was sent a stop.`);
    }
    if (result.dropped) {
      this.output.note(`${result.dropped} messages arrived faster than the program read them and were dropped.`);
    }
  }

  /** A page that ended while a program ran (a JavaScript program that filled the memory). */
  _reportLastCrash() {
    const key = CRASH_KEY_PREFIX + this.location.pathname;
    const language = this.storage.getItem(key);
    if (!language) return;
    this.storage.removeItem(key);
    this.output.note(`The page was closed or ended while your ${language === 'python' ? 'Python' : 'JavaScript'} `
      + 'program ran. If the browser ended it (a program that allocates memory forever), '
      + 'your program is still here: look for what grows without bound.');
  }

  _showState({ state, detail }) {
    let text = STATE_TEXT[state] || state;
    if (state === 'exited' && detail) text = `ended (exit status ${detail.code})`;
    if (state === 'crashed' && detail && detail.line) text = `crashed at line ${detail.line}`;
    for (const badge of [this.el.state, this.el.navState]) {
      badge.textContent = text;
      badge.dataset.state = state;
    }
    const active = ['loading', 'running', 'connected', 'stopping'].includes(state);
    this.el.stop.disabled = !active;
    this.el.restart.disabled = !active;
    this.el.run.disabled = active;
  }

  // --- download ------------------------------------------------------------------------------

  download() {
    const text = this.editor.text();
    const blob = new Blob([text], { type: this.language === 'python' ? 'text/x-python' : 'text/javascript' });
    const link = document.createElement('a');
    link.href = URL.createObjectURL(blob);
    link.download = this.filename;
    document.body.append(link);
    link.click();
    link.remove();
    setTimeout(() => URL.revokeObjectURL(link.href), 10000);
    const robot = this.robotLink();
    const scenario = this._scenario();
    const env = Object.entries(scenario ? scenario.env : {}).map(([k, v]) => `${k}=${v}`).join(' ');
    const tool = this.language === 'python' ? `python3 ${this.filename}` : `node ${this.filename}`;
    const install = this.language === 'python' ? 'pip install roslibpy' : 'npm install roslib@1.4.1';
    const token = this.pageToken();
    const url = token ? `${robot.shownUrl}?token=${token}` : robot.shownUrl;
    const command = `WEBSIM_URL='${url}' ${env} ${tool}`.replace(/\s+/g, ' ');
    const shown = command.replace(/token=[^&'\s]+/, 'token=…');
    this.el.laptop.hidden = false;
    this.el.laptopText.textContent = `On a laptop: ${install}, then ${shown} `
      + '(on the real robot only the URL differs).';
    this.el.laptopCopy.onclick = () => {
      copyText(command).then(() => { this.el.laptopCopy.textContent = 'Copied'; })
        .catch(() => { this.el.laptopCopy.textContent = 'Copy failed'; });
    };
  }

  // --- submitting ----------------------------------------------------------------------------

  _submitState() {
    const submitting = this.info && this.info.submitting;
    if (!submitting) return { enabled: false, reason: 'this server does not grade submissions' };
    if (!submitting.enabled) return submitting;
    const language = submitting.languages && submitting.languages[this.language];
    if (language && !language.enabled) return language;
    if (this.info.saving && !this.pageToken()) {
      return { enabled: false, reason: 'this page has no token for this robot (the link from your instructor has it)' };
    }
    return { enabled: true, reason: '' };
  }

  _showSubmit() {
    const { enabled, reason } = this._submitState();
    this.el.submit.disabled = !enabled;
    this.el.submit.title = enabled ? `Grade this program with websim grade ${this.el.assignment.value}` : reason;
    if (!enabled) this.el.grade.dataset.state = 'off';
    this.el.submitNote.textContent = enabled ? '' : `Submit is off: ${reason}.`;
  }

  async submit() {
    const assignment = this._assignment();
    if (!assignment) return;
    this._saveLocal();
    const text = this.editor.text();
    if (utf8Bytes(text) > this.info.limits.code_bytes) {
      this._gradeMessage(`Not submitted: the program is larger than ${this.info.limits.code_bytes} bytes.`);
      return;
    }
    this.el.submit.disabled = true;
    this.server.token = this.pageToken();
    try {
      const answer = await this.server.submit(this.language, text, assignment.name);
      this._showSubmission(answer);
      this._poll();
    } catch (error) {
      this._gradeMessage(`Not submitted: ${error.message}`);
    } finally {
      this._showSubmit();
    }
  }

  _poll(once = false) {
    clearTimeout(this.pollTimer);
    this.server.submission().then((answer) => {
      this._showSubmission(answer);
      if (!once || ['queued', 'running'].includes(answer.state)) {
        if (['queued', 'running'].includes(answer.state)) {
          this.pollTimer = setTimeout(() => this._poll(), POLL_MS);
        }
      }
    }).catch(() => {});
  }

  _gradeMessage(text) {
    this.el.grade.dataset.state = 'message';
    const p = document.createElement('p');
    p.textContent = text;
    this.el.grade.replaceChildren(p);
  }

  _showSubmission(answer) {
    const { grade } = this.el;
    grade.dataset.state = answer.state || 'none';
    if (!answer.state || answer.state === 'none') {
      grade.replaceChildren();
      return;
    }
    const head = document.createElement('p');
    head.className = 'grade-head';
    const what = `${answer.assignment} (${answer.language}, submitted ${new Date(answer.submitted_at * 1000).toLocaleTimeString()})`;
    if (answer.state === 'queued') {
      head.textContent = `Submitted ${what}: waiting, number ${answer.position} in the queue.`;
      grade.replaceChildren(head);
      return;
    }
    if (answer.state === 'running') {
      head.textContent = `Grading ${what}…`;
      grade.replaceChildren(head);
      return;
    }
    if (answer.state === 'failed') {
      head.textContent = `Not graded: ${answer.reason}`;
      grade.replaceChildren(head);
      return;
    }
    const result = answer.result;
    head.textContent = `${what}: total ${result.total.toFixed(3)}`;
    const table = document.createElement('table');
    table.className = 'grade-table';
    table.innerHTML = '<thead><tr><th>scenario</th><th>score</th><th>result</th><th></th></tr></thead>';
    const body = document.createElement('tbody');
    for (const row of result.scenarios) {
      const tr = document.createElement('tr');
      for (const text of [row.name, row.score.toFixed(4), row.passed ? 'passed' : row.reason]) {
        const td = document.createElement('td');
        td.textContent = text;
        tr.append(td);
      }
      const td = document.createElement('td');
      if (row.has_report) {
        const button = document.createElement('button');
        button.type = 'button';
        button.textContent = 'Report';
        button.addEventListener('click', () => this._showReport(row.name));
        td.append(button);
      }
      tr.append(td);
      tr.dataset.passed = String(row.passed);
      body.append(tr);
    }
    table.append(body);
    const frame = document.createElement('div');
    frame.className = 'grade-report';
    grade.replaceChildren(head, table, frame);
  }

  async _showReport(scenario) {
    const holder = this.el.grade.querySelector('.grade-report');
    try {
      const html = await this.server.report(scenario);
      const frame = document.createElement('iframe');
      frame.setAttribute('sandbox', ''); // no scripts, an origin of its own
      frame.title = `The report of ${scenario}`;
      frame.srcdoc = html;
      holder.replaceChildren(frame);
    } catch (error) {
      holder.textContent = `The report could not be loaded: ${error.message}`;
    }
  }
}
