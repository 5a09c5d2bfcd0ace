// Models: the table of the object models in the repository (#/models), and one model
// (#/models/<name>): its description, its 3D points in a three.js view you can orbit (coloured by
// height or by how many descriptors each point carries), and the images of its training views.

import * as THREE from 'three';
import { OrbitControls } from 'three/OrbitControls';
import { api, apiImage, rpc } from './api.js';
import { el, errorBox, definitionList } from './dom.js';
import { formatBytes, formatCount, formatDate, enumName, num } from './format.js';

export async function render(section, name, signal) {
  if (name) await renderModel(section, name, signal);
  else await renderList(section, signal);
}

async function renderList(section, signal) {
  section.append(el('h2', {}, 'Models'));
  const models = [];
  try {
    let pageToken = '';
    do {  // every page
      const page = await rpc('recognition.v1.ObjectRepository', 'ListModels',
        { page_size: 1000, page_token: pageToken }, signal);
      models.push(...(page.models || []));
      pageToken = page.next_page_token || '';
    } while (pageToken);
  } catch (err) {
    if (err.name === 'AbortError') throw err;
    section.append(errorBox(err, 'Cannot list the models'));
    return;
  }
  const columns = [['Name'], ['Version', 'num'], ['Class'], ['Type'], ['Points', 'num'], ['Descriptors', 'num'], ['Size', 'num'], ['Created']];
  const table = el('table', { id: 'models-table', class: 'grid' },
    el('thead', {}, el('tr', {}, columns.map(([label, cls]) => el('th', { class: cls }, label)))));
  const body = el('tbody');
  for (const m of models) {
    body.append(el('tr', { 'data-model': m.name },
      el('td', {}, el('a', { href: `#/models/${encodeURIComponent(m.name)}` }, m.name)),
      el('td', { class: 'num' }, String(m.version ?? '')),
      el('td', {}, m.object_class || '—'),
      el('td', {}, enumName(m.type, 'OBJECT_TYPE_')),
      el('td', { class: 'num' }, formatCount(m.num_points)),
      el('td', { class: 'num' }, formatCount(m.num_descriptors)),
      el('td', { class: 'num' }, formatBytes(m.size_bytes)),
      el('td', {}, formatDate(m.created_unix_ms))));
  }
  if (!models.length) {
    body.append(el('tr', { class: 'empty' }, el('td', { colspan: columns.length },
      'No models yet: upload one with "recog models push FILE".')));
  }
  table.append(body);
  section.append(table);
}

async function renderModel(section, name, signal) {
  section.append(el('p', { class: 'crumbs' }, el('a', { href: '#/models' }, '← Models')));
  section.append(el('h2', { id: 'model-title' }, name));
  let model;
  try {
    model = await api(`/api/models/${encodeURIComponent(name)}`, { signal });
  } catch (err) {
    if (err.name === 'AbortError') throw err;
    section.append(errorBox(err, 'Cannot read the model'));
    return;
  }
  const info = model.info || {};
  const bounds = model.bounds || null;
  const dims = (info.dimensions || []).filter((d) => num(d) > 0);
  const rows = [
    ['version', String(info.version ?? '—')],
    ['class', info.object_class || '—'],
    ['type', enumName(info.type, 'OBJECT_TYPE_')],
    ['units', info.units || '—'],
    ['dimensions', dims.length ? `${info.dimensions.map((d) => num(d).toPrecision(3)).join(' × ')} ${info.units || ''}` : 'unknown'],
    ['points', formatCount(info.num_points)],
    ['descriptors', formatCount(info.num_descriptors)],
    ['training views', String((model.views || []).length)],
    ['size', formatBytes(info.size_bytes)],
    ['created', formatDate(info.created_unix_ms)],
    ['source', info.source || '—'],
    ['tags', (info.tags || []).join(', ') || '—'],
    ['sha256', info.sha256 || '—'],
  ];
  if (bounds && bounds.min && bounds.max) {
    const f = (v) => v.map((x) => num(x).toPrecision(3)).join(', ');
    rows.push(['bounds', `(${f(bounds.min)}) – (${f(bounds.max)})`]);
  }
  const colourBy = el('select', { id: 'points-colour', 'aria-label': 'colour points by' },
    el('option', { value: 'height' }, 'height'),
    el('option', { value: 'observations' }, 'descriptors per point'));
  const view = el('div', { id: 'points-view' });
  section.append(el('div', { class: 'model-layout' },
    definitionList('model-info', rows),
    el('div', { class: 'points-panel' }, view,
      el('p', { class: 'muted controls' }, 'Drag to orbit, scroll to zoom, right-drag to pan. Colour by ', colourBy))));

  section.append(el('h3', {}, 'Training views'));
  const viewsBox = el('div', { id: 'views' });
  section.append(viewsBox);
  showViews(viewsBox, name, model.views || [], signal);

  let points;
  try {
    points = await api(`/api/models/${encodeURIComponent(name)}/points?max=20000`, { signal });
  } catch (err) {
    if (err.name === 'AbortError') throw err;
    view.append(errorBox(err, 'Cannot read the points'));
    return;
  }
  try {
    showPoints(view, colourBy, points, bounds, (model.views || [])[0], signal);
  } catch (err) {
    view.append(errorBox(err, 'Cannot draw the points (WebGL)'));
  }
}

function showViews(box, name, views, signal) {
  if (!views.length) {
    box.append(el('p', { class: 'muted' }, 'This model has no training views.'));
    return;
  }
  for (const v of views) {
    const figure = el('figure', { class: 'view', 'data-index': v.index });
    const caption = el('figcaption', {}, v.name || `view ${v.index}`);
    if (v.has_image) {
      const slot = el('div', { class: 'view-image muted' }, 'loading…');
      figure.append(slot, caption);
      apiImage(`/api/models/${encodeURIComponent(name)}/views/${v.index}/image`, signal).then((r) => {
        if (!r) { slot.textContent = 'no image kept'; return; }
        r.image.alt = v.name || `view ${v.index}`;
        slot.replaceWith(r.image);
      }, (err) => {
        if (err.name !== 'AbortError') slot.replaceWith(errorBox(err));
      });
    } else {
      figure.append(el('div', { class: 'view-image muted' }, 'no image kept'), caption);
    }
    box.append(figure);
  }
}

// Viridis-like ramp: t in [0, 1] → [r, g, b] in [0, 1].
const RAMP = [[0.267, 0.005, 0.329], [0.230, 0.322, 0.546], [0.128, 0.567, 0.551], [0.369, 0.789, 0.383], [0.993, 0.906, 0.144]];
function ramp(t) {
  const x = Math.min(1, Math.max(0, t)) * (RAMP.length - 1);
  const i = Math.min(RAMP.length - 2, Math.floor(x));
  const f = x - i;
  return RAMP[i].map((c, k) => c + (RAMP[i + 1][k] - c) * f);
}

function showPoints(view, colourBy, data, bounds, firstView, signal) {
  const pts = (data.points || []).filter((p) => p.length >= 3 && p.every(Number.isFinite));
  if (!pts.length) {
    view.append(el('p', { class: 'muted' }, 'This model has no points.'));
    view.dataset.points = '0';
    return;
  }
  const observations = data.observations || [];

  // Bounds: the server's, else the points'.
  const box = new THREE.Box3();
  if (bounds && bounds.min && bounds.max) {
    box.set(new THREE.Vector3(...bounds.min.map(num)), new THREE.Vector3(...bounds.max.map(num)));
  } else {
    for (const p of pts) box.expandByPoint(new THREE.Vector3(p[0], p[1], p[2]));
  }
  const center = box.getCenter(new THREE.Vector3());
  const extent = box.getSize(new THREE.Vector3());
  const size = Math.max(extent.x, extent.y, extent.z) || 1;

  // Look from the first training view's camera when there is one (pose: T_camera<-object, OpenCV
  // axes: y down), else from a corner with +y up.
  let direction = new THREE.Vector3(1, 0.8, 1.2).normalize();
  let up = new THREE.Vector3(0, 1, 0);
  const pose = firstView && firstView.pose;
  if (pose && (pose.rotation || []).length === 9 && (pose.translation || []).length === 3) {
    const R = pose.rotation.map(num);
    const t = pose.translation.map(num);
    // Camera centre in the object frame: -R^T t; the camera's y axis there: R^T e_y (row 2 of R).
    const c = new THREE.Vector3(
      -(R[0] * t[0] + R[3] * t[1] + R[6] * t[2]),
      -(R[1] * t[0] + R[4] * t[1] + R[7] * t[2]),
      -(R[2] * t[0] + R[5] * t[1] + R[8] * t[2]));
    const d = c.sub(center);
    if (d.length() > 1e-9) {
      direction = d.normalize();
      up = new THREE.Vector3(-R[3], -R[4], -R[5]).normalize();
    }
  }

  const positions = new Float32Array(pts.length * 3);
  pts.forEach((p, i) => positions.set([p[0], p[1], p[2]], i * 3));
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute('position', new THREE.BufferAttribute(positions, 3));
  const colours = new THREE.BufferAttribute(new Float32Array(pts.length * 3), 3);
  geometry.setAttribute('color', colours);

  const paint = () => {
    let values;
    if (colourBy.value === 'observations' && observations.length === pts.length) {
      values = observations.map((n) => Math.log(1 + num(n)));
    } else {
      values = pts.map((p) => p[0] * up.x + p[1] * up.y + p[2] * up.z);
    }
    let lo = Infinity;
    let hi = -Infinity;
    for (const v of values) { lo = Math.min(lo, v); hi = Math.max(hi, v); }
    const span = hi - lo || 1;
    values.forEach((v, i) => colours.array.set(ramp((v - lo) / span), i * 3));
    colours.needsUpdate = true;
  };
  paint();

  const material = new THREE.PointsMaterial({ size: 3, sizeAttenuation: false, vertexColors: THREE.VertexColors });
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0xf7f8fa);
  scene.add(new THREE.Points(geometry, material));
  const axes = new THREE.AxesHelper(size * 0.6);
  scene.add(axes);

  const width = view.clientWidth || 800;
  const height = view.clientHeight || 480;
  const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  renderer.setSize(width, height);
  view.append(renderer.domElement);

  const camera = new THREE.PerspectiveCamera(45, width / height, size / 1000, size * 1000);
  const radius = box.getBoundingSphere(new THREE.Sphere()).radius || size;
  const distance = (radius / Math.sin(THREE.Math.degToRad(camera.fov / 2))) * 1.1;
  camera.up.copy(up);
  camera.position.copy(center).addScaledVector(direction, distance);
  camera.lookAt(center);

  const controls = new OrbitControls(camera, renderer.domElement);
  controls.target.copy(center);
  controls.update();

  let pending = false;
  const draw = () => {
    if (pending) return;
    pending = true;
    requestAnimationFrame(() => {
      pending = false;
      if (!signal.aborted) renderer.render(scene, camera);
    });
  };
  controls.addEventListener('change', draw);
  colourBy.addEventListener('change', () => { paint(); draw(); });

  const resize = new ResizeObserver(() => {
    const w = view.clientWidth;
    const h = view.clientHeight;
    if (!w || !h) return;
    renderer.setSize(w, h);
    camera.aspect = w / h;
    camera.updateProjectionMatrix();
    draw();
  });
  resize.observe(view);

  renderer.render(scene, camera);
  view.dataset.points = String(pts.length);

  signal.addEventListener('abort', () => {
    resize.disconnect();
    controls.dispose();
    geometry.dispose();
    material.dispose();
    renderer.dispose();
    if (renderer.forceContextLoss) renderer.forceContextLoss();
  });
}
