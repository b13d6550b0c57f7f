// browser.test.mjs: the map client in a real browser against a live terrad.
//
// Starts `terrad serve` on a free loopback port (killed by pid at the end), drives
// Debian's chromium headless through playwright-core (a fresh profile, no network
// beyond the loopback server: any other request is refused and fails the test), and
// checks what a user sees: the default view appears on load and is a real picture,
// its timing chart is drawn, clicking the map places the camera there and renders a new
// view, keyboard keys move the camera, a burst of changes sends one request, a click in
// the view marks the picked terrain point on the map with plausible coordinates, compare
// mode shows two renders and their pixel difference, the admin panel's preload
// reaches 100 %, and the viewshed control lays the viewshed of a clicked observer over
// the map, pixel for pixel the server's answer recoloured, and shows a refusal; the
// panorama option renders a 360-degree view whose summits (POST /v1/peaks) are labelled
// over it at their pixels and marked on the map.
// Screenshots (the page, the view, the map with a viewshed) go to the output directory
// (and the page to docs/web-screenshot.png when TERRAD_WEB_DOCS_SCREENSHOT=1).
//
// Environment: TERRAD_BIN (the terrad binary; default build/terrad), TERRAD_SOURCE_DIR
// (the repository; default two levels up), TERRAD_WEB_OUT (screenshots and the server
// log; default the current directory), CHROMIUM (default /usr/bin/chromium).
//
// Run: ctest -L web (from a build directory), or node web/test/browser.test.mjs.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { spawn } from 'node:child_process';
import { freePort, sleep } from './net.mjs';
import { mkdtemp, rm, mkdir, copyFile } from 'node:fs/promises';
import { existsSync, openSync, closeSync, readFileSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { randomBytes } from 'node:crypto';

const here = path.dirname(fileURLToPath(import.meta.url));
const SRC = process.env.TERRAD_SOURCE_DIR || path.resolve(here, '..', '..');
const BIN = process.env.TERRAD_BIN || path.join(SRC, 'build', 'terrad');
const OUT = process.env.TERRAD_WEB_OUT || process.cwd();
const CHROMIUM = process.env.CHROMIUM || '/usr/bin/chromium';
const TOKEN = randomBytes(12).toString('hex');

let chromium;
try {
  ({ chromium } = await import('playwright-core'));
} catch (e) {
  console.error(`cannot load playwright-core from ${path.join(SRC, 'web', 'node_modules')}: ` +
    'run scripts/install-deps (npm ci in web/)');
  process.exit(1);
}
for (const [what, p] of [['terrad', BIN], ['chromium', CHROMIUM]]) {
  if (!existsSync(p)) {
    console.error(`${what} not found at ${p}`);
    process.exit(1);
  }
}

let server = null, serverExit = null, port = 0, base = '';
let context = null, page = null, profile = null;
const foreign = [], pageErrors = [], renderRequests = [], failed = [], viewshedRequests = [], peaksRequests = [];


async function waitReady(deadlineMs) {
  const end = Date.now() + deadlineMs;
  let last = '';
  while (Date.now() < end) {
    if (serverExit) throw new Error(`terrad exited (${serverExit}) before it was ready; see ${OUT}/web-terrad.log`);
    try {
      const r = await fetch(`${base}/readyz`);
      if (r.ok) return;
      last = `HTTP ${r.status}`;
    } catch (e) {
      last = e.message;
    }
    await sleep(100);
  }
  throw new Error(`terrad not ready after ${deadlineMs} ms (${last})`);
}

const renders = () => page.evaluate(() => Number(document.body.dataset.renders || 0));
async function waitRenders(n, ms = 20000) {
  await page.waitForFunction((k) => Number(document.body.dataset.renders || 0) >= k, n, { timeout: ms });
}
const camField = async (id) => Number(await page.inputValue(`#${id}`));

// Pixels of a displayed image, read back through a canvas in the page.
async function viewStats(selector) {
  return page.evaluate(async (sel) => {
    const { imageStats } = await import('/js/diff.js');
    const img = document.querySelector(sel);
    const c = document.createElement('canvas');
    c.width = img.naturalWidth;
    c.height = img.naturalHeight;
    const ctx = c.getContext('2d');
    ctx.drawImage(img, 0, 0);
    const s = imageStats(ctx.getImageData(0, 0, c.width, c.height).data);
    return { ...s, width: c.width, height: c.height };
  }, selector);
}

before(async () => {
  await mkdir(OUT, { recursive: true });
  port = await freePort();
  base = `http://127.0.0.1:${port}`;
  const log = openSync(path.join(OUT, 'web-terrad.log'), 'w');
  server = spawn(BIN, ['serve', '--listen', `127.0.0.1:${port}`, '--web-dir', path.join(SRC, 'web'),
    '--demo-dir', path.join(SRC, 'data'), '--preload', 'all', '--log-level', 'warn'], {
    env: { ...process.env, TERRAD_ADMIN_TOKEN: TOKEN, TERRAD_ADMIN_TOKEN_FILE: '', TERRAD_CACHE: '', TERRAD_DATA: '' },
    stdio: ['ignore', log, log],
  });
  closeSync(log);
  server.on('exit', (code, sig) => { serverExit = sig || `code ${code}`; });
  server.on('error', (e) => { serverExit = `could not start: ${e.message}`; });
  // Never leave terrad behind, even when this script is interrupted.
  process.on('exit', () => {
    if (!serverExit) try { process.kill(server.pid, 'SIGKILL'); } catch (e) { /* gone */ }
    if (profile) rmSync(profile, { recursive: true, force: true });
  });
  for (const sig of ['SIGINT', 'SIGTERM']) process.on(sig, () => process.exit(1));
  await waitReady(15000);

  profile = await mkdtemp(path.join(tmpdir(), 'terrad-web-chromium-'));
  context = await chromium.launchPersistentContext(profile, {
    executablePath: CHROMIUM,
    headless: true,
    viewport: { width: 1400, height: 1050 },
    args: ['--no-sandbox', '--disable-gpu', '--disable-background-networking',
      '--disable-component-update', '--no-first-run', '--disable-default-apps', '--disable-sync'],
  });
  // Works with no internet: only the loopback terrad may be asked for anything.
  await context.route('**/*', (route) => {
    const u = route.request().url();
    if (u.startsWith(base + '/') || u.startsWith('data:') || u.startsWith('blob:')) return route.continue();
    foreign.push(u);
    return route.abort();
  });
  page = context.pages()[0] || await context.newPage();
  page.on('pageerror', (e) => pageErrors.push(`pageerror: ${e.message}`));
  page.on('console', (m) => { if (m.type() === 'error') pageErrors.push(`console: ${m.text()}`); });
  page.on('request', (r) => {
    const pathname = new URL(r.url()).pathname;
    if (pathname === '/v1/render') renderRequests.push(r.postDataJSON());
    if (pathname === '/v1/viewshed') viewshedRequests.push(r.postDataJSON());
    if (pathname === '/v1/peaks') peaksRequests.push(r.postDataJSON());
  });
  page.on('response', (r) => {
    if (r.status() < 400) return;
    const q = r.request();
    const body = q.postData() || '';
    failed.push(`${r.status()} ${q.method()} ${new URL(r.url()).pathname}${/"lod":true/.test(body) ? ' lod' : ''}`);
  });
  page.setDefaultTimeout(20000);
});

after(async () => {
  if (context) await context.close().catch(() => {});
  if (profile) await rm(profile, { recursive: true, force: true }).catch(() => {});
  if (server && !serverExit) {
    process.kill(server.pid, 'SIGTERM');
    const end = Date.now() + 5000;
    while (!serverExit && Date.now() < end) await sleep(50);
    if (!serverExit) process.kill(server.pid, 'SIGKILL');
  }
});

test('the page loads and shows the default view at once', async () => {
  const t0 = Date.now();
  await page.goto(`${base}/`);
  await waitRenders(1);
  console.log(`# first view after ${Date.now() - t0} ms`);
  const ds = await page.inputValue('#dataset');
  assert.equal(ds, 'trinidad', 'the default dataset');
  const options = await page.$$eval('#dataset option', (os) => os.map((o) => o.value));
  assert.deepEqual(options.sort(), ['levi', 'trinidad', 'volcano']);
  const s = await viewStats('#view-img');
  assert.deepEqual([s.width, s.height], [640, 400], 'the image has the size asked for');
  assert.ok(s.opaque > 0.9 * s.pixels, `the view is opaque (${s.opaque} of ${s.pixels})`);
  assert.ok(s.variance > 20, `the view is not flat (luminance variance ${s.variance.toFixed(1)})`);
  // Map tiles came from terrad and were drawn.
  await page.waitForFunction(() => [...document.querySelectorAll('img.leaflet-tile')].some((t) => t.complete && t.naturalWidth === 256));
  // Attribution of the dataset on the page.
  assert.match(await page.textContent('#attribution-current'), /USGS/);
  assert.match(await page.textContent('footer'), /National Land Survey of Finland/);
});

test('the timing chart shows the stages of the view, with steps per ray', async () => {
  const bars = await page.$$eval('#charts svg .bar', (gs) => gs.map((g) => ({
    stage: g.dataset.stage, w: Number(g.querySelector('rect').getAttribute('width')),
  })));
  const stages = bars.map((b) => b.stage);
  for (const s of ['parse', 'queue', 'trace', 'shadows', 'sky', 'encode']) assert.ok(stages.includes(s), `stage ${s} in ${stages}`);
  assert.ok(bars.every((b) => b.w >= 1), 'every bar is drawn');
  assert.ok(Math.max(...bars.map((b) => b.w)) > 50, 'the longest bar spans the chart');
  const title = await page.textContent('#charts svg .chart-title');
  assert.match(title, /ms, \d+(\.\d)? steps\/ray/);
});

test('clicking the map places the camera there and renders its view', async () => {
  const n = await renders();
  const box = await page.locator('#map').boundingBox();
  const cx = Math.round(box.x + box.width * 0.55), cy = Math.round(box.y + box.height * 0.35);
  const want = await page.evaluate(([x, y]) => {
    const ll = window.terrad.map.mouseEventToLatLng({ clientX: x, clientY: y });
    return { x: ll.lng, y: ll.lat };
  }, [cx, cy]);
  await page.mouse.click(cx, cy);
  await waitRenders(n + 1);
  const x = await camField('cam-x'), y = await camField('cam-y');
  // Within a map pixel of where the click was (the fields show decimetres).
  const mpp = await page.evaluate(() => {
    const m = window.terrad.map;
    return m.containerPointToLatLng([1, 0]).lng - m.containerPointToLatLng([0, 0]).lng;
  });
  assert.ok(Math.abs(x - want.x) < mpp && Math.abs(y - want.y) < mpp,
    `camera at (${x}, ${y}), clicked (${want.x}, ${want.y}), ${mpp} m a pixel`);
  const last = renderRequests.at(-1);
  assert.ok(Math.abs(last.camera.position.x - want.x) < 1 && Math.abs(last.camera.position.y - want.y) < 1,
    'the render asked for the new camera');
  const paths = await page.$$eval('#map svg path', (ps) => ps.map((p) => p.getAttribute('d')).filter((d) => d && d !== 'M0 0'));
  assert.ok(paths.length >= 2, 'the wedge and the heading line are drawn');
  const apex = await page.evaluate(() => window.terrad.layers.wedgeLayer.getLatLngs()[0][0]);
  assert.ok(Math.abs(apex.lng - x) < 1 && Math.abs(apex.lat - y) < 1, 'the wedge starts at the camera');
});

test('the keyboard moves and turns the camera', async () => {
  const n = await renders();
  const h0 = await camField('cam-heading');
  await page.focus('.camera-marker');
  await page.keyboard.press('ArrowRight');
  await waitRenders(n + 1);
  const h1 = await camField('cam-heading');
  assert.ok(Math.abs(((h1 - h0 + 360) % 360) - 5) < 0.01, `heading ${h0} -> ${h1}`);
  const x0 = await camField('cam-x'), y0 = await camField('cam-y');
  await page.keyboard.press('ArrowUp');
  await waitRenders(n + 2);
  const x1 = await camField('cam-x'), y1 = await camField('cam-y');
  const moved = Math.hypot(x1 - x0, y1 - y0);
  const dir = (Math.atan2(x1 - x0, y1 - y0) * 180) / Math.PI;
  assert.ok(moved > 100, `moved ${moved} m forward`);
  assert.ok(Math.abs((((dir - h1) % 360) + 540) % 360 - 180) < 1, `moved along the heading (${dir} vs ${h1})`);
  // Enter on the focused map places the camera at the map's centre.
  await page.focus('#map');
  await page.keyboard.press('Enter');
  await waitRenders(n + 3);
  const c = await page.evaluate(() => window.terrad.map.getCenter());
  assert.ok(Math.abs((await camField('cam-x')) - c.lng) < 1 && Math.abs((await camField('cam-y')) - c.lat) < 1,
    'camera at the map centre');
});

test('a burst of changes sends one render request', async () => {
  const n = await renders();
  const before = renderRequests.length;
  // A slider moved and let go: input events 20 ms apart, as a hand makes them, then
  // one change.
  await page.evaluate(async () => {
    const r = document.getElementById('cam-pitch-range');
    for (const v of [-20, -18, -16, -14, -12]) {
      r.value = String(v);
      r.dispatchEvent(new Event('input', { bubbles: true }));
      await new Promise((ok) => setTimeout(ok, 20));
    }
    r.dispatchEvent(new Event('change', { bubbles: true }));
  });
  await waitRenders(n + 1);
  await sleep(300);
  assert.equal(renderRequests.length - before, 1, 'one request for six changes');
  const last = renderRequests.at(-1);
  assert.equal(last.camera.pitch, -12, 'with the last value');
  assert.deepEqual([last.image.width, last.image.height], [640, 400], 'in full');
});

test('dragging the heading handle turns the camera, with previews on the way', async () => {
  const before = renderRequests.length;
  const h = await page.locator('.heading-handle').boundingBox();
  const c = await page.locator('.camera-marker').boundingBox();
  const hx = h.x + h.width / 2, hy = h.y + h.height / 2;
  const cx = c.x + c.width / 2, cy = c.y + c.height / 2;
  // Swing the handle a quarter turn clockwise about the camera, over about a second.
  const r = Math.hypot(hx - cx, hy - cy), a0 = Math.atan2(hy - cy, hx - cx);
  await page.mouse.move(hx, hy);
  await page.mouse.down();
  let ex = hx, ey = hy;
  for (let i = 1; i <= 10; i++) {
    const a = a0 + (Math.PI / 2) * (i / 10);
    ex = Math.round(cx + r * Math.cos(a));
    ey = Math.round(cy + r * Math.sin(a));
    await page.mouse.move(ex, ey, { steps: 2 });
    await sleep(100);
  }
  await page.mouse.up();
  // Settled: nothing scheduled, nothing in flight, the full view of the camera shown.
  await page.waitForFunction(() => {
    const t = window.terrad;
    return !t.timer && !t.controller && t.shown.a.scene.image.width === 640 &&
      Math.abs(t.shown.a.scene.camera.heading - t.cam.heading) < 0.01;
  });
  const sent = renderRequests.slice(before);
  const previews = sent.filter((q) => q.image.width === 320);
  assert.ok(previews.length >= 1, `previews while dragging (${sent.map((q) => q.image.width)})`);
  const last = sent.at(-1);
  assert.equal(last.image.width, 640, 'the full view once dropped');
  const want = await page.evaluate(([x, y]) => {
    const ll = window.terrad.map.mouseEventToLatLng({ clientX: x, clientY: y });
    const cam = window.terrad.cam;
    const h = (Math.atan2(ll.lng - cam.x, ll.lat - cam.y) * 180) / Math.PI;
    return (h + 360) % 360;
  }, [ex, ey]);
  const heading = await camField('cam-heading');
  const off = Math.abs(((heading - want + 540) % 360) - 180);
  assert.ok(off < 2, `heading ${heading}, towards the drop point ${want}`);
  assert.ok(Math.abs(last.camera.heading - heading) < 0.01, 'the full view has that heading');
});

test('a click in the view marks the terrain point on the map', async () => {
  const img = await page.locator('#view-img').boundingBox();
  // Lower middle of the view: terrain, not sky (the camera looks down 12 degrees).
  await page.mouse.click(img.x + img.width * 0.5, img.y + img.height * 0.8);
  await page.waitForFunction(() => Number(document.body.dataset.picks || 0) >= 1);
  const m = await page.$eval('.pick-marker', (e) => ({ x: Number(e.dataset.x), y: Number(e.dataset.y), z: Number(e.dataset.z) }));
  const ds = await page.evaluate(() => window.terrad.ds);
  const cam = await page.evaluate(() => window.terrad.shown.a.scene.camera);
  assert.ok(m.x >= 0 && m.x <= ds.xmax && m.y >= 0 && m.y <= ds.ymax, `point (${m.x}, ${m.y}) inside the dataset`);
  assert.ok(m.z >= ds.zmin - 1 && m.z <= ds.zmax + 1, `height ${m.z} within ${ds.zmin}..${ds.zmax}`);
  // In front of the camera, near the centre line of the view (the middle column).
  const dir = (Math.atan2(m.x - cam.position.x, m.y - cam.position.y) * 180) / Math.PI;
  const off = Math.abs((((dir - cam.heading) % 360) + 540) % 360 - 180);
  assert.ok(off < 2, `the picked point lies along the heading (${off.toFixed(2)} degrees off)`);
  const text = await page.textContent('#pick-result');
  assert.match(text, /height \d+(\.\d)? m/);
  assert.match(text, /°/, 'lon/lat for a georeferenced dataset');
  assert.ok(await page.locator('.pick-marker').isVisible(), 'the marker is on the map');
});

test('compare mode renders both settings and their pixel difference', async () => {
  const n = await renders();
  await page.check('#cmp-on');
  await waitRenders(n + 1);
  const last2 = renderRequests.slice(-2).map((s) => `${s.quality.method}/${s.quality.surface}`).sort();
  assert.deepEqual(last2, ['auto/bilinear', 'incremental/plane']);
  assert.equal(await page.locator('#charts svg').count(), 2, 'two timing charts');
  const b = await viewStats('#view-img-b');
  assert.ok(b.opaque > 0.9 * b.pixels && b.variance > 20, 'B is a picture too');
  const differ = Number(await page.getAttribute('#view-diff', 'data-differ'));
  assert.ok(differ > 0 && differ < b.pixels, `plane and bilinear differ in some pixels (${differ})`);
  assert.match(await page.textContent('#diff-result'), /pixels differ .*PSNR/);
  // each view says how far it is from the exact picture (X-Terrad-Height-Error)
  assert.match(await page.textContent('#view-a-caption'), /bilinear.*, the exact surface$/);
  assert.match(await page.textContent('#view-b-caption'), /plane.*, [\d.]+ m mean, [\d.]+ m max off the exact surface$/);
});

test('level of detail: the view is rendered with it and still ticked', async () => {
  const n = await renders();
  await page.check('#q-lod');
  await waitRenders(n + 1);
  const lodSent = renderRequests.some((q) => q.quality.lod === true);
  assert.ok(lodSent, 'the page asked for level of detail');
  const shownLod = await page.evaluate(() => !!window.terrad.shown.a.scene.quality.lod);
  assert.ok(shownLod, 'the view on screen was rendered with level of detail');
  assert.equal(await page.isChecked('#q-lod'), true);
  await page.uncheck('#q-lod');
  await waitRenders(n + 2);
});

test('the viewshed control: a click places an observer and lays its viewshed over the map', async () => {
  await page.check('#vs-on');
  assert.equal(await page.inputValue('#vs-height'), '2', 'an eye 2 m up by default');
  await page.locator('#map').scrollIntoViewIfNeeded();
  const box = await page.locator('#map').boundingBox();
  const cam = { x: await camField('cam-x'), y: await camField('cam-y') };
  const n = await renders();
  // a point on the map with nothing (no marker) over it
  const at = await page.evaluate(([bx, by, bw, bh]) => {
    for (const [fx, fy] of [[0.4, 0.6], [0.6, 0.4], [0.3, 0.3], [0.7, 0.7], [0.5, 0.5]]) {
      const x = Math.round(bx + bw * fx), y = Math.round(by + bh * fy);
      const e = document.elementFromPoint(x, y);
      if (e && (e.id === 'map' || e.classList.contains('leaflet-tile') || e.classList.contains('leaflet-container'))) return { x, y };
    }
    return null;
  }, [box.x, box.y, box.width, box.height]);
  assert.ok(at, 'a free point on the map');
  const want = await page.evaluate(([x, y]) => {
    const ll = window.terrad.map.mouseEventToLatLng({ clientX: x, clientY: y });
    return { x: ll.lng, y: ll.lat };
  }, [at.x, at.y]);
  await page.mouse.click(at.x, at.y);
  await page.waitForFunction(() => Number(document.body.dataset.viewsheds || 0) >= 1).catch(async (e) => {
    throw new Error(`${e.message}; vs-result: ${await page.textContent('#vs-result')}; status: ${await page.textContent('#status')}`);
  });
  const body = viewshedRequests.at(-1);
  assert.equal(body.dataset, 'trinidad');
  assert.equal(body.height, 2);
  assert.equal(body.format, 'png');
  assert.ok(!('max_distance' in body), 'no max_distance when the field is empty');
  assert.ok(Math.abs(body.observer.x - want.x) < 1 && Math.abs(body.observer.y - want.y) < 1,
    `observer at (${body.observer.x}, ${body.observer.y}), clicked (${want.x}, ${want.y})`);
  const r = await page.evaluate(async (b) => {
    const vs = await import('/js/viewshed.js');
    const t = window.terrad, ds = t.ds;
    const img = document.querySelector('img.viewshed-overlay');
    const read = (src) => {
      const c = document.createElement('canvas');
      c.width = src.naturalWidth || src.width; // an <img>'s width is its size on screen
      c.height = src.naturalHeight || src.height;
      const ctx = c.getContext('2d');
      ctx.drawImage(src, 0, 0);
      return ctx.getImageData(0, 0, c.width, c.height).data;
    };
    const shown = read(img);
    // the server's own answer for the same body, recoloured here
    const resp = await fetch('/v1/viewshed', { method: 'POST', headers: { 'Content-Type': 'application/json' }, body: JSON.stringify(b) });
    const want = vs.recolourViewshed(read(await createImageBitmap(await resp.blob())));
    let worst = 0, first = null, nd = 0;
    for (let k = 0; k < shown.length; k++) {
      const d = Math.abs(shown[k] - want.out[k]);
      if (d > worst) worst = d;
      if (d > 2 && k % 4 === 3) nd++;
      if (d > 2 && !first) first = { k, shown: [...shown.slice(k - k % 4, k - k % 4 + 4)], want: [...want.out.slice(k - k % 4, k - k % 4 + 4)] };
    }
    const [i, j] = vs.sampleAt(ds, b.observer.x, b.observer.y);
    const k = 4 * (j * img.naturalWidth + i);
    const close = (p, c) => p.every((v, q) => Math.abs(v - c[q]) <= 2);
    let hidden = 0;
    for (let q = 0; q < shown.length; q += 4) if (close([...shown.slice(q, q + 4)], vs.HIDDEN_RGBA)) hidden++;
    const layer = t.viewshed.layer.getLayers().find((l) => l instanceof L.ImageOverlay);
    const bb = layer.getBounds();
    const marker = document.querySelector('.viewshed-marker').getBoundingClientRect();
    const mp = t.map.latLngToContainerPoint(L.latLng(b.observer.y, b.observer.x));
    // container points count from inside the map's border
    const mc = t.map.getContainer(), mb = mc.getBoundingClientRect();
    const mr = { x: mb.x + mc.clientLeft, y: mb.y + mc.clientTop };
    // on screen: the south-west pixel's centre on sample (0, 0), the north-east one's on
    // the last sample, so each pixel sits on its sample (Leaflet places the image on
    // whole screen pixels: within 1 px)
    const ir = img.getBoundingClientRect(), pw = ir.width / img.naturalWidth, ph = ir.height / img.naturalHeight;
    const sw = t.map.latLngToContainerPoint(L.latLng(ds.ymin, ds.xmin));
    const ne = t.map.latLngToContainerPoint(L.latLng(ds.ymax, ds.xmax));
    const place = Math.max(
      Math.abs(ir.left + pw / 2 - mr.x - sw.x), Math.abs(ir.bottom - ph / 2 - mr.y - sw.y),
      Math.abs(ir.right - pw / 2 - mr.x - ne.x), Math.abs(ir.top + ph / 2 - mr.y - ne.y));
    return {
      place,
      w: img.naturalWidth, h: img.naturalHeight, dsw: ds.width, dsh: ds.height, worst, first, nd, 
      counts: { visible: want.visible, hidden: want.hidden, outside: want.outside },
      under: [...shown.slice(k, k + 4)], underOk: close([...shown.slice(k, k + 4)], vs.VISIBLE_RGBA), hidden,
      bounds: [bb.getSouth(), bb.getWest(), bb.getNorth(), bb.getEast()], wantBounds: vs.overlayBounds(ds).flat(),
      markerOff: Math.hypot(marker.x + marker.width / 2 - mr.x - mp.x, marker.y + marker.height / 2 - mr.y - mp.y),
    };
  }, body);
  assert.deepEqual([r.w, r.h], [r.dsw, r.dsh], 'one overlay pixel a sample of the grid');
  assert.ok(r.worst <= 2, `the overlay is the server's answer recoloured (largest channel difference ${r.worst}: ${JSON.stringify(r.first)}, ${r.nd} pixels differ)`);
  assert.ok(r.underOk, `the sample under the observer is seen (${r.under})`);
  assert.ok(r.hidden > 0 && r.counts.hidden === r.hidden, `some samples are hidden (${r.hidden})`);
  assert.ok(r.counts.visible > 0 && r.counts.outside === 0, JSON.stringify(r.counts));
  r.bounds.forEach((v, q) => assert.ok(Math.abs(v - r.wantBounds[q]) < 1e-6, `bounds ${r.bounds} vs ${r.wantBounds}`));
  assert.ok(r.place < 1, `pixels centred on their samples on screen (${r.place} px off)`);
  assert.ok(r.markerOff < 1, `the observer's marker is where the click was (${r.markerOff} px off)`);
  assert.match(await page.textContent('#vs-result'), /Viewshed from .* eye 2 m up: [\d.]+ km² seen \([\d.]+% of the samples in range\)/);
  // the camera stayed where it was: no new view
  await sleep(300);
  assert.equal(await renders(), n);
  assert.deepEqual([await camField('cam-x'), await camField('cam-y')], [cam.x, cam.y]);

  await page.locator('#map-panel').screenshot({ path: path.join(OUT, 'web-viewshed.png') });
  // A refusal from terrad (max_distance must be > 0) shows in the page's status, with its field.
  const shownBefore = await page.evaluate(() => Number(document.body.dataset.viewsheds));
  await page.fill('#vs-max', '0');
  await page.mouse.click(at.x, at.y);
  await page.waitForFunction(() => /refused/.test(document.getElementById('vs-result').textContent));
  assert.match(await page.textContent('#status'), /Viewshed failed: HTTP 400: max_distance/);
  assert.ok(await page.evaluate(() => document.getElementById('status').classList.contains('error')));
  assert.equal(await page.locator('img.viewshed-overlay').count(), 0, 'no stale overlay after a refusal');
  // With a distance, samples beyond it are left clear.
  await page.fill('#vs-max', '5000');
  await page.mouse.click(at.x, at.y);
  await page.waitForFunction((k) => Number(document.body.dataset.viewsheds) > k, shownBefore);
  assert.equal(viewshedRequests.at(-1).max_distance, 5000);
  assert.match(await page.textContent('#vs-result'), /within 5,000 m/);
  await page.click('#vs-clear');
  assert.equal(await page.locator('img.viewshed-overlay').count(), 0, 'cleared');
  await page.fill('#vs-max', '');
  await page.uncheck('#vs-on');
});

test('the admin panel preloads the visible area with a progress bar', async () => {
  await page.click('#admin summary');
  await page.fill('#admin-token', TOKEN);
  await page.click('#admin-preload');
  await page.waitForFunction(() => /done|failed|refused/.test(document.getElementById('admin-progress-label').textContent));
  const label = await page.textContent('#admin-progress-label');
  assert.match(label, /Job \d+ done: \d+ tiles built/);
  assert.equal(Number(await page.getAttribute('#admin-progress', 'value')), 1);
  // A wrong token is refused, and says so.
  await page.fill('#admin-token', 'wrong');
  await page.click('#admin-preload');
  await page.waitForFunction(() => /refused/.test(document.getElementById('admin-progress-label').textContent));
  assert.match(await page.textContent('#admin-progress-label'), /401/);
});

test('the terrain control raises a disc where the map is clicked, and the version shows', async () => {
  assert.equal(await page.textContent('#dataset-version'), '1');
  await page.fill('#admin-token', TOKEN);
  await page.check('#edit-mode');
  await page.fill('#edit-radius', '3000');
  await page.fill('#edit-delta', '800');
  const n = await renders();
  const cam = { x: await camField('cam-x'), y: await camField('cam-y') };
  const before = await viewStats('#view-img');
  await page.locator('#map').scrollIntoViewIfNeeded();
  const box = await page.locator('#map').boundingBox();
  // a point a little ahead of the camera (heading is where the view looks)
  const at = await page.evaluate(([x, y]) => {
    const t = window.terrad, h = (t.cam.heading * Math.PI) / 180;
    const p = t.map.latLngToContainerPoint(L.latLng(y + 6000 * Math.cos(h), x + 6000 * Math.sin(h)));
    return { x: p.x, y: p.y };
  }, [cam.x, cam.y]);
  assert.ok(at.x > 20 && at.x < box.width - 20 && at.y > 20 && at.y < box.height - 20, `the point is on the map: ${JSON.stringify(at)} ${JSON.stringify(box)}`);
  await page.mouse.click(Math.round(box.x + at.x), Math.round(box.y + at.y));
  await page.waitForFunction(() => Number(document.body.dataset.edits || 0) >= 1 || /refused|not/.test(document.getElementById('edit-result').textContent)).catch(async (e) => {
    throw new Error(`${e.message}; edit-result: ${await page.textContent('#edit-result')}; status: ${await page.textContent('#status')}`);
  });
  assert.match(await page.textContent('#edit-result'), /Raised a disc of 3,000 m by 800 m .*heights version 2/);
  await page.waitForFunction(() => document.getElementById('dataset-version').textContent === '2');
  await waitRenders(n + 1);
  // the camera stayed where it was, and the view changed
  assert.equal(await camField('cam-x'), cam.x);
  const after = await viewStats('#view-img');
  assert.notDeepEqual(after, before, 'the view shows the raised disc');
  const ds = await (await fetch(`${base}/v1/datasets/${await page.inputValue('#dataset')}`)).json();
  assert.equal(ds.version, 2);
  await page.waitForFunction(() => [...document.querySelectorAll('img.leaflet-tile')].some((t) => t.src.endsWith('?v=2')));
  await page.uncheck('#edit-mode');
});

test('every control is labelled and reachable by Tab in reading order', async () => {
  const unlabelled = await page.$$eval('input, select, button, textarea', (els) => els
    .filter((e) => !e.disabled && !(e.labels && e.labels.length) && !e.getAttribute('aria-label') && !e.getAttribute('aria-labelledby') &&
      !(e.tagName === 'BUTTON' && e.textContent.trim()))
    .map((e) => e.id || e.outerHTML.slice(0, 60)));
  assert.deepEqual(unlabelled, []);
  // Tab from the top: the dataset picker, the map, the camera on it, its fields, the
  // quality settings, then the view and the comparison, in that order.
  await page.evaluate(() => { document.activeElement && document.activeElement.blur(); window.scrollTo(0, 0); });
  await page.focus('#dataset');
  const order = [];
  for (let i = 0; i < 48; i++) { // 40 + the summits fieldset and room
    await page.keyboard.press('Tab');
    order.push(await page.evaluate(() => {
      const e = document.activeElement;
      return e.id || [...e.classList].find((c) => /^(camera-marker|heading-handle|pick-marker|leaflet-control-zoom-in)$/.test(c)) || e.tagName;
    }));
  }
  const at = (k) => order.indexOf(k);
  for (const k of ['map', 'camera-marker', 'heading-handle', 'cam-x', 'cam-fov', 'q-method', 'view-img', 'cmp-on']) assert.ok(at(k) >= 0, `${k} reached by Tab (${order})`);
  assert.ok(at('map') < at('camera-marker') && at('camera-marker') < at('cam-x') && at('cam-x') < at('q-method') &&
    at('q-method') < at('view-img') && at('view-img') < at('cmp-on'), `reading order: ${order}`);
  // Enter on the focused view picks its centre.
  const picks = Number(await page.evaluate(() => document.body.dataset.picks || 0));
  await page.focus('#view-img');
  await page.keyboard.press('Enter');
  await page.waitForFunction((k) => Number(document.body.dataset.picks || 0) > k, picks);
});

test('a panorama with its summits labelled, each label at the pixel terrad gives', async () => {
  const n = await renders();
  await page.check('#pano-on');
  await waitRenders(n + 1);
  const last = renderRequests.at(-1);
  assert.equal(last.camera.projection, 'cylindrical');
  assert.equal(last.camera.fov, 360);
  assert.equal(last.image.height, Math.round(last.image.width / 3));
  await page.waitForFunction(() => Number(document.body.dataset.peaks || 0) >= 1).catch(async (e) => {
    throw new Error(`${e.message}; peaks-result: ${await page.textContent('#peaks-result')}; status: ${await page.textContent('#status')}`);
  });
  const body = peaksRequests.at(-1);
  assert.equal(body.camera.projection, 'cylindrical');
  assert.equal(body.min_prominence, 100);
  // the server's answer for the same body, and the labels drawn from it
  const got = await page.evaluate(async (b) => {
    const resp = await fetch('/v1/peaks', { method: 'POST', headers: { 'Content-Type': 'application/json' }, body: JSON.stringify(b) });
    const j = await resp.json();
    const img = document.getElementById('view-img').getBoundingClientRect();
    const labels = [...document.querySelectorAll('.peak-label')].map((l) => {
      const r = l.getBoundingClientRect();
      return { x: r.left - img.left, bottom: r.bottom - img.top, px: Number(l.dataset.px), py: Number(l.dataset.py) };
    });
    return { j, labels, scale: img.width / b.image.width, markers: document.querySelectorAll('.peak-marker').length };
  }, body);
  assert.ok(got.j.peaks.length >= got.labels.length && got.labels.length >= 1);
  assert.equal(got.markers, got.j.peaks.length, 'one map marker a summit');
  for (const l of got.labels) {
    assert.ok(got.j.peaks.some((p) => p.px === l.px && p.py === l.py), 'a label of a listed summit');
    assert.ok(Math.abs(l.x - (l.px + 0.5) * got.scale) < 1.5, `label x ${l.x} at the summit's ${(l.px + 0.5) * got.scale}`);
    assert.ok(Math.abs(l.bottom - (l.py + 0.5) * got.scale) < 1.5, 'the leader line ends on the summit');
  }
  for (const p of got.j.peaks) assert.ok(p.prominence >= 100);
  await page.locator('#view-panel').screenshot({ path: path.join(OUT, 'web-panorama.png') });
  const k = await renders();
  await page.uncheck('#pano-on');
  await waitRenders(k + 1);
  assert.ok(!renderRequests.at(-1).camera.projection, 'back to the perspective camera');
});

test('screenshots, and nothing went wrong on the way', async () => {
  await page.fill('#admin-token', '');
  await page.evaluate(() => { document.getElementById('admin').open = false; window.scrollTo(0, 0); });
  const shot = path.join(OUT, 'web-page.png');
  await page.screenshot({ path: shot, fullPage: true });
  await page.locator('#view-panel').screenshot({ path: path.join(OUT, 'web-view.png') });
  assert.ok(readFileSync(shot).length > 10000, 'a screenshot was written');
  if (process.env.TERRAD_WEB_DOCS_SCREENSHOT === '1') {
    await mkdir(path.join(SRC, 'docs'), { recursive: true });
    await copyFile(shot, path.join(SRC, 'docs', 'web-screenshot.png'));
  }
  assert.deepEqual(foreign, [], 'no request left the loopback server');
  // The only failed requests are the ones the tests caused: the wrong admin token (401)
  // level of detail if this terrad refuses it (400), and the viewshed's max_distance 0 (400). The browser logs a console
  // error for each; any other console error or failed request is a defect.
  const expected = (f) => f === '401 POST /v1/admin/preload' || f === '400 POST /v1/render lod' || f === '400 POST /v1/viewshed';
  assert.deepEqual(failed.filter((f) => !expected(f)), [], 'no unexpected failed request');
  const unexpected = pageErrors.filter((e) => !/Failed to load resource: .* (401|400) /.test(e));
  assert.deepEqual(unexpected, [], 'no page errors');
  assert.equal(pageErrors.length - unexpected.length, failed.length, 'one console error per failed request');
  assert.equal(serverExit, null, 'terrad is still running');
});

test('another dataset: its map, its view, its attribution', async () => {
  const n = await renders();
  await page.selectOption('#dataset', 'volcano');
  await waitRenders(n + 1);
  const last = renderRequests.at(-1);
  assert.equal(last.dataset, 'volcano');
  // Camera inside the 600 x 860 m grid and a sensible height for 100 m of relief.
  const p = last.camera.position;
  assert.ok(p.x > 0 && p.x < 600 && p.y > 0 && p.y < 860 && p.agl > 0 && p.agl < 100, JSON.stringify(p));
  const s = await viewStats('#view-img');
  assert.ok(s.opaque > 0.9 * s.pixels && s.variance > 20, 'a picture of the volcano');
  assert.match(await page.textContent('#attribution-current'), /volcano/);
  await page.waitForFunction(() => [...document.querySelectorAll('img.leaflet-tile')].some((t) => t.complete && t.naturalWidth === 256 && t.src.includes('/volcano/')));
  assert.match(page.url(), /#volcano\//, 'the camera is in the URL');
  assert.deepEqual(foreign, [], 'no request left the loopback server');
});
