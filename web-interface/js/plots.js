// Live plots (uPlot): v and ω commanded, measured by odometry and true (the simulation's
// ground truth: in dynamic mode the wheels slip, so odometry follows the command at once and
// only the true speed shows the ramp), and the heading vs its setpoint.
//
// The samples are state.history (one per /odom). Two time windows: the last 20 s, the x axis
// in seconds before the latest stamp; or the last step, the x axis in seconds after the last
// step of the command (of the setpoint, for the heading), a window short enough to read a
// ramp of a tenth of a second, and still while nothing changes. Pause freezes them; while
// paused, drag across a chart to zoom into a time range (double click: the whole window). CSV
// saves what is plotted. Each chart fills its figure, whose size the stylesheet sets.

import { uPlot } from './vendor.js';
import { HISTORY_S, historyCsv, lastStepS } from './state.js';

const REDRAW_MS = 100; // 10 Hz is smooth enough and leaves the frame budget to the view
// The command is drawn first, wide and light, so the measurement stays visible on top of it
// when the two agree (kinematic mode).
const COMMAND = { stroke: 'rgba(245, 158, 11, 0.75)', width: 5, stepped: true };
const MEASURED = { stroke: '#2563eb', width: 1.75 };
const TRUE = { stroke: 'rgba(22, 163, 74, 0.85)', width: 3 }; // under odometry, which it hides
const SETPOINT = { stroke: 'rgba(225, 29, 72, 0.6)', width: 4 };
const MIN_WIDTH_PX = 200;
const MIN_HEIGHT_PX = 120;
/** Seconds before the step the step window shows, and after it (per chart: CHARTS). */
const VELOCITY_STEP = { beforeS: 0.2, afterS: 0.8 };

/** The time windows: the live 20 s, or the last step of the command. */
export const WINDOWS = Object.freeze({
  live: { label: `Last ${HISTORY_S} s`, title: `The last ${HISTORY_S} s, live` },
  step: {
    label: 'Last step',
    title: 'From just before the last step of the command: 0 s is the step (a change after '
      + 'a steady command), so a ramp of a tenth of a second is wide enough to read',
  },
});

/** The charts a page can show; `keys` choose which (a page shows a subset). */
const CHARTS = {
  linear: {
    title: 'Linear velocity v (m/s)',
    series: [['commanded', 'vCmd', COMMAND], ['true (ground truth)', 'vTrue', TRUE],
      ['odometry', 'vMeas', MEASURED]],
    minSpan: 0.1,
    step: { key: 'vCmd', minChange: 0.01, what: 'the last step of v commanded', ...VELOCITY_STEP },
  },
  angular: {
    title: 'Angular velocity ω (rad/s)',
    series: [['commanded', 'wCmd', COMMAND], ['true (ground truth)', 'wTrue', TRUE],
      ['odometry', 'wMeas', MEASURED]],
    minSpan: 0.5,
    step: { key: 'wCmd', minChange: 0.02, what: 'the last step of ω commanded', ...VELOCITY_STEP },
  },
  heading: {
    title: 'Heading θ (°, unwrapped: it goes on past ±180°)',
    series: [['setpoint', 'setpointDeg', SETPOINT], ['odometry', 'headingDeg', MEASURED]],
    minSpan: 90,
    degrees: true,
    step: { key: 'setpointDeg', minChange: 1, what: 'the last setpoint change (a Start)',
      beforeS: 1, afterS: 7 },
  },
};

export class LivePlots {
  /**
   * @param {HTMLElement} container where the charts go (a <figure> each)
   * @param {object} state from state.js
   * @param {string[]} keys which charts: 'linear', 'angular', 'heading'
   * @param {{tools?: HTMLElement}} [options] tools: where the window, Pause and CSV buttons go
   *   (the card's heading, say); by default a row of their own above the charts
   */
  constructor(container, state, keys = ['linear', 'angular', 'heading'], { tools = null } = {}) {
    this.state = state;
    this.lastDrawMs = -Infinity;
    this.paused = false;
    this.window = 'live';
    const bar = this._tools();
    if (tools) tools.append(bar); else container.append(bar);
    this.charts = keys.map((key) => {
      const spec = CHARTS[key];
      const figure = document.createElement('figure');
      figure.className = 'plot';
      const caption = document.createElement('figcaption');
      caption.textContent = spec.title;
      const area = document.createElement('div'); // sized by the stylesheet; the chart fills it
      area.className = 'plot-area';
      figure.append(caption, area);
      container.append(figure);
      const chart = { spec, caption, range: [-HISTORY_S, 0] };
      chart.plot = new uPlot(chartOptions(spec, area.clientWidth, () => chart.range),
        emptyData(spec), area);
      const fit = () => {
        const legend = chart.plot.root.querySelector('.u-legend')?.offsetHeight ?? 0;
        const width = Math.max(MIN_WIDTH_PX, Math.floor(area.clientWidth));
        const height = Math.max(MIN_HEIGHT_PX, Math.floor(area.clientHeight - legend));
        if (chart.plot.width !== width || chart.plot.height !== height) {
          chart.plot.setSize({ width, height });
        }
      };
      new ResizeObserver(fit).observe(area);
      fit();
      return chart;
    });
  }

  /** Redraws with the latest history (called by the page's animation loop), unless paused. */
  update(nowMs) {
    if (this.paused || nowMs - this.lastDrawMs < REDRAW_MS) return;
    this.lastDrawMs = nowMs;
    const h = this.state.history;
    const latest = h.t.length ? h.t[h.t.length - 1] : 0;
    for (const chart of this.charts) {
      const { spec, plot } = chart;
      let origin = latest;
      chart.range = [-HISTORY_S, 0];
      let caption = spec.title;
      if (this.window === 'step') {
        const { key, minChange, beforeS, afterS, what } = spec.step;
        const stepS = lastStepS(h, key, minChange);
        origin = stepS ?? latest;
        chart.range = stepS === null ? [-(beforeS + afterS), 0] : [-beforeS, afterS];
        caption += stepS === null ? ' · no step yet: the last seconds' : ` · 0 s: ${what}`;
      }
      if (chart.caption.textContent !== caption) chart.caption.textContent = caption;
      // Copies: the history grows on while uPlot holds the data (a resize redraws it).
      plot.setData([h.t.map((t) => t - origin), ...spec.series.map(([, k]) => h[k].slice())]);
    }
  }

  /** The time window buttons, Pause/Resume and CSV. */
  _tools() {
    const bar = document.createElement('div');
    bar.className = 'plot-tools';
    const windows = document.createElement('div');
    windows.className = 'plot-windows';
    windows.setAttribute('role', 'group');
    windows.setAttribute('aria-label', 'Time window');
    const windowButtons = Object.entries(WINDOWS).map(([name, { label, title }]) => {
      const button = document.createElement('button');
      button.type = 'button';
      button.textContent = label;
      button.title = title;
      button.dataset.window = name;
      button.setAttribute('aria-pressed', String(name === this.window));
      button.addEventListener('click', () => {
        this.window = name;
        for (const other of windowButtons) {
          other.setAttribute('aria-pressed', String(other === button));
        }
        this._setRanges();
        this.lastDrawMs = -Infinity; // redraw now (a paused chart too)
        const { paused } = this;
        this.paused = false;
        this.update(performance.now());
        this.paused = paused;
      });
      return button;
    });
    windows.append(...windowButtons);
    const pause = document.createElement('button');
    pause.type = 'button';
    pause.textContent = 'Pause';
    pause.setAttribute('aria-pressed', 'false');
    pause.addEventListener('click', () => {
      this.paused = !this.paused;
      pause.textContent = this.paused ? 'Resume' : 'Pause';
      pause.setAttribute('aria-pressed', String(this.paused));
      this._setRanges();
      if (!this.paused) this.lastDrawMs = -Infinity; // back to live, the whole window
    });
    const csv = document.createElement('button');
    csv.type = 'button';
    csv.textContent = 'CSV';
    csv.title = 'Save the plotted samples as a CSV file';
    csv.addEventListener('click', () => {
      const link = document.createElement('a');
      link.href = URL.createObjectURL(new Blob([historyCsv(this.state.history)],
        { type: 'text/csv' }));
      link.download = 'websim-plots.csv';
      link.click();
      setTimeout(() => URL.revokeObjectURL(link.href), 1000);
    });
    bar.append(windows, pause, csv);
    return bar;
  }

  /** Paused, a drag picks the time range shown; else each chart shows its window. */
  _setRanges() {
    for (const chart of this.charts) {
      chart.plot.scales.x.range = this.paused ? (u, min, max) => [min, max] : () => chart.range;
    }
  }
}

/** @param {() => number[]} xRange the chart's time window (s) while live */
function chartOptions(spec, width, xRange) {
  const yRange = (u, min, max) => {
    const lo = Math.min(min ?? 0, 0);
    const hi = Math.max(max ?? 0, 0);
    const pad = Math.max((hi - lo) * 0.1, spec.minSpan / 2);
    return [lo - pad, hi + pad];
  };
  return {
    width: Math.max(MIN_WIDTH_PX, Math.floor(width)),
    height: MIN_HEIGHT_PX, // then the figure's height (LivePlots: fit)
    pxAlign: 0,
    cursor: { show: true, x: false, y: false, points: { show: false },
      drag: { x: true, y: false, setScale: true } }, // zoom by dragging (paused)
    legend: { live: false },
    scales: {
      x: { time: false, range: xRange },
      y: { range: yRange },
    },
    axes: [
      { values: (u, ticks) => ticks.map((t) => `${t} s`), grid: { stroke: '#eef2f7' } },
      {
        size: 48,
        grid: { stroke: '#eef2f7' },
        ...(spec.degrees ? { incrs: [45, 90, 180, 360, 720] } : {}),
      },
    ],
    series: [
      {},
      ...spec.series.map(([label, , { stepped, ...style }]) => ({
        label, ...style, points: { show: false },
        // A command holds from its sample until the next: a step is drawn upright, at its time.
        ...(stepped ? { paths: uPlot.paths.stepped({ align: 1 }) } : {}),
      })),
    ],
  };
}

function emptyData(spec) {
  return [[], ...spec.series.map(() => [])];
}
