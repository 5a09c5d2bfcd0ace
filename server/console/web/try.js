// Try it (#/try): send one photo to the server and see what it recognises — the objects of the
// repository (each drawn with its outline and its pose's axes) or the place in a map (the photo
// beside the recognised frame, with the inlier pairs between them).

import { api, apiImage, rpc } from './api.js';
import { el, errorBox } from './dom.js';
import { enumName, num } from './format.js';
import { drawPairs } from './pairs.js';

const STATUS_TEXT = {
  LOOP_STATUS_TOO_FEW_FEATURES: 'the photo has too few features',
  LOOP_STATUS_LOW_SCORE_WITH_PREVIOUS: 'no usable previous frame to normalise the score by',
  LOOP_STATUS_NO_CANDIDATES: 'no frame of the map shares a visual word with it',
  LOOP_STATUS_LOW_SCORE: 'no frame of the map is similar enough',
  LOOP_STATUS_NO_CONSISTENT_ISLAND: 'the candidate frames formed no island',
  LOOP_STATUS_FAILED_TEMPORAL_CONSISTENCY: 'the match is not yet consistent with previous queries',
  LOOP_STATUS_FAILED_GEOMETRY: 'the best candidate failed the geometric check (too few inliers)',
  LOOP_STATUS_INCONSISTENT_CAMERAS: "the rig's cameras disagree",
};

export async function render(section, _param, signal) {
  section.append(el('h2', {}, 'Try it'));

  const file = el('input', { id: 'try-file', type: 'file', accept: 'image/*', required: true });
  const target = el('select', { id: 'try-target' },
    el('option', { value: 'objects' }, 'Objects in the repository'));
  const field = (id, label) => el('label', { class: 'field' }, label,
    el('input', { id, type: 'number', step: 'any', placeholder: 'auto', inputmode: 'decimal' }));
  const run = el('button', { id: 'try-run', type: 'submit' }, 'Recognise');
  const form = el('form', { id: 'try-form', class: 'try-form' },
    el('label', { class: 'field wide' }, 'Photo (JPEG or PNG)', file),
    el('label', { class: 'field wide' }, 'Look for', target),
    el('fieldset', { class: 'intrinsics' },
      el('legend', {}, 'Camera (pixels; blank: fx = fy = width, principal point at the centre)'),
      field('try-fx', 'fx'), field('try-fy', 'fy'), field('try-cx', 'cx'), field('try-cy', 'cy')),
    el('div', { class: 'actions' }, run));
  const status = el('p', { id: 'try-status', class: 'muted' }, 'Choose a photo, then Recognise.');
  const output = el('div', { id: 'try-output' });
  section.append(form, status, output);

  // The maps to look in, as they come.
  api('/api/maps', { signal }).then((data) => {
    for (const m of data.maps || []) {
      const name = m.info && m.info.name;
      if (name) target.append(el('option', { value: `map:${name}` }, `Place in map ${name}`));
    }
  }, (err) => {
    if (err.name !== 'AbortError') form.after(errorBox(err, 'Cannot list the maps'));
  });

  const setStatus = (text, isError) => {
    status.textContent = text;
    status.className = isError ? 'error' : 'muted';
  };

  form.addEventListener('submit', async (event) => {
    event.preventDefault();
    output.replaceChildren();
    const chosen = file.files && file.files[0];
    if (!chosen) { setStatus('Choose a photo first.', true); return; }
    run.disabled = true;
    setStatus('recognising…', false);
    const started = performance.now();
    try {
      const photo = await readPhoto(chosen);
      const value = target.value;
      let timing;
      if (value.startsWith('map:')) {
        timing = await tryPlace(output, value.slice(4), photo, intrinsics(photo, false), signal);
      } else {
        timing = await tryObjects(output, photo, intrinsics(photo, true), signal);
      }
      if (signal.aborted) return;
      const ms = Math.round(performance.now() - started);
      const parts = timing ? ['decode_ms', 'features_ms', 'recognition_ms', 'queue_ms']
        .filter((k) => num(timing[k]) > 0)
        .map((k) => `${k.replace('_ms', '')} ${num(timing[k]).toFixed(1)} ms`) : [];
      setStatus(`Done in ${ms} ms${parts.length ? ` (server: ${parts.join(' · ')})` : ''}.`, false);
    } catch (err) {
      if (err.name === 'AbortError' || signal.aborted) return;
      const text = err.code ? `${err.message} (${err.code})` : err.message;
      setStatus(`Failed: ${text}`, true);
    } finally {
      run.disabled = false;
    }
  });
}

// The chosen file as { base64, image, width, height, name }; throws when it is not an image the
// browser can decode.
async function readPhoto(file) {
  const dataUrl = await new Promise((resolve, reject) => {
    const reader = new FileReader();
    reader.onload = () => resolve(reader.result);
    reader.onerror = () => reject(new Error(`cannot read "${file.name}"`));
    reader.readAsDataURL(file);
  });
  const image = new Image();
  image.src = dataUrl;
  try {
    await image.decode();
  } catch (_) {
    throw new Error(`"${file.name}" is not an image (choose a JPEG or PNG file)`);
  }
  const comma = dataUrl.indexOf(',');
  return { base64: dataUrl.slice(comma + 1), image, width: image.naturalWidth, height: image.naturalHeight, name: file.name };
}

// The intrinsics from the form; blank fields come from the image (fx = fy = width, centre).
// withDefaults false: null unless all four are given.
function intrinsics(photo, withDefaults) {
  const read = (id) => {
    const text = document.getElementById(id).value.trim();
    if (text === '') return null;
    const v = Number(text);
    if (!Number.isFinite(v)) throw new Error(`${id.slice(4)} must be a number`);
    return v;
  };
  const given = { fx: read('try-fx'), fy: read('try-fy'), cx: read('try-cx'), cy: read('try-cy') };
  if (!withDefaults && Object.values(given).some((v) => v === null)) return null;
  const fx = given.fx ?? given.fy ?? photo.width;
  return { fx, fy: given.fy ?? fx, cx: given.cx ?? photo.width / 2, cy: given.cy ?? photo.height / 2 };
}

// A canvas with the photo, at most 960 pixels wide on screen; returns [canvas, ctx, scale].
function photoCanvas(photo) {
  const scale = Math.min(1, 960 / photo.width);
  const canvas = el('canvas', { id: 'try-canvas' });
  const dpr = window.devicePixelRatio || 1;
  canvas.width = Math.round(photo.width * scale * dpr);
  canvas.height = Math.round(photo.height * scale * dpr);
  canvas.style.width = `${Math.round(photo.width * scale)}px`;
  const ctx = canvas.getContext('2d');
  ctx.setTransform(dpr * scale, 0, 0, dpr * scale, 0, 0);
  ctx.drawImage(photo.image, 0, 0, photo.width, photo.height);
  return [canvas, ctx, scale];
}

async function tryObjects(output, photo, K, signal) {
  const answer = await rpc('recognition.v1.ObjectRecognition', 'RecognizeObjects', {
    frame: { encoded_image: photo.base64, intrinsics: K },
    detection_options: { include_inliers: true },
  }, signal);
  const objects = answer.objects || [];

  // Axis length: half the largest extent of each model (its bounds), fetched once per name.
  const lengths = new Map();
  await Promise.all([...new Set(objects.map((o) => o.name))].map(async (name) => {
    try {
      const model = await api(`/api/models/${encodeURIComponent(name)}`, { signal });
      const b = model.bounds;
      if (b && b.min && b.max) {
        const extent = Math.max(...b.max.map((v, i) => num(v) - num(b.min[i])));
        if (extent > 0) lengths.set(name, 0.5 * extent);
      }
    } catch (err) {
      if (err.name === 'AbortError') throw err;
    }
  }));

  const [canvas, ctx, scale] = photoCanvas(photo);
  const list = el('ul', { id: 'try-results' });
  objects.forEach((o, i) => {
    const colour = `hsl(${(i * 67 + 200) % 360}, 90%, 50%)`;
    drawDetection(ctx, o, K, lengths.get(o.name), colour, scale);
    const t = ((o.pose && o.pose.translation) || []).map((v) => num(v).toFixed(3));
    const swatch = el('span', { class: 'swatch' });
    swatch.style.background = colour;  // through the CSSOM: the console's policy forbids style attributes
    list.append(el('li', { class: 'detected-object', 'data-name': o.name },
      swatch,
      el('strong', {}, o.name), ` · ${num(o.inliers)} inliers · translation (${t.join(', ')}) ${o.units || ''}`));
  });
  if (!objects.length) list.append(el('li', { class: 'none muted' }, 'No object recognised in this photo.'));
  output.append(list, canvas);
  return answer.timing;
}

// Projects a point of the object frame into the image with the pose (T_camera<-object) and K;
// null behind the camera.
function project(pose, K, p) {
  const R = pose.rotation.map(num);
  const t = pose.translation.map(num);
  const x = R[0] * p[0] + R[1] * p[1] + R[2] * p[2] + t[0];
  const y = R[3] * p[0] + R[4] * p[1] + R[5] * p[2] + t[1];
  const z = R[6] * p[0] + R[7] * p[1] + R[8] * p[2] + t[2];
  if (z <= 1e-9) return null;
  return [K.fx * x / z + K.cx, K.fy * y / z + K.cy];
}

function drawDetection(ctx, o, K, axisLength, colour, scale) {
  const outline = (o.outline || []).map((p) => [num(p.x), num(p.y)]);
  const lw = 2 / scale;  // 2 screen pixels whatever the photo's size
  if (outline.length >= 2) {
    ctx.strokeStyle = colour;
    ctx.lineWidth = lw;
    ctx.beginPath();
    outline.forEach(([x, y], i) => (i ? ctx.lineTo(x, y) : ctx.moveTo(x, y)));
    ctx.closePath();
    ctx.stroke();
    const top = outline.reduce((a, b) => (b[1] < a[1] ? b : a));
    ctx.font = `${Math.round(14 / scale)}px system-ui, sans-serif`;
    ctx.fillStyle = colour;
    ctx.textBaseline = 'bottom';
    ctx.fillText(o.name, top[0], top[1] - 4 / scale);
  }
  const pose = o.pose;
  if (!pose || (pose.rotation || []).length !== 9 || (pose.translation || []).length !== 3) return;
  let length = axisLength;
  if (!length) {
    // No bounds: half the outline's diagonal, back-projected at the object's depth.
    const xs = outline.map((p) => p[0]);
    const ys = outline.map((p) => p[1]);
    const diagonal = xs.length ? Math.hypot(Math.max(...xs) - Math.min(...xs), Math.max(...ys) - Math.min(...ys)) : 100;
    length = 0.5 * diagonal * Math.abs(num(pose.translation[2])) / K.fx;
  }
  const origin = project(pose, K, [0, 0, 0]);
  if (!origin) return;
  const axes = [[[length, 0, 0], '#e53935'], [[0, length, 0], '#43a047'], [[0, 0, length], '#1e63e9']];
  ctx.lineWidth = 2.5 / scale;
  for (const [end, axisColour] of axes) {
    const p = project(pose, K, end);
    if (!p) continue;
    ctx.strokeStyle = axisColour;
    ctx.beginPath();
    ctx.moveTo(origin[0], origin[1]);
    ctx.lineTo(p[0], p[1]);
    ctx.stroke();
  }
}

async function tryPlace(output, map, photo, K, signal) {
  const frame = { encoded_image: photo.base64 };
  if (K) frame.intrinsics = K;
  const answer = await rpc('recognition.v1.PlaceRecognition', 'QueryPlace', {
    map, frame, options: { include_correspondences: true },
  }, signal);
  const result = answer.result || {};
  const found = result.status === 'LOOP_STATUS_LOOP_DETECTED' && result.match_frame_id !== undefined &&
    result.match_frame_id !== null && result.match_frame_id !== '';
  const matchId = found ? String(result.match_frame_id) : '';

  const place = el('div', { id: 'try-place', 'data-match': matchId, 'data-status': result.status || '' });
  if (!found) {
    const why = STATUS_TEXT[result.status] || enumName(result.status, 'LOOP_STATUS_');
    place.append(el('p', {}, `Not recognised in map ${map}: ${why}.`));
    output.append(place, photoCanvas(photo)[0]);
    return answer.timing;
  }
  place.append(el('p', {}, `Recognised: frame ${matchId} of map ${map}` +
    (result.match_client_frame_id ? ` (${result.match_client_frame_id})` : '') +
    ` · ${num(result.inliers)} inliers · score ${num(result.score).toFixed(2)}.`));
  let match = null;
  let matchSize = { width: photo.width, height: photo.height };
  try {
    const thumb = await apiImage(`/api/maps/${encodeURIComponent(map)}/frames/${matchId}/thumbnail`, signal);
    if (thumb) {
      match = thumb.image;
      matchSize = frameSize(thumb, photo);
    }
  } catch (err) {
    if (err.name === 'AbortError') throw err;
    place.append(errorBox(err, 'Cannot load the matched frame'));
  }
  const pairs = (result.inlier_correspondences || []).map((c) =>
    [num(c.query_x), num(c.query_y), num(c.match_x), num(c.match_y)]);
  const canvas = el('canvas', { id: 'try-canvas' });
  drawPairs(canvas, { image: photo.image, width: photo.width, height: photo.height },
    { image: match, width: matchSize.width, height: matchSize.height }, pairs,
    { height: Math.min(400, photo.height) });
  output.append(place, canvas);
  return answer.timing;
}

// The full-resolution size of the frame a thumbnail was made from: the server's X-Frame-Width /
// X-Frame-Height headers; else the photo's size when the aspects agree (same camera), else the
// thumbnail's own.
function frameSize(thumb, photo) {
  const w = Number(thumb.headers.get('X-Frame-Width'));
  const h = Number(thumb.headers.get('X-Frame-Height'));
  if (w > 0 && h > 0) return { width: w, height: h };
  const image = thumb.image;
  if (Math.abs(image.naturalWidth / image.naturalHeight - photo.width / photo.height) < 0.02) {
    return { width: photo.width, height: photo.height };
  }
  return { width: image.naturalWidth, height: image.naturalHeight };
}
