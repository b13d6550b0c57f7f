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

/* Codes a tile's range is split into: 65,000 steps leave the rounding of a decode (a few
 * units in the last place of a double) and a code's rounding up room below 65,535. */
#define MAXMIP_STEPS 65000.0

/* base and step of a tile's codes from its finite maxima in v[0 .. n): base one step
 * below the lowest, so a block of holes (code 0) decodes below every real maximum. The
 * step is at least 2^-40 of the heights' magnitude, so a decode's rounding is far below
 * a step even at huge coordinates. */
static void code_scale(const float *v, size_t n, double *base, double *step)
{
    double lo = INFINITY, hi = -INFINITY;
    for (size_t i = 0; i < n; i++) {
        if (isfinite(v[i])) {
            lo = (double)v[i] < lo ? (double)v[i] : lo;
            hi = (double)v[i] > hi ? (double)v[i] : hi;
        }
    }
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

/* The smallest code whose decode is at least v (-inf: code 0): at most a step above. */
static uint16_t code_of(double base, double step, float v)
{
    uint16_t q = 0;
    if (v > -INFINITY) {
        double c = ceil(((double)v - base) / step);
        q = c < 1.0 ? 1 : (c > 65535.0 ? 65535 : (uint16_t)c);
        while (base + (double)q * step < (double)v && q < 65535)
            q++; /* the division rounded down */
        while (q > 1 && base + (double)(q - 1) * step >= (double)v)
            q--; /* or up */
    }
    return q;
}

td_status td_maxmip_build(const td_grid *g, size_t tile, td_maxmip **out, td_err *err)
{
    td_status rc = TD_OK;
    const td_tile *t = &g->tiles[tile];
    const int32_t n = t->nx > t->ny ? t->nx : t->ny;
    int L = 1;
    while (L < g->tile_log2 && ((int32_t)1 << L) < n)
        L++; /* a partial tile (east or north edge, small grid) gets a smaller pyramid */
    const int32_t T = (int32_t)1 << L;
    float *cell = NULL, *max = NULL;
    td_maxmip *m = NULL;
    size_t total = 0;

    *out = NULL;
    m = calloc(1, sizeof *m);
    cell = malloc(sizeof(float) * (size_t)t->nx * (size_t)t->ny);
    if (!m || !cell) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for a max-mipmap");
        goto out;
    }
    m->levels = L;
    for (int l = 1; l <= L; l++) {
        m->dim[l] = T >> l;
        m->offset[l] = total;
        total += (size_t)m->dim[l] * (size_t)m->dim[l];
    }
    max = malloc(sizeof(float) * total);
    m->code = malloc(sizeof(uint16_t) * total);
    if (!max || !m->code) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for a max-mipmap");
        goto out;
    }
    m->bytes = sizeof *m + sizeof(uint16_t) * total;
    td_grid_cell_max(g, t, cell);
    /* level 1 from the cells */
    for (int32_t bj = 0; bj < m->dim[1]; bj++) {
        for (int32_t bi = 0; bi < m->dim[1]; bi++) {
            float v = -INFINITY;
            for (int32_t dj = 0; dj < 2; dj++) {
                for (int32_t di = 0; di < 2; di++) {
                    int32_t ci = 2 * bi + di, cj = 2 * bj + dj;
                    if (ci < t->nx && cj < t->ny)
                        v = max2(v, cell[(size_t)cj * (size_t)t->nx + (size_t)ci]);
                }
            }
            max[m->offset[1] + (size_t)bj * (size_t)m->dim[1] + (size_t)bi] = v;
        }
    }
    for (int l = 2; l <= L; l++) {
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
    for (size_t i = 0; i < total; i++)
        m->code[i] = code_of(m->base, m->step, max[i]);
out:
    free(cell);
    free(max);
    if (rc != TD_OK) {
        td_maxmip_free(m);
        m = NULL;
    }
    *out = m;
    return rc;
}

void td_maxmip_free(td_maxmip *m)
{
    if (m) {
        free(m->code);
        free(m);
    }
}
