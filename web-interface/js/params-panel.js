// The admin page's parameter form, built from the robot description's parameter table (the
// runtime entries of robot.json's parameters[]): each field gets its parameter's type, unit,
// range and choices, so the browser refuses an out-of-range value before anything is sent.
// It reads the robot's values with get_parameters and sends the changed ones with
// set_parameters (params.js); reset calls the robot's reset service. A field the robot would
// refuse (out of range, empty) is not sent, and the notice says so; the valid changes of the
// same form are sent all the same.

import { ServiceCallError } from './connection.js';
import { getParameters, setParameters } from './params.js';
import { runtimeParameters } from './robot.js';

/**
 * A form field for `spec` (a parameters[] entry), with `types` robot.json's parameter_types:
 * {name, row (the element to insert), input, read() -> value, write(value), problem() -> why
 * the value cannot be sent, or null}. A choice list becomes a select, a number an
 * <input type=number> with min and max, a boolean a checkbox.
 */
export function parameterField(document, spec, types) {
  const row = document.createElement('div');
  row.className = 'field';
  const label = document.createElement('label');
  label.textContent = spec.unit ? `${spec.name} (${spec.unit})` : spec.name;
  const numeric = spec.type === types.DOUBLE || spec.type === types.INTEGER;
  let input;
  if (spec.choices?.length) {
    input = document.createElement('select');
    for (const choice of spec.choices) input.append(new Option(String(choice), String(choice)));
    row.classList.add('wide');
  } else {
    input = document.createElement('input');
    if (numeric) {
      input.type = 'number';
      input.inputMode = spec.type === types.INTEGER ? 'numeric' : 'decimal';
      input.step = spec.type === types.INTEGER ? '1' : 'any';
      input.required = true;
      if (spec.minimum !== null && spec.minimum !== undefined) input.min = String(spec.minimum);
      if (spec.maximum !== null && spec.maximum !== undefined) input.max = String(spec.maximum);
    } else if (spec.type === types.BOOL) {
      input.type = 'checkbox';
    } else {
      input.type = 'text';
      input.spellcheck = false;
      row.classList.add('wide');
    }
  }
  input.id = `param-${spec.name}`;
  input.dataset.param = spec.name;
  label.htmlFor = input.id;
  const hint = document.createElement('small');
  hint.className = 'field-hint';
  hint.textContent = [spec.description, rangeText(spec)].filter(Boolean).join(' · ');
  row.append(label, input, hint);
  const isBool = input.type === 'checkbox';
  const unit = spec.unit ? ` ${spec.unit}` : '';
  return {
    name: spec.name,
    row,
    input,
    numeric,
    problem: () => {
      const { validity } = input;
      if (validity.valid) return null;
      if (validity.badInput) return `${spec.name}: "${input.value}" is not a number`;
      if (validity.valueMissing) return `${spec.name} is empty`;
      if (validity.rangeOverflow) {
        return `${spec.name} = ${input.value} is above its maximum, ${spec.maximum}${unit}`;
      }
      if (validity.rangeUnderflow) {
        return `${spec.name} = ${input.value} is below its minimum, ${spec.minimum}${unit}`;
      }
      if (validity.stepMismatch) return `${spec.name} = ${input.value} is not a whole number`;
      return `${spec.name}: ${input.validationMessage}`;
    },
    read: () => {
      if (isBool) return input.checked;
      return numeric ? Number(input.value) : input.value;
    },
    write: (value) => {
      if (isBool) {
        input.checked = Boolean(value);
        return;
      }
      const text = value === undefined ? '' : String(value);
      if (input.tagName === 'SELECT' && text && ![...input.options].some((o) => o.value === text)) {
        input.append(new Option(text, text)); // the robot knows a choice the table does not
      }
      input.value = text;
    },
  };
}

function rangeText(spec) {
  const unit = spec.unit ? ` ${spec.unit}` : '';
  const low = spec.minimum ?? null;
  const high = spec.maximum ?? null;
  if (low !== null && high !== null) return `${low} to ${high}${unit}`;
  if (low !== null) return `at least ${low}${unit}`;
  if (high !== null) return `at most ${high}${unit}`;
  return '';
}

/**
 * The parameter form: fields for the robot's runtime parameters, inserted into
 * elements.fields. Events: 'refused' when the bridge refuses a set_parameters call.
 * @param {{form: HTMLFormElement, fields: HTMLElement, notice: HTMLElement,
 *          reload: HTMLButtonElement, reset: HTMLButtonElement}} elements
 */
export class ParametersPanel extends EventTarget {
  constructor(connection, robot, elements) {
    super();
    this.connection = connection;
    this.robot = robot;
    this.form = elements.form;
    this.notice = elements.notice;
    const document = elements.form.ownerDocument;
    this.fields = runtimeParameters(robot)
      .map((spec) => parameterField(document, spec, robot.parameter_types));
    elements.fields.replaceChildren(...this.fields.map((field) => field.row));
    this.loaded = {}; // the values last read from the robot
    // The form checks its fields itself (apply): an invalid one must not hold back the rest.
    this.form.noValidate = true;
    this.form.addEventListener('submit', (event) => {
      event.preventDefault();
      this.apply();
    });
    elements.reload.addEventListener('click', () => this.load());
    elements.reset.addEventListener('click', () => this.reset());
    connection.addEventListener('connected', () => this.load());
  }

  /** Reads the robot's values into the fields, except those in `keep` (refused values). */
  async load(keep = new Set()) {
    try {
      const values = await getParameters(this.connection, this.robot,
        this.fields.map((field) => field.name));
      this.loaded = values;
      for (const field of this.fields) {
        const value = values[field.name];
        field.input.disabled = value === undefined; // a robot without that parameter
        if (keep.has(field)) continue; // the user's refused value stays, to be corrected
        field.write(value);
        field.input.removeAttribute('aria-invalid');
      }
      this.form.dataset.loaded = 'true';
    } catch (error) {
      this.say('error', `Could not read the parameters: ${error.message}`);
    }
  }

  /**
   * Sends the valid fields that differ from the robot's values, then shows what the robot
   * said and which fields were not sent, and why (out of range, empty, not a number).
   */
  async apply() {
    const changes = {};
    const invalid = [];
    for (const field of this.fields) {
      if (field.input.disabled) continue;
      const problem = field.problem() ?? (field.numeric && !Number.isFinite(field.read())
        ? `${field.name}: "${field.input.value}" is not a number` : null);
      field.input.setAttribute('aria-invalid', String(problem !== null));
      if (problem !== null) {
        invalid.push({ field, problem });
        continue;
      }
      const value = field.read();
      if (value !== this.loaded[field.name]) changes[field.name] = value;
    }
    const notSent = invalid.length
      ? `Not sent: ${invalid.map(({ problem }) => problem).join('; ')}.` : '';
    if (invalid.length) invalid[0].field.input.focus();
    if (!Object.keys(changes).length) {
      if (notSent) this.say('error', `Nothing sent. ${notSent}`);
      else this.say('info', 'Nothing to apply: every field shows the robot\'s current value.');
      return;
    }
    this.say('info', 'Applying…'); // the last result must not stand for this one
    let kind = 'ok';
    let said;
    try {
      const results = await setParameters(this.connection, this.robot, changes);
      const refused = results.filter((r) => !r.successful);
      const applied = Object.entries(changes)
        .filter(([n]) => !refused.some((r) => r.name === n)).map(([n, v]) => `${n} = ${v}`);
      said = [applied.length ? `Applied: ${applied.join(', ')}.` : '',
        refused.map((r) => `${r.name} refused: ${r.reason}`).join('; ')].filter(Boolean);
      if (refused.length) kind = applied.length ? 'warn' : 'error';
    } catch (error) {
      kind = 'error';
      if (error instanceof ServiceCallError) {
        said = [`Refused: ${error.message}`];
        this.dispatchEvent(new Event('refused'));
      } else {
        said = [`Not applied: ${error.message}`];
      }
    }
    if (notSent && kind === 'ok') kind = 'warn';
    this.say(kind, [...said, notSent].filter(Boolean).join(' '));
    await this.load(new Set(invalid.map(({ field }) => field)));
  }

  async reset() {
    const { name, type } = this.robot.services.reset;
    try {
      await this.connection.callService(name, type, {});
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
