// Timing of `ltmapper view` on a store (the figures in README "View the map"): the server's
// start until it listens (the latest session's tiles and level 0 built), then in headless
// chromium (software WebGL) the page's first frame with the browser started cold, and again on
// reloads with the browser warm; each time also until the tiles near the camera are refined
// (no tile request under way) and the points drawn per level.
//
//   node web/test/view_timing.mjs --exe build/apps/ltmapper --store OUT/map.ltmap [--reloads 3]
import { chromium } from 'playwright-core';
import { spawn } from 'node:child_process';

function args() {
  const a = { exe: '', store: '', chromium: '/usr/bin/chromium', reloads: '3', threads: '2' };
  const argv = process.argv.slice(2);
  for (let i = 0; i < argv.length; i += 2) {
    const key = argv[i].replace(/^--/, '');
    if (!(key in a) || argv[i + 1] === undefined) throw new Error(`usage: unknown or incomplete option ${argv[i]}`);
    a[key] = argv[i + 1];
  }
  if (!a.exe || !a.store) throw new Error('--exe and --store are required');
  return a;
}

function startViewer(a) {
  const t0 = Date.now();
  const proc = spawn(a.exe, ['view', '--store', a.store, '--port', '0', '--threads', a.threads], { stdio: ['ignore', 'pipe', 'pipe'] });
  let log = '';
  return new Promise((resolve, reject) => {
    const onData = (d) => {
      log += d;
      const m = log.match(/on (http:\/\/127\.0\.0\.1:\d+\/)/);
      if (m) resolve({ proc, url: m[1], readyMs: Date.now() - t0, log: () => log });
    };
    proc.stdout.on('data', onData);
    proc.stderr.on('data', onData);
    proc.on('exit', (code) => reject(new Error(`ltmapper view exited (${code}):\n${log}`)));
  });
}

async function open(page, url) {
  const t0 = Date.now();
  await page.goto(url);
  await page.waitForFunction(() => window.__ltmView.firstFrameMs !== null || window.__ltmView.error, null, { timeout: 120000 });
  await page.waitForFunction(() => window.__ltmView.lodIdle || window.__ltmView.error, null, { timeout: 120000 });
  const v = await page.evaluate(() => ({ first: window.__ltmView.firstFrameMs, error: window.__ltmView.error,
                                         levels: window.__ltmView.tileLevels, points: window.__ltmView.points }));
  if (v.error) throw new Error(v.error);
  return { ...v, refinedMs: Date.now() - t0 };
}

async function main() {
  const a = args();
  const viewer = await startViewer(a);
  console.log(`server listening ${(viewer.readyMs / 1000).toFixed(2)} s after start`);
  try {
    const t0 = Date.now();
    const browser = await chromium.launch({ executablePath: a.chromium, headless: true,
                                            args: ['--use-angle=swiftshader', '--enable-unsafe-swiftshader'] });
    const page = await browser.newPage({ viewport: { width: 1280, height: 800 } });
    const launchMs = Date.now() - t0;
    const show = (what, r) => console.log(`${what}: first frame ${(r.first / 1000).toFixed(2)} s after navigation; ` +
                                         `refined ${(r.refinedMs / 1000).toFixed(2)} s; tiles per level ${JSON.stringify(r.levels)}; ${r.points} points drawn`);
    const cold = await open(page, viewer.url);
    show(`cold browser (launch ${(launchMs / 1000).toFixed(2)} s)`, cold);
    for (let k = 0; k < Number(a.reloads); k++) show(`warm reload ${k + 1}`, await open(page, viewer.url));
    await browser.close();
  } finally {
    viewer.proc.kill('SIGTERM');
  }
  console.log(viewer.log().split('\n').filter((l) => /tiles of|points at/.test(l)).slice(0, 8).join('\n'));
}

main().catch((e) => { console.error(`view timing FAILED: ${e.stack || e}`); process.exit(1); });
