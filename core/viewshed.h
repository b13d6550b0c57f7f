/* viewshed.h: what can be seen from a point (viewshed, cumulative viewshed) and whether
 * two points see each other (line of sight), exactly, on any surface, by the tracers of
 * trace.h. Called by the HTTP service (server/viewshed.c: POST /v1/viewshed, /v1/los) and
 * by `terrad viewshed` (server/cli_viewshed.c); the oracle tests hold it to the
 * double-precision reference.
 *
 * The rule. The observer's eye E stands `height` metres above the surface at (x, y); a
 * target is the point `target_height` metres above the surface at a grid sample (for the
 * `plane` surface the top of the sample's column, the one north-east of it, else the
 * sample's own height). The target is visible when the segment E -> T does not meet the
 * surface strictly between its ends and does not run under it: the ray o = E, d = T - E
 * is searched over t in [TD_LOS_TEPS, 1 - TD_LOS_TEPS] with td_occluded (viewsheds) or
 * td_trace (line of sight), which find where it meets (crosses or touches) the surface,
 * and a segment that starts under the surface there is blocked too
 * (td_viewshed_starts_under: the tracer counts crossings, and an eye on the ground whose
 * segment goes into the hill it stands on and stays under it has none). So:
 *   - touching counts as blocking (as in every tracer: a segment that grazes a ridge
 *     exactly is not a clear line), but the two ends are not looked at: an observer
 *     standing on the ground (height 0) is not blocked by the ground under his feet where
 *     the segment leaves it upwards or along it, a target on the ground not by the ground
 *     it stands on. The gap at each end is 2^-30 of the segment (0.1 mm on 100 km), far
 *     below what float heights resolve;
 *   - the observer's own cell is traced like any other; a sample at horizontal distance 0
 *     (the observer stands exactly on it) is visible;
 *   - a void sample, a plane column with a void corner, and a sample farther than
 *     max_distance (horizontal metres) from every observer are "outside";
 *   - a target on a slope that faces away is hidden when the segment passes under the
 *     slope just before the target (it does, the slope being above the segment there):
 *     the answer of a ray, not of a cell flattened to its centre.
 *
 * Curvature (optional, k the refraction coefficient): the Earth's surface falls away from
 * the observer by c*s^2 at horizontal distance s, c = (1 - k) / (2 R), R = 6371000 m, and
 * a ray bent by refraction (radius R/k) is straight in the frame where every sample is
 * lowered by c*s^2. So with curvature the traces run on a copy of the grid whose samples
 * are lowered by c*s^2 (s from that observer), skipped through the dataset's max-mipmaps
 * (they bound the lowered heights too; planes are built anew for `parametric`): the obstacles
 * along the way are lowered as well as the target, which lowering the target alone would
 * miss. Heights reported by td_los (profile, blocking point) are in the dataset's frame.
 *
 * Output of a viewshed: one byte a sample, in the DEM file's order (row 0 north): the
 * number of observers that see the sample (0 .. nobs), or TD_VS_OUTSIDE. td_viewshed_gray
 * turns a single observer's counts into the 255 / 0 / 128 picture.
 *
 * How: opts.algo, the exact horizon sweep of vsweep.h (default) or one cast a sample;
 * the same bytes. Threads: with the cast, rows of samples go to workers through an atomic
 * counter (as render.c's blocks); with the sweep, the four cones of an observer; every
 * worker traces on the same immutable view. */
#ifndef TD_VIEWSHED_H
#define TD_VIEWSHED_H

#include <stdatomic.h>
#include <stdint.h>

#include "limit.h"
#include "trace.h"

#define TD_VS_OUTSIDE 255       /* void, or beyond max_distance of every observer */
#define TD_VS_MAX_OBSERVERS 254 /* counts must stay below TD_VS_OUTSIDE (limit.h's max) */
#define TD_LOS_TEPS 0x1p-30     /* ends of the segment left out of the search */
#define TD_EARTH_RADIUS_M 6371000.0
#define TD_LOS_PROFILE_MAX 2048 /* points of a line of sight's profile, at most */

/* The ranges of the viewshed and line-of-sight fields, with limit.h's columns (JSON path,
 * min, api_max: the service's largest, max: core's). Kept apart from limit.h, whose table
 * is the scene's fields (its tests walk every row as one). */
#define TD_VS_LIMIT_LIST(X)                                                           \
    X(TD_VS_LIMIT_OBSERVERS, "observers", 1, 64, TD_VS_MAX_OBSERVERS)                 \
    X(TD_VS_LIMIT_HEIGHT, "height", 0, 100000, 100000)                                \
    X(TD_VS_LIMIT_TARGET_HEIGHT, "target_height", 0, 100000, 100000)

typedef enum td_vs_limit {
#define TD_X_ENUM(id, path, min, api_max, max) id,
    TD_VS_LIMIT_LIST(TD_X_ENUM)
#undef TD_X_ENUM
    TD_VS_LIMIT_COUNT
} td_vs_limit;

/* The row of a limit (NULL outside the table). */
const td_limit_row *td_vs_limit_get(td_vs_limit id);

/* How td_viewshed decides: the horizon sweep of vsweep.h (casting the segments it
 * cannot prove), or one cast a sample (the plane surface always casts). Same answers. */
#define TD_VS_ALGO_LIST(X)                                                            \
    X(TD_VS_ALGO_SWEEP, "sweep")                                                      \
    X(TD_VS_ALGO_CAST, "cast")

typedef enum td_vs_algo {
#define TD_X_ENUM(e, name) e,
    TD_VS_ALGO_LIST(TD_X_ENUM)
#undef TD_X_ENUM
    TD_VS_ALGO_COUNT
} td_vs_algo;

const char *td_vs_algo_name(td_vs_algo a);
td_status td_vs_algo_parse(const char *name, td_vs_algo *out);

typedef struct td_vs_point {
    double x, y; /* dataset frame, metres from the south-west sample */
} td_vs_point;

typedef struct td_viewshed_opts {
    const td_vs_point *obs; /* nobs observers */
    int nobs;
    double height;        /* eye above the surface, metres, >= 0 */
    double target_height; /* target above the surface, metres, >= 0 */
    double max_distance;  /* horizontal metres; +inf for none */
    int curvature;        /* lower the terrain by (1-k) s^2 / 2R */
    double k;
    td_surface surface;
    td_method method;
    td_vs_algo algo; /* default sweep */
    int threads; /* <= 0: one per core */
    const atomic_int *cancel; /* may be NULL; raised: TD_ECANCELED */
} td_viewshed_opts;

typedef struct td_viewshed_stats {
    uint64_t samples;  /* w * h */
    uint64_t inside;   /* samples not TD_VS_OUTSIDE */
    uint64_t visible;  /* samples seen by at least one observer */
    uint64_t swept;    /* samples the sweep decided without a cast */
    uint64_t rays;     /* traced segments */
    uint64_t steps;    /* tracer steps over all rays */
    uint64_t blocks;   /* the sweep's strip blocks left out whole (td_vsweep_stats) */
    uint64_t facing;   /* of them, those under the column's polyline (block_facing) */
    double visible_area_m2; /* visible samples * sx * sy */
    double setup_ms, trace_ms; /* curvature grids and maxmips; tracing (wall time) */
    int threads;
} td_viewshed_stats;

void td_viewshed_opts_default(td_viewshed_opts *o);

/* Checks the options against the grid: the observers inside the grid and not on a hole,
 * heights, distance, k, counts. Errors name the request field ("observer",
 * "observers[2]", "height", "target_height", "max_distance", "curvature.k"): a single
 * observer is "observer", one of several "observers[k]". */
td_status td_viewshed_check(const td_grid *g, const td_viewshed_opts *o, td_err *err);

/* Viewshed of o's observers over view v: out holds w * h bytes in file order (row 0
 * north), see above. */
td_status td_viewshed(const td_view *v, const td_viewshed_opts *o, uint8_t *out,
                      td_viewshed_stats *st, td_err *err);

/* A single observer's picture: 255 seen, 0 not, 128 outside (in place is fine). */
void td_viewshed_gray(const uint8_t *counts, size_t n, uint8_t *gray);

/* The segment traced for target sample (i, j) (south-based row) from an eye at
 * (ex, ey, ez) on grid g (the curvature grid when there is one): 0 and the ray, or 1 for
 * a sample at horizontal distance 0 (visible), or -1 for a void target. Exposed so the
 * oracle tests trace exactly the same segments. */
int td_viewshed_ray(const td_grid *g, td_surface s, double ex, double ey, double ez, int32_t i,
                    int32_t j, double target_height, td_ray *r);

/* The segment from the eye (ex, ey, ez) to sample (i, j) cast with td_occluded on view
 * v: 1 visible, 0 not, 2 visible at horizontal distance 0 (not cast), -1 a void target; adds the
 * tracer's steps to *steps. What every sample gets with algo cast. */
int td_viewshed_cast(const td_view *v, td_surface s, td_method m, double ex, double ey, double ez,
                     int32_t i, int32_t j, double target_height, uint32_t *steps);

/* Whether ray r (a viewshed's or line of sight's segment) starts under surface s: at
 * r->tmin, where the tracer starts, the segment is below the surface there (the linear
 * surface: the chord along the ray's line through that cell) by more than 2^-48 of the
 * eye's height (rounding), or within that there and by more than 16 times it at 2^-20
 * of the segment (it leaves the eye into the ground). The tracer counts crossings, so
 * such a segment that stays under the surface all the way to its target (an eye on the
 * ground looking through the hill it stands on) has none; td_viewshed_cast and td_los
 * call it blocked. Never for the plane surface (a solid column: the tracer hits at tmin)
 * nor over a hole. */
int td_viewshed_starts_under(const td_grid *g, td_surface s, const td_ray *r);
/* The segment's height over surface s where the tracer starts it (r->tmin), as
 * td_viewshed_starts_under measures it; NaN for the plane surface or over a hole. The
 * sweep proves an eye on the ground's targets hidden only where this is clearly above 0
 * (the tracer then meets the surface before any point above the segment). */
double td_viewshed_start_gap(const td_grid *g, td_surface s, const td_ray *r);
/* The surface under (x, y) on surface s (NaN on a hole, or outside the grid). */
double td_viewshed_ground(const td_grid *g, td_surface s, double x, double y);

/* Dataset-frame x, y of a lon/lat position (the grid must be lon/lat georeferenced);
 * errors name `field`. */
td_status td_vs_from_lonlat(const td_grid *g, double lon, double lat, const char *field, double *x,
                            double *y, td_err *err);

typedef struct td_los_opts {
    td_vs_point a, b;
    double height_a, height_b; /* above the surface, metres, >= 0 */
    int curvature;
    double k;
    td_surface surface;
    td_method method;
} td_los_opts;

typedef struct td_los_point {
    double s;      /* horizontal metres from a */
    double ground; /* surface height (NaN over a hole) */
    double line;   /* height of the line of sight (curved with curvature) */
} td_los_point;

typedef struct td_los_result {
    int visible;
    double eye_a[3], eye_b[3]; /* the two ends (dataset frame) */
    double block[3];           /* first point where the line meets the surface (if not visible) */
    double block_s, block_dist; /* its horizontal and straight distance from eye a */
    double distance;           /* horizontal distance a -> b */
    int nprofile;
    td_los_point profile[TD_LOS_PROFILE_MAX];
    uint32_t steps;
} td_los_result;

void td_los_opts_default(td_los_opts *o);

/* Line of sight from a to b over view v (errors name "from", "to", "from.height", ...). */
td_status td_los(const td_view *v, const td_los_opts *o, td_los_result *res, td_err *err);

#endif
