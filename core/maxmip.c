/* maxmip.c: builds one tile's max-mipmap for the hierarchical tracer.
 *
 * Layout: levels 1 .. L of a T x T tile (T = 2^L), each level a row-major array of
 * (T >> l)^2 floats, south first, concatenated:
 *
 *     level 1: (T/2)^2 maxima of 2x2 cells | level 2: (T/4)^2 | ... | level L: 1
 *
 * Level 0 (single cells) is not stored: the tracer reads a cell's four corners anyway
 * to intersect it, so storing their maximum would add 4 bytes per cell for nothing.
 * A partial (edge) tile gets the smallest power-of-two pyramid that covers its cells;
 * cells outside it and holes count as -inf. The pyramid costs
 * 4/3 * 4 / 4 = 1.33 bytes per cell. */
#include "maxmip.h"

#include <math.h>
#include <stdlib.h>

td_status td_maxmip_build(const td_grid *g, size_t tile, td_maxmip **out, td_err *err)
{
    td_status rc = TD_OK;
    const td_tile *t = &g->tiles[tile];
    const int32_t n = t->nx > t->ny ? t->nx : t->ny;
    int L = 1;
    while (L < g->tile_log2 && ((int32_t)1 << L) < n)
        L++; /* a partial tile (east or north edge, small grid) gets a smaller pyramid */
    const int32_t T = (int32_t)1 << L;
    float *cell = NULL;
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
    m->max = malloc(sizeof(float) * total);
    if (!m->max) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for a max-mipmap");
        goto out;
    }
    m->bytes = sizeof *m + sizeof(float) * total;
    td_grid_cell_max(g, t, cell);
    /* level 1 from the cells */
    for (int32_t bj = 0; bj < m->dim[1]; bj++) {
        for (int32_t bi = 0; bi < m->dim[1]; bi++) {
            float v = -INFINITY;
            for (int32_t dj = 0; dj < 2; dj++) {
                for (int32_t di = 0; di < 2; di++) {
                    int32_t ci = 2 * bi + di, cj = 2 * bj + dj;
                    if (ci < t->nx && cj < t->ny)
                        v = fmaxf(v, cell[(size_t)cj * (size_t)t->nx + (size_t)ci]);
                }
            }
            m->max[m->offset[1] + (size_t)bj * (size_t)m->dim[1] + (size_t)bi] = v;
        }
    }
    for (int l = 2; l <= L; l++) {
        const float *src = m->max + m->offset[l - 1];
        float *dst = m->max + m->offset[l];
        int32_t sd = m->dim[l - 1], dd = m->dim[l];
        for (int32_t bj = 0; bj < dd; bj++) {
            for (int32_t bi = 0; bi < dd; bi++) {
                const float *s0 = src + (size_t)(2 * bj) * (size_t)sd + (size_t)(2 * bi);
                dst[(size_t)bj * (size_t)dd + (size_t)bi] =
                    fmaxf(fmaxf(s0[0], s0[1]), fmaxf(s0[sd], s0[sd + 1]));
            }
        }
    }
out:
    free(cell);
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
        free(m->max);
        free(m);
    }
}
