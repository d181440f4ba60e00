// Browser test of `ltmapper view` (issue #19): Debian's chromium, headless, driven by
// playwright-core. Simulates a small 3-drive store (or takes --store), starts the viewer, opens the
// page and checks what a user sees: the first frame, the session name, the slider to session 0 and
// back, level of detail (tiles refined near the camera within the point budget, more after a
// zoom), the changes and coverage overlays, the meta toggle, a click on a changed object; pixels
// at projected map points are drawn (not the background) in their class colour. Saves a
// screenshot PNG.
//
//   node web/test/view_test.mjs --exe build/apps/ltmapper --screenshot build/view_browser.png
//        [--store OUT/map.ltmap] [--chromium /usr/bin/chromium] [--keep DIR]
import { execFileSync } from 'node:child_process';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import assert from 'node:assert/strict';
import { launchBrowser, parseArgs, startViewer } from './viewer_process.mjs';

const STEP_TIMEOUT_MS = 20000;        // one page step (load a cloud, fly) at most
const SAMPLES_PER_CLASS = 200;        // projected points checked per class
const MIN_DRAWN_SHARE = 0.95;         // share of them whose pixel is not the background
const MIN_COLOUR_SHARE = 0.5;         // share of static points showing the static class colour
const VIEWPORT = { width: 1280, height: 800 };
const BACKGROUND = [0x15, 0x18, 0x1d];  // web/viewer.js BACKGROUND

function args() {
  return parseArgs({ exe: '', store: '', screenshot: 'view_browser.png', chromium: '/usr/bin/chromium', keep: '' }, ['exe']);
}

// A small store: 3 simulated drives of 30 keyframes, lighter stage parameters.
function makeStore(exe, dir) {
  const w = (name, text) => fs.writeFileSync(path.join(dir, name), text);
  w('sim.yaml', 'seed: 4\nworld: {extent_m: 150.0}\nroute: {sessions: 3, keyframes: 30, keyframe_spacing_m: 4.0}\n' +
                'hd: {cars: 2, pedestrians: 2}\n');
  w('slam.yaml', 'refine: {rounds: 0}\nsc: {max_loops_per_pair: 6}\n');
  w('removert.yaml', 'map_voxel_m: 0.3\n');
  const run = (...argv) => execFileSync(exe, argv, { stdio: ['ignore', 'ignore', 'inherit'] });
  run('sim', '--quiet', '--config', path.join(dir, 'sim.yaml'), '--out', path.join(dir, 'sim'));
  const sessions = ['session_00', 'session_01', 'session_02'].map((s) => path.join(dir, 'sim/sessions', s));
  run('run', '--quiet', '--threads', '2', '--slam-config', path.join(dir, 'slam.yaml'), '--removert-config',
      path.join(dir, 'removert.yaml'), '--out', path.join(dir, 'out'), '--sessions', ...sessions);
  return path.join(dir, 'out/map.ltmap');
}

// Waits until the page has shown `count` clouds (window.__ltmView.loaded) and has no tile
// request under way, without an error.
async function waitLoaded(page, count) {
  await page.waitForFunction((n) => (window.__ltmView.loaded >= n && window.__ltmView.lodIdle) || window.__ltmView.error,
                             count, { timeout: STEP_TIMEOUT_MS });
  const err = await page.evaluate(() => window.__ltmView.error);
  assert.equal(err, null, `page error: ${err}`);
}

// In the page: project up to `samples` points of each class, read the canvas there, and count
// those whose pixel is drawn (not the background) and those in the class's own colour (or in
// `colour`, the coverage layer's). The map is one group per tile, one THREE.Points per class in it.
function probePixels({ samples, background, group, colour = null }) {
  const { renderer, camera, scene, classes } = window.__ltmView.debug;
  const byClass = new Map();
  window.__ltmView.debug[group].traverse((o) => {
    if (!o.isPoints) return;
    if (!byClass.has(o.userData.cls)) byClass.set(o.userData.cls, []);
    byClass.get(o.userData.cls).push(o.geometry.attributes.position);
  });
  renderer.render(scene, camera);
  const gl = renderer.getContext();
  const W = gl.drawingBufferWidth, H = gl.drawingBufferHeight;
  const px = new Uint8Array(W * H * 4);
  gl.readPixels(0, 0, W, H, gl.RGBA, gl.UNSIGNED_BYTE, px);
  const v = camera.position.clone();
  const out = {};
  for (const [cls, parts] of byClass) {
    const rgb = colour || classes.get(cls).rgb;
    const r = { tried: 0, drawn: 0, colour: 0, places: [] };
    const count = parts.reduce((n, p) => n + p.count, 0);
    // Spread over the whole class (its points are in tile and file order: the first ones are
    // one corner of the map); those off screen are not tried.
    const stride = Math.max(1, Math.floor(count / samples));
    for (let j = 0; j < count && r.tried < samples; j += stride) {
      let i = j, part = 0;
      while (i >= parts[part].count) i -= parts[part++].count;
      v.fromBufferAttribute(parts[part], i).project(camera);
      if (Math.abs(v.x) > 0.95 || Math.abs(v.y) > 0.95 || Math.abs(v.z) > 1) continue;
      const x = Math.round((v.x + 1) / 2 * W - 0.5), y = Math.round((v.y + 1) / 2 * H - 0.5);
      const k = 4 * (y * W + x);
      const c = [px[k], px[k + 1], px[k + 2]];
      r.tried += 1;
      if (c.some((ch, j) => Math.abs(ch - background[j]) > 8)) r.drawn += 1;
      if (c.every((ch, j) => Math.abs(ch - rgb[j]) <= 8)) r.colour += 1;
      if (r.places.length < 20) r.places.push([x, H - 1 - y, c]);
    }
    out[classes.get(cls).name] = r;
  }
  return out;
}

// `colourClass`: the class whose points must mostly show its own colour (the report's).
async function checkPixels(page, what, group = 'cloudGroup', colourClass = 'static', colour = null) {
  const probe = await page.evaluate(probePixels, { samples: SAMPLES_PER_CLASS, background: BACKGROUND, group, colour });
  let tried = 0, drawn = 0;
  for (const r of Object.values(probe)) tried += r.tried, drawn += r.drawn;
  assert.ok(tried > 50, `${what}: only ${tried} map points on screen: ${JSON.stringify(probe)}`);
  assert.ok(drawn >= MIN_DRAWN_SHARE * tried, `${what}: ${drawn} of ${tried} point places show the background`);
  const st = colourClass ? probe[colourClass] : Object.values(probe).reduce(
      (a, r) => ({ tried: a.tried + r.tried, colour: a.colour + r.colour }), { tried: 0, colour: 0 });
  assert.ok(st && st.colour >= MIN_COLOUR_SHARE * st.tried,
            `${what}: ${colourClass} points not in the report's colour: ${JSON.stringify(probe)}`);
  console.log(`${what}: ${drawn}/${tried} point places drawn; ` +
              Object.entries(probe).map(([k, r]) => `${k} ${r.colour}/${r.tried} in class colour`).join(', '));
}

async function runPage(page, url, info) {
  const t0 = Date.now();
  await page.goto(url);
  await waitLoaded(page, 1);
  const firstFrameMs = await page.evaluate(() => window.__ltmView.firstFrameMs);
  console.log(`first frame ${(firstFrameMs / 1000).toFixed(2)} s after navigation start (${Date.now() - t0} ms incl. navigation)`);
  const latest = info.sessions[info.latest].name;
  assert.match(await page.textContent('#session-label'), new RegExp(`Session ${info.latest}: ${latest}`));
  await checkPixels(page, `session ${info.latest} (live)`);
  const pointsLatest = await page.evaluate(() => window.__ltmView.points);
  await checkLod(page, info, 'opened');
  await page.focus('#session');
  await page.keyboard.press('Home');  // the slider to session 0, as a user does
  await waitLoaded(page, 2);
  assert.match(await page.textContent('#session-label'), new RegExp(`Session 0: ${info.sessions[0].name}`));
  assert.equal(await page.evaluate(() => window.__ltmView.session), 0);
  const points0 = await page.evaluate(() => window.__ltmView.points);
  await checkPixels(page, 'session 0');
  await page.keyboard.press('End');  // and back
  await waitLoaded(page, 3);
  assert.equal(await page.evaluate(() => window.__ltmView.points), pointsLatest);
  assert.match(await page.textContent('#session-label'), new RegExp(latest));
  await page.check('#changes');  // the latest step's changes over the map: ND removed in orange
  await waitLoaded(page, 4);
  await checkPixels(page, `session ${info.latest} changes`, 'changeGroup', 'nd_strong');
  await page.uncheck('#changes');
  await waitLoaded(page, 5);
  await page.check('#coverage');  // the latest step's new territory, in the coverage colour
  await waitLoaded(page, 6);
  const coverage = await page.evaluate(() => window.__ltmView.coveragePoints);
  console.log(`coverage of session ${info.latest}: ${coverage} points`);
  if (coverage > 0) await checkPixels(page, `session ${info.latest} coverage`, 'coverageGroup', null, info.coverage_rgb);
  await page.uncheck('#coverage');
  await waitLoaded(page, 7);
  assert.equal(await page.evaluate(() => window.__ltmView.debug.coverageGroup.children.length), 0);
  await page.click('#layer-meta');
  await waitLoaded(page, 8);
  assert.equal(await page.evaluate(() => window.__ltmView.layer), 'meta');
  assert.match(await page.textContent('#session-label'), /Meta map/);
  await checkPixels(page, 'meta');
  await page.click('#layer-at');
  await waitLoaded(page, 9);
  console.log(`points: session 0 ${points0}, session ${info.latest} ${pointsLatest}`);
}

// Zoom in (the wheel over the middle of the view, where the last step put the camera's target):
// the tile nearest the target, close to the camera now, is drawn at the finest level.
async function zoomIn(page, info) {
  const loaded = await page.evaluate(() => window.__ltmView.loaded);
  await page.mouse.move(VIEWPORT.width / 2, VIEWPORT.height / 2);
  for (let k = 0; k < 3; k++) await page.mouse.wheel(0, -200);
  await page.waitForTimeout(500);
  await waitLoaded(page, loaded);
  await checkLod(page, info, 'zoomed in');
  const near = await page.evaluate(() => {
    const { controls, camera, tiles } = window.__ltmView.debug;
    const list = tiles().list;
    let best = list[0];
    for (const t of list) if (t.box.distanceToPoint(controls.target) < best.box.distanceToPoint(controls.target)) best = t;
    return { id: best.id, level: best.level, levels: tiles().levels.length,
             distance: best.box.distanceToPoint(camera.position) };
  });
  console.log(`zoomed in: tile ${near.id} at the camera's target, ${near.distance.toFixed(1)} m away, level ${near.level}`);
  assert.equal(near.level, near.levels - 1, `zoom: the tile at the target is not at the finest level: ${JSON.stringify(near)}`);
}

// Level of detail as drawn: tiles per level, points within the budget, some tile finer than
// level 0 (a map this size has more points than level 0 holds), and the time to draw a frame.
async function checkLod(page, info, what) {
  const s = await page.evaluate(() => {
    const { renderer, scene, camera } = window.__ltmView.debug;
    const t = performance.now();
    const gl = renderer.getContext(), px = new Uint8Array(4);
    for (let k = 0; k < 5; k++) {
      renderer.render(scene, camera);
      gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);  // waits for the frame to be drawn
    }
    return { levels: window.__ltmView.tileLevels, points: window.__ltmView.points, frameMs: (performance.now() - t) / 5 };
  });
  console.log(`LOD ${what}: tiles per level ${JSON.stringify(s.levels)} (voxels ${JSON.stringify(info.levels)} m), ` +
              `${s.points} points drawn, ${s.frameMs.toFixed(0)} ms a frame (software WebGL)`);
  assert.ok(s.points <= info.point_budget, `${what}: ${s.points} points drawn, budget ${info.point_budget}`);
  assert.ok(s.levels.slice(1).some((k) => k > 0), `${what}: no tile refined past level 0: ${JSON.stringify(s.levels)}`);
  return s.levels;
}

// The measure tool: two clicks on drawn map points (outside the panels) give a distance.
async function measure(page) {
  await page.check('#measure');
  const probe = await page.evaluate(probePixels, { samples: SAMPLES_PER_CLASS, background: BACKGROUND, group: 'cloudGroup' });
  const panels = await page.evaluate(() => [...document.querySelectorAll('.panel')].map((e) => e.getBoundingClientRect().toJSON()));
  const free = ([x, y]) => !panels.some((r) => x >= r.left - 5 && x <= r.right + 5 && y >= r.top - 5 && y <= r.bottom + 5);
  const places = Object.values(probe).flatMap((r) => r.places).filter(free);
  assert.ok(places.length >= 2, `measure: no two map points outside the panels: ${JSON.stringify(places)}`);
  const a = places[0];
  const b = places.reduce((far, p) => (Math.hypot(p[0] - a[0], p[1] - a[1]) > Math.hypot(far[0] - a[0], far[1] - a[1]) ? p : far));
  await page.mouse.click(a[0], a[1]);
  await page.waitForFunction(() => document.getElementById('measure-text').textContent.startsWith('first'), null,
                             { timeout: STEP_TIMEOUT_MS }).catch(() => {});
  await page.mouse.click(b[0], b[1]);
  await page.waitForFunction(() => / m\)$/.test(document.getElementById('measure-text').textContent), null,
                             { timeout: STEP_TIMEOUT_MS }).catch(() => {});
  const text = await page.textContent('#measure-text');
  assert.match(text, /^\d+\.\d\d m \(horizontal \d+\.\d\d m, height -?\d+\.\d\d m\)$/, `measure: ${text}`);
  assert.ok(parseFloat(text) > 0, `measure: ${text}`);
  console.log(`measure: ${text}`);
  await page.uncheck('#measure');
}

async function clickObject(page, objects) {
  if (!objects.length) return console.log('no objects in the run: object click not tested');
  await page.waitForSelector('#object-list div');
  await page.click('#object-list div >> nth=0');
  const o = objects[0];
  // The box, and the map at the object's step with that step's changes (the object among them).
  await page.waitForFunction((n) => window.__ltmView.debug.boxGroup.children.length === 1 &&
                             window.__ltmView.session === n && window.__ltmView.debug.changeGroup.children.length > 0,
                             o.session, { timeout: STEP_TIMEOUT_MS });
  const detail = await page.textContent('#object-detail');
  assert.match(detail, new RegExp(`#${o.id} ${o.change} \\(${o.class}\\)`));
  // A move names its other end, and the alike objects when its partner was a choice among them.
  if (o.partner >= 0) assert.match(detail, new RegExp(`the other end is #${o.partner}`));
  const candidates = o.move_candidates || [];
  if (o.partner >= 0 && candidates.length > 1) assert.match(detail, new RegExp(`a choice among the alike #${candidates.join(', #')}`));
  // One that could have moved but stands among unchanged objects of its shape says why it is no move.
  if (o.partner < 0 && candidates.length && o.alike_beside) assert.match(detail, new RegExp(`no move: #${candidates.join(', #')} could be it`));
  if (o.partner < 0) assert.doesNotMatch(detail, /the other end/);
  // A view whose face goes on past its ends, unseen, says how much longer the object may be.
  if (o.hidden_length_m > 0) assert.match(detail, new RegExp(`may be up to ${o.hidden_length_m.toFixed(1)} m longer`));
  else assert.doesNotMatch(detail, /may be up to/);
  assert.match(await page.textContent('#session-label'), new RegExp(`Session ${o.session}: `));
  await page.waitForTimeout(1000);  // the camera's flight (0.8 s)
  console.log(`object #${o.id}: ${detail.split('\n')[0]}`);
}

// Opens the page on a running viewer and checks it; returns when the screenshot is written.
async function checkInBrowser(a, viewer) {
  let browser = null;
  try {
    browser = await launchBrowser(a.chromium);
    const page = await browser.newPage({ viewport: VIEWPORT });
    const errors = [];
    page.on('pageerror', (e) => errors.push(String(e)));
    const info = await (await fetch(viewer.url + 'api/info')).json();
    const objects = (await (await fetch(viewer.url + 'api/objects')).json()).objects;
    await runPage(page, viewer.url, info);
    await measure(page);
    await clickObject(page, objects);
    await page.screenshot({ path: a.screenshot });
    await zoomIn(page, info);
    assert.deepEqual(errors, [], 'uncaught errors in the page');
  } finally {
    if (browser) await browser.close();
  }
}

async function main() {
  const a = args();
  const t0 = Date.now();
  const dir = a.keep || fs.mkdtempSync(path.join(os.tmpdir(), 'ltm_view_test_'));
  try {
    fs.mkdirSync(dir, { recursive: true });
    const store = a.store || makeStore(a.exe, dir);
    console.log(`store ${store} ready in ${((Date.now() - t0) / 1000).toFixed(1)} s`);
    const viewer = await startViewer(a.exe, store, { timeoutMs: STEP_TIMEOUT_MS });
    try {
      await checkInBrowser(a, viewer);
    } finally {
      viewer.proc.kill('SIGTERM');
    }
    console.log(`screenshot ${a.screenshot}; browser test passed in ${((Date.now() - t0) / 1000).toFixed(1)} s`);
  } finally {
    if (!a.keep) fs.rmSync(dir, { recursive: true, force: true });
  }
}

main().catch((e) => {
  console.error(`view browser test FAILED: ${e.stack || e}`);
  process.exit(1);
});
