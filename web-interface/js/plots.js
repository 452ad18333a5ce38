// Live plots of the last 20 s (uPlot): commanded vs measured v and ω, heading vs setpoint.
//
// The samples are state.history (one per /odom); the x axis is seconds before the latest stamp.
// Pause freezes them; while paused, drag across a chart to zoom into a time range (double
// click: the whole 20 s). CSV saves what is plotted.

import { uPlot } from './vendor.js';
import { HISTORY_S, historyCsv } from './state.js';

const REDRAW_MS = 100; // 10 Hz is smooth enough and leaves the frame budget to the view
// The command is drawn first, wide and light, so the measurement stays visible on top of it
// when the two agree (kinematic mode).
const COMMAND = { stroke: 'rgba(245, 158, 11, 0.75)', width: 5 };
const MEASURED = { stroke: '#2563eb', width: 1.75 };
const SETPOINT = { stroke: 'rgba(225, 29, 72, 0.6)', width: 4 };
const HEIGHT_PX = 150;
/** Live, the x axis is always the last HISTORY_S seconds. */
const LIVE_X_RANGE = () => [-HISTORY_S, 0];
const MIN_WIDTH_PX = 200;

/** The charts a page can show; `keys` choose which (a page shows a subset). */
const CHARTS = {
  linear: {
    title: 'Linear velocity v (m/s)',
    series: [['commanded', 'vCmd', COMMAND], ['measured', 'vMeas', MEASURED]],
    minSpan: 0.1,
  },
  angular: {
    title: 'Angular velocity ω (rad/s)',
    series: [['commanded', 'wCmd', COMMAND], ['measured', 'wMeas', MEASURED]],
    minSpan: 0.5,
  },
  heading: {
    title: 'Heading θ (°, unwrapped: it goes on past ±180°)',
    series: [['setpoint', 'setpointDeg', SETPOINT], ['odometry', 'headingDeg', MEASURED]],
    minSpan: 90,
    degrees: true,
  },
};

export class LivePlots {
  /**
   * @param {HTMLElement} container where the charts go (a <figure> each)
   * @param {object} state from state.js
   * @param {string[]} keys which charts: 'linear', 'angular', 'heading'
   */
  constructor(container, state, keys = ['linear', 'angular', 'heading']) {
    this.state = state;
    this.lastDrawMs = -Infinity;
    this.paused = false;
    container.append(this._tools());
    this.charts = keys.map((key) => {
      const spec = CHARTS[key];
      const figure = document.createElement('figure');
      figure.className = 'plot';
      const caption = document.createElement('figcaption');
      caption.textContent = spec.title;
      figure.append(caption);
      container.append(figure);
      const plot = new uPlot(chartOptions(spec, figure.clientWidth), emptyData(spec), figure);
      new ResizeObserver(() => {
        const width = Math.max(MIN_WIDTH_PX, Math.floor(figure.clientWidth));
        if (plot.width !== width) plot.setSize({ width, height: HEIGHT_PX });
      }).observe(figure);
      return { spec, plot };
    });
  }

  /** Redraws with the latest history (called by the page's animation loop), unless paused. */
  update(nowMs) {
    if (this.paused || nowMs - this.lastDrawMs < REDRAW_MS) return;
    this.lastDrawMs = nowMs;
    const h = this.state.history;
    const latest = h.t.length ? h.t[h.t.length - 1] : 0;
    const x = h.t.map((t) => t - latest);
    for (const { spec, plot } of this.charts) {
      plot.setData([x, ...spec.series.map(([, key]) => h[key])]);
    }
  }

  /** Pause/Resume and CSV buttons above the charts. */
  _tools() {
    const bar = document.createElement('div');
    bar.className = 'plot-tools';
    const pause = document.createElement('button');
    pause.type = 'button';
    pause.textContent = 'Pause';
    pause.setAttribute('aria-pressed', 'false');
    pause.addEventListener('click', () => {
      this.paused = !this.paused;
      pause.textContent = this.paused ? 'Resume' : 'Pause';
      pause.setAttribute('aria-pressed', String(this.paused));
      for (const { plot } of this.charts) { // paused, a drag picks the time range shown
        plot.scales.x.range = this.paused ? (u, min, max) => [min, max] : LIVE_X_RANGE;
      }
      if (!this.paused) this.lastDrawMs = -Infinity; // back to live, the whole 20 s
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
    bar.append(pause, csv);
    return bar;
  }
}

function chartOptions(spec, width) {
  const yRange = (u, min, max) => {
    const lo = Math.min(min ?? 0, 0);
    const hi = Math.max(max ?? 0, 0);
    const pad = Math.max((hi - lo) * 0.1, spec.minSpan / 2);
    return [lo - pad, hi + pad];
  };
  return {
    width: Math.max(MIN_WIDTH_PX, Math.floor(width)),
    height: HEIGHT_PX,
    pxAlign: 0,
    cursor: { show: true, x: false, y: false, points: { show: false },
      drag: { x: true, y: false, setScale: true } }, // zoom by dragging (paused)
    legend: { live: false },
    scales: {
      x: { time: false, range: LIVE_X_RANGE },
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
      ...spec.series.map(([label, , style]) => ({ label, ...style, points: { show: false } })),
    ],
  };
}

function emptyData(spec) {
  return [[], ...spec.series.map(() => [])];
}
