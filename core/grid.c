/* grid.c: creation, statistics and tiling of the height field (see grid.h for the
 * frame and layout). Checks every size against overflow and the configured limits
 * before allocating, so a hostile header cannot make us allocate or write past a buffer. */
#include "grid.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>

#include "bigalloc.h"
#include "simd.h"

void td_grid_limits_default(td_grid_limits *lim)
{
    lim->max_width = 65536;
    lim->max_height = 65536;
    lim->max_bytes = (uint64_t)4 << 30; /* 4 GiB: a 32768^2 grid, far beyond the demo */
}

static int32_t tiles_along(int32_t samples, int tile_log2)
{
    int32_t cells = samples - 1;
    int32_t t = (int32_t)1 << tile_log2;
    return (cells + t - 1) / t;
}

uint64_t td_grid_bytes(int32_t w, int32_t h, int tile_log2)
{
    uint64_t bytes = 0;
    if (w >= 2 && h >= 2 && tile_log2 >= 1 && tile_log2 <= 16) {
        uint64_t n = (uint64_t)w * (uint64_t)h; /* < 2^62 for int32 sizes */
        uint64_t tiles = (uint64_t)tiles_along(w, tile_log2) * (uint64_t)tiles_along(h, tile_log2);
        bytes = n * sizeof(float) + tiles * sizeof(td_tile) + sizeof(td_grid);
    }
    return bytes;
}

td_status td_grid_create(int32_t w, int32_t h, double sx, double sy, int tile_log2,
                         const td_grid_limits *lim, td_grid **out, td_err *err)
{
    td_status rc = TD_OK;
    td_grid_limits dflt;
    td_grid *g = NULL;
    size_t n = 0, ntiles = 0, bytes = 0;

    *out = NULL;
    if (!lim) {
        td_grid_limits_default(&dflt);
        lim = &dflt;
    }
    if (w < 2 || h < 2) {
        rc = td_err_set(err, TD_EFORMAT, "grid of %d x %d samples has no cell (need at least 2 x 2)",
                        (int)w, (int)h);
        goto out;
    }
    if (w > lim->max_width || h > lim->max_height) {
        rc = td_err_set(err, TD_ETOOBIG, "grid of %d x %d samples exceeds the limit of %d x %d",
                        (int)w, (int)h, (int)lim->max_width, (int)lim->max_height);
        goto out;
    }
    if (!(sx > 0.0) || !(sy > 0.0) || !isfinite(sx) || !isfinite(sy)) {
        rc = td_err_set(err, TD_ERANGE, "spacing %g x %g m is not positive and finite", sx, sy);
        goto out;
    }
    if (tile_log2 < 1 || tile_log2 > 16) {
        rc = td_err_set(err, TD_ERANGE, "tile size 2^%d is out of range (2^1 .. 2^16)", tile_log2);
        goto out;
    }
    if (!td_mul_size((size_t)w, (size_t)h, &n) || !td_mul_size(n, sizeof(float), &bytes)) {
        rc = td_err_set(err, TD_ETOOBIG, "grid of %d x %d samples overflows", (int)w, (int)h);
        goto out;
    }
    if (lim->max_bytes && td_grid_bytes(w, h, tile_log2) > lim->max_bytes) {
        rc = td_err_set(err, TD_ETOOBIG, "grid of %d x %d samples needs %llu bytes, over the budget of %llu",
                        (int)w, (int)h, (unsigned long long)td_grid_bytes(w, h, tile_log2),
                        (unsigned long long)lim->max_bytes);
        goto out;
    }
    g = calloc(1, sizeof *g);
    if (!g) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for the grid record");
        goto out;
    }
    g->w = w;
    g->h = h;
    g->sx = sx;
    g->sy = sy;
    g->tile_log2 = tile_log2;
    g->tiles_x = tiles_along(w, tile_log2);
    g->tiles_y = tiles_along(h, tile_log2);
    ntiles = (size_t)g->tiles_x * (size_t)g->tiles_y;
    g->z = td_bigalloc(bytes); /* written whole by the loader next (bigalloc.h) */
    g->tiles = calloc(ntiles, sizeof *g->tiles);
    g->zmin = g->zmax = NAN;
    if (!g->z || !g->tiles) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for %d x %d samples", (int)w, (int)h);
        goto out;
    }
    td_grid_corners_flat(g);
out:
    if (rc != TD_OK) {
        td_grid_free(g);
        g = NULL;
    }
    *out = g;
    return rc;
}

float td_grid_key_float(int32_t k)
{
    float f;
    k ^= (k >> 31) & 0x7fffffff;
    memcpy(&f, &k, sizeof f);
    return f;
}

/* Voids and infinities in a run of n samples: adds the NaNs to *voids, returns non-zero if
 * any sample is infinite. */
TD_ROW_CLONES static int run_voids(const float *restrict z, int32_t n, int64_t *voids)
{
    int32_t nan = 0, inf = 0; /* n < 2^31; on the bits (|z| above inf's: NaN), so the loop
                                 runs eight to a register with AVX2 */
    for (int32_t i = 0; i < n; i++) {
        uint32_t b;
        memcpy(&b, &z[i], sizeof b);
        b &= 0x7fffffffu;
        nan += b > 0x7f800000u;
        inf |= b == 0x7f800000u;
    }
    *voids += nan;
    return inf;
}

/* Each key bits ^ (sign ? 0x7fffffff : 0); a value left out counts as INT32_MAX for the
 * lowest, INT32_MIN for the highest (no branch). */
TD_ROW_CLONES void td_grid_keys(const float *restrict z, size_t n, uint32_t most, int32_t *lo, int32_t *hi)
{
    int32_t l = *lo, h = *hi;
    for (size_t i = 0; i < n; i++) {
        int32_t b;
        memcpy(&b, &z[i], sizeof b);
        int32_t k = b ^ ((b >> 31) & 0x7fffffff);
        int32_t out = -(int32_t)((uint32_t)(b & 0x7fffffff) > most); /* left out: all ones */
        int32_t kl = (k & ~out) | (INT32_MAX & out), kh = (k & ~out) | (INT32_MIN & out);
        l = kl < l ? kl : l;
        h = kh > h ? kh : h;
    }
    *lo = l;
    *hi = h;
}

/* The first sample of the box (rows j0 .. j1, columns i0 .. i1, south row first) equal to
 * zero, to give a minimum or maximum of zero the sign the scalar scan (strict <, first
 * found) gave it: -0 and +0 compare equal. */
static float first_zero(const td_grid *g, int32_t i0, int32_t i1, int32_t j0, int32_t j1)
{
    float z = 0.0f;
    int found = 0;
    for (int32_t j = j0; j <= j1 && !found; j++)
        for (int32_t i = i0; i <= i1 && !found; i++)
            if (g->z[(size_t)j * (size_t)g->w + (size_t)i] == 0.0f) {
                z = g->z[(size_t)j * (size_t)g->w + (size_t)i];
                found = 1;
            }
    return z;
}

/* A tile's lowest and highest valid sample, edges included, from the keys of its runs
 * (-inf, +inf reversed for a tile of voids: hi < lo, as the tracers expect). */
static void tile_range(const td_grid *g, td_tile *t, int32_t lo, int32_t hi)
{
    t->zmin = lo == INT32_MAX ? INFINITY : td_grid_key_float(lo);
    t->zmax = hi == INT32_MIN ? -INFINITY : td_grid_key_float(hi);
    if (t->zmin == 0.0f)
        t->zmin = first_zero(g, t->i0, t->i0 + t->nx, t->j0, t->j0 + t->ny);
    if (t->zmax == 0.0f)
        t->zmax = first_zero(g, t->i0, t->i0 + t->nx, t->j0, t->j0 + t->ny);
}

/* The heights in one pass of rows, south first: each row's voids and infinities, and its
 * runs into the ranges of the tiles of its band (a row on a band's edge is read again with
 * the next band). Row by row rather than a pass of rows and then one of tiles, whose rows
 * are short runs a grid's width apart: with run_voids on the bits, trinidad's 2.9 M
 * samples 1.66-2.51 -> 1.29-1.67 ms (min of 15, Zen 3). */
td_status td_grid_finish(td_grid *g, td_err *err)
{
    td_status rc = TD_OK;
    const int32_t T = td_grid_tile_size(g);
    float gmin = INFINITY, gmax = -INFINITY;
    int64_t voids = 0;
    int32_t jv = 0; /* rows 0 .. jv - 1 counted for voids */
    int32_t *lo = malloc(sizeof(int32_t) * 2 * (size_t)g->tiles_x), *hi = lo ? lo + g->tiles_x : NULL;

    if (!lo) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for the tiles' ranges");
        goto out;
    }
    for (int32_t ty = 0; ty <= g->tiles_y && rc == TD_OK; ty++) {
        /* band ty's rows (the last pass: rows no tile holds, if any, for their voids) */
        const int32_t j0 = ty * T, ny = ty < g->tiles_y ? ((g->h - 1 - j0) < T ? (g->h - 1 - j0) : T) : -1;
        const int32_t j1 = ty < g->tiles_y ? j0 + ny : g->h - 1;
        for (int32_t tx = 0; tx < g->tiles_x; tx++)
            lo[tx] = INT32_MAX, hi[tx] = INT32_MIN;
        for (int32_t j = ty < g->tiles_y ? j0 : jv; j <= j1 && rc == TD_OK; j++) {
            const float *row = g->z + (size_t)j * (size_t)g->w;
            if (j == jv && run_voids(row, g->w, &voids)) {
                int32_t i = 0;
                while (!isinf(row[i]))
                    i++;
                rc = td_err_set(err, TD_ERANGE, "infinite height at column %d, row %d from the north",
                                (int)i, (int)(g->h - 1 - j));
            }
            jv += j == jv;
            for (int32_t tx = 0; tx < g->tiles_x && ty < g->tiles_y; tx++) {
                const int32_t i0 = tx * T, nx = (g->w - 1 - i0) < T ? (g->w - 1 - i0) : T;
                td_grid_keys(row + i0, (size_t)nx + 1, TD_KEYS_VALID, &lo[tx], &hi[tx]);
            }
        }
        /* the tiles cover every sample: their ranges give the grid's (a zero: see
           first_zero) */
        for (int32_t tx = 0; tx < g->tiles_x && ty < g->tiles_y && rc == TD_OK; tx++) {
            td_tile *t = &g->tiles[(size_t)ty * (size_t)g->tiles_x + (size_t)tx];
            t->i0 = tx * T;
            t->j0 = j0;
            t->nx = (g->w - 1 - t->i0) < T ? (g->w - 1 - t->i0) : T;
            t->ny = ny;
            tile_range(g, t, lo[tx], hi[tx]);
            gmin = t->zmin < gmin ? t->zmin : gmin;
            gmax = t->zmax > gmax ? t->zmax : gmax;
        }
    }
    if (rc != TD_OK)
        goto out;
    if (gmin == 0.0f)
        gmin = first_zero(g, 0, g->w - 1, 0, g->h - 1);
    if (gmax == 0.0f)
        gmax = first_zero(g, 0, g->w - 1, 0, g->h - 1);
    g->voids = voids;
    g->zmin = voids == (int64_t)g->w * g->h ? NAN : gmin;
    g->zmax = voids == (int64_t)g->w * g->h ? NAN : gmax;
out:
    free(lo);
    return rc;
}

void td_grid_corners_flat(td_grid *g)
{
    td_corners c = {g->z, 1, 0, (size_t)g->w, ((uint32_t)1 << TD_CORNERS_FLAT_LOG2) - 1u,
                    TD_CORNERS_FLAT_LOG2};
    g->cz = c;
}

void td_grid_free(td_grid *g)
{
    if (g) {
        if (g->bmap)
            munmap(g->bmap, g->bmap_bytes);
        if (g->map)
            munmap(g->map, g->map_bytes);
        else
            free(g->z);
        free(g->tiles);
        free(g);
    }
}

td_status td_grid_tile_range(const td_grid *g, int32_t tx0, int32_t tx1, int32_t ty0, int32_t ty1,
                             size_t **tiles, size_t *n, td_err *err)
{
    td_status rc = TD_OK;
    size_t k = 0, cnt = (size_t)(tx1 - tx0 + 1) * (size_t)(ty1 - ty0 + 1);

    *n = 0;
    *tiles = malloc(cnt * sizeof **tiles);
    if (!*tiles) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for %zu tile indices", cnt);
        goto out;
    }
    for (int32_t ty = ty0; ty <= ty1; ty++)
        for (int32_t tx = tx0; tx <= tx1; tx++)
            (*tiles)[k++] = (size_t)ty * (size_t)g->tiles_x + (size_t)tx;
    *n = k;
out:
    return rc;
}

int td_grid_bilinear_cell(const td_grid *g, int32_t ci, int32_t cj, double x, double y, double *z,
                          double n[3])
{
    const float *s0 = td_grid_corner(&g->cz, ci, cj);
    double z00 = s0[0], z10 = s0[1], z01 = s0[g->cz.stride], z11 = s0[g->cz.stride + 1];
    double u = x / g->sx - ci, v = y / g->sy - cj;
    int ok = !(isnan(z00) || isnan(z10) || isnan(z01) || isnan(z11));
    if (ok) {
        u = u < 0 ? 0 : u > 1 ? 1 : u;
        v = v < 0 ? 0 : v > 1 ? 1 : v;
        *z = (1 - v) * ((1 - u) * z00 + u * z10) + v * ((1 - u) * z01 + u * z11);
        if (n) {
            double dzdx = ((1 - v) * (z10 - z00) + v * (z11 - z01)) / g->sx;
            double dzdy = ((1 - u) * (z01 - z00) + u * (z11 - z10)) / g->sy;
            double l = sqrt(dzdx * dzdx + dzdy * dzdy + 1.0);
            n[0] = -dzdx / l;
            n[1] = -dzdy / l;
            n[2] = 1.0 / l;
        }
    }
    return ok;
}

int td_grid_bilinear(const td_grid *g, double x, double y, double *z, double n[3])
{
    double fi = floor(x / g->sx), fj = floor(y / g->sy);
    int32_t ci = !(fi >= 0.0) ? 0 : (fi > (double)(g->w - 2) ? g->w - 2 : (int32_t)fi);
    int32_t cj = !(fj >= 0.0) ? 0 : (fj > (double)(g->h - 2) ? g->h - 2 : (int32_t)fj);
    return td_grid_bilinear_cell(g, ci, cj, x, y, z, n);
}

/* One run of td_grid_cell_max: cells k of the rows of samples s0 (south) and s1. A loop
 * that vectorises (with the AVX2 clone): max-mipmap builds spent a third of their time here. */
TD_ROW_CLONES static void cell_max_row(const float *restrict s0, const float *restrict s1,
                                       float *restrict o, int32_t n)
{
    for (int32_t k = 0; k < n; k++) {
        float a = s0[k], b = s0[k + 1], c = s1[k], d = s1[k + 1];
        float ab = a > b ? a : b, cd = c > d ? c : d;
        o[k] = isnan(a + b + c + d) ? -INFINITY : (ab > cd ? ab : cd);
    }
}

void td_grid_cell_max(const td_grid *g, const td_tile *t, float *out)
{
    const size_t W = g->cz.stride;
    for (int32_t cj = 0; cj < t->ny; cj++) {
        float *o = out + (size_t)cj * (size_t)t->nx;
        /* runs of cells inside one block of g->cz (a whole row of an in-memory grid) */
        for (int32_t ci = 0, n; ci < t->nx; ci += n, o += n) {
            int32_t i = t->i0 + ci;
            const float *s0 = td_grid_corner(&g->cz, i, t->j0 + cj), *s1 = s0 + W;
            int64_t left = (int64_t)g->cz.mask + 1 - (int64_t)((uint32_t)i & g->cz.mask);
            n = left < t->nx - ci ? (int32_t)left : t->nx - ci;
            cell_max_row(s0, s1, o, n);
        }
    }
}

void td_grid_lonlat_spacing(double lat_deg, double dlon_deg, double dlat_deg, double *sx,
                            double *sy)
{
    const double a = 6378137.0, e2 = 6.69437999014e-3; /* WGS84 */
    const double deg = M_PI / 180.0;
    double s = sin(lat_deg * deg);
    double w = sqrt(1.0 - e2 * s * s);
    double n = a / w;                       /* prime vertical radius of curvature */
    double m = a * (1.0 - e2) / (w * w * w); /* meridional radius of curvature */
    *sx = n * cos(lat_deg * deg) * dlon_deg * deg;
    *sy = m * dlat_deg * deg;
}
