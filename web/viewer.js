// ltmapper view: the map store in 3D (three.js). Talks to the API of src/ltmapper/view
// (docs/FORMATS.md, "Viewer API"): /api/info, /api/tiles, /api/tile, /api/cloud, /api/trajectories,
// /api/objects. Level of detail: the map is drawn from its tiles at level 0 (the coarsest voxel)
// first, then the tiles near the camera are fetched at finer levels within the point budget.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';

const BACKGROUND = 0x15181d;   // page and canvas background (tests check points are not this)
const POINT_SIZE_PX = 2;       // on-screen point size [pixels]
const CHANGE_SIZE_PX = 3;      // the step's changes, drawn over the map [pixels]
const FLY_SECONDS = 0.8;       // camera flight to a clicked object [s]
const OBJECT_VIEW_DIST = 3.0;  // camera distance to a clicked object, in box diagonals
const HEADER_BYTES = 16;       // cloud header: "LTMC", version, count, voxel
const CLICK_SLOP_PX = 4;       // a pointer that moved less than this between down and up clicked
const PICK_PX = 4;             // measure: a click picks points drawn within this many pixels
const LOD_MIN_PX = 1.0;        // a finer level is fetched while its voxel still spans this many pixels
const LOD_PARALLEL = 4;        // tile requests in flight at once
const LOD_DELAY_MS = 150;      // the camera rests this long before tiles are refined
const LOD_SURFACE_GROWTH = 4;  // a tile's points per level finer (surfaces: halved voxel, 4 x points)

const $ = (id) => document.getElementById(id);
const state = {
  info: null, layer: 'at', session: 0, classes: new Map(), classVisible: new Map(),
  showChanges: false, showCoverage: false, measure: [], cloudGroup: new THREE.Group(), changeGroup: new THREE.Group(),
  coverageGroup: new THREE.Group(), trajGroup: new THREE.Group(), boxGroup: new THREE.Group(),
  measureGroup: new THREE.Group(), objects: [], selected: -1, loads: 0, overlays: 0,
  tiles: null, lod: { timer: null, queue: [], inflight: 0 },
};
// What the browser test reads: frames drawn, the cloud on screen (points drawn, tiles per level),
// time to the first frame, whether level-of-detail requests are still under way.
window.__ltmView = { frames: 0, loaded: 0, points: 0, layer: 'at', session: -1, firstFrameMs: null, error: null,
                     lodIdle: false, tileLevels: [], coveragePoints: 0 };

const renderer = new THREE.WebGLRenderer({ antialias: false, preserveDrawingBuffer: true });
renderer.setPixelRatio(1);
renderer.setClearColor(BACKGROUND);
$('view').appendChild(renderer.domElement);
const scene = new THREE.Scene();
scene.add(state.cloudGroup, state.changeGroup, state.coverageGroup, state.trajGroup, state.boxGroup, state.measureGroup);
const camera = new THREE.PerspectiveCamera(60, 1, 0.1, 20000);
camera.up.set(0, 0, 1);  // the map's world frame is z-up
const controls = new OrbitControls(camera, renderer.domElement);
controls.addEventListener('change', () => { render(); scheduleLod(); });
// Test hook (web/test/view_test.mjs reads pixels at projected points and the box shown).
window.__ltmView.debug = { renderer, camera, scene, cloudGroup: state.cloudGroup, changeGroup: state.changeGroup,
                           coverageGroup: state.coverageGroup, boxGroup: state.boxGroup, classes: state.classes,
                           controls, tiles: () => state.tiles };

function render() {
  renderer.render(scene, camera);
  window.__ltmView.frames += 1;
}

function resize() {
  const w = window.innerWidth, h = window.innerHeight;
  renderer.setSize(w, h);
  camera.aspect = w / h;
  camera.updateProjectionMatrix();
  render();
}
window.addEventListener('resize', resize);

async function fetchOk(url) {
  const r = await fetch(url);
  if (!r.ok) throw new Error(`${url}: ${r.status} ${(await r.text()).trim()}`);
  return r;
}

function setStatus(text) { $('status').textContent = text; }
// An element with text set as text (names from the store and objects.json are never parsed as HTML).
function el(tag, { cls = '', text = '', color = null, id = '' } = {}) {
  const e = document.createElement(tag);
  if (cls) e.className = cls;
  if (text) e.textContent = text;
  if (color) e.style.background = rgbCss(color);
  if (id) e.id = id;
  return e;
}
// A legend row: checkbox, colour swatch, label, muted note.
function legendRow(rgb, label, note, noteId = '') {
  const row = el('label', { cls: 'row' });
  const box = el('input');
  box.type = 'checkbox';
  box.checked = true;
  row.append(box, el('span', { cls: 'swatch', color: rgb }), el('span', { text: label }),
             el('span', { cls: 'muted', text: note, id: noteId }));
  return { row, box };
}
function rgbCss(rgb) { return `rgb(${rgb[0]}, ${rgb[1]}, ${rgb[2]})`; }

// ------------------------------------------------------------------------------- the cloud
function decodeCloud(buf) {
  const view = new DataView(buf);
  const magic = String.fromCharCode(...new Uint8Array(buf, 0, 4));
  if (magic !== 'LTMC' || view.getUint32(4, true) !== 1) throw new Error('not an LTMC v1 cloud');
  const n = view.getUint32(8, true);
  if (buf.byteLength !== HEADER_BYTES + 13 * n) throw new Error(`cloud: ${buf.byteLength} bytes for ${n} points`);
  return { n, voxel: view.getFloat32(12, true), xyz: new Float32Array(buf, HEADER_BYTES, 3 * n),
           cls: new Uint8Array(buf, HEADER_BYTES + 12 * n, n) };
}

// One THREE.Points per class, so a class is shown or hidden without touching the buffers.
function splitByClass(cloud) {
  const counts = new Map();
  for (let i = 0; i < cloud.n; i++) counts.set(cloud.cls[i], (counts.get(cloud.cls[i]) || 0) + 1);
  const parts = new Map();
  for (const [c, k] of counts) parts.set(c, { xyz: new Float32Array(3 * k), k: 0 });
  for (let i = 0; i < cloud.n; i++) {
    const p = parts.get(cloud.cls[i]);
    p.xyz.set(cloud.xyz.subarray(3 * i, 3 * i + 3), 3 * p.k++);
  }
  return parts;
}

function clearGroup(group) {
  for (const child of [...group.children]) {
    if (child.isGroup) clearGroup(child);
    else child.geometry.dispose(), child.material.dispose();
    group.remove(child);
  }
}

// Every THREE.Points below a group (the map: one group per tile, one Points per class in it).
function pointsIn(group) {
  const out = [];
  group.traverse((o) => { if (o.isPoints) out.push(o); });
  return out;
}

// `onTop`: drawn over everything else (the step's changes must not hide behind the map).
// `color`: one colour for every class (the coverage layer), else the class colours.
function showCloud(cloud, group, sizePx, onTop = false, color = null) {
  clearGroup(group);
  for (const [c, part] of splitByClass(cloud)) {
    const geom = new THREE.BufferGeometry();
    geom.setAttribute('position', new THREE.BufferAttribute(part.xyz, 3));
    const rgb = color || (state.classes.get(c) || { rgb: [70, 70, 70] }).rgb;
    const mat = new THREE.PointsMaterial({ size: sizePx, sizeAttenuation: false,
                                           color: new THREE.Color(rgbCss(rgb)), depthTest: !onTop });
    const points = new THREE.Points(geom, mat);
    points.renderOrder = onTop ? 1 : 0;
    points.userData.cls = c;
    points.visible = state.classVisible.get(c) !== false;
    group.add(points);
  }
}

// The overlays of the slider's session step, over the map: its changes (PD added, ND removed or
// kept) and its coverage difference (new territory: map keyframes the step created).
async function loadOverlay(layer, on, group, sizePx, color) {
  if (!on || state.layer !== 'at' || state.session === 0) return { cloud: null, group, sizePx, color };
  const buf = await (await fetchOk(`/api/cloud?layer=${layer}&session=${state.session}`)).arrayBuffer();
  return { cloud: decodeCloud(buf), group, sizePx, color };
}

async function loadOverlays() {
  const ticket = ++state.overlays, loads = state.loads;
  const parts = await Promise.all([
    loadOverlay('changes', state.showChanges, state.changeGroup, CHANGE_SIZE_PX, null),
    loadOverlay('coverage', state.showCoverage, state.coverageGroup, CHANGE_SIZE_PX, state.info.coverage_rgb)]);
  if (ticket !== state.overlays || loads !== state.loads) return false;  // replaced meanwhile
  for (const p of parts) {
    if (p.cloud) showCloud(p.cloud, p.group, p.sizePx, true, p.color);
    else clearGroup(p.group);
  }
  window.__ltmView.coveragePoints = parts[1].cloud ? parts[1].cloud.n : 0;
  return true;
}

// An overlay switched on or off: only the overlays are fetched again.
async function reloadOverlays() {
  if (await loadOverlays()) {
    render();
    window.__ltmView.loaded += 1;
  }
}

function tileQuery() {
  return state.layer === 'meta' ? 'layer=meta' : `layer=at&session=${state.session}`;
}

// The map of the slider's session (or meta): the tile index and every tile at level 0 in one
// response, cut into one group per tile; finer levels follow (updateLod).
async function loadCloud() {
  const ticket = ++state.loads;
  const query = tileQuery();
  setStatus('loading…');
  const t = performance.now();
  cancelLod();
  const [index, buf] = await Promise.all([
    fetchOk(`/api/tiles?${query}`).then((r) => r.json()),
    fetchOk(`/api/tile?${query}&tile=all&level=0`).then((r) => r.arrayBuffer())]);
  if (ticket !== state.loads) return;  // a newer request replaced this one
  const cloud = decodeCloud(buf);
  clearGroup(state.cloudGroup);
  const tiles = { query, levels: index.levels, list: [], byId: new Map(), coarseSeconds: (performance.now() - t) / 1000 };
  let at = 0;
  for (const info of index.tiles) {
    const n = info.coarse;
    const coarse = { n, voxel: cloud.voxel, xyz: cloud.xyz.subarray(3 * at, 3 * (at + n)), cls: cloud.cls.subarray(at, at + n) };
    at += n;
    const tile = { id: info.id, raw: info.points, coarse, counts: [n], level: 0, target: 0, loading: -1, drawn: n,
                   box: new THREE.Box3(new THREE.Vector3(...info.lo), new THREE.Vector3(...info.hi)),
                   group: new THREE.Group() };
    showCloud(coarse, tile.group, POINT_SIZE_PX);
    state.cloudGroup.add(tile.group);
    tiles.list.push(tile);
    tiles.byId.set(tile.id, tile);
  }
  if (at !== cloud.n) throw new Error(`tiles: the index counts ${at} points at level 0, the cloud has ${cloud.n}`);
  state.tiles = tiles;
  updateLegendCounts();
  await loadOverlays();
  if (ticket !== state.loads) return;
  if (window.__ltmView.loaded === 0) frameAll();
  render();
  Object.assign(window.__ltmView, { loaded: window.__ltmView.loaded + 1, points: cloud.n, layer: state.layer,
                                    session: state.session });
  // performance.now() counts from the navigation's start: the time a user waits for the map
  // (reading a pixel back waits until the frame is drawn, not only queued).
  if (window.__ltmView.firstFrameMs === null) {
    const gl = renderer.getContext();
    gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, new Uint8Array(4));
    window.__ltmView.firstFrameMs = performance.now();
  }
  updateStatus();
  scheduleLod(0);
}

function updateStatus() {
  const tiles = state.tiles;
  if (!tiles) return;
  const perLevel = tiles.levels.map(() => 0);
  let points = 0;
  for (const tile of tiles.list) perLevel[tile.level] += 1, points += tile.drawn;
  const levels = perLevel.map((k, i) => (k ? `${k} at ${tiles.levels[i].toFixed(2)} m` : '')).filter(Boolean).join(', ');
  Object.assign(window.__ltmView, { points, tileLevels: perLevel });
  setStatus(`${points.toLocaleString()} points in ${tiles.list.length} tiles: ${levels}` +
            `${state.lod.inflight || state.lod.queue.length ? ' (refining…)' : ''}` +
            `\nlevel 0 in ${tiles.coarseSeconds.toFixed(2)} s; ` +
            `first frame ${(window.__ltmView.firstFrameMs / 1000).toFixed(2)} s after opening the page`);
}

// ------------------------------------------------------------------------- level of detail
// Per tile, the finest level whose voxel still spans LOD_MIN_PX pixels at the tile's distance
// (tiles out of view: level 0); nearest tiles first while the points drawn stay within the
// budget (a level's count is known once fetched, else estimated from level 0).
function cancelLod() {
  clearTimeout(state.lod.timer);
  state.lod.queue = [];
  window.__ltmView.lodIdle = false;
}

function scheduleLod(delayMs = LOD_DELAY_MS) {
  if (!state.tiles) return;
  clearTimeout(state.lod.timer);
  window.__ltmView.lodIdle = false;
  state.lod.timer = setTimeout(updateLod, delayMs);
}

function estimate(tile, level) {
  if (tile.counts[level] !== undefined) return tile.counts[level];
  return Math.min(tile.raw, tile.coarse.n * LOD_SURFACE_GROWTH ** level);
}

function updateLod() {
  const tiles = state.tiles;
  if (!tiles) return;
  camera.updateMatrixWorld();
  const frustum = new THREE.Frustum().setFromProjectionMatrix(
      new THREE.Matrix4().multiplyMatrices(camera.projectionMatrix, camera.matrixWorldInverse));
  const focal = renderer.domElement.clientHeight / 2 / Math.tan((camera.fov * Math.PI) / 360);
  const order = tiles.list.map((tile) => {
    const d = Math.max(tile.box.distanceToPoint(camera.position), 1e-3);
    const inView = frustum.intersectsBox(tile.box);
    let want = 0;
    if (inView) for (let k = 1; k < tiles.levels.length; k++) if ((tiles.levels[k] * focal) / d >= LOD_MIN_PX) want = k;
    return { tile, d, want };
  }).sort((a, b) => a.d - b.d);
  let total = 0;
  for (const { tile } of order) total += tile.coarse.n;
  for (const o of order) {
    o.tile.target = 0;
    for (let k = 1; k <= o.want; k++) {
      const extra = estimate(o.tile, k) - estimate(o.tile, k - 1);
      if (total + extra > state.info.point_budget) break;
      total += extra;
      o.tile.target = k;
    }
  }
  state.lod.queue = [];
  for (const { tile } of order) {
    if (tile.target === tile.level || tile.target === tile.loading) continue;
    if (tile.target === 0) showTile(tile, tile.coarse, 0);
    else state.lod.queue.push(tile);
  }
  render();
  pumpLod(state.loads);
}

function showTile(tile, cloud, level) {
  showCloud(cloud, tile.group, POINT_SIZE_PX);
  tile.level = level;
  tile.drawn = cloud.n;
}

function pumpLod(ticket) {
  while (state.lod.inflight < LOD_PARALLEL && state.lod.queue.length) {
    const tile = state.lod.queue.shift(), level = tile.target;
    tile.loading = level;
    state.lod.inflight += 1;
    fetchOk(`/api/tile?${state.tiles.query}&tile=${tile.id}&level=${level}`).then((r) => r.arrayBuffer()).then((buf) => {
      if (ticket !== state.loads) return;
      const cloud = decodeCloud(buf);
      tile.counts[level] = cloud.n;
      // The plan used an estimate: a tile that turns out larger than the budget allows waits
      // for the next plan (which knows its count).
      const drawn = state.tiles.list.reduce((n, t) => n + t.drawn, 0);
      if (tile.target === level && drawn - tile.drawn + cloud.n <= state.info.point_budget) showTile(tile, cloud, level);
      requestRender();
    }).catch(fail).finally(() => {
      tile.loading = -1;
      state.lod.inflight -= 1;
      pumpLod(state.loads);
    });
  }
  if (!state.lod.inflight && !state.lod.queue.length && !window.__ltmView.lodIdle) {
    updateLegendCounts();
    updateStatus();
    render();
    window.__ltmView.lodIdle = true;
  }
}

let renderQueued = false;
function requestRender() {
  if (renderQueued) return;
  renderQueued = true;
  requestAnimationFrame(() => { renderQueued = false; render(); });
}

function frameAll() {
  const box = new THREE.Box3();
  for (const child of pointsIn(state.cloudGroup)) {
    child.geometry.computeBoundingBox();
    box.union(child.geometry.boundingBox);
  }
  if (box.isEmpty()) return;
  const center = box.getCenter(new THREE.Vector3()), size = box.getSize(new THREE.Vector3());
  const r = Math.max(size.x, size.y, 1);
  controls.target.copy(center);
  camera.position.set(center.x - 0.35 * r, center.y - 0.55 * r, center.z + 0.6 * r);
  camera.far = 20 * r;
  camera.updateProjectionMatrix();
  controls.update();
}

// ----------------------------------------------------------------------------- the panels
function sessionText() {
  if (state.layer === 'meta') return 'Meta map (all sessions)';
  const s = state.info.sessions[state.session];
  const ref = s.reference < 0 ? 'central' : `vs ${state.info.sessions[s.reference].name}`;
  const live = state.session === state.info.latest ? ' (live)' : '';
  return `Session ${s.order}: ${s.name}${live}, ${ref}`;
}

function updatePanel() {
  $('session-label').textContent = sessionText();
  $('layer-at').classList.toggle('on', state.layer === 'at');
  $('layer-meta').classList.toggle('on', state.layer === 'meta');
  $('session').disabled = state.layer === 'meta';
  $('changes').disabled = state.layer === 'meta';
  $('coverage').disabled = state.layer === 'meta';
}

function buildLegend() {
  $('legend').replaceChildren();
  for (const c of state.info.classes) {
    state.classes.set(c.id, c);
    const { row, box } = legendRow(c.rgb, c.name, '', `count-${c.id}`);
    box.addEventListener('change', (e) => {
      state.classVisible.set(c.id, e.target.checked);
      for (const p of [...pointsIn(state.cloudGroup), ...state.changeGroup.children])
        if (p.userData.cls === c.id) p.visible = e.target.checked;
      render();
    });
    $('legend').appendChild(row);
  }
}

// Points drawn per class (every tile at its current level).
function updateLegendCounts() {
  const counts = new Map();
  for (const p of pointsIn(state.cloudGroup))
    counts.set(p.userData.cls, (counts.get(p.userData.cls) || 0) + p.geometry.attributes.position.count);
  for (const c of state.info.classes) $(`count-${c.id}`).textContent = counts.get(c.id) ? `${counts.get(c.id)}` : '';
}

function onSessionChange() {
  state.session = Number($('session').value);
  updatePanel();
  loadCloud().catch(fail);
}

function wireControls() {
  $('session').max = String(state.info.latest);
  $('session').value = String(state.info.latest);
  $('session').addEventListener('input', () => { $('session-label').textContent = 'Session ' + $('session').value + '…'; });
  $('session').addEventListener('change', onSessionChange);
  $('layer-at').addEventListener('click', () => { state.layer = 'at'; onSessionChange(); });
  $('layer-meta').addEventListener('click', () => { state.layer = 'meta'; updatePanel(); loadCloud().catch(fail); });
  $('changes').addEventListener('change', (e) => { state.showChanges = e.target.checked; reloadOverlays().catch(fail); });
  $('coverage').addEventListener('change', (e) => { state.showCoverage = e.target.checked; reloadOverlays().catch(fail); });
  $('coverage-swatch').style.background = rgbCss(state.info.coverage_rgb);
  $('go-live').addEventListener('click', () => {
    state.layer = 'at';
    $('session').value = String(state.info.latest);
    onSessionChange();
  });
}

// ---------------------------------------------------------------------------- trajectories
async function loadTrajectories() {
  const data = await (await fetchOk('/api/trajectories')).json();
  for (const s of data.sessions) {
    if (s.positions.length < 2) continue;
    const geom = new THREE.BufferGeometry().setFromPoints(s.positions.map((p) => new THREE.Vector3(...p)));
    const rgb = state.info.session_colors[s.order % state.info.session_colors.length];
    const line = new THREE.Line(geom, new THREE.LineBasicMaterial({ color: new THREE.Color(rgbCss(rgb)) }));
    state.trajGroup.add(line);
    const { row, box } = legendRow(rgb, s.name, `${s.positions.length} poses (${s.source})`);
    box.addEventListener('change', (e) => { line.visible = e.target.checked; render(); });
    $('trajectories').appendChild(row);
  }
  render();
}

// -------------------------------------------------------------------------------- objects
async function loadObjects() {
  const data = await (await fetchOk('/api/objects')).json();
  state.objects = data.objects;
  const list = $('object-list');
  if (!data.objects.length) list.append(el('div', { cls: 'muted', text: 'no objects.json in the run folder' }));
  data.objects.forEach((o, k) => {
    const row = el('div');
    const rgb = (state.classes.get(classId(o.class)) || { rgb: [200, 200, 200] }).rgb;
    row.append(el('span', { cls: 'swatch', color: rgb }), ` #${o.id} ${o.change} `,
               el('span', { cls: 'muted', text: `session ${o.session}, ${o.points} pts` }));
    row.addEventListener('click', () => selectObject(k));
    list.appendChild(row);
  });
}

function classId(name) {
  for (const c of state.info.classes) if (c.name === name) return c.id;
  return 0;
}

function selectObject(k) {
  const o = state.objects[k];
  state.selected = k;
  [...$('object-list').children].forEach((row, i) => row.classList.toggle('selected', i === k));
  const name = (i) => (state.info.sessions[i] || { name: String(i) }).name;
  // A move's partner, and whether it was a choice among alike objects (objects.json's move_candidates).
  const alike = o.move_candidates || [];
  const partner = o.partner < 0 ? '' : `\nmoved: the other end is #${o.partner}` +
      (alike.length > 1 ? ` (a choice among the alike #${alike.join(', #')})` : '');
  // Could have moved, but stands among unchanged objects of its shape (objects.json's alike_beside).
  const among = o.partner >= 0 || !alike.length || !o.alike_beside ? '' :
      `\nno move: #${alike.join(', #')} could be it, but ${o.alike_beside} unchanged object(s) of its shape stand beside it`;
  // How much longer than its box it may be, unseen (objects.json's hidden_length_m).
  const longer = !(o.hidden_length_m > 0) ? '' :
      `\nmay be up to ${o.hidden_length_m.toFixed(1)} m longer: past its ends its face goes on in fragments or was never sampled`;
  $('object-detail').textContent =
      `#${o.id} ${o.change} (${o.class}) in ${name(o.session)} vs ${name(o.reference)}\n` +
      `${o.points} points, confidence ${o.confidence}\n` +
      `box ${o.box.size.map((v) => v.toFixed(1)).join(' x ')} m at ${o.box.center.map((v) => v.toFixed(1)).join(', ')}` +
      partner + among + longer;
  showBox(o);
  flyTo(new THREE.Vector3(...o.box.center), new THREE.Vector3(...o.box.size).length());
  showStep(o.session);
}

// The map at the step that found the object, with that step's changes over it: the object in
// its class colour (PD appeared / ND disappeared).
function showStep(session) {
  if (state.layer === 'at' && state.session === session && state.showChanges) return;
  state.layer = 'at';
  state.showChanges = true;
  $('changes').checked = true;
  $('session').value = String(session);
  onSessionChange();
}

function showBox(o) {
  for (const child of [...state.boxGroup.children]) state.boxGroup.remove(child);
  const rgb = (state.classes.get(classId(o.class)) || { rgb: [255, 255, 255] }).rgb;
  const edges = new THREE.EdgesGeometry(new THREE.BoxGeometry(...o.box.size));
  const box = new THREE.LineSegments(edges, new THREE.LineBasicMaterial({ color: new THREE.Color(rgbCss(rgb)) }));
  box.position.set(...o.box.center);
  box.rotation.z = (o.box.yaw_deg * Math.PI) / 180;
  state.boxGroup.add(box);
}

function flyTo(target, diagonal) {
  const dist = Math.max(diagonal, 1) * OBJECT_VIEW_DIST;
  const fromT = controls.target.clone(), fromP = camera.position.clone();
  const dir = fromP.clone().sub(fromT).normalize();
  const toP = target.clone().add(dir.multiplyScalar(dist));
  const start = performance.now();
  const step = () => {
    const a = Math.min(1, (performance.now() - start) / (FLY_SECONDS * 1000));
    const e = a * a * (3 - 2 * a);
    controls.target.lerpVectors(fromT, target, e);
    camera.position.lerpVectors(fromP, toP, e);
    controls.update();
    if (a < 1) requestAnimationFrame(step);
  };
  requestAnimationFrame(step);
}

// -------------------------------------------------------------------------------- measure
// With "measure" on, two clicks on map points give their distance (3D, horizontal, height).
// The map point drawn under the pointer: among the visible points whose projection lies within
// PICK_PX pixels of it, the one nearest the camera (what the user sees on top).
function pickPoint(clientX, clientY) {
  const rect = renderer.domElement.getBoundingClientRect();
  const px = clientX - rect.left, py = clientY - rect.top;
  const e = new THREE.Matrix4().multiplyMatrices(camera.projectionMatrix, camera.matrixWorldInverse).elements;
  let best = null, bestDepth = Infinity;
  for (const pts of pointsIn(state.cloudGroup)) {
    if (!pts.visible) continue;
    const a = pts.geometry.attributes.position.array;
    for (let i = 0; i < a.length; i += 3) {
      const x = a[i], y = a[i + 1], z = a[i + 2];
      const w = e[3] * x + e[7] * y + e[11] * z + e[15];
      if (w <= 0 || w >= bestDepth) continue;
      const sx = ((e[0] * x + e[4] * y + e[8] * z + e[12]) / w + 1) / 2 * rect.width;
      const sy = (1 - (e[1] * x + e[5] * y + e[9] * z + e[13]) / w) / 2 * rect.height;
      if ((sx - px) ** 2 + (sy - py) ** 2 > PICK_PX * PICK_PX) continue;
      best = new THREE.Vector3(x, y, z);
      bestDepth = w;
    }
  }
  return best;
}

function addMeasurePoint(p) {
  if (state.measure.length === 2) state.measure = [];
  state.measure.push(p);
  clearGroup(state.measureGroup);
  const geom = new THREE.BufferGeometry().setFromPoints(state.measure);
  const mat = { color: 0xffffff, depthTest: false };
  state.measureGroup.add(new THREE.Points(geom, new THREE.PointsMaterial({ ...mat, size: 8, sizeAttenuation: false })));
  if (state.measure.length === 2) {
    state.measureGroup.add(new THREE.Line(geom.clone(), new THREE.LineBasicMaterial(mat)));
    const [a, b] = state.measure;
    const d = b.clone().sub(a);
    $('measure-text').textContent = `${d.length().toFixed(2)} m (horizontal ${Math.hypot(d.x, d.y).toFixed(2)} m, ` +
                                    `height ${d.z.toFixed(2)} m)`;
  } else {
    $('measure-text').textContent = 'first point set: click the second';
  }
  render();
}

function wireMeasure() {
  let down = null;
  renderer.domElement.addEventListener('pointerdown', (e) => { down = [e.clientX, e.clientY]; });
  renderer.domElement.addEventListener('pointerup', (e) => {
    if (!$('measure').checked || !down || Math.hypot(e.clientX - down[0], e.clientY - down[1]) > CLICK_SLOP_PX) return;
    const p = pickPoint(e.clientX, e.clientY);
    if (p) addMeasurePoint(p);
    else $('measure-text').textContent = 'no map point there';
  });
  $('measure').addEventListener('change', (e) => {
    state.measure = [];
    clearGroup(state.measureGroup);
    $('measure-text').textContent = e.target.checked ? 'click two map points' : '';
    render();
  });
}

// ------------------------------------------------------------------------------------ main
function fail(err) {
  window.__ltmView.error = String(err.message || err);
  setStatus('error: ' + window.__ltmView.error);
}

async function main() {
  resize();
  state.info = await (await fetchOk('/api/info')).json();
  $('store-name').textContent = state.info.store;
  if (state.info.latest < 0) throw new Error('the store holds no session yet');
  state.session = state.info.latest;
  buildLegend();
  wireControls();
  wireMeasure();
  updatePanel();
  await loadCloud();
  await Promise.all([loadTrajectories(), loadObjects()]);
}

main().catch(fail);
