// unit.test.mjs: the page's pure modules under node's test runner (no browser, no
// server): Server-Timing parsing, the scene JSON, the pick answer, job progress, the
// frame <-> map transformation, camera geometry, the pixel difference and the viewshed
// overlay.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import {
  parseServerTiming, buildScene, pickScene, firstPick, jobProgress, renderInfo, parseHeightError, routedUrl,
} from '../js/api.js';
import {
  normaliseDataset, transformation, maxNativeZoom, wedge, headingTo, along, normHeading,
  keyMove, defaultCamera, frameToGeo, roundNice,
} from '../js/frame.js';
import { diffRGBA, imageStats } from '../js/diff.js';
import { discRegion, raiseDisc, encodeHeights, decodeHeights } from '../js/disc.js';
import {
  recolourViewshed, overlayBounds, sampleAt, viewshedBody, VISIBLE_RGBA, HIDDEN_RGBA, OUTSIDE_RGBA,
} from '../js/viewshed.js';
import { panoramaScene, peaksBody, peakText, placeLabels } from '../js/peaks.js';
import { stagesOf, totalOf } from '../js/chart.js';

const near = (a, b, eps = 1e-9) => Math.abs(a - b) <= eps;

// As GET /v1/datasets answers for the Trinidad demo (trimmed).
const TRINIDAD = {
  id: 'trinidad', file: 'blanca.f32', size: { width: 600, height: 500 },
  spacing: [73.61123492, 92.49042298],
  extent: { x: [0, 44093.12972], y: [0, 46152.72107], z: [2254, 4322] },
  georeference: { kind: 'lonlat', origin: [-105.7358333, 37.37000001], step: [0.0008333333434, 0.0008333333535] },
  tiles: { size: 256, x: 3, y: 2, total: 6 }, residency: { tiles: 6 },
};

test('Server-Timing: entries in order, durations, quoted descriptions with commas', () => {
  const t = parseServerTiming('parse;dur=0.042, queue;dur=1.5, trace;desc="primary, curved";dur=370.25,encode;dur=12');
  assert.deepEqual(t.map((e) => e.name), ['parse', 'queue', 'trace', 'encode']);
  assert.deepEqual(t.map((e) => e.dur), [0.042, 1.5, 370.25, 12]);
  assert.equal(t[2].desc, 'primary, curved');
  assert.deepEqual(parseServerTiming(''), []);
  assert.deepEqual(parseServerTiming(null), []);
  const odd = parseServerTiming('cache, miss;dur=abc');
  assert.deepEqual(odd, [{ name: 'cache', dur: null, desc: '' }, { name: 'miss', dur: null, desc: '' }]);
});

test('chart: a pagein entry is a bar, not added to the total (it is inside trace)', () => {
  const info = { timing: parseServerTiming('parse;dur=1, trace;dur=100, encode;dur=4, pagein;dur=60;desc="9 major faults"') };
  assert.deepEqual(stagesOf(info).map((s) => s.name), ['parse', 'trace', 'encode', 'pagein']);
  assert.equal(totalOf(info), 105);
});

test('render headers: steps per ray from X-Terrad-Steps over X-Terrad-Rays', () => {
  const h = new Headers({ 'Server-Timing': 'trace;dur=10', 'X-Terrad-Method': 'auto:parametric',
    'X-Terrad-Surface': 'bilinear', 'X-Terrad-Rays': '1000', 'X-Terrad-Steps': '12500' });
  const i = renderInfo(h);
  assert.equal(i.method, 'auto:parametric');
  assert.equal(i.surface, 'bilinear');
  assert.equal(i.stepsPerRay, 12.5);
  assert.equal(renderInfo(new Headers()).stepsPerRay, null);
  assert.equal(renderInfo(new Headers()).heightError, null);
  assert.equal(renderInfo(new Headers()).sunBound, null);
  assert.equal(renderInfo(new Headers({ 'X-Terrad-Sun-Bound': 'kept' })).sunBound, 'kept');
});

test('render headers: how far the picture is from the exact one', () => {
  const i = renderInfo(new Headers({ 'X-Terrad-Height-Error': 'mean=0.261; max=18.7; hits=41833' }));
  assert.deepEqual(i.heightError, { mean: 0.261, max: 18.7, hits: 41833 });
  assert.deepEqual(parseHeightError('mean=1e-13; max=9.1e-12'), { mean: 1e-13, max: 9.1e-12 });
  assert.equal(parseHeightError('mean=abc; max=1'), null);
  assert.equal(parseHeightError(''), null);
});

test('scene JSON: camera above ground, only the effects that are on', () => {
  const cam = { x: 1000.12345, y: 2000, agl: 300, heading: 45, pitch: -5, fov: 60 };
  const fx = { sunAzimuth: 315, sunElevation: 35, shadows: true, sky: false, haze: true, hazeKm: 80,
    water: false, waterLevel: 0, ao: true, aoRays: 8, curvature: false };
  const s = buildScene('trinidad', cam, { width: 640, height: 400 },
    { method: 'auto', surface: 'bilinear', samples: 2, lod: false }, fx);
  assert.deepEqual(s, {
    dataset: 'trinidad',
    camera: { position: { x: 1000.123, y: 2000, agl: 300 }, heading: 45, pitch: -5, fov: 60 },
    image: { width: 640, height: 400, format: 'png' },
    quality: { method: 'auto', surface: 'bilinear', samples: 2 },
    effects: { sun: { azimuth: 315, elevation: 35 }, shadows: true, haze: { visibility_km: 80 }, ambient_occlusion: 8 },
  });
  const p = pickScene(s, 319.5, 300);
  assert.equal(p.image.format, 'pick');
  assert.deepEqual(p.pick, [[319.5, 300]]);
  assert.equal(s.image.format, 'png', 'the render scene is left as it was');
});

test('pick answer: terrad\'s shape, hit and miss', () => {
  const hit = firstPick({ dataset: 'trinidad', picks: [{ pixel: [320, 300], hit: true,
    point: { x: 28219.5, y: 36536.1, z: 2821.7 }, distance: 1269, cell: [383, 395], lonlat: [-105.41637, 37.69919] }] });
  assert.equal(hit.hit, true);
  assert.deepEqual([hit.x, hit.y, hit.z, hit.lon, hit.lat, hit.distance], [28219.5, 36536.1, 2821.7, -105.41637, 37.69919, 1269]);
  const miss = firstPick({ dataset: 'x', picks: [{ pixel: [1, 2], hit: false }] });
  assert.equal(miss.hit, false);
  assert.equal(miss.x, null);
  const proj = firstPick({ picks: [{ pixel: [0, 0], hit: true, point: { x: 1, y: 2, z: 3 }, projected: [5, 6] }] });
  assert.deepEqual([proj.east, proj.north, proj.lon], [5, 6, null]);
  assert.equal(firstPick({ picks: [] }), null);
});

test('job progress: builds share the bar, done is 1', () => {
  const j = (state, phase, done, total, build = ['maxmip', 'planes']) => ({ state, phase, tiles: { done, total }, build });
  assert.equal(jobProgress(j('queued', '', 0, 0)), 0);
  assert.equal(jobProgress(j('running', 'checking', 0, 6)), 0);
  assert.equal(jobProgress(j('running', 'maxmip', 3, 6)), 0.25);
  assert.equal(jobProgress(j('running', 'planes', 3, 6)), 0.75);
  assert.equal(jobProgress(j('running', 'planes', 3, 6, ['planes'])), 0.5);
  assert.equal(jobProgress(j('running', 'publishing', 6, 6)), 0.99);
  assert.equal(jobProgress(j('done', 'publishing', 6, 6)), 1);
  assert.equal(jobProgress(null), 0);
});

test('map transformation: the zoom-0 tile holds the grid, north-west at its top-left', () => {
  const ds = normaliseDataset(TRINIDAD);
  assert.equal(ds.width, 600);
  assert.equal(ds.ymax, 46152.72107);
  const t = transformation(ds);
  const px = (x, y) => [t.a * x + t.b, t.c * y + t.d];
  assert.deepEqual(px(0, ds.ymax), [0, 0]);
  const [sx, sy] = px(ds.xmax, 0);
  assert.ok(near(sy, 256, 1e-9), 'the taller side fills the tile');
  assert.ok(near(sx, (256 * ds.xmax) / ds.ymax, 1e-9));
  // The server's tile x = 1, y = 1 at zoom 1 starts at metres (side/2, ymax - side/2).
  const side = ds.ymax;
  const [p1x, p1y] = px(side / 2, ds.ymax - side / 2);
  assert.ok(near(p1x * 2, 256) && near(p1y * 2, 256));
  // 599 cells in 256 px: zoom 2 (1024 px) is the first with a pixel per cell or less.
  assert.equal(maxNativeZoom(ds), 2);
  assert.equal(maxNativeZoom(normaliseDataset({ ...TRINIDAD, size: { width: 61, height: 87 } })), 0);
});

test('lon/lat of a frame point with the server\'s formula', () => {
  const ds = normaliseDataset(TRINIDAD);
  const g = frameToGeo(ds, 0, 0);
  assert.deepEqual([g.x, g.y], [-105.7358333, 37.37000001]);
  const ne = frameToGeo(ds, ds.xmax, ds.ymax);
  assert.ok(near(ne.x, -105.7358333 + 599 * 0.0008333333434, 1e-6));
  assert.ok(near(ne.y, 37.37000001 + 499 * 0.0008333333535, 1e-6));
  assert.equal(frameToGeo(normaliseDataset({ ...TRINIDAD, georeference: null }), 1, 1), null);
});

test('headings: clockwise from north', () => {
  assert.equal(headingTo(0, 0, 0, 10), 0);
  assert.equal(headingTo(0, 0, 10, 0), 90);
  assert.equal(headingTo(0, 0, 0, -10), 180);
  assert.equal(headingTo(0, 0, -10, 0), 270);
  assert.equal(normHeading(-30), 330);
  assert.equal(normHeading(725), 5);
  const [x, y] = along(100, 100, 90, 50);
  assert.ok(near(x, 150) && near(y, 100, 1e-9));
});

test('the wedge spans heading +- fov/2 at the given distance', () => {
  const w = wedge({ x: 0, y: 0, heading: 90, fov: 60 }, 1000, 6);
  assert.deepEqual(w[0], [0, 0]);
  assert.equal(w.length, 8);
  for (const [x, y] of w.slice(1)) assert.ok(near(Math.hypot(x, y), 1000, 1e-6));
  assert.ok(near(headingTo(0, 0, ...w[1]), 60, 1e-9));
  assert.ok(near(headingTo(0, 0, ...w[4]), 90, 1e-9));
  assert.ok(near(headingTo(0, 0, ...w[7]), 120, 1e-9));
});

test('keyboard moves: forward along the heading, turns, stays in the grid', () => {
  const ds = normaliseDataset(TRINIDAD);
  const cam = { x: 1000, y: 1000, heading: 0, agl: 100, pitch: 0, fov: 60 };
  const up = keyMove(cam, 'ArrowUp', ds, false);
  assert.ok(near(up.x, 1000, 1e-9) && near(up.y, 1000 + 0.01 * ds.ymax, 1e-9));
  assert.equal(keyMove(cam, 'ArrowRight', ds, false).heading, 5);
  assert.equal(keyMove(cam, 'ArrowLeft', ds, true).heading, 345);
  const back = keyMove(cam, 'ArrowDown', ds, true);
  assert.equal(back.y, 0, 'clamped at the southern edge');
  assert.equal(keyMove(cam, 'a', ds, false), null);
  assert.equal(cam.y, 1000, 'the camera given is not changed');
});

test('default camera: inside the grid, above ground, looking towards the centre', () => {
  const ds = normaliseDataset(TRINIDAD);
  const c = defaultCamera(ds);
  assert.ok(c.x > 0 && c.x < ds.xmax && c.y > 0 && c.y < ds.ymax);
  assert.equal(c.agl, 500);
  const toCentre = headingTo(c.x, c.y, ds.xmax / 2, ds.ymax / 2);
  assert.ok(Math.abs(c.heading - toCentre) < c.fov / 2);
  assert.deepEqual([roundNice(517), roundNice(2100), roundNice(99)], [500, 2000, 50]);
});

test('pixel difference: counts, threshold, PSNR and the difference image', () => {
  const w = 4, h = 2, n = w * h;
  const a = new Uint8ClampedArray(n * 4).fill(100);
  const b = new Uint8ClampedArray(a);
  b[0] = 110;        // pixel 0: 10 in red (visible at threshold 8)
  b[4 + 2] = 103;    // pixel 1: 3 in blue (differs, not visible)
  b[8 + 3] = 0;      // pixel 2: alpha 100 -> 0
  const r = diffRGBA(a, b, w, h, 8);
  assert.equal(r.differ, 3);
  assert.equal(r.visible, 2);
  assert.equal(r.max, 100);
  assert.ok(near(r.mean, (10 + 3 + 100) / n));
  const mse = (10 * 10 + 3 * 3) / (n * 3);
  assert.ok(near(r.psnr, 10 * Math.log10((255 * 255) / mse), 1e-9));
  // Pixel 0 (grey 50 in A) differs by 10: 10/32 of the way to red.
  assert.equal(r.image[0], Math.round(50 + 205 * (10 / 32)), 'a differing pixel turns red');
  assert.equal(r.image[1], Math.round(50 * (22 / 32)));
  // Pixel 2 differs by 100 (alpha): fully red.
  assert.deepEqual([...r.image.subarray(8, 12)], [255, 0, 0, 255]);
  assert.equal(r.image[12], 50, 'an equal pixel is a dimmed grey of A');
  assert.equal(r.image[12 + 3], 255);
  const same = diffRGBA(a, a, w, h);
  assert.equal(same.differ, 0);
  assert.equal(same.psnr, Infinity);
  assert.throws(() => diffRGBA(a, b.subarray(0, 8), w, h));
});

test('image statistics: transparent pixels do not count', () => {
  const d = new Uint8ClampedArray([0, 0, 0, 0, 255, 255, 255, 255, 0, 0, 0, 255]);
  const s = imageStats(d);
  assert.equal(s.pixels, 3);
  assert.equal(s.opaque, 2);
  assert.ok(near(s.mean, 127.5, 1e-9));
  assert.ok(near(s.variance, 127.5 * 127.5, 1e-6));
});

test('terrain disc: the region in file order, the bump, the body both ways', () => {
  const ds = { width: 11, height: 9, sx: 10, sy: 20 }; // x 0..100, y 0..160
  // radius 25 around (50, 80): columns 3..7 (30..70), south rows 3..5 (60..100) = file rows 5..3
  assert.deepEqual(discRegion(ds, 50, 80, 25), { x: 3, y: 3, w: 5, h: 3 });
  // clipped at the grid's south-west corner: column 0..2, south rows 0..1 = file rows 8..7
  assert.deepEqual(discRegion(ds, 0, 0, 25), { x: 0, y: 7, w: 3, h: 2 });
  assert.equal(discRegion(ds, 500, 80, 25), null);
  assert.equal(discRegion(ds, 50, 80, 0), null);
  const reg = discRegion(ds, 50, 80, 25);
  const z = new Float32Array(reg.w * reg.h).fill(100);
  z[0] = NaN;
  const out = raiseDisc(z, reg, ds, 50, 80, 25, 40);
  // the centre (column 5, south row 4 = file row 4: region row 1, column 2) rises by 40
  assert.equal(out[1 * 5 + 2], 140);
  // 10 m east: cos bump 0.5 * (1 + cos(pi * 10 / 25))
  assert.ok(near(out[1 * 5 + 3], 100 + 20 * (1 + Math.cos(Math.PI * 0.4)), 1e-4));
  // 20 m north (file row 3 = region row 0), 20 m west: d = 28.3 > 25, untouched; voids stay
  assert.equal(out[0 * 5 + 0], z[0 * 5 + 0]);
  assert.ok(Number.isNaN(out[0]));
  const lowered = raiseDisc(z, reg, ds, 50, 80, 25, -40);
  assert.equal(lowered[7], 60);
  const buf = encodeHeights(new Float32Array([1.5, -0.25, NaN]));
  assert.deepEqual([...new Uint8Array(buf)].slice(0, 8), [0, 0, 0xc0, 0x3f, 0, 0, 0x80, 0xbe]);
  const back = decodeHeights(buf);
  assert.equal(back[0], 1.5);
  assert.equal(back[1], -0.25);
  assert.ok(Number.isNaN(back[2]));
});

test('viewshed overlay: seen green, hidden dark, outside and void transparent', () => {
  // four gray pixels as a canvas reads the server's PNG back: 255, 0, 128, 255
  const gray = new Uint8ClampedArray([255, 255, 255, 255, 0, 0, 0, 255, 128, 128, 128, 255, 255, 255, 255, 255]);
  const r = recolourViewshed(gray);
  assert.deepEqual([...r.out], [...VISIBLE_RGBA, ...HIDDEN_RGBA, ...OUTSIDE_RGBA, ...VISIBLE_RGBA]);
  assert.deepEqual([r.visible, r.hidden, r.outside], [2, 1, 1]);
  assert.equal(OUTSIDE_RGBA[3], 0, 'outside is fully transparent');
  assert.ok(VISIBLE_RGBA[3] > 0 && VISIBLE_RGBA[3] < 255 && HIDDEN_RGBA[3] > 0 && HIDDEN_RGBA[3] < 255, 'translucent');
  assert.ok(VISIBLE_RGBA[1] > VISIBLE_RGBA[0] && VISIBLE_RGBA[1] > VISIBLE_RGBA[2], 'seen is green');
  // in place, as the page does it on the canvas's own pixels
  const same = recolourViewshed(gray, gray);
  assert.equal(same.out, gray);
  assert.deepEqual([...gray.slice(0, 4)], VISIBLE_RGBA);
});

test('viewshed overlay: bounds half a sample beyond the grid, the observer\'s pixel, the body', () => {
  const ds = normaliseDataset(TRINIDAD);
  const [[s, w], [n, e]] = overlayBounds(ds);
  assert.ok(near(w, -ds.sx / 2) && near(s, -ds.sy / 2));
  assert.ok(near(e, 599 * ds.sx + ds.sx / 2, 1e-3) && near(n, 499 * ds.sy + ds.sy / 2, 1e-3));
  // each of the 600 x 500 pixels is one spacing wide: pixel i centred on sample i
  assert.ok(near((e - w) / 600, ds.sx, 1e-6) && near((n - s) / 500, ds.sy, 1e-6));
  assert.deepEqual(sampleAt(ds, 0, 0), [0, 499], 'south-west sample: last row');
  assert.deepEqual(sampleAt(ds, ds.xmax, ds.ymax), [599, 0], 'north-east sample: first row');
  assert.deepEqual(sampleAt(ds, 10.4 * ds.sx, 3.6 * ds.sy), [10, 495]);
  assert.deepEqual(sampleAt(ds, -5, 1e9), [0, 0], 'clamped to the grid');
  assert.deepEqual(viewshedBody('trinidad', 1234.56789, 42, { height: null, maxDistance: null, surface: 'bilinear' }),
    { dataset: 'trinidad', observer: { x: 1234.568, y: 42 }, height: 2, format: 'png', surface: 'bilinear' });
  const b = viewshedBody('volcano', 1, 2, { height: 10, maxDistance: 5000 });
  assert.equal(b.height, 10);
  assert.equal(b.max_distance, 5000);
  assert.equal(viewshedBody('v', 1, 2, { maxDistance: 0 }).max_distance, 0, 'terrad judges 0, not the page');
});

test('the camera fragment round-trips (page and web map share it)', async () => {
  const { cameraHash, parseCameraHash } = await import('../js/frame.js');
  const cam = { x: 20000.123, y: 15000, agl: 300, heading: 60, pitch: -8.5, fov: 60 };
  const h = cameraHash('a b/c', cam);
  assert.equal(h, '#a%20b%2Fc/20000.12/15000/300/60/-8.5/60');
  assert.deepEqual(parseCameraHash(h), { id: 'a b/c', cam: { ...cam, x: 20000.12 } });
  assert.equal(parseCameraHash('#trinidad/1/2/3'), null);
  assert.equal(parseCameraHash('#trinidad/1/2/3/x/5/6'), null);
});

test('POSTs carry the body\'s dataset in the query: the key a proxy routes replicas on', () => {
  assert.equal(routedUrl('/v1/render', { dataset: 'trinidad', camera: {} }), '/v1/render?dataset=trinidad');
  assert.equal(routedUrl('/v1/x?a=1', { dataset: 'a b/c' }), '/v1/x?a=1&dataset=a%20b%2Fc');
  assert.equal(routedUrl('/v1/admin/preload', { tiles: [] }), '/v1/admin/preload');
  assert.equal(routedUrl('/v1/render', null), '/v1/render');
});

test('panorama and summits: the scenes, the body, labels in tiers that never overlap', () => {
  const scene = buildScene('trinidad', { x: 1, y: 2, agl: 3, heading: 40, pitch: -2, fov: 60 },
    { width: 900, height: 400 }, { method: 'auto', surface: 'bilinear', samples: 1 }, { sunAzimuth: 1, sunElevation: 2 });
  const pano = panoramaScene(scene);
  assert.equal(pano.camera.projection, 'cylindrical');
  assert.equal(pano.camera.fov, 360);
  assert.equal(pano.image.height, 300);
  assert.equal(scene.camera.fov, 60, 'the scene itself is left alone');
  const b = peaksBody({ ...pickScene(pano, 1, 2) }, 150);
  assert.equal(b.min_prominence, 150);
  assert.equal(b.image.format, 'png');
  assert.ok(!('pick' in b));
  assert.equal(peakText({ z: 4321.6, distance: 15300 }), '4322 m · 15 km');
  assert.equal(peakText({ z: 100, distance: 2340 }), '100 m · 2.3 km');
  const peaks = [0, 5, 10, 300, 8].map((px) => ({ px, py: 50, z: 3000, distance: 5000 }));
  const placed = placeLabels(peaks, 2, { maxTiers: 3 });
  // the first three overlap (each label is ~90 px wide at scale 2): tiers 0, 1, 2; the
  // fourth is far away: tier 0; the fifth has no tier left: left out
  assert.deepEqual(placed.map((l) => l.tier), [0, 1, 2, 0]);
  assert.ok(near(placed[3].x, 601) && near(placed[3].y, 101));
  for (let i = 0; i < placed.length; i++)
    for (let j = i + 1; j < placed.length; j++)
      if (placed[i].tier === placed[j].tier) assert.ok(Math.abs(placed[i].x - placed[j].x) > 90);
  // summits at different heights: a box is where its tier puts it, not a row of its own
  const two = placeLabels([{ px: 0, py: 100, z: 1, distance: 1 }, { px: 20, py: 110, z: 1, distance: 1 }], 1);
  assert.deepEqual(two.map((l) => l.tier), [0, 2], 'one tier up lands on the first box; two clear it');
});
