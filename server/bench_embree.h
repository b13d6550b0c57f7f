/* bench_embree.h: Embree 3 as the speed yardstick of `terrad bench`: the same height
 * field as a triangle mesh (terrad's diagonal, void cells left out, as embree_ref.c) or
 * as Embree's GRID geometry, built on a device of its own with a memory monitor, and
 * traced one ray at a time (rtcIntersect1) or 16 at a time (rtcIntersect16).
 *
 * Why a second Embree module beside embree_ref.c: the oracle's scene is opaque (its
 * RTCScene is private), and the benchmark needs the scene for packets, a GRID geometry,
 * a single-threaded build and the device's memory monitor. The triangle layout is the
 * oracle's (refine 1), so both trace the same triangles.
 *
 * Rays are prepared once, outside the timed loop (td_bench_embree_prepare): clipped to
 * the grid's box in double, moved to the scene's local frame (centred on the grid) and
 * rounded to float with a unit direction, which is the form Embree takes natively. The
 * timed loops only copy prepared rays into Embree's structures, intersect and convert
 * tfar back to the caller's t: Embree's best case. */
#ifndef TD_BENCH_EMBREE_H
#define TD_BENCH_EMBREE_H

#include <stddef.h>
#include <stdint.h>

#include "trace.h"

#define TD_BENCH_EMBREE_GEOM_LIST(X)                                           \
    X(TD_BENCH_EMBREE_TRIANGLES, "triangle mesh")                              \
    X(TD_BENCH_EMBREE_GRID, "GRID geometry")

typedef enum td_bench_embree_geom {
#define TD_X_ENUM(e, name) e,
    TD_BENCH_EMBREE_GEOM_LIST(TD_X_ENUM)
#undef TD_X_ENUM
    TD_BENCH_EMBREE_GEOM_COUNT
} td_bench_embree_geom;

const char *td_bench_embree_geom_name(td_bench_embree_geom g);

typedef struct td_bench_embree td_bench_embree;

typedef struct td_bench_embree_stats {
    double build_seconds;  /* buffers filled + rtcCommitScene, wall time */
    int64_t bytes;         /* resident after the build, by the device's memory monitor
                              (BVH and Embree-owned vertex/index/grid buffers) */
    int64_t peak_bytes;    /* highest the monitor saw during the build */
    size_t primitives;     /* triangles, or RTCGrid records */
} td_bench_embree_stats;

/* One prepared ray (local frame, float, unit direction); valid = 0 when the ray misses
 * the grid's box (t stays +inf without calling Embree). */
typedef struct td_bench_eray {
    float o[3], d[3];
    float tfar;
    int valid;
    double lo, n; /* caller t = lo + tfar / n */
} td_bench_eray;

/* Builds the scene with `threads` build threads (Embree's `threads=` device setting). */
td_status td_bench_embree_build(const td_grid *g, td_bench_embree_geom geom, int threads,
                                td_bench_embree **out, td_bench_embree_stats *st, td_err *err);
void td_bench_embree_free(td_bench_embree *e);

void td_bench_embree_prepare(const td_bench_embree *e, const td_ray *r, size_t n,
                             td_bench_eray *out);

/* t[k] for every prepared ray (+inf for a miss), one ray per call. */
void td_bench_embree_trace1(const td_bench_embree *e, const td_bench_eray *r, size_t n, double *t);
/* The same with 16-wide packets of consecutive rays (the caller orders them coherently). */
void td_bench_embree_trace16(const td_bench_embree *e, const td_bench_eray *r, size_t n, double *t);

#endif
