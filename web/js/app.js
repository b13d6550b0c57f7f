// app.js: the page's wiring. The map (Leaflet, CRS.Simple with LatLng = dataset frame
// point, see frame.js) shows the dataset's shaded tiles, the camera, its heading handle,
// the view's wedge and picked points; the panel beside it shows the view from the camera
// rendered by POST /v1/render, its Server-Timing as a bar chart, and in compare mode a
// second render with other settings and the pixel difference of the two.
// With the viewshed control on, a map click places an observer instead of the camera
// and viewshed.js lays what it sees over the map.
//
// Requests: every change of camera or settings schedules a render, debounced (a burst
// of changes sends one request) but with a longest wait so a long drag still shows
// views; a new render aborts the one in flight (AbortController), so only the latest
// camera's view is ever shown. Picks use the scene of the image on screen, not the
// camera as it is now, so the marker is the point under the pixel that was clicked.
//
// State the browser test reads: body[data-renders] counts views shown,
// body[data-picks] picked points, body[data-viewsheds] viewshed overlays shown;
// window.terrad exposes the state.
import * as api from './api.js';
import {
  normaliseDataset, transformation, maxNativeZoom, defaultCamera, wedge, along, headingTo,
  normHeading, clampToDataset, keyMove, frameToGeo, clamp, cameraHash, parseCameraHash,
} from './frame.js';
import { drawTimingChart, totalOf, fmtMs } from './chart.js';
import { diffImages } from './diff.js';
import { discRegion, raiseDisc, encodeHeights, decodeHeights } from './disc.js';
import { ViewshedControl } from './viewshed.js';
import { PeaksControl, panoramaScene } from './peaks.js';

const $ = (id) => document.getElementById(id);
const DEBOUNCE_MS = 150, MAX_WAIT_MS = 500;

// Attribution of each demo dataset (data/README.md), matched on the dataset id.
const ATTRIBUTIONS = [
  { match: /^levi/i, name: 'Levi (Finnish Lapland)', short: '© National Land Survey of Finland',
    html: 'Levi: elevation model © National Land Survey of Finland, open data licence v1.0 (via Qt Data Visualization examples).' },
  { match: /^trinidad|^blanca/i, name: 'Trinidad / Blanca Peak (Colorado)', short: 'USGS (public domain)',
    html: 'Trinidad / Blanca Peak: USGS 3″ DEM “Trinidad”, US public domain.' },
  { match: /^volcano/i, name: 'Volcano (Maunga Whau, Auckland)', short: 'R datasets::volcano',
    html: 'Volcano: Maunga Whau (Mt Eden), Auckland, from R’s <code>datasets::volcano</code> (GPL-2).' },
  { match: /^picos/i, name: 'Picos de Europa (Spain)', short: '© IGN España, CC-BY 4.0',
    html: 'Picos de Europa: © Instituto Geográfico Nacional de España, CC-BY 4.0.' },
];

const state = {
  datasets: [],
  ds: null,
  cam: null,
  map: null,
  layers: null,
  controller: null,
  timer: null,
  firstScheduled: 0,
  renders: 0,
  picks: 0,
  shown: null,      // {a: {scene, info}, b: {scene, info} | null}
  urls: new Map(),  // img element -> object URL shown
  adminJob: null,
  viewshed: null,   // ViewshedControl (viewshed.js)
  peaks: null,      // PeaksControl (peaks.js): summit labels over view A and the map
};
window.terrad = state;

// --- status ---------------------------------------------------------------------------

function setStatus(text, isError = false) {
  const s = $('status');
  s.textContent = text;
  s.classList.toggle('error', isError);
}

function attributionFor(id) {
  const a = ATTRIBUTIONS.find((x) => x.match.test(id));
  return a ? a.html : `${escapeHtml(id)}: user data (see its source for terms).`;
}

function shortAttribution(id) {
  const a = ATTRIBUTIONS.find((x) => x.match.test(id));
  return a ? a.short : escapeHtml(id);
}

function escapeHtml(s) {
  return String(s).replace(/[&<>"']/g, (c) => ({ '&': '&amp;', '<': '&lt;', '>': '&gt;', '"': '&quot;', "'": '&#39;' })[c]);
}

function fmtM(v) {
  return `${Math.round(v).toLocaleString('en-US')} m`;
}

// --- datasets -------------------------------------------------------------------------

async function loadDatasets() {
  setStatus('Loading datasets…');
  const list = (await api.datasets()).map(normaliseDataset);
  if (!list.length) throw new Error('terrad serves no dataset');
  state.datasets = list;
  const sel = $('dataset');
  sel.replaceChildren(...list.map((d) => {
    const o = document.createElement('option');
    o.value = d.id;
    o.textContent = d.id;
    return o;
  }));
  const ul = $('attributions');
  ul.replaceChildren(...list.map((d) => {
    const li = document.createElement('li');
    li.innerHTML = attributionFor(d.id);
    return li;
  }));
}

function describeDataset(ds) {
  let t = `${ds.width} × ${ds.height} samples, ${+ds.sx.toFixed(2)} × ${+ds.sy.toFixed(2)} m, ` +
    `${fmtM(ds.xmax - ds.xmin)} × ${fmtM(ds.ymax - ds.ymin)}, heights ${Math.round(ds.zmin)}–${Math.round(ds.zmax)} m`;
  if (ds.tiles && ds.residency) t += `; accelerated tiles ${ds.residency.tiles}/${ds.tiles.total}`;
  return t;
}

async function refreshDatasetInfo() {
  try {
    const d = normaliseDataset(await api.dataset(state.ds.id));
    const i = state.datasets.findIndex((x) => x.id === d.id);
    if (i >= 0) state.datasets[i] = d;
    if (state.ds.id === d.id) {
      const was = state.ds.version;
      state.ds = d;
      $('dataset-info').textContent = describeDataset(d);
      $('dataset-version').textContent = String(d.version);
      if (d.version !== was && state.layers) {
        // a new layer, not setUrl: Leaflet's redraw asks for tiles at a fractional zoom
        state.map.removeLayer(state.layers.tiles);
        state.layers.tiles = tileLayer(d).addTo(state.map);
      }
    }
  } catch (e) { /* informational only */ }
}

function selectDataset(id, cam) {
  const ds = state.datasets.find((d) => d.id === id) || state.datasets[0];
  state.ds = ds;
  $('dataset').value = ds.id;
  $('dataset-info').textContent = describeDataset(ds);
  $('dataset-version').textContent = String(ds.version);
  $('attribution-current').innerHTML = attributionFor(ds.id);
  const relief = Math.max(ds.zmax - ds.zmin, 1);
  $('cam-agl-range').max = String(Math.max(200, Math.ceil((relief * 2) / 100) * 100));
  state.cam = cam || defaultCamera(ds);
  [state.cam.x, state.cam.y] = clampToDataset(ds, state.cam.x, state.cam.y);
  buildMap();
  syncFields();
  drawCamera();
  scheduleRender({ now: true });
}

// --- map ------------------------------------------------------------------------------

const LL = (x, y) => L.latLng(y, x);
// The heights version in the URL: the browser keeps tiles for a day, and an edit must show.
const tileUrl = (ds) => `/v1/tiles/${encodeURIComponent(ds.id)}/{z}/{x}/{y}.png?v=${ds.version}`;

function tileLayer(ds) {
  const nz = maxNativeZoom(ds);
  return L.tileLayer(tileUrl(ds), {
    tileSize: 256, minNativeZoom: 0, maxNativeZoom: nz, minZoom: -2, maxZoom: nz + 3,
    bounds: L.latLngBounds(LL(ds.xmin, ds.ymin), LL(ds.xmax, ds.ymax)), noWrap: true,
    attribution: shortAttribution(ds.id), className: 'terrad-tiles',
  });
}

function buildMap() {
  const ds = state.ds;
  if (state.map) state.map.remove();
  const t = transformation(ds);
  const crs = L.extend({}, L.CRS.Simple, { transformation: new L.Transformation(t.a, t.b, t.c, t.d) });
  const bounds = L.latLngBounds(LL(ds.xmin, ds.ymin), LL(ds.xmax, ds.ymax));
  const nz = maxNativeZoom(ds);
  const map = L.map('map', {
    crs, minZoom: -2, maxZoom: nz + 3, keyboard: true, zoomControl: true, zoomSnap: 0.25, zoomDelta: 0.5,
    maxBounds: bounds.pad(0.5), maxBoundsViscosity: 0.8,
  });
  map.attributionControl.setPrefix('Leaflet');
  const tiles = tileLayer(ds).addTo(map);
  L.control.scale({ imperial: false }).addTo(map);
  map.fitBounds(bounds, { padding: [8, 8] });

  const camIcon = L.divIcon({ className: '', html: '<div class="cam-icon"></div>', iconSize: [18, 18], iconAnchor: [9, 9] });
  const handleIcon = L.divIcon({ className: '', html: '<div class="handle-icon"></div>', iconSize: [14, 14], iconAnchor: [7, 7] });
  const wedgeLayer = L.polygon([], { color: '#d6336c', weight: 1.5, fillOpacity: 0.15, interactive: false }).addTo(map);
  const headingLine = L.polyline([], { color: '#d6336c', weight: 2, dashArray: '4 4', interactive: false }).addTo(map);
  const camera = L.marker(LL(state.cam.x, state.cam.y), {
    icon: camIcon, draggable: true, keyboard: true, autoPan: true, zIndexOffset: 1000,
    title: 'Camera (↑/↓ move, ←/→ turn)', alt: 'Camera',
  }).addTo(map);
  const handle = L.marker(LL(state.cam.x, state.cam.y), {
    icon: handleIcon, draggable: true, keyboard: true, zIndexOffset: 900,
    title: 'Heading handle (drag, or ←/→ to turn)', alt: 'Camera heading',
  }).addTo(map);
  const picks = L.layerGroup().addTo(map);
  state.map = map;
  state.layers = { camera, handle, wedgeLayer, headingLine, picks, tiles };
  state.viewshed.attach(map, ds);
  state.peaks.attach(map);

  // While dragging, previews (half size, no comparison); the full view when dropped.
  camera.on('drag', () => {
    const p = camera.getLatLng();
    const [x, y] = clampToDataset(ds, p.lng, p.lat);
    setCamera({ x, y }, { keepCameraMarker: true, preview: true });
  });
  camera.on('dragend', () => setCamera({}));
  handle.on('drag', () => {
    const p = handle.getLatLng();
    setCamera({ heading: headingTo(state.cam.x, state.cam.y, p.lng, p.lat) }, { keepHandle: true, preview: true });
  });
  handle.on('dragend', () => setCamera({}));
  map.on('click', (e) => {
    const [x, y] = clampToDataset(ds, e.latlng.lng, e.latlng.lat);
    if ($('edit-mode').checked) {
      editTerrainAt(x, y);
      return;
    }
    if ($('vs-on').checked) {
      state.viewshed.placeAt(x, y);
      return;
    }
    setCamera({ x, y });
    setStatus(`Camera placed at ${fmtM(x)} E, ${fmtM(y)} N.`);
  });
  map.on('mousemove', (e) => showCursor(e.latlng.lng, e.latlng.lat));
  // Keyboard: Enter on the focused map places the camera (or the viewshed's observer)
  // at the map's centre; arrows on the camera move and turn it, on the handle turn it
  // (and never pan the map).
  L.DomEvent.on(map.getContainer(), 'keydown', (e) => {
    if (e.key === 'Enter' && e.target === map.getContainer()) {
      const c = map.getCenter();
      const [x, y] = clampToDataset(ds, c.lng, c.lat);
      if ($('vs-on').checked) {
        state.viewshed.placeAt(x, y);
      } else {
        setCamera({ x, y });
        setStatus(`Camera placed at the map's centre, ${fmtM(x)} E, ${fmtM(y)} N.`);
      }
      L.DomEvent.preventDefault(e);
    }
  });
  const onMarkerKey = (turnOnly) => (e) => {
    const key = turnOnly && (e.key === 'ArrowUp' || e.key === 'ArrowDown') ? null : e.key;
    const c = key && keyMove(state.cam, key, ds, e.shiftKey);
    if (c) {
      setCamera(c);
      L.DomEvent.stop(e);
    }
  };
  L.DomEvent.on(camera.getElement(), 'keydown', onMarkerKey(false));
  L.DomEvent.on(handle.getElement(), 'keydown', onMarkerKey(true));
  camera.getElement().setAttribute('aria-label', 'Camera: arrow up and down move it, left and right turn it');
  handle.getElement().setAttribute('aria-label', 'Camera heading handle: left and right turn the camera');
  camera.getElement().classList.add('camera-marker');
  handle.getElement().classList.add('heading-handle');
}

function showCursor(x, y) {
  let t = `${fmtM(x)} E, ${fmtM(y)} N`;
  const g = frameToGeo(state.ds, x, y);
  if (g && g.kind === 'lonlat') t += ` (${g.x.toFixed(5)}°, ${g.y.toFixed(5)}°)`;
  $('cursor').textContent = t;
}

// Wedge length: far enough to show where the view looks, within the map.
function viewDistance() {
  const ds = state.ds;
  return 0.35 * Math.hypot(ds.xmax - ds.xmin, ds.ymax - ds.ymin);
}

function drawCamera(opts = {}) {
  const { camera, handle, wedgeLayer, headingLine } = state.layers;
  const c = state.cam;
  const hd = 0.4 * viewDistance();
  if (!opts.keepCameraMarker) camera.setLatLng(LL(c.x, c.y));
  if (!opts.keepHandle) {
    const [hx, hy] = along(c.x, c.y, c.heading, hd);
    handle.setLatLng(LL(hx, hy));
  }
  const [ex, ey] = along(c.x, c.y, c.heading, hd);
  headingLine.setLatLngs([LL(c.x, c.y), LL(ex, ey)]);
  wedgeLayer.setLatLngs(wedge(c, viewDistance()).map(([x, y]) => LL(x, y)));
}

// --- camera fields --------------------------------------------------------------------

const PAIRS = [
  ['heading', 'cam-heading', 'cam-heading-range'],
  ['agl', 'cam-agl', 'cam-agl-range'],
  ['pitch', 'cam-pitch', 'cam-pitch-range'],
  ['fov', 'cam-fov', 'cam-fov-range'],
];

function syncFields() {
  const c = state.cam;
  $('cam-x').value = c.x.toFixed(1);
  $('cam-y').value = c.y.toFixed(1);
  for (const [k, num, range] of PAIRS) {
    const v = k === 'heading' ? normHeading(c[k]) : c[k];
    if (document.activeElement !== $(num)) $(num).value = +v.toFixed(2);
    if (document.activeElement !== $(range)) $(range).value = v;
  }
}

// Applies a change to the camera, redraws it and schedules a render (a preview while
// something is being dragged, else the full view).
function setCamera(patch, drawOpts = {}) {
  const c = { ...state.cam, ...patch };
  c.heading = normHeading(c.heading);
  c.pitch = clamp(c.pitch, -90, 90);
  c.fov = clamp(c.fov, 1, 170);
  c.agl = Math.max(0, c.agl);
  state.cam = c;
  syncFields();
  drawCamera(drawOpts);
  saveHash();
  scheduleRender({ preview: !!drawOpts.preview });
}

function wireCameraFields() {
  const readXY = () => {
    const x = Number($('cam-x').value), y = Number($('cam-y').value);
    if (Number.isFinite(x) && Number.isFinite(y)) {
      const [cx, cy] = clampToDataset(state.ds, x, y);
      setCamera({ x: cx, y: cy });
    }
  };
  $('cam-x').addEventListener('change', readXY);
  $('cam-y').addEventListener('change', readXY);
  for (const [k, num, range] of PAIRS) {
    // A slider previews while it moves (input) and renders in full when let go (change).
    const apply = (el, preview) => {
      const v = Number(el.value);
      if (el.value !== '' && Number.isFinite(v)) setCamera({ [k]: v }, { preview });
    };
    $(num).addEventListener('input', () => apply($(num), false));
    $(range).addEventListener('input', () => apply($(range), true));
    $(range).addEventListener('change', () => apply($(range), false));
  }
}

// The camera in the URL fragment: #dataset/x/y/agl/heading/pitch/fov (a link shows the
// same view).
function saveHash() {
  const h = cameraHash(state.ds.id, state.cam);
  history.replaceState(null, '', h);
  const wm = document.getElementById('webmap-link');
  if (wm) wm.href = `map.html${h}`; // the web map shows this camera
}

function readHash() {
  return parseCameraHash(location.hash);
}

// --- settings -------------------------------------------------------------------------

function imageSize() {
  const [w, h] = $('q-size').value.split('x').map(Number);
  return { width: w, height: h };
}

function effects() {
  return {
    sunAzimuth: Number($('fx-sun-az').value) || 0,
    sunElevation: clamp(Number($('fx-sun-el').value) || 0, -90, 90),
    shadows: $('fx-shadows').checked,
    sky: $('fx-sky').checked,
    haze: $('fx-haze').checked,
    hazeKm: Math.max(0.01, Number($('fx-haze-km').value) || 60),
    water: $('fx-water').checked,
    waterLevel: Number($('fx-water-level').value) || 0,
    ao: $('fx-ao').checked,
    aoRays: clamp(Math.round(Number($('fx-ao-rays').value) || 8), 1, 64),
    curvature: $('fx-curvature').checked,
  };
}

function qualityA() {
  return { method: $('q-method').value, surface: $('q-surface').value, samples: Number($('q-samples').value), lod: $('q-lod').checked };
}

function qualityB() {
  return { method: $('cmp-method').value, surface: $('cmp-surface').value, samples: Number($('cmp-samples').value), lod: $('q-lod').checked };
}

const comparing = () => $('cmp-on').checked;

function wireSettings() {
  const ids = ['q-method', 'q-surface', 'q-samples', 'q-lod', 'q-size', 'fx-shadows', 'fx-sky', 'fx-haze',
    'fx-haze-km', 'fx-water', 'fx-water-level', 'fx-ao', 'fx-ao-rays', 'fx-curvature', 'fx-sun-az',
    'fx-sun-el', 'cmp-on', 'cmp-method', 'cmp-surface', 'cmp-samples'];
  for (const id of ids) $(id).addEventListener('change', () => scheduleRender());
  $('cmp-on').addEventListener('change', showCompareLayout);
  $('fx-water').addEventListener('change', () => {
    // A useful default level: a fifth of the way up the relief.
    if ($('fx-water').checked && Number($('fx-water-level').value) === 0 && state.ds.zmin > 0) {
      $('fx-water-level').value = Math.round(state.ds.zmin + 0.2 * (state.ds.zmax - state.ds.zmin));
    }
  });
  $('dataset').addEventListener('change', () => {
    selectDataset($('dataset').value);
    saveHash();
  });
  showCompareLayout();
}

function showCompareLayout() {
  const on = comparing();
  $('view-b').hidden = !on;
  $('view-diff').hidden = !on;
  $('views').classList.toggle('compare', on);
  for (const id of ['cmp-method', 'cmp-surface', 'cmp-samples']) $(id).disabled = !on;
  if (!on) $('diff-result').textContent = '';
}

// --- rendering ------------------------------------------------------------------------

// Debounced: a burst of changes sends one request, DEBOUNCE_MS after the last, or
// MAX_WAIT_MS after the first when changes keep coming (a long drag). The kind of the
// last change wins: a full render scheduled after a preview replaces it.
function scheduleRender({ now = false, preview = false } = {}) {
  const t = performance.now();
  if (!state.timer) state.firstScheduled = t;
  clearTimeout(state.timer);
  const wait = now ? 0 : Math.max(0, Math.min(DEBOUNCE_MS, MAX_WAIT_MS - (t - state.firstScheduled)));
  state.timer = setTimeout(() => {
    state.timer = null;
    renderNow(preview);
  }, wait);
}

// When terrad's queue is full it answers 503 with Retry-After: try again once then,
// unless a newer view was asked for meanwhile.
function retryLater(err) {
  const s = Math.min(10, Math.max(1, err.retryAfter || 1));
  setStatus(`terrad is busy (${err.message}); retrying in ${s} s.`, true);
  const asked = state.asked;
  setTimeout(() => { if (state.asked === asked) scheduleRender({ now: true }); }, s * 1000);
}

async function showBlob(img, blob) {
  const url = URL.createObjectURL(blob);
  const old = state.urls.get(img);
  img.src = url;
  await img.decode();
  state.urls.set(img, url);
  if (old) URL.revokeObjectURL(old);
}

// How far the picture is from the exact one, in metres with a sensible number of digits;
// rounding-level errors read as exact.
function heightErrorText(e) {
  const m = (v) => (v < 0.001 ? '0' : v < 1 ? v.toFixed(3) : v.toFixed(1));
  return e.max < 0.001 ? 'the exact surface' : `${m(e.mean)} m mean, ${m(e.max)} m max off the exact surface`;
}

function describeInfo(info, scene) {
  const q = scene.quality;
  // `auto:incremental=24%,hierarchical=76%` reads as `auto (incremental 24%, hierarchical 76%)`
  const raw = info.method || q.method, s = info.surface || q.surface;
  const [head, used] = raw.split(':');
  const m = used ? `${head} (${used.split(',').map((u) => u.replace('=', ' ')).join(', ')})` : raw;
  let t = `${m}${head !== q.method ? ` (asked ${q.method})` : ''} / ${s}, ${q.samples}×${q.samples} samples`;
  if (info.rays != null) t += `, ${info.rays.toLocaleString('en-US')} rays`;
  if (info.stepsPerRay != null && Number.isFinite(info.stepsPerRay)) t += `, ${info.stepsPerRay.toFixed(1)} steps/ray`;
  /* the shadow rays' sun bound kept from an earlier render (its build not in `shadows`) */
  if (info.sunBound === 'kept') t += ', sun bound kept';
  if (info.heightError) t += `, ${heightErrorText(info.heightError)}`;
  return t;
}

// Renders the current camera: A, and B in compare mode. A preview is half the size,
// one sample a pixel and no B; the B view and the difference are marked stale until
// the next full render.
async function renderNow(preview = false) {
  if (state.controller) state.controller.abort();
  const controller = new AbortController();
  state.controller = controller;
  state.asked = (state.asked || 0) + 1;
  const full = imageSize(), fx = effects();
  const size = preview ? { width: Math.round(full.width / 2), height: Math.round(full.height / 2) } : full;
  const qa = preview ? { ...qualityA(), samples: 1 } : qualityA();
  const pano = (sc) => ($('pano-on').checked ? panoramaScene(sc) : sc); /* peaks.js */
  const sceneA = pano(api.buildScene(state.ds.id, state.cam, size, qa, fx));
  const sceneB = comparing() && !preview ? pano(api.buildScene(state.ds.id, state.cam, size, qualityB(), fx)) : null;
  $('view-b').classList.toggle('stale', comparing() && preview);
  $('view-diff').classList.toggle('stale', comparing() && preview);
  const frames = [$('view-a'), $('view-b')].map((f) => f.querySelector('.frame'));
  frames.forEach((f) => f.classList.add('loading'));
  $('view-panel').setAttribute('aria-busy', 'true');
  try {
    const [ra, rb] = await Promise.all([
      api.render(sceneA, controller.signal),
      sceneB ? api.render(sceneB, controller.signal) : Promise.resolve(null),
    ]);
    if (controller.signal.aborted) return;
    await showBlob($('view-img'), ra.blob);
    if (rb) await showBlob($('view-img-b'), rb.blob);
    if (controller.signal.aborted) return;
    state.shown = { a: { scene: sceneA, info: ra.info, preview }, b: rb ? { scene: sceneB, info: rb.info } : null };
    $('view-a-caption').textContent = `A${preview ? ' (preview)' : ''}: ${describeInfo(ra.info, sceneA)}`;
    if (rb) $('view-b-caption').textContent = `B: ${describeInfo(rb.info, sceneB)}`;
    drawCharts();
    if (rb) showDiff();
    if (!preview) state.peaks.show(sceneA, $('view-img'), $('view-a').querySelector('.frame'));
    state.renders++;
    document.body.dataset.renders = String(state.renders);
    setStatus(`View ${state.renders}: ${fmtMs(totalOf(ra.info))} on the server` +
      (rb ? `, B ${fmtMs(totalOf(rb.info))}` : '') + `, ${Math.round(ra.ms)} ms round trip.`);
  } catch (e) {
    if (e.name === 'AbortError') return;
    if (e.status === 503) {
      retryLater(e);
    } else if (e.status === 400 && /quality\.lod:/.test(e.message) && $('q-lod').checked) {
      // This terrad does not do level of detail: say so, untick it, show the view without.
      $('q-lod').checked = false;
      setStatus(`terrad refused level of detail (${e.message}); rendering without it.`, true);
      scheduleRender({ now: true });
      $('q-lod-note').textContent = 'not available on this server';
    } else {
      setStatus(`Render failed: ${e.message}`, true);
    }
  } finally {
    if (state.controller === controller) {
      state.controller = null;
      frames.forEach((f) => f.classList.remove('loading'));
      $('view-panel').removeAttribute('aria-busy');
    }
  }
}

function drawCharts() {
  const views = [['A', state.shown.a]];
  if (state.shown.b) views.push(['B', state.shown.b]);
  const scale = Math.max(...views.map(([, v]) => Math.max(0, ...v.info.timing.filter((t) => t.name !== 'total' && t.dur != null).map((t) => t.dur))));
  const host = $('charts');
  host.replaceChildren();
  for (const [label, v] of views) {
    const div = document.createElement('div');
    div.className = 'chart';
    div.dataset.view = label;
    const q = v.scene.quality;
    // the chart's title keeps to one line: `auto`, not what it chose (the caption says that)
    const method = (v.info.method || q.method).split(':')[0];
    drawTimingChart(div, v.info, scale, `${label}${v.preview ? ' preview' : ''} ${method}/${v.info.surface || q.surface}`);
    host.append(div);
  }
}

function showDiff() {
  try {
    const r = diffImages($('view-img'), $('view-img-b'), $('diff-canvas'));
    const pct = (n) => `${((100 * n) / r.pixels).toFixed(2)}%`;
    const psnr = Number.isFinite(r.psnr) ? `${r.psnr.toFixed(1)} dB` : '∞ (identical)';
    const text = `${r.differ.toLocaleString('en-US')} pixels differ (${pct(r.differ)}), ` +
      `${r.visible.toLocaleString('en-US')} by more than ${r.threshold}/255 (${pct(r.visible)}); ` +
      `mean ${r.mean.toFixed(2)}, max ${r.max}; PSNR ${psnr}.`;
    $('diff-caption').textContent = `Difference: ${text}`;
    $('diff-result').textContent = text;
    $('view-diff').dataset.differ = String(r.differ);
  } catch (e) {
    $('diff-result').textContent = `No difference computed: ${e.message}`;
  }
}

// --- picking --------------------------------------------------------------------------

// Pixel (centres at integers) under a point of the displayed image.
function pixelAt(img, clientX, clientY) {
  const r = img.getBoundingClientRect();
  const px = ((clientX - r.left) / r.width) * img.naturalWidth - 0.5;
  const py = ((clientY - r.top) / r.height) * img.naturalHeight - 0.5;
  return [clamp(px, -0.5, img.naturalWidth - 0.5), clamp(py, -0.5, img.naturalHeight - 0.5)];
}

async function pickAt(which, px, py) {
  const view = state.shown && state.shown[which];
  if (!view) return;
  const out = $('pick-result');
  out.textContent = 'Picking…';
  try {
    const p = await api.pick(api.pickScene(view.scene, px, py));
    if (!p || !p.hit) {
      out.textContent = `No terrain under pixel (${Math.round(px)}, ${Math.round(py)}): that is sky.`;
      return;
    }
    let text = `${fmtM(p.x)} E, ${fmtM(p.y)} N, height ${p.z.toFixed(1)} m`;
    if (p.lon != null && p.lat != null) text += ` (${p.lon.toFixed(5)}°, ${p.lat.toFixed(5)}°)`;
    if (p.distance != null) text += `, ${fmtM(p.distance)} from the camera`;
    if (view.scene.dataset !== state.ds.id) return;
    const icon = L.divIcon({ className: '', html: '<div class="pick-icon"></div>', iconSize: [14, 14], iconAnchor: [7, 7] });
    const m = L.marker(LL(p.x, p.y), { icon, keyboard: true, title: text, alt: `Picked point: ${text}` });
    m.bindTooltip(text, { direction: 'top', offset: [0, -8] });
    m.options.terrad = p;
    state.layers.picks.clearLayers();
    // The line of sight from where the view was taken to the point.
    const cp = view.scene.camera.position;
    L.polyline([LL(cp.x, cp.y), LL(p.x, p.y)], { color: '#1c7c54', weight: 1.5, dashArray: '2 4', interactive: false })
      .addTo(state.layers.picks);
    m.addTo(state.layers.picks);
    m.getElement().classList.add('pick-marker');
    m.getElement().dataset.x = String(p.x);
    m.getElement().dataset.y = String(p.y);
    m.getElement().dataset.z = String(p.z);
    m.openTooltip();
    state.picks++;
    document.body.dataset.picks = String(state.picks);
    out.textContent = `Picked: ${text}.`;
  } catch (e) {
    out.textContent = `Pick failed: ${e.message}`;
  }
}

function wirePicking() {
  for (const [id, which] of [['view-img', 'a'], ['view-img-b', 'b']]) {
    const img = $(id);
    img.addEventListener('click', (e) => {
      const [px, py] = pixelAt(img, e.clientX, e.clientY);
      pickAt(which, px, py);
    });
    img.addEventListener('keydown', (e) => {
      if (e.key === 'Enter' || e.key === ' ') {
        e.preventDefault();
        pickAt(which, (img.naturalWidth - 1) / 2, (img.naturalHeight - 1) / 2);
      }
    });
  }
}

// --- admin ----------------------------------------------------------------------------

function visibleBox() {
  const b = state.map.getBounds(), ds = state.ds;
  return [
    Math.max(ds.xmin, b.getWest()), Math.max(ds.ymin, b.getSouth()),
    Math.min(ds.xmax, b.getEast()), Math.min(ds.ymax, b.getNorth()),
  ];
}

function wireAdmin() {
  $('admin-form').addEventListener('submit', async (e) => {
    e.preventDefault();
    const token = $('admin-token').value.trim();
    const label = $('admin-progress-label'), bar = $('admin-progress');
    if (!token) {
      label.textContent = 'Enter the admin token first.';
      $('admin-token').focus();
      return;
    }
    const build = [];
    if ($('admin-maxmip').checked) build.push('maxmip');
    if ($('admin-planes').checked) build.push('planes');
    if (!build.length) {
      label.textContent = 'Choose at least one structure to build.';
      return;
    }
    const box = visibleBox();
    if (!(box[2] > box[0] && box[3] > box[1])) {
      label.textContent = 'The visible map area does not meet the dataset.';
      return;
    }
    const dsId = state.ds.id;
    $('admin-preload').disabled = true;
    bar.value = 0;
    try {
      let j = await api.preload(token, { dataset: dsId, bbox: box.map((v) => +v.toFixed(2)), build, pin: $('admin-pin').checked });
      state.adminJob = j;
      label.textContent = `Job ${j.id} ${j.state}: ${j.tiles ? j.tiles.requested : '?'} tiles of ${dsId}.`;
      while (j.state === 'queued' || j.state === 'running') {
        await new Promise((r) => setTimeout(r, 250));
        j = await api.job(token, j.id);
        state.adminJob = j;
        bar.value = api.jobProgress(j);
        const t = j.tiles || {};
        const eta = j.estimate_s != null ? `, about ${j.estimate_s.toFixed(1)} s left` : '';
        label.textContent = `Job ${j.id} ${j.state}, ${j.phase}: ${t.done ?? 0} of ${t.total ?? '?'} tiles, ${(j.elapsed_s || 0).toFixed(1)} s${eta}.`;
      }
      bar.value = api.jobProgress(j);
      if (j.state === 'done') {
        label.textContent = `Job ${j.id} done: ${j.tiles.built} tiles built in ${(j.elapsed_s || 0).toFixed(1)} s.`;
      } else {
        label.textContent = `Job ${j.id} failed: ${j.error ? j.error.message : 'no reason given'}.`;
      }
      await refreshDatasetInfo();
    } catch (err) {
      label.textContent = `Preload refused: ${err.message}`;
    } finally {
      $('admin-preload').disabled = false;
    }
  });
}

// The terrain control: read the disc's region, add the bump, write it back; then the
// new version, the map's tiles and the view show the change.
async function editTerrainAt(x, y) {
  const out = $('edit-result'), token = $('admin-token').value.trim(), ds = state.ds;
  const r = Number($('edit-radius').value), delta = Number($('edit-delta').value);
  if (!token) {
    out.textContent = 'Enter the admin token first.';
    $('admin-token').focus();
    return;
  }
  const reg = discRegion(ds, x, y, r);
  if (!reg || !Number.isFinite(delta)) {
    out.textContent = 'The disc does not meet the grid (or the change is not a number).';
    return;
  }
  try {
    out.textContent = `Editing ${reg.w} × ${reg.h} samples at ${fmtM(x)} E, ${fmtM(y)} N…`;
    const cur = await api.heights(token, ds.id, reg);
    const z = raiseDisc(decodeHeights(cur.buf), reg, ds, x, y, r, delta);
    const a = await api.putHeights(token, ds.id, reg, encodeHeights(z));
    out.textContent = `${delta >= 0 ? 'Raised' : 'Lowered'} a disc of ${fmtM(r)} by ${Math.abs(delta)} m at ` +
      `${fmtM(x)} E, ${fmtM(y)} N: heights version ${a.version}` +
      (a.job ? ` (acceleration of ${a.rebuild} tiles rebuilding, job ${a.job}).` : '.');
    document.body.dataset.edits = String(Number(document.body.dataset.edits || 0) + 1);
    await refreshDatasetInfo();
    scheduleRender({ now: true });
  } catch (err) {
    out.textContent = `Edit refused: ${err.message}`;
  }
}

// --- viewshed -------------------------------------------------------------------------

// The control itself is viewshed.js; here its fields, and one click mode at a time.
function wireViewshed() {
  const num = (id) => ($(id).value.trim() === '' ? null : Number($(id).value));
  state.viewshed = new ViewshedControl(api, {
    result: $('vs-result'),
    onError: (text) => setStatus(text, true),
    readOptions: () => ({ height: num('vs-height'), maxDistance: num('vs-max'), surface: $('q-surface').value }),
  });
  $('vs-on').addEventListener('change', () => { if ($('vs-on').checked) $('edit-mode').checked = false; });
  $('edit-mode').addEventListener('change', () => { if ($('edit-mode').checked) $('vs-on').checked = false; });
  $('vs-clear').addEventListener('click', () => state.viewshed.clear());
}

// --- summits and panoramas (peaks.js) ---------------------------------------------------

function wirePeaks() {
  state.peaks = new PeaksControl(api, {
    result: $('peaks-result'),
    onError: (text) => setStatus(text, true),
    readOptions: () => ({ on: $('peaks-on').checked, minProminence: Number($('peaks-prominence').value) || 0 }),
  });
  for (const id of ['peaks-on', 'peaks-prominence', 'pano-on'])
    $(id).addEventListener('change', () => scheduleRender({ now: true }));
}

// --- start ----------------------------------------------------------------------------

async function main() {
  if (typeof L === 'undefined') {
    setStatus('Leaflet did not load (/vendor/leaflet/leaflet.js): run scripts/install-deps.', true);
    return;
  }
  wireCameraFields();
  wireSettings();
  wirePicking();
  wireAdmin();
  wireViewshed();
  wirePeaks();
  try {
    await loadDatasets();
  } catch (e) {
    setStatus(`Cannot list datasets: ${e.message}`, true);
    return;
  }
  const fromHash = readHash();
  const preferred = state.datasets.find((d) => d.id === 'trinidad') ? 'trinidad' : state.datasets[0].id;
  if (fromHash && state.datasets.some((d) => d.id === fromHash.id)) selectDataset(fromHash.id, fromHash.cam);
  else selectDataset(preferred);
}

main();
