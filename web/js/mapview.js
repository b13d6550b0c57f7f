// mapview.js: the web map page (map.html): a dataset in Web Mercator with MapLibre GL JS.
//
// Sources come from terrad's TileJSON (GET /v1/maps/{dataset}/{style}.json): `shaded`
// (ray-traced, cast shadows, the sun of ?time=) as a raster layer and `terrain-rgb` as a
// raster-dem source for 3D terrain. The time-of-day slider asks for the shaded TileJSON of
// the new instant (which names the sun terrad computed) and swaps the layer's tiles: the
// shadows move. The camera is the main page's (#dataset/x/y/agl/heading/pitch/fov in the
// dataset frame); its wedge is drawn by frame.js's geometry, turned into lon/lat by the
// dataset's georeference (lon/lat datasets: a projected one shows no wedge), and the
// marker is the terrain point at the centre of its view (POST /v1/pick).
// window.terradMap exposes the map and its state to the browser test.
import { normaliseDataset, frameToGeo, wedge, defaultCamera, cameraHash, parseCameraHash } from './frame.js';

const $ = (id) => document.getElementById(id);
const state = { ds: null, cam: null, map: null, sun: null, picked: null, marker: null, seq: 0, errors: [] };
window.terradMap = state;

function status(msg) { $('wm-status').textContent = msg; }

// The instant of the date and time inputs, ISO 8601 UTC ("2026-06-21T18:00Z").
export function timeIso() {
  const d = $('wm-date').value || '2026-06-21';
  const h = Math.min(23.99, Math.max(0, Number($('wm-time').value) || 0));
  const hh = Math.floor(h), mm = Math.round((h - hh) * 60);
  return `${d}T${String(hh).padStart(2, '0')}:${String(mm).padStart(2, '0')}Z`;
}

function shadedQuery() {
  return `time=${encodeURIComponent(timeIso())}&shadows=${$('wm-shadows').checked}`;
}

async function tileJson(style, query) {
  const url = `/v1/maps/${encodeURIComponent(state.ds.id)}/${style}.json${query ? `?${query}` : ''}`;
  const r = await fetch(url);
  const j = await r.json();
  if (!r.ok) throw new Error(j.error ? j.error.message : `HTTP ${r.status}`);
  return j;
}

function saveHash() {
  const h = cameraHash(state.ds.id, state.cam);
  history.replaceState(null, '', h);
  $('wm-back').href = `index.html${h}`;
}

// Frame point -> [lon, lat], or null (no lon/lat georeference).
function lonLat(x, y) {
  const g = frameToGeo(state.ds, x, y);
  return g && g.kind === 'lonlat' ? [g.x, g.y] : null;
}

function cameraGeoJson() {
  const c = state.cam, ds = state.ds;
  const ring = wedge(c, 0.25 * Math.max(ds.xmax - ds.xmin, ds.ymax - ds.ymin)).map(([x, y]) => lonLat(x, y));
  const at = lonLat(c.x, c.y);
  if (!at || ring.some((p) => !p)) return { type: 'FeatureCollection', features: [] };
  ring.push(ring[0]);
  return {
    type: 'FeatureCollection',
    features: [
      { type: 'Feature', properties: { kind: 'wedge' }, geometry: { type: 'Polygon', coordinates: [ring] } },
      { type: 'Feature', properties: { kind: 'camera' }, geometry: { type: 'Point', coordinates: at } },
    ],
  };
}

// The terrain point at the centre of the camera's view, as a marker.
async function pickCentre() {
  const c = state.cam, seq = ++state.seq;
  const body = {
    dataset: state.ds.id,
    camera: { position: { x: c.x, y: c.y, agl: c.agl }, heading: c.heading, pitch: c.pitch, fov: c.fov },
    image: { width: 64, height: 48 },
    pick: [[32, 24]],
  };
  const r = await fetch('/v1/pick', { method: 'POST', headers: { 'Content-Type': 'application/json' }, body: JSON.stringify(body) });
  const j = await r.json();
  if (seq !== state.seq) return;
  const p = r.ok && j.picks && j.picks[0];
  if (state.marker) state.marker.remove();
  state.marker = null;
  state.picked = p && p.hit && p.lonlat ? p : null;
  if (!state.picked) {
    status(r.ok ? 'The centre of the view meets no terrain.' : `Pick refused: ${j.error ? j.error.message : r.status}`);
    return;
  }
  const text = `${p.point.z.toFixed(1)} m at ${p.lonlat[1].toFixed(5)}, ${p.lonlat[0].toFixed(5)}; ${(p.distance / 1000).toFixed(2)} km from the camera`;
  state.marker = new maplibregl.Marker({ color: '#c0392b' })
    .setLngLat(p.lonlat)
    .setPopup(new maplibregl.Popup({ offset: 24 }).setText(text))
    .addTo(state.map);
  status(`Centre of the view: ${text}`);
}

function drawCamera() {
  const src = state.map && state.map.getSource('camera');
  if (src) src.setData(cameraGeoJson());
}

// The shaded layer for the slider's instant: a new TileJSON (terrad's sun), new tiles.
async function updateTime() {
  // the local mean solar time at the dataset's centre too: UTC + longitude / 15 hours
  const lon = state.ds.geo && state.ds.geo.kind === 'lonlat' ? lonLat(0.5 * state.ds.xmax, 0.5 * state.ds.ymax)[0] : null;
  const solar = lon === null ? '' : (() => {
    const h = (((Number($('wm-time').value) + lon / 15) % 24) + 24) % 24;
    return ` (about ${String(Math.floor(h)).padStart(2, '0')}:${String(Math.floor((h % 1) * 60)).padStart(2, '0')} local solar time)`;
  })();
  $('wm-time-out').textContent = timeIso().slice(11) + solar;
  const tj = await tileJson('shaded', shadedQuery());
  state.sun = tj.sun;
  $('wm-sun').textContent = `sun: azimuth ${tj.sun.azimuth.toFixed(1)}°, elevation ${tj.sun.elevation.toFixed(1)}°` +
    (tj.sun.elevation <= 0 ? ' (below the horizon)' : '');
  const src = state.map && state.map.getSource('shaded');
  if (src) src.setTiles(tj.tiles);
  return tj;
}

function style(shaded, dem) {
  return {
    version: 8,
    sources: {
      shaded: { type: 'raster', tiles: shaded.tiles, tileSize: 256, bounds: shaded.bounds,
        maxzoom: Math.min(shaded.maxzoom + 2, 18), attribution: shaded.attribution },
      dem: { type: 'raster-dem', tiles: dem.tiles, tileSize: 256, bounds: dem.bounds, maxzoom: dem.maxzoom,
        encoding: dem.encoding },
      camera: { type: 'geojson', data: { type: 'FeatureCollection', features: [] } },
    },
    layers: [
      { id: 'background', type: 'background', paint: { 'background-color': '#dde3e8' } },
      { id: 'shaded', type: 'raster', source: 'shaded', paint: { 'raster-fade-duration': 0 } },
      { id: 'wedge', type: 'fill', source: 'camera', filter: ['==', ['get', 'kind'], 'wedge'],
        paint: { 'fill-color': '#2980b9', 'fill-opacity': 0.25 } },
      { id: 'wedge-line', type: 'line', source: 'camera', filter: ['==', ['get', 'kind'], 'wedge'],
        paint: { 'line-color': '#1f5f8b', 'line-width': 2 } },
      { id: 'camera', type: 'circle', source: 'camera', filter: ['==', ['get', 'kind'], 'camera'],
        paint: { 'circle-radius': 6, 'circle-color': '#1f5f8b', 'circle-stroke-color': '#fff', 'circle-stroke-width': 2 } },
    ],
  };
}

async function showDataset(ds, cam) {
  state.ds = ds;
  state.cam = cam || defaultCamera(ds);
  saveHash();
  if (state.map) { state.map.remove(); state.map = null; }
  status(`Loading ${ds.id}…`);
  const [shaded, dem] = await Promise.all([tileJson('shaded', shadedQuery()), tileJson('terrain-rgb')]);
  state.sun = shaded.sun;
  const map = new maplibregl.Map({
    container: 'wm-map',
    style: style(shaded, dem),
    bounds: shaded.bounds,
    fitBoundsOptions: { padding: 20 },
    maxPitch: 75,
    canvasContextAttributes: { preserveDrawingBuffer: true }, // screenshots of the canvas
  });
  state.map = map;
  map.addControl(new maplibregl.NavigationControl({ visualizePitch: true }));
  map.on('error', (e) => { state.errors.push(String(e.error && e.error.message || e)); });
  map.on('click', (e) => {
    const g = state.ds.geo;
    if (!g || g.kind !== 'lonlat') return;
    state.cam = { ...state.cam,
      x: ((e.lngLat.lng - g.origin[0]) / g.step[0]) * state.ds.sx,
      y: ((e.lngLat.lat - g.origin[1]) / g.step[1]) * state.ds.sy };
    saveHash();
    drawCamera();
    pickCentre();
  });
  await new Promise((resolve) => map.once('load', resolve));
  if ($('wm-3d').checked) {
    map.setTerrain({ source: 'dem', exaggeration: 1.5 });
    map.easeTo({ pitch: 55, duration: 0 });
  }
  drawCamera();
  await updateTime();
  await pickCentre();
}

async function main() {
  const r = await fetch('/v1/datasets');
  const all = (await r.json()).map(normaliseDataset).filter((d) => d.geo);
  if (!all.length) { status('No dataset has a georeference: nothing to map.'); return; }
  const sel = $('wm-dataset');
  for (const d of all) sel.add(new Option(d.id, d.id));
  const h = parseCameraHash(location.hash);
  const first = (h && all.find((d) => d.id === h.id)) || all.find((d) => d.id === 'trinidad') || all[0];
  sel.value = first.id;
  sel.addEventListener('change', () => showDataset(all.find((d) => d.id === sel.value)));
  let timer = 0;
  const later = () => { clearTimeout(timer); timer = setTimeout(() => updateTime().catch((e) => status(e.message)), 150); };
  $('wm-time').addEventListener('input', later);
  $('wm-date').addEventListener('change', later);
  $('wm-shadows').addEventListener('change', later);
  $('wm-3d').addEventListener('change', () => {
    state.map.setTerrain($('wm-3d').checked ? { source: 'dem', exaggeration: 1.5 } : null);
  });
  state.ready = showDataset(first, h && h.id === first.id ? h.cam : null);
  await state.ready;
  status(`${first.id}: Web Mercator tiles from terrad`);
}

main().catch((e) => { state.errors.push(e.message); status(e.message); });
