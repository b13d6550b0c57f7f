/* planes.h: one tile's Paglieroni-Petersen parameter planes for the parametric tracer:
 * per block of 2 x 2 cells an apex height z_p and a slope s_p (height per metre) of a
 * cone of empty space that bounds every surface of every cell of the tile, seen from any
 * point over the block (see planes.c for why). */
#ifndef TD_PLANES_H
#define TD_PLANES_H

#include <stdint.h>

#include "trace.h"

/* The most slices a tile's planes can have: apex indices are bytes (0 .. K). */
#define TD_PLANES_K_MAX 255

/* Cones are kept per block of 2^B x 2^B cells (B = 1: half a byte a cell; see planes.c). */
#define TD_PLANES_BLOCK_LOG2 1

/* One cell's cone, quantised to two bytes: the apex is one of the tile's K slice heights
 * or its top (apex[] below), the slope a code of the slope table, both rounded up, so the
 * decoded cone is never narrower than the computed one (see planes.c). */
typedef struct td_cone {
    uint8_t apex;  /* index into td_planes.apex */
    uint8_t slope; /* code: 0 flat, 1 .. 254 slope_scale * td_planes_slope_unit[code], 255 +inf */
} td_cone;

/* Slope code -> slope in units of slope_scale: 0, then (1 + m/16) * 2^e for code - 1 =
 * 16e + m (e 0 .. 15, steps of at most 6.25%), then +inf. Exact binary fractions. */
extern const double td_planes_slope_unit[256];

struct td_planes {
    int k;              /* slices used */
    int32_t nx, ny;     /* cells */
    int32_t bnx, bny;   /* blocks of cones: the cells rounded up to whole blocks */
    double slope_scale; /* a power of two chosen per tile so its steepest slope fits */
    float *apex;        /* k + 1 apex heights (rounded up; -inf in a tile of holes) */
    td_cone *cone;      /* bnx*bny, row-major, south first */
    size_t bytes;
};

/* Blocks of cones for n cells. */
static inline int32_t td_planes_blocks(int32_t n)
{
    return (n + ((int32_t)1 << TD_PLANES_BLOCK_LOG2) - 1) >> TD_PLANES_BLOCK_LOG2;
}

/* The cone over cell (li, lj) of the tile (tile-local indices). */
static inline td_cone td_planes_cone(const td_planes *p, int32_t li, int32_t lj)
{
    return p->cone[(size_t)(lj >> TD_PLANES_BLOCK_LOG2) * (size_t)p->bnx +
                   (size_t)(li >> TD_PLANES_BLOCK_LOG2)];
}

static inline double td_cone_apex(const td_planes *p, td_cone c) { return (double)p->apex[c.apex]; }
static inline double td_cone_slope(const td_planes *p, td_cone c)
{
    return p->slope_scale * td_planes_slope_unit[c.slope];
}

td_status td_planes_build(const td_grid *g, size_t tile, int k, td_planes **out, td_err *err);

/* The build's dilation: out[c] = the maximum of h over cell c's 3x3 neighbourhood (the
 * cell and its eight neighbours inside the nx x ny array; nothing beyond its edges
 * counts, so a tile never looks into the next). With h the cells' highest corners (-inf
 * for holes), {out >= z} is {h >= z} dilated by one cell: what turns the EDT's
 * centre distances into footprint gaps (planes.c). out must not overlap h. */
void td_planes_max3x3(const float *h, int32_t nx, int32_t ny, float *out);
void td_planes_free(td_planes *p);

#endif
