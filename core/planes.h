/* planes.h: one tile's Paglieroni-Petersen parameter planes for the parametric tracer:
 * per cell an apex height z_p and a slope s_p (height per metre) of a cone of empty
 * space that bounds every surface of every cell of the tile (see planes.c for why). */
#ifndef TD_PLANES_H
#define TD_PLANES_H

#include "trace.h"

/* One cell's cone; apex and slope side by side so a step costs one cache miss. */
typedef struct td_cone {
    float zp; /* apex height (rounded up) */
    float sp; /* slope, metres of height per metre of distance (rounded up) */
} td_cone;

struct td_planes {
    int k;          /* slices used */
    int32_t nx, ny; /* cells */
    td_cone *cone;  /* nx*ny, row-major, south first */
    size_t bytes;
};

td_status td_planes_build(const td_grid *g, size_t tile, int k, td_planes **out, td_err *err);
void td_planes_free(td_planes *p);

#endif
