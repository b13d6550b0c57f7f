/* maxmip.c: builds one tile's max-mipmap for the hierarchical tracer.
 *
 * Layout: levels 1 .. L of a T x T tile (T = 2^L), each level a row-major array of
 * (T >> l)^2 codes, south first, concatenated:
 *
 *     level 1: (T/2)^2 maxima of 2x2 cells | level 2: (T/4)^2 | ... | level L: 1
 *
 * Level 0 (single cells) is not stored: the tracer reads a cell's four corners anyway
 * to intersect it. A partial (edge) tile gets the smallest power-of-two pyramid that
 * covers its cells; cells outside it and holes count as -inf.
 *
 * The maxima are 16-bit codes over the tile's own range (td_maxmip_bound): the tile's
 * lowest to highest maximum in about 65,000 steps, each code rounded up and checked, so
 * a decoded bound is never below the maximum it stands for and at most a step above it
 * (4.6 cm on trinidad's 2,963 m of relief: a block test fails a little earlier, which
 * the tests below it settle; no ray's answer changes). The pyramid costs
 * 4/3 * 2 / 4 = 0.67 bytes per cell, half what floats took (issue 12's 6 bytes a cell). */
#include "maxmip.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "simd.h"

/* Codes a tile's range is split into: 65,000 steps leave the rounding of a decode (a few
 * units in the last place of a double) and a code's rounding up room below 65,535. */
#define MAXMIP_STEPS 65000.0

/* base and step of a tile's codes from its finite maxima in v[0 .. n): base one step
 * below the lowest, so a block of holes (code 0) decodes below every real maximum. The
 * step is at least 2^-40 of the heights' magnitude, so a decode's rounding is far below
 * a step even at huge coordinates. The range from integer keys (td_grid_keys: a loop built
 * for AVX2 as well, where one converting each to double ran scalar; -0 just below +0 gives
 * the same base and step): trinidad's max-mipmaps 41.9 -> 32.3 M instructions. */
static void code_scale(const float *v, size_t n, double *base, double *step)
{
    int32_t klo = INT32_MAX, khi = INT32_MIN;
    td_grid_keys(v, n, TD_KEYS_FINITE, &klo, &khi);
    double lo = klo == INT32_MAX ? INFINITY : (double)td_grid_key_float(klo);
    double hi = khi == INT32_MIN ? -INFINITY : (double)td_grid_key_float(khi);
    if (!(lo <= hi))
        lo = hi = 0.0; /* a tile of holes: every code is 0 */
    double mag = fabs(lo) > fabs(hi) ? fabs(lo) : fabs(hi);
    double s = (hi - lo) / MAXMIP_STEPS;
    if (s < mag * 0x1p-40)
        s = mag * 0x1p-40;
    if (s < 0x1p-30)
        s = 0x1p-30;
    *step = s;
    *base = lo - s;
}

/* The larger of two maxima (never NaN: holes are -inf); fmaxf is a call into libm. */
static inline float max2(float a, float b) { return a > b ? a : b; }

/* The codes of v[0 .. n): for each, the smallest code whose decode is at least v (-inf:
 * code 0), at most a step above. That code is unique (decodes rise with the code, and
 * code 65,535 decodes above the tile's highest maximum), so the estimate it starts from
 * only has to be near: one multiplication a value in a loop that vectorises (with the AVX2
 * clone), then each checked and moved, usually not at all, by the exact decode. Measured
 * on trinidad's tiles: about 40 -> 12 instructions a code. */
TD_ROW_CLONES static void codes_of(double base, double step, const float *restrict v, size_t n,
                                   uint16_t *restrict q)
{
    const double inv = 1.0 / step;
    for (size_t i = 0; i < n; i++) {
        double c = ((double)v[i] - base) * inv + 1.0; /* -inf for a hole: code 0 below */
        c = c < 1.0 ? 1.0 : (c > 65535.0 ? 65535.0 : c);
        q[i] = v[i] > -INFINITY ? (uint16_t)c : 0;
    }
    /* one step of each loop below for all at once, then their tests, in loops that
     * vectorise (flags, no branch): a step is all that an estimate ever needed on the
     * DEMs measured, so the loops (scalar) run only for a tile with a code still to move.
     * The loops end on the one code whatever they start from. Issue 18: trinidad's build
     * 55.2 -> 41.9 M instructions, the same codes (one loop for the three: not vectorised,
     * 2.6x the instructions). */
    int move = 0;
    for (size_t i = 0; i < n; i++) {
        int c = q[i];
        double x = (double)v[i];
        c += (c > 0) & (c < 65535) & (base + (double)c * step < x);
        c -= (c > 1) & (base + (double)(c - 1) * step >= x);
        q[i] = (uint16_t)c;
    }
    for (size_t i = 0; i < n; i++) {
        double c = (double)q[i], x = (double)v[i];
        move |= (q[i] > 0) & (base + c * step < x) & (q[i] < 65535);
        move |= (q[i] > 1) & (base + (c - 1.0) * step >= x);
    }
    for (size_t i = 0; i < n && move; i++) {
        while (q[i] > 0 && base + (double)q[i] * step < (double)v[i] && q[i] < 65535)
            q[i]++;
        while (q[i] > 1 && base + (double)(q[i] - 1) * step >= (double)v[i])
            q[i]--;
    }
}

/* Level 1: each 2 x 2 cells' largest maximum, from the tile's cell maxima (nx x ny, rows
 * of nx; cells outside them count as -inf). Rows of whole blocks take the loop that
 * vectorises; the tile's odd last column or row, if any, the general one. */
TD_ROW_CLONES static void level1(const float *restrict cell, int32_t nx, int32_t ny, int32_t dim,
                                 float *restrict out)
{
    for (int32_t bj = 0; bj < dim; bj++) {
        const float *r0 = cell + (size_t)(2 * bj) * (size_t)nx, *r1 = r0 + nx;
        float *o = out + (size_t)bj * (size_t)dim;
        int32_t full = 2 * bj + 1 < ny ? nx / 2 : 0; /* blocks with all four cells */
        for (int32_t bi = 0; bi < full; bi++)
            o[bi] = max2(max2(r0[2 * bi], r0[2 * bi + 1]), max2(r1[2 * bi], r1[2 * bi + 1]));
        for (int32_t bi = full; bi < dim; bi++) {
            float m = -INFINITY;
            for (int32_t dj = 0; dj < 2; dj++)
                for (int32_t di = 0; di < 2; di++)
                    if (2 * bi + di < nx && 2 * bj + dj < ny)
                        m = max2(m, cell[(size_t)(2 * bj + dj) * (size_t)nx + (size_t)(2 * bi + di)]);
            o[bi] = m;
        }
    }
}

/* NaN-sticky minimum (a void stays) */
static inline float min_void(float v, float z) { return z < v || z != z ? z : v; }

/* The tile's min4 (maxmip.h): per row of blocks, the minimum of its 5 sample rows sample
 * by sample (runs of contiguous samples, td_grid_run: a loop that vectorises; the one that
 * keeps NaN only in a grid with voids), then of each block's 5 columns. col is scratch
 * for twice the tile's nx + 1 samples. */
TD_ROW_CLONES static void blocks_min4(const td_grid *g, const td_tile *t, td_maxmip *m,
                                      float *restrict col)
{
    for (int32_t by = 0; by < m->min4_h; by++) {
        int32_t j1 = 4 * by + 4 < t->ny ? 4 * by + 4 : t->ny;
        for (int32_t j = 4 * by; j <= j1; j++) {
            for (int32_t i = 0, n; i <= t->nx; i += n) {
                const float *restrict s = td_grid_corner(&g->cz, t->i0 + i, t->j0 + j);
                n = td_grid_run(&g->cz, t->i0 + i, t->nx + 1 - i);
                if (j == 4 * by)
                    memcpy(col + i, s, (size_t)n * sizeof *col);
                else if (g->voids) /* a void's NaN kept */
                    for (int32_t k = 0; k < n; k++)
                        col[i + k] = min_void(col[i + k], s[k]);
                else /* the common case, the plain minimum: vminps */
                    for (int32_t k = 0; k < n; k++)
                        col[i + k] = s[k] < col[i + k] ? s[k] : col[i + k];
            }
        }
        /* q[i]: the minimum of col[i .. i + 3] (pairs, then pairs of pairs), so that a
           whole block is min(q[4 bx], col[4 bx + 4]) */
        float *restrict q = col + t->nx + 1, *o = m->min4 + (size_t)by * (size_t)m->min4_w;
        const int32_t np = t->nx - 3; /* the i with i + 3 <= nx */
        if (g->voids) {
            for (int32_t i = 0; i < np; i++)
                q[i] = min_void(min_void(col[i], col[i + 1]), min_void(col[i + 2], col[i + 3]));
        } else {
            for (int32_t i = 0; i + 1 <= t->nx; i++)
                q[i] = col[i + 1] < col[i] ? col[i + 1] : col[i];
            for (int32_t i = 0; i < np; i++)
                q[i] = q[i + 2] < q[i] ? q[i + 2] : q[i];
        }
        for (int32_t bx = 0; bx < m->min4_w; bx++) {
            int32_t i1 = 4 * bx + 4 < t->nx ? 4 * bx + 4 : t->nx;
            float v;
            if (i1 == 4 * bx + 4) { /* a whole block */
                v = min_void(q[4 * bx], col[i1]);
            } else { /* the tile's east edge */
                v = col[4 * bx];
                for (int32_t i = 4 * bx + 1; i <= i1; i++)
                    v = min_void(v, col[i]);
            }
            o[bx] = v;
        }
    }
}

td_status td_maxmip_build(const td_grid *g, size_t tile, td_maxmip **out, td_err *err)
{
    return td_maxmip_build_opts(g, tile, 1, out, err);
}

/* m's levels, their blocks and offsets, and its minima's size for tile t: the pyramid
 * covers the tile's cells (a partial tile, on the east or north edge or of a small grid,
 * gets a smaller one). Returns the codes of all its levels. */
static size_t shape(const td_grid *g, const td_tile *t, int minima, td_maxmip *m)
{
    const int32_t n = t->nx > t->ny ? t->nx : t->ny;
    int L = 1;
    size_t total = 0;
    while (L < g->tile_log2 && ((int32_t)1 << L) < n)
        L++;
    m->levels = L;
    for (int l = 1; l <= L; l++) {
        m->dim[l] = ((int32_t)1 << L) >> l;
        m->offset[l] = total;
        total += (size_t)m->dim[l] * (size_t)m->dim[l];
    }
    m->min4_w = minima ? (t->nx + 3) / 4 : 0;
    m->min4_h = minima ? (t->ny + 3) / 4 : 0;
    return total;
}

void td_maxmip_sizes(const td_grid *g, size_t tile, int minima, size_t *codes, size_t *mins)
{
    td_maxmip m;
    *codes = shape(g, &g->tiles[tile], minima, &m);
    *mins = (size_t)m.min4_w * (size_t)m.min4_h;
}

size_t td_maxmip_scratch_floats(const td_grid *g, size_t tile, int minima)
{
    const td_tile *t = &g->tiles[tile];
    td_maxmip m;
    size_t total = shape(g, t, minima, &m);
    return (size_t)t->nx * (size_t)t->ny + 2 * ((size_t)t->nx + 1) + total;
}

td_status td_maxmip_build_into(const td_grid *g, size_t tile, int minima, td_maxmip *m, uint16_t *code,
                               float *min4, float *scratch, td_err *err)
{
    td_status rc = TD_OK;
    const td_tile *t = &g->tiles[tile];
    float *own = NULL, *cell, *max;
    size_t total, ncell = (size_t)t->nx * (size_t)t->ny + 2 * ((size_t)t->nx + 1);

    memset(m, 0, sizeof *m);
    total = shape(g, t, minima, m);
    m->code = code;
    m->min4 = minima ? min4 : NULL;
    if (!scratch)
        scratch = own = malloc(sizeof(float) * (ncell + total));
    cell = scratch;
    max = scratch ? scratch + ncell : NULL;
    if (!scratch) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for a max-mipmap");
        goto out;
    }
    m->bytes = sizeof *m + sizeof(uint16_t) * total + sizeof(float) * (size_t)m->min4_w * (size_t)m->min4_h;
    if (minima)
        blocks_min4(g, t, m, cell); /* cell: nx x ny floats, free until level1 */
    td_grid_cell_max(g, t, cell);
    level1(cell, t->nx, t->ny, m->dim[1], max + m->offset[1]);
    for (int l = 2; l <= m->levels; l++) {
        const float *src = max + m->offset[l - 1];
        float *dst = max + m->offset[l];
        int32_t sd = m->dim[l - 1], dd = m->dim[l];
        for (int32_t bj = 0; bj < dd; bj++) {
            for (int32_t bi = 0; bi < dd; bi++) {
                const float *s0 = src + (size_t)(2 * bj) * (size_t)sd + (size_t)(2 * bi);
                dst[(size_t)bj * (size_t)dd + (size_t)bi] =
                    max2(max2(s0[0], s0[1]), max2(s0[sd], s0[sd + 1]));
            }
        }
    }
    code_scale(max, m->dim[1] * (size_t)m->dim[1], &m->base, &m->step); /* level 1 has them all */
    codes_of(m->base, m->step, max, total, m->code);
out:
    free(own);
    return rc;
}

td_status td_maxmip_build_opts(const td_grid *g, size_t tile, int minima, td_maxmip **out, td_err *err)
{
    td_status rc = TD_OK;
    td_maxmip *m = calloc(1, sizeof *m);
    uint16_t *code = NULL;
    float *min4 = NULL;
    size_t codes, mins;

    td_maxmip_sizes(g, tile, minima, &codes, &mins);
    code = malloc(sizeof *code * codes);
    min4 = minima ? malloc(sizeof *min4 * (mins ? mins : 1)) : NULL;
    if (!m || !code || (minima && !min4))
        rc = td_err_set(err, TD_ENOMEM, "out of memory for a max-mipmap");
    else
        rc = td_maxmip_build_into(g, tile, minima, m, code, min4, NULL, err);
    if (rc != TD_OK) {
        free(code);
        free(min4);
        free(m);
        m = NULL;
    }
    *out = m;
    return rc;
}

void td_maxmip_free(td_maxmip *m)
{
    if (m) {
        free(m->code);
        free(m->min4);
        free(m);
    }
}
