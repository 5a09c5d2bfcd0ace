// Live (#/live): the server's last five minutes, one sample a second — throughput, latency
// percentiles, queue depth and errors — as four line charts refreshed every 2 seconds while the
// page is open.

import { api } from './api.js';
import { el, errorBox } from './dom.js';
import { formatTime, num } from './format.js';
import { lineChart } from './linechart.js';

const REFRESH_MS = 2000;

// canvas id → title, y axis, and the series (sample field, label, colour)
const CHARTS = [
  ['chart-throughput', 'Throughput', 'per second',
    [['calls_per_s', 'calls/s', '#1e63e9'], ['frames_per_s', 'frames/s', '#43a047']]],
  ['chart-latency', 'Latency', 'ms',
    [['latency_p50_ms', 'p50', '#43a047'], ['latency_p90_ms', 'p90', '#fb8c00'], ['latency_p99_ms', 'p99', '#e53935']]],
  ['chart-queue', 'Queue depth', 'calls waiting',
    [['queue_depth', 'queue depth', '#8e24aa']]],
  ['chart-errors', 'Errors', 'per second',
    [['errors_per_s', 'errors/s', '#e53935']]],
];

export async function render(section, _param, signal) {
  section.append(el('h2', {}, 'Live'));
  const status = el('p', { id: 'live-status', class: 'muted' }, 'waiting for the first samples…');
  const problem = el('div', { class: 'live-problem' });
  const grid = el('div', { class: 'charts' });
  section.append(status, problem, grid);

  const charts = await Promise.all(CHARTS.map(async ([id, title, unit, series]) => {
    const canvas = el('canvas', { id });
    grid.append(el('div', { class: 'chart' }, el('h3', {}, title), el('div', { class: 'chart-box' }, canvas)));
    return {
      series,
      chart: await lineChart(canvas, {
        series: series.map(([, label, colour]) => ({ label, colour, data: [] })),
        xTitle: 'seconds ago',
        yTitle: unit,
        x: { reverse: true, min: 0 },
        y: { beginAtZero: true },
        dataset: { pointRadius: 0 },
        interaction: { mode: 'index', intersect: false },
      }),
    };
  }));

  let timer = null;
  const stop = () => {
    clearTimeout(timer);
    for (const c of charts) c.chart.destroy();
  };
  if (signal.aborted) { stop(); return; }  // left while Chart.js was loading
  signal.addEventListener('abort', stop);

  const refresh = async () => {
    try {
      const data = await api('/api/live', { signal });
      if (signal.aborted) return;
      const samples = data.samples || [];
      const last = samples.length ? num(samples[samples.length - 1].unix_ms) : 0;
      for (const { series, chart } of charts) {
        series.forEach(([field], i) => {
          chart.data.datasets[i].data = samples.map((s) => ({ x: (last - num(s.unix_ms)) / 1000, y: num(s[field]) }));
        });
        chart.update('none');
      }
      status.textContent = samples.length
        ? `${samples.length} sample${samples.length === 1 ? '' : 's'}, last at ${formatTime(last)}`
        : '0 samples yet: the server records one a second.';
      status.dataset.samples = String(samples.length);
      problem.replaceChildren();
    } catch (err) {
      if (err.name === 'AbortError' || signal.aborted) return;
      problem.replaceChildren(errorBox(err, 'Cannot read the live samples'));
      if (err.status === 401 || err.status === 403) return;  // saving a token reloads the page
    }
    if (!signal.aborted) timer = setTimeout(refresh, REFRESH_MS);
  };
  await refresh();
}
