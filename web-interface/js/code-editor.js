// The Code panel's editor: CodeMirror 6 (npm, served from node_modules through the page's
// import map, websim/import_map.py), Python or JavaScript, with line numbers, bracket matching,
// indentation, undo, search (Ctrl/Cmd+F), and a program's errors shown at their lines.
//
// Keyboard: Tab indents inside the editor; Escape then Tab moves the focus out (CodeMirror's
// rule, so a keyboard user is never trapped). Touch: CodeMirror's own text input.

import { basicSetup, EditorView } from 'codemirror';
import {
  Compartment, EditorState, Prec, StateEffect,
} from '@codemirror/state';
import { keymap } from '@codemirror/view';
import { indentWithTab } from '@codemirror/commands';
import { ensureSyntaxTree, indentUnit } from '@codemirror/language';
import {
  forceLinting, forEachDiagnostic, linter, lintGutter,
} from '@codemirror/lint';
import { python } from '@codemirror/lang-python';
import { javascript } from '@codemirror/lang-javascript';

const LANGUAGES = {
  python: () => [python(), indentUnit.of('    ')],
  javascript: () => [javascript(), indentUnit.of('  ')],
};

/** How long the syntax check may parse (ms) before it gives up until the next edit. */
const PARSE_BUDGET_MS = 200;

/** The lines where the language's parser found a syntax error ([] while it cannot tell). */
export function syntaxErrors(state, budgetMs = PARSE_BUDGET_MS) {
  const tree = ensureSyntaxTree(state, state.doc.length, budgetMs);
  if (!tree) return [];
  const found = [];
  tree.iterate({
    enter(node) {
      if (!node.type.isError) return true;
      const line = state.doc.lineAt(node.from);
      if (!found.some((p) => p.line === line.number)) {
        found.push({ line: line.number, from: node.from, to: Math.max(node.to, Math.min(line.to, node.from + 1)) });
      }
      return false;
    },
  });
  return found;
}

/** Tells the checker that a run's problems changed (no edit did). */
const refreshProblems = StateEffect.define();

/** The diagnostics of a line's problem ({line, message, severity}) in `state`. */
function lineDiagnostic(state, problem) {
  const line = state.doc.line(problem.line);
  return { from: line.from, to: line.to, severity: problem.severity || 'error', message: problem.message };
}

const theme = EditorView.theme({
  '&': { fontSize: '14px', border: '1px solid #cbd5e1', borderRadius: '8px', background: '#fff' },
  '.cm-scroller': { fontFamily: 'ui-monospace, SFMono-Regular, Menlo, monospace', lineHeight: '1.45' },
  '&.cm-focused': { outline: '3px solid #f59e0b', outlineOffset: '2px' },
  '.cm-content': { minHeight: '18rem' },
});

/**
 * An editor in `parent`. Returns {view, text(), setText(text), setLanguage(name),
 * showProblems([{line, message, severity}]), focus()}; onChange(text) after each edit; onRun()
 * on Ctrl+Enter (Cmd+Enter).
 */
export function createEditor(parent, {
  text = '', language = 'python', label, onChange, onRun,
}) {
  const languageSlot = new Compartment();
  // What the last run found (its crash, a callback's exception): shown until the next edit,
  // with the syntax errors the parser finds as the student types.
  let runProblems = [];
  const check = linter((view) => {
    const { state } = view;
    // the first only: a parser's recovery often flags the lines after it too
    const syntax = syntaxErrors(state).slice(0, 1).map((p) => ({
      from: p.from, to: p.to, severity: 'error', message: 'syntax error',
    }));
    const run = runProblems.filter((p) => p.line >= 1 && p.line <= state.doc.lines)
      .map((p) => lineDiagnostic(state, p));
    return [...run, ...syntax.filter((d) => !run.some((r) => r.from <= d.from && d.from <= r.to))];
  }, {
    delay: 600,
    needsRefresh: (update) => update.transactions.some(
      (transaction) => transaction.effects.some((effect) => effect.is(refreshProblems))),
  });
  const view = new EditorView({
    parent,
    state: EditorState.create({
      doc: text,
      extensions: [
        basicSetup,
        Prec.highest(keymap.of([{ key: 'Mod-Enter', run: () => { if (onRun) onRun(); return true; } }])),
        keymap.of([indentWithTab]),
        languageSlot.of(LANGUAGES[language]()),
        lintGutter(),
        check,
        theme,
        EditorView.contentAttributes.of({ 'aria-label': label, spellcheck: 'false', autocapitalize: 'off', autocorrect: 'off' }),
        EditorView.updateListener.of((update) => {
          if (!update.docChanged) return;
          runProblems = [];
          if (onChange) onChange(update.state.doc.toString());
        }),
      ],
    }),
  });

  return {
    view,
    text: () => view.state.doc.toString(),
    setText(next) {
      view.dispatch({ changes: { from: 0, to: view.state.doc.length, insert: next } });
    },
    setLanguage(name) {
      view.dispatch({ effects: languageSlot.reconfigure(LANGUAGES[name]()) });
    },
    showProblems(problems) {
      runProblems = problems;
      view.dispatch({ effects: refreshProblems.of(null) });
      forceLinting(view); // now, not after the typing delay
    },
    /** The problems shown: [{line, severity, message}]. */
    problems() {
      const shown = [];
      forEachDiagnostic(view.state, (diagnostic, from) => {
        shown.push({
          line: view.state.doc.lineAt(from).number,
          severity: diagnostic.severity,
          message: diagnostic.message,
        });
      });
      return shown;
    },
    /** The first syntax error's line, or null. */
    firstSyntaxError() {
      const [first] = syntaxErrors(view.state, 1000);
      return first ? first.line : null;
    },
    focus: () => view.focus(),
  };
}
