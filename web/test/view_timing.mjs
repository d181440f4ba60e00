// Timing of `ltmapper view` on a store (the figures in docs/RESULTS.md "View the map"): the server's
// start until it listens (the latest session's tiles and level 0 built), then in headless
// chromium (software WebGL) the page's first frame with the browser started cold, and again on
// reloads with the browser warm; each time also until the tiles near the camera are refined
// (no tile request under way) and the points drawn per level.
//
//   node web/test/view_timing.mjs --exe build/apps/ltmapper --store OUT/map.ltmap [--reloads 3]
import { launchBrowser, parseArgs, startViewer } from './viewer_process.mjs';

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
  const a = parseArgs({ exe: '', store: '', chromium: '/usr/bin/chromium', reloads: '3', threads: '2' }, ['exe', 'store']);
  const viewer = await startViewer(a.exe, a.store, { threads: a.threads });
  console.log(`server listening ${(viewer.readyMs / 1000).toFixed(2)} s after start`);
  try {
    const t0 = Date.now();
    const browser = await launchBrowser(a.chromium);
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
