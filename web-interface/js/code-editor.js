// The Code panel's editor: CodeMirror 6 (npm, served from node_modules through the page's
// import map, websim/import_map.py), Python or JavaScript, with line numbers, bracket matching,
// indentation, undo, search (Ctrl/Cmd+F), and a program's errors shown at their lines.
//
// Keyboard: Tab indents inside the editor; Escape then Tab moves the focus out (CodeMirror's
// rule, so a keyboard user is never trapped). Touch: CodeMirror's own text input.

import { basicSetup, EditorView } from 'codemirror';
import { Compartment, EditorState, Prec } from '@codemirror/state';
import { keymap } from '@codemirror/view';
import { indentWithTab } from '@codemirror/commands';
import { ensureSyntaxTree, indentUnit } from '@codemirror/language';
import { linter, lintGutter, setDiagnostics } from '@codemirror/lint';
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

/** Syntax errors as the student types, at their lines (the parser's, before any run). */
const syntaxCheck = linter((view) => syntaxErrors(view.state).slice(0, 20).map((p) => ({
  from: p.from, to: p.to, severity: 'error', message: 'syntax error',
})), { delay: 600 });

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
        syntaxCheck,
        theme,
        EditorView.contentAttributes.of({ 'aria-label': label, spellcheck: 'false', autocapitalize: 'off', autocorrect: 'off' }),
        EditorView.updateListener.of((update) => {
          if (update.docChanged && onChange) onChange(update.state.doc.toString());
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
      const { doc } = view.state;
      const diagnostics = problems.filter((p) => p.line >= 1 && p.line <= doc.lines).map((p) => {
        const line = doc.line(p.line);
        return { from: line.from, to: line.to, severity: p.severity || 'error', message: p.message };
      });
      view.dispatch(setDiagnostics(view.state, diagnostics));
    },
    /** The first syntax error's line, or null. */
    firstSyntaxError() {
      const [first] = syntaxErrors(view.state, 1000);
      return first ? first.line : null;
    },
    focus: () => view.focus(),
  };
}
