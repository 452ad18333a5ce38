// The page restates nothing robot.json says: no JS file under web-interface/js holds one of the
// robot's topic or service names, their message types, or the node's name in a string, nor
// one of the robot's own numbers (robot.json's `robot` section) as a number literal. Modules
// take them from the description (robot.js); comments may still name topics to explain.
import assert from 'node:assert/strict';
import { readdir, readFile } from 'node:fs/promises';
import { test } from 'node:test';

import { robot } from './robot.mjs';

const JS_DIR = new URL('../../web-interface/js/', import.meta.url);

/** After these (ignoring spaces), a `/` starts a regular expression, not a division. */
const BEFORE_REGEX = new Set(
  ['', '(', ',', '=', ':', '[', '!', '&', '|', '?', '{', '}', ';', '+', '-', '*', '%', '<', '>']);

/**
 * A JS source split into {code, strings}: `code` with comments, strings and regular
 * expressions blanked out, `strings` the text of each string literal and template chunk. A
 * small scanner, enough for these sources: template ${...} nests, regexes are told from
 * division by the character before them.
 */
export function splitSource(source) {
  let code = '';
  const strings = [];
  const templates = []; // brace depth inside each open template's ${...}
  let i = 0;
  const lastSignificant = () => code.trimEnd().slice(-1);
  const readQuoted = (close) => { // from just after the opening quote to its close
    let text = '';
    while (i < source.length && source[i] !== close) {
      if (source[i] === '\\') i += 1;
      text += source[i];
      i += 1;
    }
    i += 1;
    return text;
  };
  const readTemplateChunk = () => { // until ` (template ends) or ${ (an expression starts)
    let text = '';
    while (i < source.length && source[i] !== '`' && !source.startsWith('${', i)) {
      if (source[i] === '\\') i += 1;
      text += source[i];
      i += 1;
    }
    strings.push(text);
    if (source[i] === '`') {
      i += 1;
      code += 'S';
    } else {
      i += 2;
      templates.push(0);
      code += ' ';
    }
  };
  while (i < source.length) {
    const c = source[i];
    if (source.startsWith('//', i)) {
      i = source.indexOf('\n', i) === -1 ? source.length : source.indexOf('\n', i);
    } else if (source.startsWith('/*', i)) {
      i = source.indexOf('*/', i + 2) + 2;
      code += ' ';
    } else if (c === '\'' || c === '"') {
      i += 1;
      strings.push(readQuoted(c));
      code += 'S'; // an operand: a `/` after it divides
    } else if (c === '`') {
      i += 1;
      readTemplateChunk();
    } else if (c === '/' && BEFORE_REGEX.has(lastSignificant())) {
      i += 1;
      let inClass = false;
      while (i < source.length && (inClass || source[i] !== '/')) {
        if (source[i] === '\\') i += 1;
        else if (source[i] === '[') inClass = true;
        else if (source[i] === ']') inClass = false;
        i += 1;
      }
      i += 1;
      code += 'S';
    } else if (templates.length && c === '}' && templates.at(-1) === 0) {
      templates.pop(); // back in the template's text
      i += 1;
      readTemplateChunk();
    } else {
      if (templates.length && c === '{') templates[templates.length - 1] += 1;
      if (templates.length && c === '}') templates[templates.length - 1] -= 1;
      code += c;
      i += 1;
    }
  }
  return { code, strings };
}

/** The robot's names: node, topics and services, and their message and service types. */
function robotNames() {
  const entries = [...Object.values(robot.topics), ...Object.values(robot.services)];
  return [robot.node, ...entries.flatMap((entry) => [entry.name, entry.type])];
}

/**
 * The robot's own numbers (footprint, limits, wheels...). Values with one significant digit
 * (max_linear_mps is 0.5) are left out: halves and the like are everywhere in drawing code
 * and would say nothing about the robot.
 */
function robotNumbers() {
  return Object.values(robot.robot)
    .filter((value) => typeof value === 'number')
    .map(String)
    .filter((text) => text.replace(/^[0.]+|\./g, '').length >= 2);
}

async function sources() {
  const files = (await readdir(JS_DIR)).filter((name) => name.endsWith('.js')).sort();
  assert.ok(files.length > 5, `no scripts in ${JS_DIR}`);
  return Promise.all(
    files.map(async (name) => [name, await readFile(new URL(name, JS_DIR), 'utf8')]));
}

const escape = (text) => text.replace(/[.*+?^${}()|[\]\\/]/g, '\\$&');

test('the scanner tells strings, templates, regexes and comments apart', () => {
  const { code, strings } = splitSource([
    "const a = '/odom'; // not '/scan'",
    'const b = `at ${x ? `${y}/tf` : "/world"} done`; /* 0.11 */ const c = 0.25 / 2;',
    "const d = s.replace(/['\"]+/g, '');",
  ].join('\n'));
  assert.deepEqual(strings, ['/odom', 'at ', '', '/tf', '/world', ' done', '']);
  assert.match(code, /0\.25 \/ 2/);
  assert.doesNotMatch(code, /0\.11|scan|odom/);
});

test('robot.json\'s names and types appear in no string of web-interface/js', async () => {
  const names = robotNames();
  assert.ok(names.includes('/odom') && names.includes('/cmd_vel') && names.includes(robot.node));
  const found = [];
  for (const [file, source] of await sources()) {
    for (const text of splitSource(source).strings) {
      for (const name of names) {
        // The name on its own: '/tf' is not part of '/tf_static'.
        if (new RegExp(`(^|[^\\w/])${escape(name)}(?![\\w/])`).test(text)) {
          found.push(`${file}: ${JSON.stringify(text)} names ${name}`);
        }
      }
    }
  }
  assert.deepEqual(found, [], 'take these from the robot description (robot.js) instead');
});

test('robot.json\'s numbers appear as no number literal in web-interface/js', async () => {
  const numbers = robotNumbers();
  assert.ok(numbers.includes(String(robot.robot.footprint_radius_m)));
  assert.ok(numbers.includes(String(robot.robot.max_angular_rps)));
  const found = [];
  for (const [file, source] of await sources()) {
    const { code } = splitSource(source);
    for (const number of numbers) {
      if (new RegExp(`(?<![\\w.])${escape(number)}(?![\\w.])`).test(code)) {
        found.push(`${file}: ${number}`);
      }
    }
  }
  assert.deepEqual(found, [], 'take these from the robot description (robot.js) instead');
});
