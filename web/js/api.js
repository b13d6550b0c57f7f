// api.js: terrad's HTTP API as the page uses it: the scene JSON built from the page's
// state, Server-Timing parsed into stages, JSON errors turned into readable messages,
// and the render/pick calls. Pure apart from `fetch` (node's test runner checks the
// pure parts: test/unit.test.mjs).

// Server-Timing: `name;dur=1.2;desc="..."` entries separated by commas (commas inside
// quoted descriptions do not split). Returns [{name, dur, desc}] in header order.
export function parseServerTiming(header) {
  const out = [];
  if (!header) return out;
  const parts = [];
  let cur = '', quoted = false;
  for (const ch of header) {
    if (ch === '"') quoted = !quoted;
    if (ch === ',' && !quoted) { parts.push(cur); cur = ''; } else cur += ch;
  }
  parts.push(cur);
  for (const p of parts) {
    const fields = [];
    let f = '', q = false;
    for (const ch of p) {
      if (ch === '"') q = !q;
      if (ch === ';' && !q) { fields.push(f); f = ''; } else f += ch;
    }
    fields.push(f);
    const name = fields[0].trim();
    if (!name) continue;
    const e = { name, dur: null, desc: '' };
    for (const kv of fields.slice(1)) {
      const i = kv.indexOf('=');
      if (i < 0) continue;
      const k = kv.slice(0, i).trim().toLowerCase();
      let v = kv.slice(i + 1).trim();
      if (v.startsWith('"') && v.endsWith('"') && v.length >= 2) v = v.slice(1, -1).replace(/\\(.)/g, '$1');
      if (k === 'dur') { const d = Number(v); e.dur = Number.isFinite(d) ? d : null; }
      else if (k === 'desc') e.desc = v;
    }
    out.push(e);
  }
  return out;
}

// The page's state -> scene JSON (DESIGN.md). `q` holds quality, `fx` the effects.
export function buildScene(dataset, cam, size, q, fx) {
  const scene = {
    dataset,
    camera: {
      position: { x: round(cam.x, 3), y: round(cam.y, 3), agl: round(Math.max(0, cam.agl), 3) },
      heading: round(cam.heading, 3),
      pitch: round(cam.pitch, 3),
      fov: round(cam.fov, 3),
    },
    image: { width: size.width, height: size.height, format: 'png' },
    quality: { method: q.method, surface: q.surface, samples: q.samples },
    effects: { sun: { azimuth: fx.sunAzimuth, elevation: fx.sunElevation } },
  };
  if (q.lod) scene.quality.lod = true;
  // An effect absent from the scene costs nothing on the server: send only those on.
  if (fx.shadows) scene.effects.shadows = true;
  if (fx.sky) scene.effects.sky = true;
  if (fx.haze) scene.effects.haze = { visibility_km: fx.hazeKm };
  if (fx.water) scene.effects.water = { level: fx.waterLevel };
  if (fx.ao) scene.effects.ambient_occlusion = fx.aoRays;
  if (fx.curvature) scene.effects.curvature = true;
  return scene;
}

// The same scene asking which terrain point is under pixel (px, py) (pixel centres are
// integers, as the server counts them).
export function pickScene(scene, px, py) {
  const s = JSON.parse(JSON.stringify(scene));
  s.image.format = 'pick';
  s.pick = [[round(px, 3), round(py, 3)]];
  return s;
}

function round(v, digits) {
  const k = Math.pow(10, digits);
  return Math.round(v * k) / k;
}

// A readable message from a failed response: the JSON error's field and message.
export async function errorMessage(resp) {
  let text = '';
  try { text = await resp.text(); } catch (e) { /* body gone */ }
  let msg = `HTTP ${resp.status}`;
  try {
    const j = JSON.parse(text);
    if (j && j.error) {
      msg += `: ${j.error.field ? j.error.field + ': ' : ''}${j.error.message || j.error.code}`;
      return msg;
    }
  } catch (e) { /* not JSON */ }
  if (text) msg += `: ${text.slice(0, 200)}`;
  return msg;
}

export class ApiError extends Error {
  constructor(message, status, retryAfter = null) {
    super(message);
    this.status = status;
    this.retryAfter = retryAfter;
  }
}

async function apiError(resp) {
  const ra = Number(resp.headers.get('Retry-After'));
  return new ApiError(await errorMessage(resp), resp.status, Number.isFinite(ra) && ra > 0 ? ra : null);
}

// X-Terrad-Height-Error: `mean=0.26; max=18.7; hits=41833`, metres between the camera hits
// and the exact (bilinear, full grid) surface: how far the picture is from the exact one.
export function parseHeightError(value) {
  const out = {};
  for (const part of (value || '').split(';')) {
    const [k, v] = part.split('=').map((s) => s.trim());
    if (['mean', 'max', 'hits'].includes(k) && v !== undefined && v !== '' && Number.isFinite(Number(v))) out[k] = Number(v);
  }
  return out.mean === undefined || out.max === undefined ? null : out;
}

// Reads the render's headers: Server-Timing stages and whatever terrad says about the
// method, surface, rays, steps and the shadow rays' sun bound (X-Terrad-*: `built` for this
// render, or `kept` by the dataset from an earlier one with the same sun).
export function renderInfo(headers) {
  const get = (n) => headers.get(n);
  const num = (n) => { const v = get(n); return v == null || v === '' ? null : Number(v); };
  const info = {
    timing: parseServerTiming(get('Server-Timing')),
    method: get('X-Terrad-Method'),
    surface: get('X-Terrad-Surface'),
    rays: num('X-Terrad-Rays'),
    steps: num('X-Terrad-Steps'),
    stepsPerRay: num('X-Terrad-Steps-Per-Ray'),
    heightError: parseHeightError(get('X-Terrad-Height-Error')),
    sunBound: get('X-Terrad-Sun-Bound'),
  };
  if (info.stepsPerRay == null && info.rays > 0 && info.steps != null) info.stepsPerRay = info.steps / info.rays;
  return info;
}

// The body's dataset also goes into the query: the key a proxy in front of several terrad
// replicas routes on (docker/nginx.conf), so each dataset stays on the replica that keeps it hot.
export function routedUrl(url, body) {
  const id = body && typeof body.dataset === 'string' ? body.dataset : null;
  return id ? `${url}${url.includes('?') ? '&' : '?'}dataset=${encodeURIComponent(id)}` : url;
}

async function postJson(url, body, signal, extraHeaders = {}) {
  return fetch(routedUrl(url, body), {
    method: 'POST',
    headers: { 'Content-Type': 'application/json', ...extraHeaders },
    body: JSON.stringify(body),
    signal,
  });
}

// POST /v1/render -> {blob, info, ms}; throws ApiError (or AbortError).
export async function render(scene, signal) {
  const t0 = performance.now();
  const resp = await postJson('/v1/render', scene, signal);
  if (!resp.ok) throw await apiError(resp);
  const blob = await resp.blob();
  return { blob, info: renderInfo(resp.headers), ms: performance.now() - t0 };
}

// POST /v1/viewshed (format png) -> {blob, visible, visibleArea, ms}; throws ApiError.
export async function viewshed(body, signal) {
  const t0 = performance.now();
  const resp = await postJson('/v1/viewshed', body, signal);
  if (!resp.ok) throw await apiError(resp);
  const blob = await resp.blob();
  const num = (n) => { const v = resp.headers.get(n); return v == null || v === '' ? null : Number(v); };
  return { blob, visible: num('X-Terrad-Visible'), visibleArea: num('X-Terrad-Visible-Area'), ms: performance.now() - t0 };
}

// POST /v1/peaks (the summits a scene sees, peaks.js) -> its JSON; throws ApiError.
export async function peaks(body, signal) {
  const resp = await postJson('/v1/peaks', body, signal);
  if (!resp.ok) throw await apiError(resp);
  return resp.json();
}

// POST /v1/pick -> the first picked pixel, normalised (see firstPick).
export async function pick(scene, signal) {
  const resp = await postJson('/v1/pick', scene, signal);
  if (!resp.ok) throw await apiError(resp);
  return firstPick(await resp.json());
}

// terrad answers {"dataset", "picks": [{"pixel": [px, py], "hit", "point": {x, y, z},
// "distance", "cell": [i, j], "lonlat" | "projected": [a, b]}]}; the first entry as
// {px, py, hit, x, y, z, distance, cell, lon, lat, east, north} (absent fields null).
export function firstPick(j) {
  const list = Array.isArray(j) ? j : (j && j.picks) || [];
  if (!list.length) return null;
  const e = list[0];
  const pt = e.point || e;
  const px = e.pixel || [e.px, e.py];
  const out = {
    px: px[0], py: px[1], hit: !!e.hit,
    x: pt.x ?? null, y: pt.y ?? null, z: pt.z ?? null,
    distance: e.distance ?? null, cell: e.cell || null,
    lon: null, lat: null, east: null, north: null,
  };
  if (Array.isArray(e.lonlat)) [out.lon, out.lat] = e.lonlat;
  else if (e.lon != null) [out.lon, out.lat] = [e.lon, e.lat];
  if (Array.isArray(e.projected)) [out.east, out.north] = e.projected;
  return out;
}

export async function datasets(signal) {
  const resp = await fetch('/v1/datasets', { signal });
  if (!resp.ok) throw await apiError(resp);
  const j = await resp.json();
  return Array.isArray(j) ? j : j.datasets || [];
}

export async function dataset(id, signal) {
  const resp = await fetch(`/v1/datasets/${encodeURIComponent(id)}`, { signal });
  if (!resp.ok) throw await apiError(resp);
  return resp.json();
}

// POST /v1/admin/preload -> the job (202).
export async function preload(token, body) {
  const resp = await postJson('/v1/admin/preload', body, undefined, { Authorization: `Bearer ${token}` });
  if (!resp.ok) throw await apiError(resp);
  return resp.json();
}

export async function job(token, id, signal) {
  const resp = await fetch(`/v1/admin/jobs/${encodeURIComponent(id)}`, {
    headers: { Authorization: `Bearer ${token}` },
    signal,
  });
  if (!resp.ok) throw await apiError(resp);
  return resp.json();
}

// GET /v1/admin/datasets/{id}/heights?x&y&w&h -> {buf (w*h float32 LE), version}.
export async function heights(token, id, reg) {
  const q = `x=${reg.x}&y=${reg.y}&w=${reg.w}&h=${reg.h}`;
  const resp = await fetch(`/v1/admin/datasets/${encodeURIComponent(id)}/heights?${q}`, {
    headers: { Authorization: `Bearer ${token}` }, cache: 'no-store',
  });
  if (!resp.ok) throw await apiError(resp);
  return { buf: await resp.arrayBuffer(), version: Number(resp.headers.get('X-Terrad-Version')) };
}

// PUT the same -> {dataset, version, region, tiles, rebuild, job}.
export async function putHeights(token, id, reg, buf) {
  const q = `x=${reg.x}&y=${reg.y}&w=${reg.w}&h=${reg.h}`;
  const resp = await fetch(`/v1/admin/datasets/${encodeURIComponent(id)}/heights?${q}`, {
    method: 'PUT',
    headers: { Authorization: `Bearer ${token}`, 'Content-Type': 'application/octet-stream' },
    body: buf,
  });
  if (!resp.ok) throw await apiError(resp);
  return resp.json();
}

// Overall progress of a preload job in [0, 1]. The builds (maxmip, then planes) each
// report tiles done of total and share the bar equally; checking counts as 0 and
// publishing as nearly done (both are short).
export function jobProgress(j) {
  if (!j) return 0;
  if (j.state === 'done') return 1;
  if (j.state === 'queued' || j.phase === 'checking') return 0;
  if (j.phase === 'publishing') return 0.99;
  const build = (Array.isArray(j.build) ? j.build : ['maxmip', 'planes'])
    .filter((b) => b === 'maxmip' || b === 'planes');
  const i = build.indexOf(j.phase);
  if (i < 0) return 0;
  const t = j.tiles || {};
  const frac = t.total > 0 ? Math.min(1, t.done / t.total) : 0;
  return (i + frac) / build.length;
}
