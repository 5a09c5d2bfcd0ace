// Line charts with Chart.js (Debian's libjs-chart.js 3.9), for the Live and Charts pages. The
// library is loaded on the first chart: pages without charts never fetch it.

let chartClass = null;

// Chart.js's Chart with all its parts registered.
function loadChart() {
  if (!chartClass) {
    chartClass = import('chart.js').then(({ Chart, registerables }) => {
      Chart.register(...registerables);
      return Chart;
    }, (err) => {
      chartClass = null;  // try again on the next page
      throw err;
    });
  }
  return chartClass;
}

// A line chart in `canvas`, which fills its parent (a .chart-box): each of `series`
// ({label, colour, data: [{x, y}, ...]}) joined by straight lines, linear axes titled xTitle and
// yTitle (x, y: more options of each scale), a legend below when there are several series, no
// animation. type: 'line' or 'scatter' (lines too with dataset {showLine: true}); dataset: more
// options of every series; interaction, tooltip: Chart.js's options of those names.
export async function lineChart(canvas, {
  type = 'line', series, xTitle, yTitle, x = {}, y = {}, dataset = {}, interaction, tooltip = {},
}) {
  const Chart = await loadChart();
  const options = {
    animation: false,
    responsive: true,
    maintainAspectRatio: false,
    scales: {
      x: { type: 'linear', ...x, title: { display: true, text: xTitle } },
      y: { type: 'linear', ...y, title: { display: true, text: yTitle } },
    },
    plugins: { legend: { display: series.length > 1, position: 'bottom' }, tooltip },
  };
  if (interaction) options.interaction = interaction;
  return new Chart(canvas, {
    type,
    data: {
      datasets: series.map(({ label, colour, data }) => ({
        label, data, borderColor: colour, backgroundColor: colour, borderWidth: 1.5, tension: 0, ...dataset,
      })),
    },
    options,
  });
}
