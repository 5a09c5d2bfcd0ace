// Charts (#/charts): the plots the evaluation tools wrote to the server's charts folder
// (console.charts_dir; "recog eval ... --plot FILE.png" writes FILE.json beside the PNG), each
// redrawn from that JSON as a line chart with the same title, axes, ranges, series and colours,
// the point labels (e.g. each point's alpha) in the tooltip.

import { api } from './api.js';
import { el, errorBox } from './dom.js';
import { formatDate } from './format.js';
import { lineChart } from './linechart.js';

// for a series without a colour of its own
const COLOURS = ['#1450c8', '#dc2828', '#28a028', '#8e24aa', '#fb8c00'];

export async function render(section, _param, signal) {
  section.append(el('h2', {}, 'Charts'));
  let data;
  try {
    data = await api('/api/charts', { signal });
  } catch (err) {
    if (err.name === 'AbortError') throw err;
    section.append(errorBox(err, 'Cannot list the charts'));
    return;
  }
  const entries = data.charts || [];
  const errors = data.errors || [];
  const plotCommand = el('code', {}, 'recog eval ... --plot');
  if (!data.configured) {
    section.append(el('p', { id: 'charts-none', class: 'muted' },
      'No charts folder: start recogd with ', el('code', {}, 'console.charts_dir'), ' (or ',
      el('code', {}, '--console-charts-dir DIR'), ') pointing at the folder where ', plotCommand,
      ' writes its plots.'));
  } else if (!entries.length) {
    section.append(el('p', { id: 'charts-none', class: 'muted' },
      'No chart there yet: run ', plotCommand, ' with the plot in the charts folder (it writes NAME.png',
      ' and, beside it, NAME.json), then reload this page.'));
  }
  if (errors.length) {
    section.append(el('p', { class: 'muted' }, `Not shown: ${errors.length} file${errors.length === 1 ? '' : 's'} that cannot be read.`),
      el('ul', { id: 'charts-errors' }, errors.map((e) =>
        el('li', { 'data-file': e.file }, el('code', {}, e.file), `: ${e.message}`))));
  }
  if (!entries.length) return;

  // Every chart's place first, then the charts one by one.
  const boxes = entries.map((entry) => {
    const canvas = el('canvas', { class: 'chart-canvas' });
    const box = el('section', { class: 'chart', 'data-name': entry.name },
      el('h3', {}, (entry.chart && entry.chart.title) || entry.name),
      el('p', { class: 'muted chart-file' },
        el('code', {}, entry.file), ` · ${formatDate(entry.modified_unix_ms)}`),
      el('div', { class: 'chart-box tall' }, canvas));
    return { entry, box, canvas };
  });
  section.append(el('div', { class: 'charts' }, boxes.map((b) => b.box)));
  const drawn = [];
  const stop = () => { for (const chart of drawn.splice(0)) chart.destroy(); };
  signal.addEventListener('abort', stop);
  for (const { entry, box, canvas } of boxes) {
    try {
      const chart = await drawChart(canvas, entry.chart || {});
      drawn.push(chart);
      box.dataset.series = String(chart.data.datasets.length);
    } catch (err) {
      if (!signal.aborted) box.append(errorBox(err, `Cannot draw ${entry.file}`));
    }
    if (signal.aborted) { stop(); return; }  // left while drawing: the abort came too early for these
  }
}

// Draws `chart` (the JSON beside a plot) into `canvas`; resolves to the Chart.
function drawChart(canvas, chart) {
  // Points [x, y] with their labels; a point that is not two numbers (null for NaN) is left out.
  const series = (chart.series || []).map((s, i) => {
    const labels = s.point_labels || [];
    const data = [];
    (s.points || []).forEach((p, k) => {
      const x = p && p[0] !== null ? Number(p[0]) : NaN;
      const y = p && p[1] !== null ? Number(p[1]) : NaN;
      if (Number.isFinite(x) && Number.isFinite(y)) data.push({ x, y, label: labels[k] || '' });
    });
    return { label: s.label || `series ${i + 1}`, colour: s.color || COLOURS[i % COLOURS.length], data };
  });
  return lineChart(canvas, {
    type: 'scatter',
    series,
    xTitle: chart.x_label || 'x',
    yTitle: chart.y_label || 'y',
    x: range(chart.x_min, chart.x_max),
    y: range(chart.y_min, chart.y_max),
    dataset: { showLine: true, pointRadius: 2.5, pointHoverRadius: 5, clip: 6 },  // whole points on the edges
    tooltip: {
      callbacks: {
        label: (item) => `${item.dataset.label}: (${short(item.parsed.x)}, ${short(item.parsed.y)})`,
        afterLabel: (item) => (item.raw && item.raw.label ? `label: ${item.raw.label}` : ''),
      },
    },
  });
}

// A fixed axis range, or none (Chart.js fits the data) when the JSON's is not a range.
function range(min, max) {
  const lo = Number(min);
  const hi = Number(max);
  return min !== null && max !== null && Number.isFinite(lo) && Number.isFinite(hi) && hi > lo ? { min: lo, max: hi } : {};
}

// 4 significant digits: 0.8181818 → "0.8182", 12 → "12".
function short(v) {
  return String(Number(Number(v).toPrecision(4)));
}
