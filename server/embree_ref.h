/* embree_ref.h: Embree 3 as the triangle oracle, for the oracle tests and `terrad bench`.
 *
 * Builds one robust, high-quality scene from a grid: a triangle mesh with exactly
 * terrad's split (each cell cut along the diagonal from its south-east corner (i+1, j)
 * to its north-west corner (i, j+1)), void cells left out. With refine = n > 1 each cell
 * becomes n x n sub-quads whose vertices lie on the cell's bilinear patch (same split),
 * an approximation of the bilinear surface within td_embree_refine_bound() metres
 * vertically.
 *
 * Vertices are stored in a local frame centred on the grid (float32 relative to the
 * centre, half the error of the dataset frame); rays are advanced in double to where
 * they enter the grid's bounding box before they are rounded to float, and t is
 * returned in the caller's units (of the caller's, not necessarily unit, direction).
 * A built scene is read-only; tracing is thread-safe. */
#ifndef TD_EMBREE_REF_H
#define TD_EMBREE_REF_H

#include <stddef.h>

#include "trace.h"

typedef struct td_embree td_embree;

/* refine = 1: terrad's triangles; refine = n in 2..64: n x n sub-quads per cell on the
 * bilinear patch. */
td_status td_embree_build(const td_grid *g, int refine, td_embree **out, td_err *err);
void td_embree_free(td_embree *e);

/* Max vertical distance between the refined mesh and the bilinear patches (0 for
 * refine = 1). */
double td_embree_refine_bound(const td_embree *e);

/* Number of triangles in the scene. */
size_t td_embree_triangles(const td_embree *e);

/* First hit t of r in [tmin, tmax] (units of r->d), +inf for a miss. */
double td_embree_trace(const td_embree *e, const td_ray *r);
void td_embree_trace_many(const td_embree *e, const td_ray *r, size_t n, double *t);

#endif
