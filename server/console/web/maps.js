// Maps: the table of the server's place maps (#/maps), and one map (#/maps/<name>): its settings
// and the loops it answered since the server started, each drawn as the two frames' thumbnails
// with the RANSAC inlier pairs between them.

import { api, apiImage } from './api.js';
import { el, errorBox, definitionList } from './dom.js';
import { formatBytes, formatCount, formatDate, enumName, num } from './format.js';
import { drawPairs } from './pairs.js';

export async function render(section, name, signal) {
  if (name) await renderMap(section, name, signal);
  else await renderList(section, signal);
}

async function renderList(section, signal) {
  section.append(el('h2', {}, 'Maps'));
  let data;
  try {
    data = await api('/api/maps', { signal });
  } catch (err) {
    if (err.name === 'AbortError') throw err;
    section.append(errorBox(err, 'Cannot list the maps'));
    return;
  }
  const maps = data.maps || [];
  const columns = [['Name'], ['Frames', 'num'], ['Size on disk', 'num'], ['Thumbnails kept', 'num'], ['Loops kept', 'num'], ['Group'], ['Preset']];
  const table = el('table', { id: 'maps-table', class: 'grid' },
    el('thead', {}, el('tr', {}, columns.map(([label, cls]) => el('th', { class: cls }, label)))));
  const body = el('tbody');
  for (const entry of maps) {
    const info = entry.info || {};
    const settings = info.settings || {};
    body.append(el('tr', { 'data-map': info.name },
      el('td', {}, el('a', { href: `#/maps/${encodeURIComponent(info.name)}` }, info.name)),
      el('td', { class: 'num' }, formatCount(info.frames)),
      el('td', { class: 'num' }, formatBytes(entry.disk_bytes)),
      el('td', { class: 'num' }, formatCount(entry.thumbnails)),
      el('td', { class: 'num' }, formatCount(entry.loops_kept)),
      el('td', {}, settings.group || '—'),
      el('td', {}, settings.preset || '—')));
  }
  if (!maps.length) {
    body.append(el('tr', { class: 'empty' }, el('td', { colspan: columns.length },
      'No maps yet: create one with "recog stream --map NAME --create --keep-thumbnails --images FOLDER".')));
  }
  table.append(body);
  section.append(table);
}

// One setting's value as text (rig cameras by name, enums without their prefix).
function settingText(key, value) {
  if (Array.isArray(value)) {
    if (!value.length) return 'none';
    return value.map((v) => (v && typeof v === 'object' ? v.name || JSON.stringify(v) : String(v))).join(', ');
  }
  if (value && typeof value === 'object') return JSON.stringify(value);
  if (key === 'geometry') return enumName(value, 'GEOMETRY_CHECK_');
  if (value === '') return '—';
  return String(value);
}

async function renderMap(section, name, signal) {
  section.append(el('p', { class: 'crumbs' }, el('a', { href: '#/maps' }, '← Maps')));
  section.append(el('h2', { id: 'map-title' }, name));

  const [listing, loops] = await Promise.allSettled([
    api('/api/maps', { signal }),
    api(`/api/maps/${encodeURIComponent(name)}/loops`, { signal }),
  ]);
  if (signal.aborted) return;

  if (listing.status === 'rejected') {
    section.append(errorBox(listing.reason, 'Cannot read the map'));
  } else {
    const entry = (listing.value.maps || []).find((m) => m.info && m.info.name === name);
    if (!entry) {
      section.append(el('p', { class: 'error' }, `There is no map named "${name}".`));
    } else {
      const info = entry.info;
      const rows = Object.entries(info.settings || {}).map(([key, value]) =>
        [key.replaceAll('_', ' '), settingText(key, value)]);
      rows.push(
        ['frames', formatCount(info.frames)],
        ['next frame id', String(info.next_frame_id ?? '—')],
        ['created', formatDate(info.created_unix_ms)],
        ['vocabulary checksum', info.vocabulary_checksum || '—'],
        ['size on disk', formatBytes(entry.disk_bytes)],
        ['thumbnails kept', formatCount(entry.thumbnails)]);
      section.append(definitionList('map-settings', rows));
    }
  }

  section.append(el('h3', {}, 'Loops'));
  const loopsBox = el('div', { id: 'loops' });
  section.append(loopsBox);
  if (loops.status === 'rejected') {
    loopsBox.append(errorBox(loops.reason, 'Cannot read the loops'));
    return;
  }
  const list = loops.value.loops || [];
  if (!list.length) {
    loopsBox.append(el('p', { id: 'no-loops', class: 'muted' },
      'No loop yet. Loops appear here as the server answers frames of this map that close a loop ' +
      '(the last 50 since the server started).'));
    return;
  }

  // Each frame's thumbnail is asked for once, however many loops it is in.
  const thumbnails = new Map();
  const thumbnail = (id) => {
    if (!thumbnails.has(id)) {
      thumbnails.set(id, apiImage(`/api/maps/${encodeURIComponent(name)}/frames/${id}/thumbnail`, signal)
        .then((r) => (r ? r.image : null), (err) => { if (err.name !== 'AbortError') console.warn(err); return null; }));
    }
    return thumbnails.get(id);
  };

  await Promise.all(list.map(async (loop) => {
    const canvas = el('canvas', { class: 'loop-canvas' });
    const caption = `frame ${loop.frame_id} ↔ frame ${loop.match_frame_id} · ${num(loop.inliers)} inliers · ` +
      `score ${num(loop.score).toFixed(2)} · ${formatDate(loop.unix_ms)}`;
    const box = el('div', { class: 'loop', 'data-frame': loop.frame_id, 'data-match': loop.match_frame_id,
      'data-inliers': num(loop.inliers) }, el('p', { class: 'caption' }, caption), canvas);
    loopsBox.append(box);
    const [left, right] = await Promise.all([thumbnail(loop.frame_id), thumbnail(loop.match_frame_id)]);
    if (signal.aborted) return;
    const [fw, fh] = loop.frame_size || [0, 0];
    const [mw, mh] = loop.match_size || loop.frame_size || [0, 0];
    drawPairs(canvas, { image: left, width: fw, height: fh }, { image: right, width: mw, height: mh },
      loop.pairs || [], { height: 240 });
  }));
}
