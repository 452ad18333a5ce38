// The instructor's submissions page: every student's newest saved program and last submission
// (GET /class/submissions.json), their reports, and everyone's code as a .zip for
// `websim grade --submissions` (GET /class/code.zip). The instructor's token is the
// dashboard's (this tab's sessionStorage, or ?token=), sent in a header to this server only.

import { bindTokenCard, instructorToken } from './class-token.js';

const REFRESH_MS = 4000;
const $ = (selector) => document.querySelector(selector);

function time(seconds) {
  return seconds ? new Date(seconds * 1000).toLocaleTimeString() : '';
}

function cell(text, attributes = {}) {
  const td = document.createElement('td');
  td.textContent = text;
  for (const [name, value] of Object.entries(attributes)) td.setAttribute(name, value);
  return td;
}

class SubmissionsPage {
  constructor() {
    this.token = instructorToken(window.location, window.history, window.sessionStorage);
    this.students = [];
    this.timer = null;
    this.card = bindTokenCard({
      card: $('#token-card'), form: $('#token-form'), input: $('#token-input'),
      forget: $('#token-forget'),
    }, {
      storage: window.sessionStorage,
      onToken: (token) => { this.token = token; this.refresh(); },
    });
    $('#subs-export').addEventListener('click', () => this.exportZip());
  }

  async call(path) {
    const response = await fetch(path, {
      headers: { Authorization: `Bearer ${this.token}` }, cache: 'no-store',
    });
    if (response.status === 403 || response.status === 401) {
      this.card.ask(true);
      throw new Error('the instructor\'s token is needed');
    }
    if (!response.ok) {
      const answer = await response.json().catch(() => ({}));
      throw new Error(answer.reason || `HTTP ${response.status}`);
    }
    return response;
  }

  async refresh() {
    clearTimeout(this.timer);
    if (!this.token) {
      this.card.ask(true);
      return;
    }
    try {
      const overview = await (await this.call('class/submissions.json')).json();
      this.card.ask(false);
      $('#fatal').hidden = true;
      this.show(overview);
    } catch (error) {
      $('#fatal').textContent = `Submissions could not be loaded: ${error.message}`;
      $('#fatal').hidden = false;
    }
    this.timer = setTimeout(() => this.refresh(), REFRESH_MS);
  }

  show({ students, submitting }) {
    this.students = students;
    const submitted = students.filter((s) => s.submission && s.submission.state).length;
    $('#subs-summary').textContent = `${students.length} students, `
      + `${students.filter((s) => s.saved).length} saved, ${submitted} submitted`;
    $('#subs-grading').textContent = submitting.enabled ? ''
      : `Submit is off on this server: ${submitting.reason}.`;
    const rows = students.map((student) => {
      const tr = document.createElement('tr');
      tr.dataset.student = student.name;
      tr.append(cell(student.name));
      const { saved, submission } = student;
      tr.append(cell(saved ? `${saved.language}, ${time(saved.saved_at)}, v${saved.version}, `
        + `${saved.bytes} B` : '—'));
      if (submission && submission.state) {
        tr.append(cell(`${submission.assignment} (${submission.language}), `
          + `${time(submission.submitted_at)}: ${submission.state}`
          + (submission.state === 'queued' ? ` #${submission.position}` : '')));
        const result = submission.result;
        tr.append(cell(result ? result.total.toFixed(3) : ''));
        const failing = result ? result.scenarios.filter((r) => !r.passed) : [];
        tr.append(cell(result ? (failing.length ? `${failing[0].name}: ${failing[0].reason}`
          : 'passed') : submission.reason, { 'data-passed': String(Boolean(result) && !failing.length) }));
      } else {
        tr.append(cell('—'), cell(''), cell(''));
      }
      const actions = document.createElement('td');
      if (saved) actions.append(this.button('Code', () => this.showCode(student)));
      for (const row of (submission && submission.result && submission.result.scenarios) || []) {
        if (row.has_report) {
          actions.append(this.button(`Report ${row.name}`, () => this.showReport(student, row.name)));
        }
      }
      tr.append(actions);
      return tr;
    });
    $('#subs-table tbody').replaceChildren(...rows);
  }

  button(text, onClick) {
    const button = document.createElement('button');
    button.type = 'button';
    button.textContent = text;
    button.addEventListener('click', onClick);
    return button;
  }

  showCode(student) {
    $('#subs-detail').hidden = false;
    $('#subs-detail-title').textContent = `${student.name}: saved ${student.saved.language} `
      + `program, version ${student.saved.version}`;
    $('#subs-code').textContent = student.saved.text;
    $('#subs-report').replaceChildren();
  }

  async showReport(student, scenario) {
    $('#subs-detail').hidden = false;
    $('#subs-detail-title').textContent = `${student.name}: report of ${scenario}`;
    $('#subs-code').textContent = '';
    try {
      const html = await (await this.call(
        `robots/${encodeURIComponent(student.name)}/code/report/${encodeURIComponent(scenario)}`)).text();
      const frame = document.createElement('iframe');
      frame.setAttribute('sandbox', '');
      frame.title = `Report of ${scenario} for ${student.name}`;
      frame.srcdoc = html;
      $('#subs-report').replaceChildren(frame);
    } catch (error) {
      $('#subs-report').textContent = `The report could not be loaded: ${error.message}`;
    }
  }

  async exportZip() {
    try {
      const blob = await (await this.call('class/code.zip')).blob();
      const link = document.createElement('a');
      link.href = URL.createObjectURL(blob);
      link.download = 'websim-submissions.zip';
      document.body.append(link);
      link.click();
      link.remove();
      setTimeout(() => URL.revokeObjectURL(link.href), 10000);
    } catch (error) {
      $('#fatal').textContent = `The code could not be exported: ${error.message}`;
      $('#fatal').hidden = false;
    }
  }
}

new SubmissionsPage().refresh();
