// monet label: the page. Plain JavaScript, no build step, no external asset.
// Image pixel coordinates: pixel centres on integers (the labels table's convention);
// a view's transform maps them to canvas pixels: x = u * s + tx, y = v * s + ty.
// Names (cameras, keypoints, subjects' track / individual names) come from files: they are
// put in the page as text only (textContent / text nodes), never parsed as HTML.
// Subjects: the labels of one subject (an animal of the instant, id 0, 1, ...) are edited
// at a time; a click labels the selected subject; the others are drawn as grey marks.
'use strict';

const COLORS = ['#e6194b', '#3cb44b', '#ffe119', '#4363d8', '#f58231', '#911eb4', '#46f0f0',
  '#f032e6', '#bcf60c', '#fabebe', '#008080', '#e6beff', '#9a6324', '#fffac8', '#800000',
  '#aaffc3', '#808000', '#ffd8b1', '#000075', '#808080', '#ffffff'];
const HIT_PX = 8;

const S = {
  summary: null, t: 0, labels: {}, assist: {}, epipolar: {}, selected: 0, history: [],
  views: [], busy: 0, ready: false, prefill: false, suggest: null, labelled: [],
  hoverView: null, error: null, generation: 0, saves: Promise.resolve(), loaded: false,
  sync: {}, notice: null, subject: 0, others: {}, subjectIds: [0],
};
window.monetLabel = S;

const $ = (id) => document.getElementById(id);
// the server's per-run token: every request that changes something carries it
const TOKEN = document.querySelector('meta[name="monet-token"]').content;

async function api(method, url, body) {
  const options = { method, headers: {} };
  if (method !== 'GET') options.headers['X-Monet-Token'] = TOKEN;
  if (body !== undefined) {
    options.headers['Content-Type'] = 'application/json';
    options.body = JSON.stringify(body);
  }
  const response = await fetch(url, options);
  let data = {};
  try { data = await response.json(); } catch (error) { data = {}; }
  if (!response.ok) {
    const error = new Error(data.error || `${response.status} ${response.statusText}`);
    error.status = response.status;
    error.data = data;
    throw error;
  }
  return data;
}

// An element with properties and children (strings become text nodes, never HTML).
function element(tag, props, ...children) {
  const out = document.createElement(tag);
  Object.assign(out, props || {});
  out.append(...children);
  return out;
}

function setStatus(text, kind) {
  const el = $('status');
  el.textContent = text;
  el.className = kind || '';
}

async function busy(work) {
  S.busy += 1;
  setStatus('working', 'busy');
  try {
    await work();
    S.error = null;
  } catch (error) {
    S.error = String(error.message || error);
  } finally {
    S.busy -= 1;
    if (S.busy === 0) setStatus(S.error ? 'error: ' + S.error : 'saved', S.error ? 'error' : '');
  }
}

// ------------------------------------------------------------------ views
function buildViews() {
  const holder = $('views');
  holder.replaceChildren();
  S.views = S.summary.cameras.map((cam, index) => {
    const box = document.createElement('div');
    box.className = 'view';
    box.dataset.camera = cam.name;
    const err = element('span', { className: 'err' });
    const title = element('div', { className: 'title' },
      element('span', {}, cam.name + ' ',
        element('span', { className: 'note' }, `${cam.width}x${cam.height}`)), err);
    const canvas = document.createElement('canvas');
    canvas.id = 'view-' + cam.name;
    box.append(title, canvas);
    holder.append(box);
    const view = { cam, index, box, canvas, err, image: null,
      s: 1, tx: 0, ty: 0, fitted: false };
    attachMouse(view);
    return view;
  });
  layout();
  window.addEventListener('resize', () => { layout(); draw(); });
}

// Columns and scale so that every view fits the window at the largest common scale.
function layout() {
  const holder = $('views');
  const W = holder.clientWidth - 16;
  const H = Math.max(200, window.innerHeight - holder.getBoundingClientRect().top - 16);
  const n = S.views.length;
  let best = null;
  for (let k = 1; k <= n; k += 1) {
    const rows = Math.ceil(n / k);
    const cw = (W - 6 * (k - 1)) / k - 4;
    const ch = (H - 6 * (rows - 1)) / rows - 26;
    const s = Math.min(...S.views.map((v) => Math.min(cw / v.cam.width, ch / v.cam.height)));
    if (!best || s > best.s) best = { k, s };
  }
  const s = Math.max(best.s, 0.05);
  holder.style.gridTemplateColumns = `repeat(${best.k}, max-content)`;
  S.views.forEach((view) => {
    view.canvas.width = Math.max(1, Math.floor(view.cam.width * s));
    view.canvas.height = Math.max(1, Math.floor(view.cam.height * s));
    view.canvas.style.width = view.canvas.width + 'px';
    view.canvas.style.height = view.canvas.height + 'px';
    fit(view);
  });
}

function fit(view) {
  view.s = Math.min(view.canvas.width / view.cam.width, view.canvas.height / view.cam.height);
  view.tx = 0.5 * view.s;
  view.ty = 0.5 * view.s;
  view.fitted = true;
}

function toCanvas(view, u, v) { return [u * view.s + view.tx, v * view.s + view.ty]; }
function toImage(view, x, y) { return [(x - view.tx) / view.s, (y - view.ty) / view.s]; }

// Page (client) coordinates of an image pixel of a camera (used by the browser tests).
S.toClient = function (camera, u, v) {
  const view = S.views.find((w) => w.cam.name === camera);
  const rect = view.canvas.getBoundingClientRect();
  const [x, y] = toCanvas(view, u, v);
  return [rect.left + x * rect.width / view.canvas.width,
    rect.top + y * rect.height / view.canvas.height];
};

function eventPoint(view, event) {
  const rect = view.canvas.getBoundingClientRect();
  const x = (event.clientX - rect.left) * view.canvas.width / rect.width;
  const y = (event.clientY - rect.top) * view.canvas.height / rect.height;
  return [x, y];
}

function keypointName() { return S.summary.keypoints[S.selected]; }

function hit(view, x, y, only) {
  // the labelled keypoint (only: that one) nearest to canvas point (x, y) within HIT_PX
  const points = S.labels[view.cam.name] || {};
  let best = null;
  let bestD = HIT_PX;
  for (const [kp, uv] of Object.entries(points)) {
    if (only !== undefined && kp !== only) continue;
    const [px, py] = toCanvas(view, uv[0], uv[1]);
    const d = Math.hypot(px - x, py - y);
    if (d <= bestD) { best = kp; bestD = d; }
  }
  return best;
}

function inside(cam, u, v) {
  return u >= -0.5 && v >= -0.5 && u <= cam.width - 0.5 && v <= cam.height - 0.5;
}

function attachMouse(view) {
  const canvas = view.canvas;
  let drag = null;
  canvas.addEventListener('contextmenu', (e) => e.preventDefault());
  canvas.addEventListener('mouseenter', () => { S.hoverView = view.cam.name; });
  canvas.addEventListener('mouseleave', () => { S.hoverView = null; });
  canvas.addEventListener('mousedown', (event) => {
    event.preventDefault();
    const [x, y] = eventPoint(view, event);
    if (event.button !== 0 || event.shiftKey) {
      drag = { pan: true, x, y, tx: view.tx, ty: view.ty };
      return;
    }
    if (!S.loaded) return;                  // the instant's saved labels are not here yet
    // the selected keypoint's own point is dragged; while it is not placed in this view a
    // click places it (even beside another point); once placed, another point near the
    // click is dragged (and selected), else the selected keypoint moves to the click
    const own = (S.labels[view.cam.name] || {})[keypointName()];
    const kp = hit(view, x, y, keypointName()) || (own ? hit(view, x, y) : null);
    if (kp !== null) {
      selectKeypoint(S.summary.keypoints.indexOf(kp));
      drag = { kp, moved: false, before: snapshot() };
      return;
    }
    const [u, v] = toImage(view, x, y);
    if (!inside(view.cam, u, v)) return;
    pushHistory();
    setPoint(view.cam.name, keypointName(), u, v);
    changed();
  });
  canvas.addEventListener('mousemove', (event) => {
    if (!drag) return;
    const [x, y] = eventPoint(view, event);
    if (drag.pan) {
      view.tx = drag.tx + x - drag.x;
      view.ty = drag.ty + y - drag.y;
      draw();
      return;
    }
    let [u, v] = toImage(view, x, y);
    u = Math.min(Math.max(u, -0.5), view.cam.width - 0.5);
    v = Math.min(Math.max(v, -0.5), view.cam.height - 0.5);
    drag.moved = true;
    setPoint(view.cam.name, drag.kp, u, v);
    draw();
  });
  const end = () => {
    if (drag && !drag.pan && drag.moved && S.loaded) {
      S.history.push(drag.before);
      changed();
    }
    drag = null;
  };
  canvas.addEventListener('mouseup', end);
  canvas.addEventListener('mouseleave', end);
  canvas.addEventListener('wheel', (event) => {
    event.preventDefault();
    const [x, y] = eventPoint(view, event);
    const factor = Math.exp(-event.deltaY * 0.0015);
    view.tx = x - (x - view.tx) * factor;
    view.ty = y - (y - view.ty) * factor;
    view.s *= factor;
    draw();
  }, { passive: false });
}

// ------------------------------------------------------------------ labels
function snapshot() { return JSON.stringify(S.labels); }
function pushHistory() { S.history.push(snapshot()); if (S.history.length > 200) S.history.shift(); }

function setPoint(camera, kp, u, v) {
  if (!S.labels[camera]) S.labels[camera] = {};
  S.labels[camera][kp] = [u, v];
}

function deletePoint(camera, kp) {
  if (S.labels[camera]) {
    delete S.labels[camera][kp];
    if (Object.keys(S.labels[camera]).length === 0) delete S.labels[camera];
  }
}

function acceptGhosts() {
  let count = 0;
  const before = snapshot();
  for (const [kp, info] of Object.entries(S.assist)) {
    for (const view of S.views) {
      const ghost = info.views[view.cam.name].ghost;
      const have = S.labels[view.cam.name] && S.labels[view.cam.name][kp];
      if (ghost && !have && inside(view.cam, ghost[0], ghost[1])) {
        setPoint(view.cam.name, kp, ghost[0], ghost[1]);
        count += 1;
      }
    }
  }
  if (count) { S.history.push(before); changed(); }
  return count;
}

function undo() {
  if (!S.history.length) return;
  S.labels = JSON.parse(S.history.pop());
  changed();
}

// ------------------------------------------------------------------ saving
// What `to` changed from `from`: [[camera, keypoint, [u, v] | null (deleted)], ...].
function labelDelta(from, to) {
  const out = [];
  for (const cam of new Set([...Object.keys(from), ...Object.keys(to)])) {
    const a = from[cam] || {};
    const b = to[cam] || {};
    for (const kp of new Set([...Object.keys(a), ...Object.keys(b)])) {
      const p = a[kp];
      const q = b[kp];
      if (!q) {
        if (p) out.push([cam, kp, null]);
      } else if (!p || p[0] !== q[0] || p[1] !== q[1]) {
        out.push([cam, kp, [q[0], q[1]]]);
      }
    }
  }
  return out;
}

function applyDelta(labels, delta) {
  const out = JSON.parse(JSON.stringify(labels));
  for (const [cam, kp, uv] of delta) {
    if (uv) {
      if (!out[cam]) out[cam] = {};
      out[cam][kp] = [uv[0], uv[1]];
    } else if (out[cam]) {
      delete out[cam][kp];
      if (Object.keys(out[cam]).length === 0) delete out[cam];
    }
  }
  return out;
}

// Save this tab's labels `mine` of instant t. S.sync[t] holds the labels saved on the
// server (base) at its version, and this tab's labels they were built from (local). The
// save sends base + (what this tab changed since local), with that version. A 409 means
// another tab or client saved the instant meanwhile: it brings the saved labels and their
// version, the same change is applied to them and sent again - per keypoint and view, so
// both tabs' points survive (a point both changed takes this tab's value, the later
// edit). Reloading the server's version instead would drop this tab's edit.
function syncKey(t, subject) { return `${t}/${subject}`; }

async function saveInstant(t, subject, mine) {
  const sync = S.sync[syncKey(t, subject)];
  if (!sync) throw new Error(`instant ${t}: its saved labels were not loaded`);
  const delta = labelDelta(sync.local, mine);
  let merged = false;
  for (let attempt = 0; ; attempt += 1) {
    const labels = applyDelta(sync.base, delta);
    try {
      const saved = await api('PUT', `/api/labels/${t}`,
        { labels, version: sync.version, subject });
      sync.base = labels;
      sync.version = saved.version;
      sync.local = mine;
      if (merged) adoptMerge(t, subject, mine, labels);
      return saved;
    } catch (error) {
      if (error.status !== 409 || attempt >= 5) throw error;
      sync.base = error.data.labels;
      sync.version = error.data.version;
      merged = true;
    }
  }
}

// The page takes in the points another tab or client saved (those this tab has not
// changed since `mine`), in its labels and its undo history, and says so.
function adoptMerge(t, subject, mine, saved) {
  const later = new Set(labelDelta(mine, S.labels).map(([c, k]) => c + '\n' + k));
  const foreign = labelDelta(mine, saved).filter(([c, k]) => !later.has(c + '\n' + k));
  S.notice = `instant ${t} was saved by another tab or client meanwhile: merged, ` +
    `${foreign.length} of its points taken in, your changes kept`;
  $('notice').textContent = S.notice;
  if (t !== S.t || subject !== S.subject || !foreign.length) return;
  S.labels = applyDelta(S.labels, foreign);
  S.history = S.history.map((h) => JSON.stringify(applyDelta(JSON.parse(h), foreign)));
  S.generation += 1;
  draw();
  renderKeypoints();
}

// Save the instant, then triangulate and fetch epipolar curves (in that order).
function changed() {
  S.prefill = false;
  S.generation += 1;
  const t = S.t;
  const subject = S.subject;
  const labels = JSON.parse(snapshot());
  draw();
  // saves go out one after the other, in the order of the changes (never a stale one last)
  const save = S.saves.then(() => saveInstant(t, subject, labels));
  S.saves = save.catch(() => null);
  busy(async () => {
    const saved = await save;
    S.labelled = saved.labelled;
    renderLabelled();
    const current = t === S.t && subject === S.subject;
    await refreshAssist(t, current ? JSON.parse(snapshot()) : labels);
  });
}

async function refreshAssist(t, labels) {
  const generation = S.generation;
  const assist = await api('POST', '/api/triangulate', { labels });
  const kp = keypointName();
  const epipolar = {};
  await Promise.all(S.views.map(async (view) => {
    epipolar[view.cam.name] = await api('POST', '/api/epipolar',
      { labels, camera: view.cam.name, keypoint: kp });
  }));
  if (generation !== S.generation || t !== S.t) return;    // a newer change is on its way
  S.assist = assist;
  S.epipolar = epipolar;
  draw();
  renderKeypoints();
}

function selectKeypoint(index) {
  const n = S.summary.keypoints.length;
  S.selected = ((index % n) + n) % n;
  renderKeypoints();
  draw();
  const t = S.t;
  const labels = JSON.parse(snapshot());
  busy(() => refreshAssist(t, labels));
}

async function openInstant(t) {
  const count = S.summary.instants.length;
  t = Math.max(0, Math.min(count - 1, t | 0));
  S.t = t;
  S.generation += 1;
  S.history = [];
  S.assist = {};
  S.epipolar = {};
  S.loaded = false;
  $('instant').value = t;
  $('stamp').textContent = 'stamp ' + S.summary.instants[t].stamp_ns + ' ns';
  renderLabelled();
  renderSuggestions();
  await busy(async () => {
    await S.saves;                       // this tab's own saves are in what comes back
    const subject = S.subject;
    const data = await api('GET', `/api/labels/${t}?subject=${subject}`);
    if (S.t !== t || S.subject !== subject) return;
    S.labels = data.labels;
    S.others = data.others || {};
    S.prefill = data.prefill;
    // a pre-fill is the detector's, not saved: the server has no labels there yet
    const base = data.prefill ? {} : data.labels;
    S.sync[syncKey(t, subject)] = { version: data.version, base,
      local: JSON.parse(JSON.stringify(base)) };
    S.loaded = true;
    renderSubjects();
    renderSuggestions();
    const loads = S.views.map((view) => new Promise((resolve) => {
      const image = new Image();
      image.onload = () => { view.image = image; resolve(); };
      image.onerror = () => { view.image = null; resolve(); };
      view.image = null;
      image.src = `/api/image/${t}/${encodeURIComponent(view.cam.name)}`;
    }));
    await Promise.all(loads);
    await refreshAssist(t, JSON.parse(snapshot()));
  });
  draw();
  S.ready = true;
}

// ------------------------------------------------------------------ drawing
function drawPoint(ctx, x, y, color, kind) {
  ctx.beginPath();
  ctx.arc(x, y, kind === 'ghost' ? 6 : 4, 0, 2 * Math.PI);
  if (kind === 'ghost') {
    ctx.setLineDash([3, 2]);
    ctx.strokeStyle = color;
    ctx.lineWidth = 2;
    ctx.stroke();
    ctx.setLineDash([]);
  } else {
    ctx.fillStyle = color;
    ctx.fill();
    ctx.lineWidth = kind === 'flagged' ? 3 : 1;
    ctx.strokeStyle = kind === 'flagged' ? '#ff0000' : '#000';
    ctx.stroke();
  }
}

function viewPoints(view) {
  // keypoint -> [u, v, kind] : clicked labels, else ghosts
  const out = {};
  const clicks = S.labels[view.cam.name] || {};
  for (const [kp, info] of Object.entries(S.assist)) {
    const g = info.views[view.cam.name];
    if (g && g.ghost && !clicks[kp]) out[kp] = [g.ghost[0], g.ghost[1], 'ghost'];
  }
  for (const [kp, uv] of Object.entries(clicks)) {
    const a = S.assist[kp] && S.assist[kp].views[view.cam.name];
    out[kp] = [uv[0], uv[1], a && a.flagged ? 'flagged' : 'label'];
  }
  return out;
}

// The other subjects' labels of the instant: small grey squares with the subject's id.
function drawOthers(ctx, view) {
  ctx.lineWidth = 1;
  ctx.font = '10px sans-serif';
  for (const [subject, labels] of Object.entries(S.others)) {
    for (const uv of Object.values(labels[view.cam.name] || {})) {
      const [x, y] = toCanvas(view, uv[0], uv[1]);
      ctx.strokeStyle = 'rgba(200,200,200,0.9)';
      ctx.strokeRect(x - 3, y - 3, 6, 6);
      ctx.fillStyle = 'rgba(200,200,200,0.9)';
      ctx.fillText(subject, x + 4, y - 4);
    }
  }
}

function drawView(view) {
  if (!view.fitted) fit(view);
  const ctx = view.canvas.getContext('2d');
  ctx.setTransform(1, 0, 0, 1, 0, 0);
  ctx.fillStyle = '#111';
  ctx.fillRect(0, 0, view.canvas.width, view.canvas.height);
  if (view.image) {
    ctx.setTransform(view.s, 0, 0, view.s, view.tx, view.ty);
    ctx.imageSmoothingEnabled = view.s < 2;
    ctx.drawImage(view.image, -0.5, -0.5, view.cam.width, view.cam.height);
    ctx.setTransform(1, 0, 0, 1, 0, 0);
  }
  const names = S.summary.keypoints;
  const points = viewPoints(view);
  // skeleton
  ctx.lineWidth = 1.5;
  ctx.strokeStyle = 'rgba(255,255,255,0.6)';
  for (const [a, b] of S.summary.bones) {
    const p = points[names[a]];
    const q = points[names[b]];
    if (!p || !q) continue;
    const [x1, y1] = toCanvas(view, p[0], p[1]);
    const [x2, y2] = toCanvas(view, q[0], q[1]);
    ctx.setLineDash(p[2] === 'ghost' || q[2] === 'ghost' ? [4, 3] : []);
    ctx.beginPath();
    ctx.moveTo(x1, y1);
    ctx.lineTo(x2, y2);
    ctx.stroke();
  }
  ctx.setLineDash([]);
  drawOthers(ctx, view);
  // epipolar curves of the selected keypoint
  const curves = S.epipolar[view.cam.name] || {};
  ctx.strokeStyle = COLORS[S.selected % COLORS.length];
  ctx.lineWidth = 1;
  for (const lines of Object.values(curves)) {
    for (const line of lines) {
      ctx.beginPath();
      line.forEach(([u, v], i) => {
        const [x, y] = toCanvas(view, u, v);
        if (i === 0) ctx.moveTo(x, y); else ctx.lineTo(x, y);
      });
      ctx.stroke();
    }
  }
  for (const [kp, [u, v, kind]] of Object.entries(points)) {
    const c = names.indexOf(kp);
    const [x, y] = toCanvas(view, u, v);
    drawPoint(ctx, x, y, COLORS[c % COLORS.length], kind);
    if (c === S.selected) {
      ctx.strokeStyle = '#fff';
      ctx.lineWidth = 1;
      ctx.strokeRect(x - 9, y - 9, 18, 18);
    }
  }
  // reprojection errors
  const kp = keypointName();
  const sel = S.assist[kp] && S.assist[kp].views[view.cam.name];
  const errors = Object.values(S.assist).map((i) => i.views[view.cam.name])
    .filter((v) => v && v.error !== null);
  const anyFlag = errors.some((v) => v.flagged);
  let text = '';
  if (sel && sel.error !== null) text += `${kp}: ${sel.error.toFixed(1)} px`;
  if (errors.length) {
    const mean = errors.reduce((a, v) => a + v.error, 0) / errors.length;
    text += `${text ? ' | ' : ''}mean ${mean.toFixed(1)} px (${errors.length})`;
  }
  view.err.textContent = text;
  view.err.classList.toggle('flagged', Boolean(sel && sel.flagged));
  view.box.classList.toggle('flagged', anyFlag);
}

function draw() {
  if (!S.summary) return;
  S.views.forEach(drawView);
}

// ------------------------------------------------------------------ side panel
function renderKeypoints() {
  const list = $('keypoints');
  list.replaceChildren();
  S.summary.keypoints.forEach((kp, c) => {
    const count = Object.values(S.labels).filter((p) => p[kp]).length;
    const swatch = element('span', { className: 'swatch' });
    swatch.style.background = COLORS[c % COLORS.length];
    const li = element('li', {}, swatch, kp, element('span', { className: 'count' },
      `${count}/${S.views.length}${S.assist[kp] ? ' 3D' : ''}`));
    li.className = c === S.selected ? 'selected' : '';
    li.dataset.keypoint = kp;
    li.addEventListener('click', () => selectKeypoint(c));
    list.append(li);
  });
}

// ------------------------------------------------------------------ subjects
// The subject buttons: every subject the table or an import knows, those labelled at this
// instant, the selected one, and 'new' (the next free id). Names are text only.
function renderSubjects() {
  const holder = $('subjects');
  holder.replaceChildren();
  const names = {};
  (S.summary.subjects || []).forEach((s) => { names[s.id] = s.name; });
  const ids = new Set([0, S.subject, ...Object.keys(names).map(Number),
    ...Object.keys(S.others).map(Number), ...S.subjectIds]);
  S.subjectIds = [...ids].sort((a, b) => a - b);
  S.subjectIds.forEach((id) => {
    const label = names[id] ? `${id} (${names[id]})` : String(id);
    const here = id === S.subject ? Object.keys(S.labels).length > 0
      : Boolean(S.others[String(id)]);
    const button = element('button', { textContent: label + (here ? ' *' : '') });
    button.className = id === S.subject ? 'current' : '';
    button.dataset.subject = String(id);
    button.addEventListener('click', () => selectSubject(id));
    holder.append(button);
  });
  const next = Math.max(...S.subjectIds) + 1;
  const add = element('button', { textContent: 'new' });
  add.dataset.subject = 'new';
  add.title = `label a new subject (id ${next})`;
  add.addEventListener('click', () => selectSubject(next));
  holder.append(add);
  $('subject-current').textContent = names[S.subject]
    ? `subject ${S.subject} (${names[S.subject]})` : `subject ${S.subject}`;
}

// Edit another subject's labels of this instant (this tab's saves go out first).
function selectSubject(id) {
  if (id === S.subject || id < 0 || id > 99) return Promise.resolve();
  S.subject = id;
  if (!S.subjectIds.includes(id)) S.subjectIds.push(id);
  return openInstant(S.t);
}
S.selectSubject = selectSubject;

function instantButton(t, extra) {
  const button = document.createElement('button');
  button.textContent = extra ? `${t} (${extra})` : String(t);
  button.className = t === S.t ? 'current' : '';
  button.addEventListener('click', () => openInstant(t));
  return button;
}

function renderLabelled() {
  const holder = $('labelled');
  holder.replaceChildren();
  if (!S.labelled.length) holder.textContent = 'none yet';
  S.labelled.forEach((t) => holder.append(instantButton(t)));
}

function renderSuggestions() {
  const holder = $('suggestions');
  holder.replaceChildren();
  if (!S.suggest) return;
  const here = S.suggest.disagreement[String(S.t)];
  $('disagreement').textContent = here === undefined || here === null ? ''
    : `detector disagreement ${here.toFixed(1)} px${S.prefill ? ' (pre-filled)' : ''}`;
  const method = S.suggest.method === 'detector'
    ? 'k-means on the detector\'s 3D poses (and time); disagreement = reprojection error (px) ' +
      'of the all-view triangulation'
    : 'k-means on image thumbnails (16x12 grey, all views) and time; no --model given';
  $('suggest-method').textContent = method;
  S.suggest.instants.forEach((t) => {
    const d = S.suggest.disagreement[String(t)];
    holder.append(instantButton(t, d === undefined || d === null ? '' : d.toFixed(1) + ' px'));
  });
}

// ------------------------------------------------------------------ keyboard
document.addEventListener('keydown', (event) => {
  if (event.target.tagName === 'INPUT') return;
  const key = event.key;
  if ((event.ctrlKey || event.metaKey) && key.toLowerCase() === 'z') {
    event.preventDefault();
    if (S.loaded) undo();
  } else if (key === 'a') {
    if (S.loaded) acceptGhosts();
  } else if (key === 'Delete' || key === 'Backspace') {
    event.preventDefault();
    if (!S.loaded) return;
    const kp = keypointName();
    const cams = event.shiftKey ? S.views.map((v) => v.cam.name)
      : (S.hoverView ? [S.hoverView] : []);
    if (cams.some((c) => S.labels[c] && S.labels[c][kp])) {
      pushHistory();
      cams.forEach((c) => deletePoint(c, kp));
      changed();
    }
  } else if (key === 'n' || key === 'ArrowDown') {
    event.preventDefault();
    selectKeypoint(S.selected + 1);
  } else if (key === 'p' || key === 'ArrowUp') {
    event.preventDefault();
    selectKeypoint(S.selected - 1);
  } else if (key === 'ArrowRight') {
    openInstant(S.t + 1);
  } else if (key === 'ArrowLeft') {
    openInstant(S.t - 1);
  } else if (key === 'f') {
    S.views.forEach(fit);
    draw();
  } else if (key === 's') {
    const i = S.subjectIds.indexOf(S.subject);
    selectSubject(S.subjectIds[(i + 1) % S.subjectIds.length]);
  }
});

async function start() {
  S.summary = await api('GET', '/api/summary');
  S.labelled = S.summary.labelled;
  $('recording').textContent = S.summary.recording;
  $('labels-path').textContent = S.summary.labels_path;
  $('instant-count').textContent = `/ ${S.summary.instants.length - 1}`;
  $('instant').max = S.summary.instants.length - 1;
  $('instant').addEventListener('change', (e) => openInstant(Number(e.target.value)));
  $('prev').addEventListener('click', () => openInstant(S.t - 1));
  $('next').addEventListener('click', () => openInstant(S.t + 1));
  buildViews();
  renderKeypoints();
  const first = new URLSearchParams(window.location.search).get('t');
  await openInstant(first === null ? (S.labelled[0] || 0) : Number(first));
  api('GET', '/api/suggest').then((data) => { S.suggest = data; renderSuggestions(); })
    .catch((error) => { $('suggest-method').textContent = 'unavailable: ' + error.message; });
}

start().catch((error) => setStatus('error: ' + error.message, 'error'));
