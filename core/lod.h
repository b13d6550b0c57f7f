/* lod.h: level of detail for far pixels (Cohen-Or et al. 1996; Qu et al. 2003): a
 * pyramid of coarser grids, each with its own acceleration, traced instead of the full
 * grid where a pixel's footprint covers several cells.
 *
 * Level l (1 .. levels) samples the base grid every 2^l samples (spacing 2^l * sx, 2^l
 * * sy), each value the 1-2-1 weighted mean of the base samples around that point (void
 * where the base sample is void); the last row and column are clamped to the base edge so
 * the coarse grid covers the whole extent. Built levels are immutable. */
#ifndef TD_LOD_H
#define TD_LOD_H

#include "accel.h"

#define TD_LOD_MAX 8

typedef struct td_lod {
    int levels;                     /* coarse levels built (0 .. TD_LOD_MAX) */
    td_grid *grid[TD_LOD_MAX + 1];  /* [1 .. levels]; [0] unused (the base is the caller's) */
    td_accel *accel[TD_LOD_MAX + 1];
    td_view view[TD_LOD_MAX + 1];   /* [1 .. levels] */
    uint64_t bytes;                 /* grids and acceleration */
} td_lod;

/* Builds up to `levels` coarser levels of `base` (fewer if the grid gets too small: a
 * level needs at least 2 x 2 samples), with the acceleration `o` asks for. */
td_status td_lod_build(const td_grid *base, int levels, const td_accel_opts *o, td_lod **out,
                       td_err *err);
void td_lod_free(td_lod *l);

#endif
