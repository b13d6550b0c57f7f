// viewshed.js: the map's viewshed control. With it on, a click on the map places an
// observer there (app.js converts the click to the dataset frame as for every other
// click and calls placeAt), the page asks POST /v1/viewshed for the PNG (8-bit gray in
// the dataset's grid, one pixel a sample, row 0 north: 255 seen, 0 not, 128 outside
// max_distance or void), recolours it on a canvas (seen: translucent green, hidden:
// translucent dark, outside: transparent) and lays it over the map with L.imageOverlay,
// each pixel centred on its sample.
//
// The pure parts (the request body, the overlay's bounds, the recolouring) take no DOM
// and no Leaflet, so node's test runner checks them (test/unit.test.mjs).
//
// State the browser test reads: body[data-viewsheds] counts overlays shown; the overlay
// is img.viewshed-overlay, the observer .viewshed-marker.

// RGBA of each class of sample in the overlay.
export const VISIBLE_RGBA = [46, 204, 64, 150];
export const HIDDEN_RGBA = [20, 24, 40, 110];
export const OUTSIDE_RGBA = [0, 0, 0, 0];

// The body of POST /v1/viewshed for an observer at frame point (x, y). opts: height (eye
// above the ground, m), maxDistance (m; null/NaN for none), surface. Values go as the
// user typed them: terrad judges them and names the field it refuses.
export function viewshedBody(dsId, x, y, opts = {}) {
  const body = {
    dataset: dsId,
    observer: { x: round3(x), y: round3(y) },
    height: Number.isFinite(opts.height) ? opts.height : 2,
    format: 'png',
  };
  if (opts.maxDistance != null && !Number.isNaN(opts.maxDistance)) body.max_distance = opts.maxDistance;
  if (opts.surface) body.surface = opts.surface;
  return body;
}

function round3(v) {
  return Math.round(v * 1000) / 1000;
}

// The overlay's corners in the frame, [[south, west], [north, east]] (Leaflet's LatLng
// order: lat = y, lng = x). Sample (i, j) sits at (i*sx, j*sy) and its pixel covers half a
// sample spacing around it, so the image reaches half a spacing beyond the grid's
// extent of (w-1)*sx by (h-1)*sy metres on every side.
export function overlayBounds(ds) {
  const hx = ds.sx / 2, hy = ds.sy / 2;
  return [[ds.ymin - hy, ds.xmin - hx], [ds.ymax + hy, ds.xmax + hx]];
}

// The pixel (column, row; row 0 north) of the sample nearest to frame point (x, y).
export function sampleAt(ds, x, y) {
  const i = Math.min(ds.width - 1, Math.max(0, Math.round((x - ds.xmin) / ds.sx)));
  const j = Math.min(ds.height - 1, Math.max(0, Math.round((y - ds.ymin) / ds.sy)));
  return [i, ds.height - 1 - j];
}

// The server's gray picture (RGBA, as a canvas reads it back: gray in R, G and B) ->
// the overlay's RGBA, into `out` (a new array when absent). 255 seen, 0 hidden, anything
// else (128: outside or void) transparent. Returns out and the counts.
export function recolourViewshed(rgba, out = new Uint8ClampedArray(rgba.length)) {
  let visible = 0, hidden = 0, outside = 0;
  for (let k = 0; k < rgba.length; k += 4) {
    const v = rgba[k];
    const c = v === 255 ? VISIBLE_RGBA : v === 0 ? HIDDEN_RGBA : OUTSIDE_RGBA;
    if (v === 255) visible++; else if (v === 0) hidden++; else outside++;
    out[k] = c[0]; out[k + 1] = c[1]; out[k + 2] = c[2]; out[k + 3] = c[3];
  }
  return { out, visible, hidden, outside };
}

// --- the control (browser only: uses the DOM and Leaflet's global L) -------------------

// api: {viewshed(body, signal)}; ui: {onError(text), result (element), readOptions()}.
export class ViewshedControl {
  constructor(api, ui) {
    this.api = api;
    this.ui = ui;
    this.map = null;
    this.ds = null;
    this.layer = null;      // L.layerGroup: the marker and the overlay
    this.controller = null;
    this.url = null;        // the overlay's object URL
    this.shown = 0;
    this.last = null;       // {body, counts, visibleArea}
  }

  // A new map (or dataset): what was drawn on the old one went with it.
  attach(map, ds) {
    this.cancel();
    this.map = map;
    this.ds = ds;
    this.layer = L.layerGroup().addTo(map);
    this.last = null;
    this.revoke();
    this.ui.result.textContent = '';
  }

  cancel() {
    if (this.controller) this.controller.abort();
    this.controller = null;
  }

  revoke() {
    if (this.url) URL.revokeObjectURL(this.url);
    this.url = null;
  }

  clear() {
    this.cancel();
    if (this.layer) this.layer.clearLayers();
    this.revoke();
    this.last = null;
    this.ui.result.textContent = '';
  }

  // An observer at frame point (x, y): its marker at once, the overlay when it arrives.
  async placeAt(x, y) {
    const ds = this.ds, map = this.map, out = this.ui.result;
    this.cancel();
    const controller = new AbortController();
    this.controller = controller;
    const body = viewshedBody(ds.id, x, y, this.ui.readOptions());
    this.layer.clearLayers();
    const icon = L.divIcon({ className: '', html: '<div class="viewshed-icon"></div>', iconSize: [16, 16], iconAnchor: [8, 8] });
    const m = (v) => `${Math.round(v).toLocaleString('en-US')} m`;
    const where = `${m(x)} E, ${m(y)} N`;
    const marker = L.marker(L.latLng(y, x), { icon, keyboard: false, interactive: false, alt: `Viewshed observer at ${where}` })
      .addTo(this.layer);
    marker.getElement().classList.add('viewshed-marker');
    out.textContent = `Viewshed from ${where}, eye ${body.height} m up…`;
    try {
      const r = await this.api.viewshed(body, controller.signal);
      const bitmap = await createImageBitmap(r.blob);
      if (controller.signal.aborted) return;
      const canvas = document.createElement('canvas');
      canvas.width = bitmap.width;
      canvas.height = bitmap.height;
      const ctx = canvas.getContext('2d');
      ctx.drawImage(bitmap, 0, 0);
      const img = ctx.getImageData(0, 0, canvas.width, canvas.height);
      const counts = recolourViewshed(img.data, img.data);
      ctx.putImageData(img, 0, 0);
      const blob = await new Promise((ok) => canvas.toBlob(ok, 'image/png'));
      if (controller.signal.aborted || this.map !== map) return;
      this.revoke();
      this.url = URL.createObjectURL(blob);
      const overlay = L.imageOverlay(this.url, overlayBounds(ds), {
        interactive: false, className: 'viewshed-overlay', alt: `Viewshed from ${where}`,
      });
      overlay.once('load', () => {
        this.shown++;
        document.body.dataset.viewsheds = String(this.shown);
      });
      overlay.addTo(this.layer);
      this.last = { body, counts, visibleArea: r.visibleArea };
      const inside = counts.visible + counts.hidden;
      const pct = inside ? ` (${((100 * counts.visible) / inside).toFixed(1)}% of the samples in range)` : '';
      const area = r.visibleArea != null ? `${(r.visibleArea / 1e6).toFixed(2)} km²` : `${counts.visible} samples`;
      out.textContent = `Viewshed from ${where}, eye ${body.height} m up` +
        (body.max_distance != null ? `, within ${m(body.max_distance)}` : '') +
        `: ${area} seen${pct}; ${Math.round(r.ms)} ms.`;
    } catch (e) {
      if (e.name === 'AbortError') return;
      this.layer.clearLayers();
      out.textContent = `Viewshed refused: ${e.message}`;
      this.ui.onError(`Viewshed failed: ${e.message}`);
    } finally {
      if (this.controller === controller) this.controller = null;
    }
  }
}
