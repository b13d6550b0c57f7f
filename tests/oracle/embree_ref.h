/* embree_ref.h: Embree 3 on terrad's height field: the triangle oracle of the tests and
 * the yardstick of `terrad bench`.
 *
 * Builds one robust, high-quality scene from a grid, as a triangle mesh with exactly
 * terrad's split (each cell cut along the diagonal from its south-east corner (i+1, j)
 * to its north-west corner (i, j+1)), void cells left out, or as Embree's GRID geometry
 * over the same samples (same diagonal; holes left out). With refine = n > 1 the mesh
 * has n x n sub-quads per cell whose vertices lie on the cell's bilinear patch, an
 * approximation of the bilinear surface within td_embree_refine_bound() metres.
 *
 * Vertices are stored in a local frame centred on the grid (float32 relative to the
 * centre, half the error of the dataset frame). Rays are prepared in double: advanced to
 * where they enter the grid's bounding box, moved to the local frame and rounded to float
 * with a unit direction; t comes back in the caller's units (of the caller's, not
 * necessarily unit, direction). A built scene is read-only; tracing is thread-safe. */
#ifndef TD_EMBREE_REF_H
#define TD_EMBREE_REF_H

#include <stddef.h>
#include <stdint.h>

#include "trace.h"

#define TD_EMBREE_GEOM_LIST(X)                                                 \
    X(TD_EMBREE_TRIANGLES, "triangle mesh")                                    \
    X(TD_EMBREE_GRID, "GRID geometry")

typedef enum td_embree_geom {
#define TD_X_ENUM(e, name) e,
    TD_EMBREE_GEOM_LIST(TD_X_ENUM)
#undef TD_X_ENUM
    TD_EMBREE_GEOM_COUNT
} td_embree_geom;

const char *td_embree_geom_name(td_embree_geom g);

typedef struct td_embree td_embree;

typedef struct td_embree_opts {
    td_embree_geom geom;
    int refine;  /* 1: terrad's triangles; 2..64: sub-quads on the bilinear patch (mesh only) */
    int threads; /* Embree's build threads; 0: all */
} td_embree_opts;

typedef struct td_embree_stats {
    double build_seconds; /* buffers filled + rtcCommitScene, wall time */
    int64_t bytes;        /* resident after the build, by the device's memory monitor */
    int64_t peak_bytes;   /* highest the monitor saw during the build */
    size_t primitives;    /* triangles, or RTCGrid records */
} td_embree_stats;

/* A ray prepared for Embree (local frame, float, unit direction); valid = 0 when it
 * misses the grid's box. The caller's t = lo + tfar / n. */
typedef struct td_embree_ray {
    float o[3], d[3];
    float tfar;
    int valid;
    double lo, n;
} td_embree_ray;

void td_embree_opts_default(td_embree_opts *o);
td_status td_embree_build_opts(const td_grid *g, const td_embree_opts *o, td_embree **out,
                               td_embree_stats *st, td_err *err);
/* The triangle mesh with refinement `refine` (the oracle's scene). */
td_status td_embree_build(const td_grid *g, int refine, td_embree **out, td_err *err);
/* A robust triangle mesh of any triangles: nv vertices (x, y, z in the dataset frame;
 * a NaN z marks a vertex no triangle uses) and nt triangles (three vertex indices each),
 * in a local frame centred on their box, rays prepared and traced as for a grid's scene.
 * The isometric lattice's Embree oracle (oracle_iso.c). */
td_status td_embree_build_mesh(const double *v, size_t nv, const uint32_t *tri, size_t nt,
                               td_embree **out, td_err *err);
void td_embree_free(td_embree *e);

/* Max vertical distance between the refined mesh and the bilinear patches (0 for
 * refine = 1). */
double td_embree_refine_bound(const td_embree *e);

/* Number of primitives in the scene (triangles or GRID records). */
size_t td_embree_triangles(const td_embree *e);

void td_embree_prepare(const td_embree *e, const td_ray *r, size_t n, td_embree_ray *out);
/* t[k] for every prepared ray (+inf for a miss), one ray per rtcIntersect1 call. */
void td_embree_trace1(const td_embree *e, const td_embree_ray *r, size_t n, double *t);
/* The same with 16-wide packets of consecutive rays (the caller orders them coherently). */
void td_embree_trace16(const td_embree *e, const td_embree_ray *r, size_t n, double *t);

/* Whether each prepared ray meets the mesh in its interval (1) or not (0): rtcOccluded16
 * in 16-wide packets of consecutive rays, as td_embree_trace16 (a ray that misses the
 * grid's box is 0). */
void td_embree_occluded16(const td_embree *e, const td_embree_ray *r, size_t n, uint8_t *occ);

/* First hit t of r in [tmin, tmax] (units of r->d), +inf for a miss. */
double td_embree_trace(const td_embree *e, const td_ray *r);
void td_embree_trace_many(const td_embree *e, const td_ray *r, size_t n, double *t);

#endif
