// Shared by the viewer's browser test and timing script: their command line, the `ltmapper view`
// process, and headless chromium with software WebGL.
import { chromium } from 'playwright-core';
import { spawn } from 'node:child_process';
import fs from 'node:fs';

// --key value pairs over `defaults` (every key must be one of them); `required` must be set.
export function parseArgs(defaults, required) {
  const a = { ...defaults };
  const argv = process.argv.slice(2);
  for (let i = 0; i < argv.length; i += 2) {
    const key = argv[i].replace(/^--/, '');
    if (!(key in a) || argv[i + 1] === undefined) throw new Error(`usage: unknown or incomplete option ${argv[i]}`);
    a[key] = argv[i + 1];
  }
  for (const key of required) if (!a[key]) throw new Error(`--${key} is required`);
  if (!fs.existsSync(a.chromium)) throw new Error(`${a.chromium}: no chromium (scripts/install-deps.sh installs it)`);
  return a;
}

// Starts `ltmapper view --port 0` and resolves once it listens: { proc, url, readyMs, log() }.
export function startViewer(exe, store, { threads = '2', timeoutMs = 60000 } = {}) {
  const t0 = Date.now();
  const proc = spawn(exe, ['view', '--store', store, '--port', '0', '--threads', threads], { stdio: ['ignore', 'pipe', 'pipe'] });
  let log = '';
  return new Promise((resolve, reject) => {
    const timer = setTimeout(() => reject(new Error(`ltmapper view did not start:\n${log}`)), timeoutMs);
    const onData = (d) => {
      log += d;
      const m = log.match(/on (http:\/\/127\.0\.0\.1:\d+\/)/);
      if (m) { clearTimeout(timer); resolve({ proc, url: m[1], readyMs: Date.now() - t0, log: () => log }); }
    };
    proc.stdout.on('data', onData);
    proc.stderr.on('data', onData);
    proc.on('exit', (code) => { clearTimeout(timer); reject(new Error(`ltmapper view exited (${code}):\n${log}`)); });
  });
}

// SwiftShader: WebGL in software, the same on every machine (no GPU needed).
export function launchBrowser(executablePath) {
  return chromium.launch({ executablePath, headless: true, args: ['--use-angle=swiftshader', '--enable-unsafe-swiftshader'] });
}
