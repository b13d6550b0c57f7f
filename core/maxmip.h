/* maxmip.h: one tile's max-mipmap (quadtree of maxima) for the hierarchical tracer.
 * Level 0 (one cell) is not stored: the tracer reads the cell's corners anyway. Level L
 * >= 1 holds, per block of 2^L x 2^L cells, a bound on the highest corner of any non-hole
 * cell in it, which bounds every surface: a 16-bit code per block, decoded by
 * td_maxmip_bound to a height never below that corner and at most one step of the
 * tile's code above it (a block of holes only decodes to the tile's lowest code). It also
 * keeps each 4 x 4 block's lowest corner (min4), for the sun bound's shadow side. */
#ifndef TD_MAXMIP_H
#define TD_MAXMIP_H

#include "trace.h"

struct td_maxmip {
    int levels;          /* stored levels 1 .. levels (block of the top level covers the tile) */
    int32_t dim[17];     /* blocks per side at level L: dim[L] = 2^levels >> L, where 2^levels
                            covers the tile's cells (T, or less for a partial tile) */
    size_t offset[17];   /* offset of level L in `code` */
    double base, step;   /* code q stands for the height base + q * step (step > 0) */
    uint16_t *code;      /* all levels, row-major, south first */
    /* Per block of 4 x 4 cells of the tile (min4_w x min4_h, fewer cells on its east and
     * north edges), the lowest corner, NaN where one is void: the sun bound's shadow side
     * reads them (sunlit.h). NULL in a prepared grid's tiles (prepaccel.c keeps the codes
     * only) and where the build was asked for none (td_maxmip_build_opts). */
    float *min4;
    int32_t min4_w, min4_h;
    size_t bytes;
};

/* The code of block (bi, bj) of level L (1 .. levels). */
static inline uint16_t td_maxmip_code(const td_maxmip *m, int L, int32_t bi, int32_t bj)
{
    return m->code[m->offset[L] + (size_t)bj * (size_t)m->dim[L] + (size_t)bi];
}

/* Its bound. */
static inline double td_maxmip_bound(const td_maxmip *m, int L, int32_t bi, int32_t bj)
{
    return m->base + (double)td_maxmip_code(m, L, bi, bj) * m->step;
}

td_status td_maxmip_build(const td_grid *g, size_t tile, td_maxmip **out, td_err *err);

/* td_maxmip_build, with the 4 x 4 blocks' minima only when `minima` (min4 NULL without:
 * a viewshed or `terrad trace` has no sun bound to read them). */
td_status td_maxmip_build_opts(const td_grid *g, size_t tile, int minima, td_maxmip **out, td_err *err);
void td_maxmip_free(td_maxmip *m);

/* The storage tile `tile`'s max-mipmap takes: its codes and, with `minima`, its 4 x 4
 * blocks' minima (0 without). */
void td_maxmip_sizes(const td_grid *g, size_t tile, int minima, size_t *codes, size_t *mins);
/* td_maxmip_build_opts into storage the caller owns (a whole grid's codes in one buffer,
 * accel.c): m is filled, its code and min4 pointing at `code` and `min4` (the sizes
 * td_maxmip_sizes gives; min4 unused without minima). Not for td_maxmip_free. */
td_status td_maxmip_build_into(const td_grid *g, size_t tile, int minima, td_maxmip *m, uint16_t *code,
                               float *min4, float *scratch, td_err *err);
/* The floats td_maxmip_build_into's `scratch` holds for tile `tile` (its cells' maxima
 * and the levels above them; NULL there: it allocates its own): a build over many tiles
 * keeps one (accel.c) */
size_t td_maxmip_scratch_floats(const td_grid *g, size_t tile, int minima);

#endif
