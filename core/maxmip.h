/* maxmip.h: one tile's max-mipmap (quadtree of maxima) for the hierarchical tracer.
 * Level 0 (one cell) is not stored: the tracer reads the cell's corners anyway. Level L
 * >= 1 holds, per block of 2^L x 2^L cells, the highest corner of any non-hole cell in
 * it (-inf if all are holes), which bounds every surface. */
#ifndef TD_MAXMIP_H
#define TD_MAXMIP_H

#include "trace.h"

struct td_maxmip {
    int levels;          /* stored levels 1 .. levels (block of the top level covers the tile) */
    int32_t dim[17];     /* blocks per side at level L: dim[L] = 2^levels >> L, where 2^levels
                            covers the tile's cells (T, or less for a partial tile) */
    size_t offset[17];   /* offset of level L in `max` */
    float *max;          /* all levels, row-major, south first */
    size_t bytes;
};

td_status td_maxmip_build(const td_grid *g, size_t tile, td_maxmip **out, td_err *err);
void td_maxmip_free(td_maxmip *m);

#endif
