// panorama.mjs: the README gallery's labelled panorama. Starts `terrad serve` on a free
// loopback port with the demo data, renders docs/gallery/trinidad-panorama.json
// (POST /v1/render: a 360-degree cylindrical view) and asks POST /v1/peaks for the summits
// of at least 100 m prominence that view sees, then lays the labels over the picture as
// the web page does (web/js/peaks.js's placeLabels, web/style.css's .peak-label) in
// headless chromium and writes docs/gallery/trinidad-panorama-labelled.png and the answer as
// trinidad-panorama.peaks.json.
//   usage: node docs/gallery/panorama.mjs [BUILD_DIR]   (default: build; needs web/node_modules)
import { spawn } from 'node:child_process';
import { createServer } from 'node:net';
import { readFileSync, writeFileSync } from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { createRequire } from 'node:module';

const here = path.dirname(fileURLToPath(import.meta.url));
const root = path.resolve(here, '..', '..');
const terrad = path.join(root, process.argv[2] || 'build', 'terrad');
const { chromium } = createRequire(path.join(root, 'web', 'package.json'))('playwright-core');
const { placeLabels } = await import(path.join(root, 'web', 'js', 'peaks.js'));

const port = await new Promise((ok) => { const s = createServer(); s.listen(0, '127.0.0.1', () => { const p = s.address().port; s.close(() => ok(p)); }); });
const base = `http://127.0.0.1:${port}`;
const server = spawn(terrad, ['serve', '--listen', `127.0.0.1:${port}`, '--demo-dir', path.join(root, 'data'), '--log-level', 'warn'],
  { stdio: 'inherit' });
try {
  for (let k = 0; ; k++) {
    const r = await fetch(`${base}/readyz`).catch(() => null);
    if (r && r.ok) break;
    if (k > 300) throw new Error('terrad did not get ready');
    await new Promise((ok) => setTimeout(ok, 100));
  }
  const scene = JSON.parse(readFileSync(path.join(here, 'trinidad-panorama.json'), 'utf8'));
  const post = (p, body) => fetch(`${base}${p}`, { method: 'POST', headers: { 'Content-Type': 'application/json' }, body: JSON.stringify(body) });
  const png = Buffer.from(await (await post('/v1/render', scene)).arrayBuffer());
  const peaks = await (await post('/v1/peaks', { ...scene, min_prominence: 100, max_peaks: 60 })).json();
  if (!peaks.peaks) throw new Error(JSON.stringify(peaks));
  writeFileSync(path.join(here, 'trinidad-panorama.peaks.json'), JSON.stringify(peaks, null, 1) + '\n');
  const css = readFileSync(path.join(root, 'web', 'style.css'), 'utf8');
  const labels = placeLabels(peaks.peaks, 1).map((l) =>
    `<div class="peak-label" style="left:${l.x}px;top:${l.y}px;--tier:${l.tier}"><span>${l.text}</span></div>`).join('');
  const { width, height } = scene.image;
  const browser = await chromium.launch({ executablePath: process.env.CHROMIUM || '/usr/bin/chromium', headless: true, args: ['--no-sandbox'] });
  const page = await browser.newPage({ viewport: { width, height } });
  await page.setContent(`<style>${css} body{margin:0} #p{position:relative;width:${width}px;height:${height}px;line-height:0}</style>` +
    `<div id="p"><img src="data:image/png;base64,${png.toString('base64')}"><div class="peak-labels" style="aspect-ratio:${width}/${height}">${labels}</div></div>`);
  await page.locator('#p').screenshot({ path: path.join(here, 'trinidad-panorama-labelled.png') });
  await browser.close();
  console.log(`${peaks.visible} of ${peaks.summits} summits labelled; ${peaks.rays} rays; summits found in ${peaks.summits_ms.toFixed(0)} ms`);
} finally {
  server.kill('SIGTERM');
}
