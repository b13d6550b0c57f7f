/* vsweep.h: one observer's viewshed by an exact horizon sweep, each sample's answer the
 * one td_occluded gives for its segment (viewshed.h's rule). Called by td_viewshed
 * (viewshed.c) once per observer; the tests hold it to the plain per-sample cast
 * (tests/unit/test_vsweep.c, tests/oracle/viewshed_oracle.c).
 *
 * The idea (vsweep.c has the details). Split the samples around the eye E into four
 * cones (east, west, north, south: |dj| <= di and so on, in cell units). In the east
 * cone, map every point (u, v, z) east of the eye to (m, q) = ((v - Ev) / (u - Eu),
 * (z - Ez) / (u - Eu)): a central projection, so it maps segments to segments. A segment
 * from E to a target T is the set of points with m = m_T and u < u_T, and it meets the
 * surface exactly when some surface point there has q >= q_T. On the linear and
 * triangle surfaces the height along a ray is linear inside each piece of a cell, so q
 * (z over distance) is monotone there and its maximum along a ray is reached where the
 * ray crosses an edge (a sample column, a sample row, the triangle's diagonal). The
 * edges project to segments; their upper envelope over m, swept column by column, is
 * the exact horizon of every ray at once. The bilinear surface lies between its cell's
 * two triangulations: the envelope with the upper one's diagonals bounds it from above,
 * the grid-line crossings (real points) from below.
 *
 * A sample is decided by the envelope only when its q is above the upper bound or below
 * the lower bound by a margin (1e-6 m per cell of distance, far above double rounding in
 * either this code or the tracer); otherwise, and for the samples within two cells of the
 * eye, for the plane surface, and for grids too narrow, its segment is cast with
 * td_occluded, as td_viewshed_cast does. So the answers are the cast's by construction
 * where it is used and by proof elsewhere. */
#ifndef TD_VSWEEP_H
#define TD_VSWEEP_H

#include <stdatomic.h>
#include <stdint.h>

#include "trace.h"

typedef struct td_vsweep_job {
    const td_view *v; /* the observer's view (the lowered grid with curvature) */
    td_surface surface;
    td_method method;           /* for the casts */
    double ex, ey, ez;          /* the eye, dataset frame */
    double ground;              /* the surface under the eye (ez - height) */
    double target_height;
    double maxd2;               /* horizontal distance squared beyond which samples are skipped */
    int threads;                /* the four cones over up to this many threads */
    const atomic_int *cancel;   /* may be NULL */
    int north_first;            /* vis's rows north first (row h-1-j), as td_viewshed's counts */
} td_vsweep_job;

typedef struct td_vsweep_stats {
    uint64_t swept;  /* samples decided by the envelope */
    uint64_t rays;   /* samples cast */
    uint64_t steps;  /* tracer steps of the casts */
    uint64_t blocks; /* strip blocks whose edges were left out whole (vsweep.c block_under) */
    uint64_t facing; /* of them, those under the column's polyline (vsweep.c block_facing) */
    int cancelled;
} td_vsweep_stats;

/* Writes vis[j * w + i] (south-based rows; with north_first vis[(h-1-j) * w + i]) = 1
 * visible, 0 not, for every non-void sample within maxd2 of the eye; other bytes are left
 * as they are. Returns TD_ENOMEM or
 * TD_ECANCELED (err set), else TD_OK. */
td_status td_vsweep(const td_vsweep_job *job, uint8_t *vis, td_vsweep_stats *st, td_err *err);

#endif
