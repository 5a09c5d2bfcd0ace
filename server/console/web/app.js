// The console's shell: the API helper (JSON calls, images and the gRPC gateway, all with the
// bearer token kept in localStorage), small DOM and formatting helpers the pages share, Chart.js
// line charts, the token field in the header, and the hash router that loads one page module per
// route.

const TOKEN_KEY = 'recog.token';

export function getToken() {
  return localStorage.getItem(TOKEN_KEY) || '';
}

// An error answered by the server ({"code","message"}) or met on the way (network, bad JSON).
export class ApiError extends Error {
  constructor(status, code, message) {
    super(message);
    this.status = status;
    this.code = code;
  }
}

async function request(path, { method = 'GET', body, signal } = {}) {
  const headers = {};
  const token = getToken();
  if (token) headers.Authorization = `Bearer ${token}`;
  if (body !== undefined) headers['Content-Type'] = 'application/json';
  let response;
  try {
    response = await fetch(path, {
      method, headers, signal, cache: 'no-store',
      body: body === undefined ? undefined : JSON.stringify(body),
    });
  } catch (err) {
    if (err.name === 'AbortError') throw err;
    throw new ApiError(0, 'UNAVAILABLE', `cannot reach the server (${err.message})`);
  }
  if (!response.ok) {
    let code = `HTTP ${response.status}`;
    let message = response.status === 413 ? 'the request is too large for the server'
      : response.statusText || 'request failed';
    try {
      const data = await response.json();
      if (data.code) code = data.code;
      if (data.message) message = data.message;
    } catch (_) { /* not JSON: keep the HTTP status */ }
    throw new ApiError(response.status, code, message);
  }
  return response;
}

// GET or POST a JSON resource under /api; throws ApiError.
export async function api(path, options = {}) {
  const response = await request(path, options);
  try {
    return await response.json();
  } catch (err) {
    throw new ApiError(response.status, 'INTERNAL', `the server's answer is not JSON (${err.message})`);
  }
}

// One unary call through the gRPC gateway, e.g. rpc('recognition.v1.ObjectRepository', 'ListModels').
export function rpc(service, method, message = {}, signal) {
  return api(`/api/rpc/${service}/${method}`, { method: 'POST', body: message, signal });
}

// An image from the API (sent with the token, which <img src> cannot do). Resolves to
// { image, headers } with a decoded HTMLImageElement, or null when the server has none (404).
export async function apiImage(path, signal) {
  let response;
  try {
    response = await request(path, { signal });
  } catch (err) {
    if (err instanceof ApiError && err.status === 404) return null;
    throw err;
  }
  const url = URL.createObjectURL(await response.blob());
  const image = new Image();
  image.src = url;
  try {
    await image.decode();
  } catch (_) {
    throw new ApiError(response.status, 'INTERNAL', `the image at ${path} cannot be decoded`);
  } finally {
    URL.revokeObjectURL(url);
  }
  return { image, headers: response.headers };
}

// ---- DOM helpers ----

// el('p', {class: 'error', 'data-x': 1}, 'text', child...) — attributes and children.
export function el(tag, attrs = {}, ...children) {
  const node = document.createElement(tag);
  for (const [key, value] of Object.entries(attrs)) {
    if (value === undefined || value === null || value === false) continue;
    if (key === 'class') node.className = value;
    else if (key.startsWith('on')) node.addEventListener(key.slice(2), value);
    else node.setAttribute(key, value === true ? '' : String(value));
  }
  for (const child of children.flat()) {
    if (child === undefined || child === null || child === false) continue;
    node.append(child instanceof Node ? child : String(child));
  }
  return node;
}

// A <p class="error"> saying what failed.
export function errorBox(err, what) {
  let text = err instanceof ApiError ? `${err.message} (${err.code})` : (err && err.message) || String(err);
  if (err && err.status === 401) text += getToken() ? ' — check the API token at the top right.' : ' — enter an API token at the top right.';
  return el('p', { class: 'error', role: 'alert' }, what ? `${what}: ${text}` : text);
}

// A <dl> from [term, value] pairs.
export function definitionList(id, rows) {
  const dl = el('dl', { id });
  for (const [term, value] of rows) dl.append(el('dt', {}, term), el('dd', {}, value));
  return dl;
}

// ---- formatting ----

export function num(value) {
  const n = Number(value);
  return Number.isFinite(n) ? n : 0;
}

export function formatBytes(value) {
  let n = num(value);
  const units = ['B', 'KB', 'MB', 'GB', 'TB'];
  let i = 0;
  while (n >= 1024 && i < units.length - 1) { n /= 1024; i += 1; }
  return i === 0 ? `${n} B` : `${n.toFixed(n < 10 ? 1 : 0)} ${units[i]}`;
}

export function formatCount(value) {
  return num(value).toLocaleString('en-US');
}

export function formatDate(unixMs) {
  const ms = num(unixMs);
  if (!ms) return '—';
  const d = new Date(ms);
  const pad = (v) => String(v).padStart(2, '0');
  return `${d.getFullYear()}-${pad(d.getMonth() + 1)}-${pad(d.getDate())} ` +
    `${pad(d.getHours())}:${pad(d.getMinutes())}:${pad(d.getSeconds())}`;
}

export function formatTime(unixMs) {
  return formatDate(unixMs).slice(11);
}

// "OBJECT_TYPE_3D" → "3D", "LOOP_STATUS_LOW_SCORE" → "low score".
export function enumName(value, prefix) {
  if (value === undefined || value === null || value === '') return '—';
  let s = String(value);
  if (prefix && s.startsWith(prefix)) s = s.slice(prefix.length);
  return /^[0-9]/.test(s) ? s : s.toLowerCase().replaceAll('_', ' ');
}

// ---- charts ----

let chartClass = null;

// Chart.js's Chart (Debian's libjs-chart.js 3.9) with all its parts registered, loaded on first
// use: pages without charts never fetch it.
export function loadChart() {
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

// ---- token field ----

async function showAuthState() {
  const state = document.getElementById('auth-state');
  try {
    const who = await api('/api/whoami');
    if (!who.auth_required) state.textContent = '';
    else state.textContent = who.authenticated ? 'signed in' : 'token needed';
    state.className = who.auth_required && !who.authenticated ? 'warn' : 'muted';
  } catch (_) {
    state.textContent = '';
  }
}

function setUpToken() {
  const input = document.getElementById('token');
  input.value = getToken();
  document.getElementById('token-form').addEventListener('submit', (event) => {
    event.preventDefault();
    const token = input.value.trim();
    if (token) localStorage.setItem(TOKEN_KEY, token);
    else localStorage.removeItem(TOKEN_KEY);
    showAuthState();
    route();  // redraw the page with the new token
  });
  showAuthState();
}

// ---- router ----

// #/<name>[/<param>] → the page module (loaded on first use); each exports
// render(section, param, signal), signal aborting when the page is left.
const ROUTES = {
  maps: () => import('./maps.js'),
  models: () => import('./models.js'),
  try: () => import('./try.js'),
  live: () => import('./live.js'),
  charts: () => import('./charts.js'),
};

let current = null;  // { controller } of the page on screen

async function route() {
  const hash = location.hash.replace(/^#\/?/, '');
  const [name, ...rest] = hash.split('/');
  const page = ROUTES[name] ? name : 'maps';
  const param = rest.length ? decodeURIComponent(rest.join('/')) : null;

  if (current) current.controller.abort();  // stops the old page's timers and requests
  const controller = new AbortController();
  current = { controller };

  for (const link of document.querySelectorAll('nav a')) {
    link.classList.toggle('active', link.dataset.route === page);
  }
  const main = document.getElementById('main');
  const section = el('section', { class: `page page-${page}` });
  main.replaceChildren(section);
  try {
    const module = await ROUTES[page]();
    if (controller.signal.aborted) return;
    await module.render(section, param, controller.signal);
  } catch (err) {
    if (err.name === 'AbortError' || controller.signal.aborted) return;
    console.warn('page failed:', err);
    section.append(errorBox(err, `The ${page} page failed`));
  }
}

setUpToken();
window.addEventListener('hashchange', route);
route();
