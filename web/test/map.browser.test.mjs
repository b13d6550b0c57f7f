// map.browser.test.mjs: the web map (map.html, MapLibre GL JS from npm) in headless
// Chromium with software WebGL (SwiftShader), against a live terrad.
//
// Starts `terrad serve` on a free loopback port and a second plain HTTP server on another
// port (another origin) serving a bare MapLibre page that uses terrad's TileJSON, map
// tiles and render endpoint across origins (CORS). Checks: map.html loads terrad's shaded
// and terrain-RGB tiles with no error and draws them (the canvas is not blank), the time
// slider asks for new shaded tiles at the new instant and the picture changes (the
// shadows move) with the sun terrad names, a click on the map moves the camera and puts
// the picked terrain point on it, and the page on the other origin draws terrad's tiles
// and POSTs a render (a CORS preflight), and a source without bounds whose tiles off the
// data answer 404 raises no map error (what MapLibre does with a 404 tile). Only the two loopback servers may be asked for
// anything. Screenshots go to the output directory (and docs/web-map.png when
// TERRAD_WEB_DOCS_SCREENSHOT=1).
//
// Environment: as browser.test.mjs (TERRAD_BIN, TERRAD_SOURCE_DIR, TERRAD_WEB_OUT, CHROMIUM).
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { spawn } from 'node:child_process';
import { freePort, sleep } from './net.mjs';
import http from 'node:http';
import { copyFile, mkdir } from 'node:fs/promises';
import { existsSync, openSync, closeSync } from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

const here = path.dirname(fileURLToPath(import.meta.url));
const SRC = process.env.TERRAD_SOURCE_DIR || path.resolve(here, '..', '..');
const BIN = process.env.TERRAD_BIN || path.join(SRC, 'build', 'terrad');
const OUT = process.env.TERRAD_WEB_OUT || process.cwd();
const CHROMIUM = process.env.CHROMIUM || '/usr/bin/chromium';

let chromium;
try {
  ({ chromium } = await import('playwright-core'));
} catch (e) {
  console.error('cannot load playwright-core: run scripts/install-deps (npm ci in web/)');
  process.exit(1);
}
for (const [what, p] of [['terrad', BIN], ['chromium', CHROMIUM]]) {
  if (!existsSync(p)) {
    console.error(`${what} not found at ${p}`);
    process.exit(1);
  }
}

let server = null, serverExit = null, base = '', other = null, otherBase = '', browser = null, page = null;
const foreign = [], pageErrors = [], mapTiles = [];


async function waitReady(deadlineMs) {
  const end = Date.now() + deadlineMs;
  while (Date.now() < end) {
    if (serverExit) throw new Error(`terrad exited (${serverExit}); see ${OUT}/web-map-terrad.log`);
    try {
      if ((await fetch(`${base}/readyz`)).ok) return;
    } catch (e) { /* not yet */ }
    await sleep(100);
  }
  throw new Error('terrad was not ready in time');
}

// The bare page of the other origin: MapLibre (from terrad) with terrad's TileJSON as
// sources, and a render POSTed to terrad.
function otherPage(terrad) {
  return `<!doctype html><html><head><meta charset="utf-8">
<link rel="stylesheet" href="${terrad}/vendor/maplibre-gl/maplibre-gl.css">
<script src="${terrad}/vendor/maplibre-gl/maplibre-gl.js"></script></head>
<body style="margin:0"><div id="m" style="width:600px;height:400px"></div><script>
window.result = { errors: [] };
const map = new maplibregl.Map({ container: 'm', canvasContextAttributes: { preserveDrawingBuffer: true },
  style: { version: 8, sources: {
      shaded: { type: 'raster', url: '${terrad}/v1/maps/trinidad/shaded.json?azimuth=300&elevation=20', tileSize: 256 },
      dem: { type: 'raster-dem', url: '${terrad}/v1/maps/trinidad/terrain-rgb.json', tileSize: 256 },
      // the same tiles without TileJSON's bounds: MapLibre asks for tiles off the data (404)
      unbounded: { type: 'raster', tiles: ['${terrad}/v1/maps/trinidad/shaded/{z}/{x}/{y}.png?azimuth=300&elevation=20'],
        tileSize: 256 } },
    layers: [{ id: 'bg', type: 'background', paint: { 'background-color': '#000' } },
             { id: 'unbounded', type: 'raster', source: 'unbounded', paint: { 'raster-fade-duration': 0 } },
             { id: 'shaded', type: 'raster', source: 'shaded', paint: { 'raster-fade-duration': 0 } }],
    terrain: { source: 'dem', exaggeration: 1.2 } },
  center: [-105.486, 37.578], zoom: 10, pitch: 40 });
map.on('error', (e) => window.result.errors.push(String(e.error && e.error.message || e)));
map.on('idle', () => { window.result.idle = true; });
fetch('${terrad}/v1/render', { method: 'POST', headers: { 'Content-Type': 'application/json' },
  body: JSON.stringify({ dataset: 'trinidad', camera: { position: { x: 20000, y: 15000, agl: 300 }, heading: 60, pitch: -8, fov: 60 },
    image: { width: 160, height: 100 } }) })
  .then(async (r) => { window.result.render = { status: r.status, type: r.headers.get('Content-Type'),
    timing: r.headers.get('Server-Timing'), bytes: (await r.arrayBuffer()).byteLength }; })
  .catch((e) => { window.result.render = { error: e.message }; });
window.map = map;
</script></body></html>`;
}

// Fraction of the map canvas's pixels that differ from its background colour, and a
// digest of its pixels (to tell two pictures apart).
async function canvasStats(p, bg) {
  return p.evaluate((bgc) => {
    const src = document.querySelector('canvas.maplibregl-canvas');
    const c = document.createElement('canvas');
    c.width = src.width;
    c.height = src.height;
    const ctx = c.getContext('2d');
    ctx.drawImage(src, 0, 0);
    const d = ctx.getImageData(0, 0, c.width, c.height).data;
    let n = 0, sum = 0;
    for (let k = 0; k < d.length; k += 4) {
      if (Math.abs(d[k] - bgc[0]) + Math.abs(d[k + 1] - bgc[1]) + Math.abs(d[k + 2] - bgc[2]) > 12) n++;
      sum = (sum * 31 + d[k] + 7 * d[k + 1]) % 1000000007;
    }
    return { drawn: n / (d.length / 4), digest: sum, data: Array.from(d.filter((v, i) => i % 4 === 0)) };
  }, bg);
}

async function idle(p) {
  await p.waitForFunction(() => {
    const m = (window.terradMap && window.terradMap.map) || window.map;
    return m && m.loaded() && m.areTilesLoaded();
  }, null, { timeout: 60000 });
  await sleep(300);
}

before(async () => {
  await mkdir(OUT, { recursive: true });
  const port = await freePort();
  base = `http://127.0.0.1:${port}`;
  const log = openSync(path.join(OUT, 'web-map-terrad.log'), 'w');
  server = spawn(BIN, ['serve', '--listen', `127.0.0.1:${port}`, '--web-dir', path.join(SRC, 'web'),
    '--demo-dir', path.join(SRC, 'data'), '--render-workers', '2', '--log-level', 'warn'], {
    env: { ...process.env, TERRAD_ADMIN_TOKEN: '', TERRAD_ADMIN_TOKEN_FILE: '', TERRAD_CACHE: '', TERRAD_DATA: '',
      TERRAD_CORS_ORIGINS: '*' },
    stdio: ['ignore', log, log],
  });
  closeSync(log);
  server.on('exit', (code, sig) => { serverExit = sig || `code ${code}`; });
  process.on('exit', () => { if (!serverExit) try { process.kill(server.pid, 'SIGKILL'); } catch (e) { /* gone */ } });
  await waitReady(15000);
  const oport = await freePort();
  otherBase = `http://127.0.0.1:${oport}`;
  other = http.createServer((req, res) => {
    res.writeHead(200, { 'Content-Type': 'text/html; charset=utf-8' });
    res.end(otherPage(base));
  });
  await new Promise((r) => other.listen(oport, '127.0.0.1', r));
  browser = await chromium.launch({
    executablePath: CHROMIUM,
    headless: true,
    // software WebGL (SwiftShader): MapLibre needs WebGL 2
    args: ['--no-sandbox', '--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--ignore-gpu-blocklist',
      '--disable-background-networking', '--disable-component-update', '--no-first-run'],
  });
  const context = await browser.newContext({ viewport: { width: 1280, height: 900 } });
  await context.route('**/*', (route) => {
    const u = route.request().url();
    if (u.startsWith(base + '/') || u.startsWith(otherBase + '/') || u.startsWith('data:') || u.startsWith('blob:')) {
      return route.continue();
    }
    foreign.push(u);
    return route.abort();
  });
  page = await context.newPage();
  page.on('pageerror', (e) => pageErrors.push(`pageerror: ${e.message}`));
  page.on('console', (m) => { if (m.type() === 'error') pageErrors.push(`console: ${m.text()}`); });
  page.on('response', (r) => {
    const u = new URL(r.url());
    if (u.pathname.startsWith('/v1/maps/') && u.pathname.endsWith('.png')) mapTiles.push({ status: r.status(), url: u.pathname + u.search });
  });
});

after(async () => {
  if (browser) await browser.close().catch(() => {});
  if (other) other.close();
  if (server && !serverExit) {
    process.kill(server.pid, 'SIGTERM');
    const end = Date.now() + 5000;
    while (!serverExit && Date.now() < end) await sleep(50);
    if (!serverExit) process.kill(server.pid, 'SIGKILL');
  }
});

test('the web map draws terrad\'s shaded and terrain-RGB tiles', async () => {
  await page.goto(`${base}/map.html#trinidad/20000/15000/300/60/-8/60`);
  await page.waitForFunction(() => window.terradMap && window.terradMap.ready, null, { timeout: 30000 });
  await page.evaluate(() => window.terradMap.ready);
  await idle(page);
  const st = await canvasStats(page, [0xdd, 0xe3, 0xe8]);
  assert.ok(st.drawn > 0.3, `the map shows terrain (${(100 * st.drawn).toFixed(1)} % of the canvas drawn)`);
  const shaded = mapTiles.filter((t) => t.url.includes('/shaded/'));
  const dem = mapTiles.filter((t) => t.url.includes('/terrain-rgb/'));
  assert.ok(shaded.length > 0 && dem.length > 0, `shaded ${shaded.length} and terrain-rgb ${dem.length} tiles asked for`);
  assert.ok(shaded.every((t) => t.status === 200 && t.url.includes('time=2026-06-21T23:30Z')),
    `every shaded tile at the slider's instant: ${shaded.map((t) => t.url).join(' ')}`);
  assert.deepEqual(await page.evaluate(() => window.terradMap.errors), []);
  const sun = await page.evaluate(() => window.terradMap.sun);
  assert.ok(sun.elevation > 0 && sun.elevation < 45, `the sun of 23:30 UTC is in the afternoon sky (${sun.elevation})`);
  assert.match(await page.locator('#wm-sun').textContent(), /azimuth \d/);
  await page.screenshot({ path: path.join(OUT, 'web-map.png') });
});

test('the time slider moves the shadows', async () => {
  const before = await canvasStats(page, [0xdd, 0xe3, 0xe8]);
  const sunBefore = await page.evaluate(() => window.terradMap.sun);
  const n0 = mapTiles.length;
  // 01:00 UTC: about 18:00 local solar time over trinidad (105.5 W), the sun low in the west
  await page.locator('#wm-time').fill('1');
  await page.waitForFunction((el) => window.terradMap.sun && window.terradMap.sun.elevation !== el, sunBefore.elevation);
  await sleep(200);
  await idle(page);
  const after = await canvasStats(page, [0xdd, 0xe3, 0xe8]);
  const fresh = mapTiles.slice(n0).filter((t) => t.url.includes('/shaded/'));
  assert.ok(fresh.length > 0 && fresh.every((t) => t.status === 200 && t.url.includes('time=2026-06-21T01:00Z')),
    `new shaded tiles at 01:00: ${fresh.map((t) => t.url).join(' ')}`);
  const sun = await page.evaluate(() => window.terradMap.sun);
  assert.ok(sun.elevation > 0 && sun.elevation < sunBefore.elevation - 5 && sun.azimuth > 270,
    `the sun went down in the west: ${JSON.stringify(sunBefore)} -> ${JSON.stringify(sun)}`);
  assert.match(await page.locator('#wm-time-out').textContent(), /01:00Z \(about 17:5\d local solar time\)/);
  let changed = 0;
  for (let k = 0; k < before.data.length; k++) if (Math.abs(before.data[k] - after.data[k]) > 8) changed++;
  assert.ok(changed > 0.05 * before.data.length, `the picture changed (${changed} of ${before.data.length} pixels)`);
});

test('a click moves the camera and marks the picked point', async () => {
  const hash0 = await page.evaluate(() => location.hash);
  const box = await page.locator('#wm-map').boundingBox();
  await page.mouse.click(box.x + box.width * 0.45, box.y + box.height * 0.55);
  await page.waitForFunction((h) => location.hash !== h, hash0);
  await page.waitForFunction(() => window.terradMap.picked && document.querySelector('.maplibregl-marker'));
  const picked = await page.evaluate(() => window.terradMap.picked);
  assert.ok(picked.hit && picked.point.z > 2000 && picked.point.z < 4400, `a terrain point (${picked.point.z} m)`);
  assert.ok(Math.abs(picked.lonlat[0] + 105.49) < 0.3 && Math.abs(picked.lonlat[1] - 37.58) < 0.25, 'on trinidad');
  assert.match(await page.locator('#wm-back').getAttribute('href'), /^index\.html#trinidad\//);
  await page.screenshot({ path: path.join(OUT, 'web-map-picked.png') });
  if (process.env.TERRAD_WEB_DOCS_SCREENSHOT === '1') await copyFile(path.join(OUT, 'web-map-picked.png'), path.join(SRC, 'docs', 'web-map.png'));
});

test('a page on another origin uses terrad\'s tiles and renders (CORS)', async () => {
  const p = await page.context().newPage();
  const errs = [], answers = [];
  p.on('response', (r) => { if (r.url().includes('/v1/maps/')) answers.push(r.status()); });
  p.on('pageerror', (e) => errs.push(e.message));
  p.on('console', (m) => { if (m.type() === 'error') errs.push(m.text()); });
  await p.goto(`${otherBase}/`);
  await p.waitForFunction(() => window.result && window.result.render && window.result.idle, null, { timeout: 60000 });
  await idle(p);
  const res = await p.evaluate(() => window.result);
  assert.deepEqual(res.errors, [], 'no map error across origins');
  assert.equal(res.render.status, 200, `the cross-origin render answered: ${JSON.stringify(res.render)}`);
  assert.equal(res.render.type, 'image/png');
  assert.ok(res.render.timing && res.render.timing.includes('trace'), 'Server-Timing is exposed to the other origin');
  const st = await canvasStats(p, [0, 0, 0]);
  assert.ok(st.drawn > 0.5, `terrad's tiles drawn on the other origin's map (${(100 * st.drawn).toFixed(1)} %)`);
  // (the browser's console notes every 404 as a failed load; that is not the page's error)
  assert.deepEqual(errs.filter((m) => !/status of 404/.test(m)), []);
  // tiles wholly off the data answer 404, and MapLibre takes them as empty: no error event
  const n404 = answers.filter((s) => s === 404).length;
  assert.ok(n404 > 0, `tiles off the data were asked for and answered 404 (${n404} of ${answers.length})`);
  assert.ok(answers.every((s) => s === 200 || s === 404), `answers: ${answers.join(' ')}`);
  console.log(`other origin: ${answers.length} map answers, ${n404} of them 404, ${res.errors.length} map errors`);
  await p.screenshot({ path: path.join(OUT, 'web-map-other-origin.png') });
  await p.close();
});

test('nothing went wrong on the way', () => {
  assert.deepEqual(foreign, [], 'no request left the two loopback servers');
  assert.deepEqual(pageErrors, []);
  assert.ok(mapTiles.every((t) => t.status === 200 || t.status === 304), `tile answers: ${mapTiles.filter((t) => t.status >= 400).map((t) => `${t.status} ${t.url}`).join(' ')}`);
});
