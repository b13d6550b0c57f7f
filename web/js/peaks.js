// peaks.js: summit labels (issue 19). After each view is shown, the page asks POST
// /v1/peaks with the view's own scene for the summits it sees (terrad checks each with a
// camera ray: a summit behind nearer terrain is not listed) and draws a label over the
// view at each summit's pixel, with a leader line, and a marker on the map. The
// panorama option turns the camera into a 360-degree cylindrical one (terrad's
// camera.projection "cylindrical", curvature and refraction on).
//
// The pure parts (the scenes, the body, where labels go) take no DOM and no Leaflet, so
// node's test runner checks them (test/unit.test.mjs).
//
// State the browser test reads: body[data-peaks] counts the labels drawn for the last
// view; labels are .peak-label (data-px, data-py: the summit's pixel in the image), map
// markers .peak-marker.

// A 360-degree panorama of the same camera: cylindrical, the image twice as wide as it is
// tall (a row of 3:1 shows too little sky and ground at the default pitch).
export function panoramaScene(scene) {
  const s = JSON.parse(JSON.stringify(scene));
  s.camera.projection = 'cylindrical';
  s.camera.fov = 360;
  s.image.height = Math.max(1, Math.round(s.image.width / 3));
  return s;
}

// The body of POST /v1/peaks for a rendered scene: the scene itself (a pick scene has
// no place here) with the prominence threshold.
export function peaksBody(scene, minProminence = 100, maxPeaks = 60) {
  const s = JSON.parse(JSON.stringify(scene));
  delete s.pick;
  if (s.image) s.image.format = 'png';
  s.min_prominence = minProminence;
  s.max_peaks = maxPeaks;
  return s;
}

// The text of a summit's label.
export function peakText(p) {
  const km = p.distance >= 10000 ? (p.distance / 1000).toFixed(0) : (p.distance / 1000).toFixed(1);
  return `${Math.round(p.z)} m · ${km} km`;
}

// Where the labels go, in displayed pixels: each at its summit's x, its text on a leader
// line going up from the summit, the line 14 + 15 * tier px long (style.css's
// .peak-label), the tier the lowest whose text box (14 px tall, about charWidth a
// character wide) meets no box already placed; most prominent first (terrad lists them
// so); a summit with no free tier up to maxTiers goes unlabelled. scale: displayed pixels
// per image pixel. Returns [{x, y, tier, text, peak}], (x, y) the summit, displayed.
export function placeLabels(peaks, scale, { charWidth = 6.5, pad = 6, maxTiers = 4 } = {}) {
  const boxes = [];
  const out = [];
  for (const p of peaks) {
    const text = peakText(p);
    const x = (p.px + 0.5) * scale, y = (p.py + 0.5) * scale;
    const w = text.length * charWidth + pad;
    let tier = 0;
    for (; tier < maxTiers; tier++) {
      const y1 = y - 14 - 15 * tier, y0 = y1 - 14;
      if (!boxes.some(([a, b, c, d]) => x < b && x + w > a && y0 < d && y1 > c)) {
        boxes.push([x, x + w, y0, y1]);
        break;
      }
    }
    if (tier < maxTiers) out.push({ x, y, tier, text, peak: p });
  }
  return out;
}

// --- the control (browser only: uses the DOM and Leaflet's global L) -------------------

// api: {peaks(body, signal)}; ui: {result (element), onError(text), readOptions() ->
// {on, minProminence}}.
export class PeaksControl {
  constructor(api, ui) {
    this.api = api;
    this.ui = ui;
    this.layer = null;
    this.controller = null;
    this.last = null;
  }

  attach(map) {
    this.cancel();
    this.layer = L.layerGroup().addTo(map);
  }

  cancel() {
    if (this.controller) this.controller.abort();
    this.controller = null;
  }

  clear(frame) {
    this.cancel();
    if (this.layer) this.layer.clearLayers();
    if (frame) frame.querySelectorAll('.peak-labels').forEach((e) => e.remove());
    document.body.dataset.peaks = '0';
    this.last = null;
  }

  // The summits of the scene just shown in img (inside frame).
  async show(scene, img, frame) {
    const opts = this.ui.readOptions();
    this.clear(frame);
    if (!opts.on) {
      this.ui.result.textContent = '';
      return;
    }
    const controller = new AbortController();
    this.controller = controller;
    try {
      const r = await this.api.peaks(peaksBody(scene, opts.minProminence), controller.signal);
      if (controller.signal.aborted) return;
      this.draw(r, scene, img, frame);
      this.ui.result.textContent = `${r.visible} of ${r.summits} summits of at least ` +
        `${r.min_prominence} m prominence in view and not hidden (${r.rays} rays` +
        `${r.cached ? '' : `; summits found in ${Math.round(r.summits_ms)} ms`}).`;
    } catch (e) {
      if (e.name === 'AbortError') return;
      this.ui.result.textContent = `Summits refused: ${e.message}`;
      this.ui.onError(`Summits failed: ${e.message}`);
    } finally {
      if (this.controller === controller) this.controller = null;
    }
  }

  draw(r, scene, img, frame) {
    const box = document.createElement('div');
    box.className = 'peak-labels';
    box.style.aspectRatio = `${scene.image.width} / ${scene.image.height}`; /* the picture's box, whatever the frame's */
    const scale = img.clientWidth / scene.image.width;
    const placed = placeLabels(r.peaks, scale);
    for (const l of placed) {
      const el = document.createElement('div');
      el.className = 'peak-label';
      /* in per cent of the picture: the labels stay on their summits when it is resized */
      el.style.left = `${(100 * (l.peak.px + 0.5)) / scene.image.width}%`;
      el.style.top = `${(100 * (l.peak.py + 0.5)) / scene.image.height}%`;
      el.style.setProperty('--tier', String(l.tier));
      el.dataset.px = String(l.peak.px);
      el.dataset.py = String(l.peak.py);
      el.title = `Summit ${Math.round(l.peak.z)} m, prominence ${Math.round(l.peak.prominence)} m, ` +
        `${(l.peak.distance / 1000).toFixed(2)} km away`;
      const span = document.createElement('span');
      span.textContent = l.text;
      el.appendChild(span);
      box.appendChild(el);
    }
    frame.appendChild(box);
    for (const p of r.peaks) {
      const icon = L.divIcon({ className: 'peak-marker', html: `<span>▲ ${Math.round(p.z)}</span>`, iconSize: null });
      L.marker(L.latLng(p.y, p.x), { icon, keyboard: false, interactive: false, alt: `Summit ${Math.round(p.z)} m` })
        .addTo(this.layer);
    }
    this.last = { count: placed.length, peaks: r.peaks };
    document.body.dataset.peaks = String(placed.length);
  }
}
