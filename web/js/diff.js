// diff.js: the pixel difference of two renders of the same view (compare mode),
// computed in the page. `diffRGBA` is pure (RGBA byte arrays in, statistics and a
// difference image out) so node's test runner checks it; `diffImages` feeds it from two
// <img> elements through canvases.
//
// Per pixel the difference is the largest absolute difference over R, G, B (alpha is
// compared too: sky against no sky is a difference). Statistics: pixels that differ at
// all, pixels that differ by more than `threshold` (visible), mean and max difference,
// and PSNR over RGB. The difference image is a dimmed grey copy of image A turning red
// where the two differ, fully red from 32 levels up, so where the settings disagree
// (silhouettes, shadow edges) stands out and rounding-level noise does not.

export function diffRGBA(a, b, width, height, threshold = 8) {
  const n = width * height;
  if (a.length < n * 4 || b.length < n * 4) throw new Error('image buffers smaller than width x height');
  const out = new Uint8ClampedArray(n * 4);
  let differ = 0, visible = 0, sum = 0, max = 0, sq = 0;
  for (let i = 0, o = 0; i < n; i++, o += 4) {
    const dr = Math.abs(a[o] - b[o]), dg = Math.abs(a[o + 1] - b[o + 1]);
    const db = Math.abs(a[o + 2] - b[o + 2]), da = Math.abs(a[o + 3] - b[o + 3]);
    const d = Math.max(dr, dg, db, da);
    sq += dr * dr + dg * dg + db * db;
    sum += d;
    if (d > max) max = d;
    if (d > 0) differ++;
    if (d > threshold) visible++;
    // Dimmed grey of A, blended towards red as the difference grows (full red from 32
    // levels): a difference of a level or two barely tints, an edge that moved glows.
    const g = (a[o] + a[o + 1] + a[o + 2]) / 6;
    const k = Math.min(1, d / 32);
    out[o] = g + (255 - g) * k;
    out[o + 1] = g * (1 - k);
    out[o + 2] = g * (1 - k);
    out[o + 3] = 255;
  }
  const mse = sq / (n * 3);
  return {
    width, height, pixels: n,
    differ, visible, threshold,
    mean: n ? sum / n : 0,
    max,
    psnr: mse > 0 ? 10 * Math.log10((255 * 255) / mse) : Infinity,
    image: out,
  };
}

// Pixel data of a decoded <img> (or ImageBitmap) at its natural size.
export function pixelsOf(img, width, height) {
  const c = document.createElement('canvas');
  c.width = width;
  c.height = height;
  const ctx = c.getContext('2d', { willReadFrequently: true });
  ctx.drawImage(img, 0, 0);
  return ctx.getImageData(0, 0, width, height).data;
}

// Compares two images of the same size and draws the difference on `canvas`.
export function diffImages(imgA, imgB, canvas, threshold = 8) {
  const w = imgA.naturalWidth || imgA.width, h = imgA.naturalHeight || imgA.height;
  const wb = imgB.naturalWidth || imgB.width, hb = imgB.naturalHeight || imgB.height;
  if (w !== wb || h !== hb) throw new Error(`the two images differ in size (${w}x${h}, ${wb}x${hb})`);
  const r = diffRGBA(pixelsOf(imgA, w, h), pixelsOf(imgB, w, h), w, h, threshold);
  canvas.width = w;
  canvas.height = h;
  canvas.getContext('2d').putImageData(new ImageData(r.image, w, h), 0, 0);
  return r;
}

// Statistics of one image alone: how many pixels are not transparent, and the variance
// of their luminance (the browser test's "the view is not empty").
export function imageStats(data) {
  let opaque = 0, sum = 0, sq = 0;
  for (let o = 0; o < data.length; o += 4) {
    if (data[o + 3] === 0) continue;
    const l = 0.299 * data[o] + 0.587 * data[o + 1] + 0.114 * data[o + 2];
    opaque++;
    sum += l;
    sq += l * l;
  }
  const mean = opaque ? sum / opaque : 0;
  return { pixels: data.length / 4, opaque, mean, variance: opaque ? sq / opaque - mean * mean : 0 };
}
