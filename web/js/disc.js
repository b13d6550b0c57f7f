// disc.js: the arithmetic of the page's terrain control (pure, unit-tested in
// test/unit.test.mjs): which samples a disc of radius r metres around the dataset-frame
// point (x, y) covers, as the region of PUT /v1/admin/datasets/{id}/heights (x, y the
// north-west sample in the file's order, row 0 north; w x h samples), the region's new
// heights (a smooth cosine bump of `delta` metres: a dam or a hill up, a crater down;
// voids stay voids), and the body's little-endian float32 encoding both ways.
//
// The sample at column i and south-based row j sits at (i*sx, j*sy); file row = H-1-j.

// The region (or null when the disc misses the grid), clipped to the grid.
export function discRegion(ds, x, y, r) {
  const i0 = Math.max(0, Math.ceil((x - r) / ds.sx)), i1 = Math.min(ds.width - 1, Math.floor((x + r) / ds.sx));
  const j0 = Math.max(0, Math.ceil((y - r) / ds.sy)), j1 = Math.min(ds.height - 1, Math.floor((y + r) / ds.sy));
  if (!(r > 0) || i0 > i1 || j0 > j1) return null;
  return { x: i0, y: ds.height - 1 - j1, w: i1 - i0 + 1, h: j1 - j0 + 1 };
}

// z: the region's heights (row 0 north); a new Float32Array with the bump added.
export function raiseDisc(z, reg, ds, x, y, r, delta) {
  const out = new Float32Array(z.length);
  for (let row = 0; row < reg.h; row++) {
    const py = (ds.height - 1 - (reg.y + row)) * ds.sy;
    for (let col = 0; col < reg.w; col++) {
      const k = row * reg.w + col;
      const d = Math.hypot((reg.x + col) * ds.sx - x, py - y);
      out[k] = d < r ? z[k] + delta * 0.5 * (1 + Math.cos((Math.PI * d) / r)) : z[k];
    }
  }
  return out;
}

export function encodeHeights(z) {
  const buf = new ArrayBuffer(z.length * 4), dv = new DataView(buf);
  z.forEach((v, k) => dv.setFloat32(4 * k, v, true));
  return buf;
}

export function decodeHeights(buf) {
  const dv = new DataView(buf), z = new Float32Array(buf.byteLength >> 2);
  for (let k = 0; k < z.length; k++) z[k] = dv.getFloat32(4 * k, true);
  return z;
}
