// The console's entry point, loaded by index.html and imported by no module: the token field in
// the header and the hash router that loads one page module per route (#/maps, #/models, #/try,
// #/live, #/charts) into <main>.

import { api, getToken, setToken } from './api.js';
import { el, errorBox } from './dom.js';

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
    setToken(input.value.trim());
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
