// The DOM helpers the pages share: elements built in one call, the box that says what failed, and
// definition lists.

import { ApiError, getToken } from './api.js';

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

// A <p class="error"> saying what failed; a refused token (401) says where to enter one.
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
