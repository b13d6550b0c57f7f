// frame.js: the dataset frame on the map, and the camera's geometry. Pure functions
// (no DOM, no Leaflet) so node's test runner checks them too (test/unit.test.mjs).
//
// The dataset frame (DESIGN.md): x east, y north, metres, the south-west sample at the
// origin; the grid spans [0, X] x [0, Y] with X = (W-1)*sx, Y = (H-1)*sy. The map uses
// Leaflet's CRS.Simple with a transformation chosen so that a LatLng *is* a frame point
// (lat = y, lng = x): markers, the wedge and picked points need no conversion, and the
// scale bar reads metres. Tile pyramid (server/routes_render.inc): zoom 0 is one 256 px
// tile holding the whole grid, its north-west corner at the tile's top-left, the longer
// side filling the tile; every zoom halves the metres per pixel.

export const TILE = 256;

// Normalises one entry of GET /v1/datasets.
export function normaliseDataset(d) {
  const size = d.size || {};
  const w = size.width, h = size.height;
  const sp = Array.isArray(d.spacing) ? d.spacing : [1, 1];
  const ext = d.extent || {};
  const xr = ext.x || [0, (w - 1) * sp[0]];
  const yr = ext.y || [0, (h - 1) * sp[1]];
  const zr = ext.z || [0, 0];
  return {
    id: d.id,
    file: d.file || '',
    width: w, height: h,
    sx: sp[0], sy: sp[1],
    xmin: xr[0], xmax: xr[1], ymin: yr[0], ymax: yr[1],
    zmin: zr[0], zmax: zr[1],
    geo: d.georeference || null,
    tiles: d.tiles || null,
    residency: d.residency || null,
    version: Number.isInteger(d.version) ? d.version : 1, // of the heights: +1 an edit
  };
}

// Metres covered by the zoom-0 tile's side.
export function zoom0Side(ds) {
  return Math.max(ds.xmax - ds.xmin, ds.ymax - ds.ymin, 1e-9);
}

// Deepest zoom the server renders natively: the one where a map pixel is about a cell.
export function maxNativeZoom(ds) {
  const cells = Math.max(ds.width - 1, ds.height - 1, 1);
  return Math.max(0, Math.ceil(Math.log2(cells / TILE)));
}

// The affine map frame -> zoom-0 pixel: px = a*x + b, py = c*y + d (Leaflet's
// L.Transformation(a, b, c, d) with lng = x, lat = y).
export function transformation(ds) {
  const k = TILE / zoom0Side(ds);
  return { a: k, b: -k * ds.xmin, c: -k, d: k * ds.ymax };
}

// Frame point -> lon/lat (or projected easting/northing) with the server's formula
// (the pick response carries the same); null when the dataset has no georeference.
export function frameToGeo(ds, x, y) {
  const g = ds.geo;
  if (!g || !Array.isArray(g.origin) || !Array.isArray(g.step)) return null;
  return {
    kind: g.kind,
    x: g.origin[0] + (x / ds.sx) * g.step[0],
    y: g.origin[1] + (y / ds.sy) * g.step[1],
  };
}

export function clamp(v, lo, hi) {
  return Math.min(hi, Math.max(lo, v));
}

// Heading in [0, 360).
export function normHeading(h) {
  const r = h % 360;
  return r < 0 ? r + 360 : r;
}

// Heading (degrees clockwise from north) of the direction from a to b.
export function headingTo(ax, ay, bx, by) {
  return normHeading((Math.atan2(bx - ax, by - ay) * 180) / Math.PI);
}

// The point at distance `dist` from (x, y) along heading h.
export function along(x, y, h, dist) {
  const r = (h * Math.PI) / 180;
  return [x + dist * Math.sin(r), y + dist * Math.cos(r)];
}

// Wedge of the view on the map: the camera, then an arc from heading - fov/2 to
// heading + fov/2 at distance `dist`, as [x, y] points (a closed polygon's ring).
export function wedge(cam, dist, arcSteps = 12) {
  const pts = [[cam.x, cam.y]];
  const half = Math.min(cam.fov, 179) / 2;
  for (let i = 0; i <= arcSteps; i++) {
    const h = cam.heading - half + (2 * half * i) / arcSteps;
    pts.push(along(cam.x, cam.y, h, dist));
  }
  return pts;
}

// A default camera for a dataset: in the south-west, looking across the centre, a little
// above the ground, pitched slightly down.
export function defaultCamera(ds) {
  const X = ds.xmax - ds.xmin, Y = ds.ymax - ds.ymin;
  const x = ds.xmin + 0.2 * X, y = ds.ymin + 0.15 * Y;
  const relief = Math.max(ds.zmax - ds.zmin, 1);
  return {
    x, y,
    heading: headingTo(x, y, ds.xmin + 0.55 * X, ds.ymin + 0.6 * Y),
    agl: roundNice(clamp(relief * 0.25, 10, 2000)),
    pitch: -8,
    fov: 60,
  };
}

// 1, 2 or 5 times a power of ten, the nearest below v.
export function roundNice(v) {
  const p = Math.pow(10, Math.floor(Math.log10(v)));
  const m = v / p;
  return (m >= 5 ? 5 : m >= 2 ? 2 : 1) * p;
}

// Keeps a camera inside the grid.
export function clampToDataset(ds, x, y) {
  return [clamp(x, ds.xmin, ds.xmax), clamp(y, ds.ymin, ds.ymax)];
}

// Moves the camera by a keyboard step: forward/back along the heading, or turns it.
export function keyMove(cam, key, ds, big) {
  const step = (big ? 0.05 : 0.01) * Math.max(ds.xmax - ds.xmin, ds.ymax - ds.ymin);
  const turn = big ? 15 : 5;
  const c = { ...cam };
  if (key === 'ArrowUp' || key === 'ArrowDown') {
    const [nx, ny] = along(c.x, c.y, c.heading, key === 'ArrowUp' ? step : -step);
    [c.x, c.y] = clampToDataset(ds, nx, ny);
  } else if (key === 'ArrowLeft' || key === 'ArrowRight') {
    c.heading = normHeading(c.heading + (key === 'ArrowRight' ? turn : -turn));
  } else {
    return null;
  }
  return c;
}

// The camera in a URL fragment, shared by the page and the web map:
// #dataset/x/y/agl/heading/pitch/fov (frame metres and degrees, 2 decimals).
export function cameraHash(id, c) {
  return `#${encodeURIComponent(id)}/${[c.x, c.y, c.agl, c.heading, c.pitch, c.fov].map((v) => +v.toFixed(2)).join('/')}`;
}

// The dataset id and camera of such a fragment, or null.
export function parseCameraHash(hash) {
  const parts = hash.replace(/^#/, '').split('/');
  if (parts.length !== 7) return null;
  const v = parts.slice(1).map(Number);
  if (!v.every(Number.isFinite)) return null;
  return { id: decodeURIComponent(parts[0]), cam: { x: v[0], y: v[1], agl: v[2], heading: v[3], pitch: v[4], fov: v[5] } };
}
