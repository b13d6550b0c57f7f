/* lod.h: level of detail for far pixels (Cohen-Or et al. 1996; Qu et al. 2003): a
 * pyramid of coarser grids, each with its own acceleration, traced instead of the full
 * grid where a pixel's footprint covers several cells.
 *
 * Level l (1 .. levels) samples the base grid every 2^l samples (spacing 2^l * sx, 2^l
 * * sy), each value the 1-2-1 weighted mean of the base samples around that point (void
 * where the base sample is void); the last row and column are clamped to the base edge so
 * the coarse grid covers the whole extent. Built levels are immutable.
 *
 * Beside each square level, on demand (td_lod_add_iso), its isometric twin (isogrid.h,
 * square rows: issue 14): the same rows, columns and spacing, odd rows slid half a cell
 * east, every sample the same 1-2-1 mean of the finer level at that point (a node of the
 * finer level, since the spacing doubles), kept as two-byte vertices per tile of 64 x 64
 * (td_iso_pack_lattice; the walk decodes them); quality.lod_grid picks which one far
 * rays are traced on. docs/isometric.md measures both; "square" is the default (why:
 * there), so the twins (about 2.1 bytes a sample with their block maxima, against 4.1
 * as floats) are built only where asked. */
#ifndef TD_LOD_H
#define TD_LOD_H

#include "accel.h"
#include "isogrid.h"

#define TD_LOD_MAX 8
#define TD_LOD_ISO_TILE_LOG2 6 /* the twins' packing tiles: 64 x 64 samples */

#define TD_LOD_GRID_LIST(X)                                                    \
    X(TD_LOD_GRID_SQUARE, "square")                                            \
    X(TD_LOD_GRID_ISOMETRIC, "isometric")

typedef enum td_lod_grid {
#define TD_X_ENUM(e, name) e,
    TD_LOD_GRID_LIST(TD_X_ENUM)
#undef TD_X_ENUM
    TD_LOD_GRID_COUNT
} td_lod_grid;

/* Parse a name; TD_EINVAL (and *out left) for an unknown one. */
td_status td_lod_grid_parse(const char *name, td_lod_grid *out);
const char *td_lod_grid_name(td_lod_grid g);

typedef struct td_lod {
    int levels;                     /* coarse levels built (0 .. TD_LOD_MAX) */
    td_grid *grid[TD_LOD_MAX + 1];  /* [1 .. levels]; [0] unused (the base is the caller's) */
    td_accel *accel[TD_LOD_MAX + 1];
    td_view view[TD_LOD_MAX + 1];   /* [1 .. levels] */
    td_iso *iso[TD_LOD_MAX + 1];    /* [1 .. levels]: the isometric twins (packed), or all NULL */
    uint64_t bytes;                 /* grids, lattices and acceleration */
} td_lod;

/* Builds up to `levels` coarser levels of `base` (fewer if the grid gets too small: a
 * level needs at least 2 x 2 samples), with the acceleration `o` asks for. */
td_status td_lod_build(const td_grid *base, int levels, const td_accel_opts *o, td_lod **out,
                       td_err *err);
void td_lod_free(td_lod *l);

/* Builds the isometric twin of every level of l (built from `base` by td_lod_build), and
 * adds their bytes to l->bytes; call before l is shared. Nothing changes on failure. */
td_status td_lod_add_iso(td_lod *l, const td_grid *base, td_err *err);

/* Traces ray r on level `level` (1 .. levels)'s isometric twin (td_iso_trace); on a hit,
 * ci, cj name the square level's cell under the hit point (what callers that look up a
 * cell, such as smooth normals, expect), not the lattice's triangle. */
void td_lod_iso_trace(const td_lod *l, int level, const td_ray *r, td_hit *hit);

#endif
