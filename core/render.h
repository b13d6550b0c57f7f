/* render.h: one scene, one view of the terrain -> an RGBA8 image or a depth buffer,
 * with counts of every ray traced and the time of every stage that ran.
 *
 * Callers: `terrad render` (server/cli_render.c), the HTTP render, tile and pick
 * routes. The view (grid + resident acceleration) is shared read-only; the scene says
 * what to draw. An effect the scene does not ask for traces no ray, runs no pass and
 * allocates nothing; the stats prove it (rays by kind, stage_ran).
 *
 * Stages (one X-macro table, also the names of `stages_ms` and of Server-Timing):
 *   primary    camera rays traced straight
 *   curvature  camera rays that reach far enough for the earth's curvature to move a
 *              pixel, traced bent (see render.c)
 *   water      water plane, Fresnel reflection rays
 *   shadows    one ray per lit hit toward the sun
 *   ao         N hemisphere rays per hit
 *   shade      normals, colour, Lambert + ambient (not for depth formats)
 *   haze       aerial perspective
 *   sky        background gradient and sun disc
 *   resolve    n x n samples -> pixel, 8-bit conversion / depth
 *   encode     PNG or raw encoding (td_render_encode)
 * A stage's time is the sum over threads of the time spent in it, divided by the number
 * of threads: the stages add up to the wall time of the render. */
#ifndef TD_RENDER_H
#define TD_RENDER_H

#include <stdatomic.h>

#include "camera.h"
#include "image.h"
#include "lod.h"
#include "scene.h"
#include "sunlit.h"

#define TD_RAY_KIND_LIST(X)                                                    \
    X(TD_RAY_PRIMARY, "primary")                                               \
    X(TD_RAY_SHADOW, "shadow")                                                 \
    X(TD_RAY_REFLECTION, "reflection")                                         \
    X(TD_RAY_AO, "ao")

/* The stages: enum, name (the `stages_ms` key and the Server-Timing entry; in render.c
 * also the stem of the stage's two functions: stage_<name> runs it on one block,
 * on_<name> says whether the scene needs it), and the floats of per-sample scratch the
 * stage fills for later ones (allocated only when it runs). The block stages run in
 * this order on every block of pixels (16 wide, 16 to 64 tall: render.c); encode runs
 * once on the whole image
 * (td_render_encode). A new stage is a row here and those two functions. */
#define TD_BLOCK_STAGE_LIST(X)                                                 \
    X(TD_STAGE_PRIMARY, primary, 0)                                            \
    X(TD_STAGE_CURVATURE, curvature, 0)                                        \
    X(TD_STAGE_WATER, water, 4)                                                \
    X(TD_STAGE_SHADOWS, shadows, 1)                                            \
    X(TD_STAGE_AO, ao, 1)                                                      \
    X(TD_STAGE_SHADE, shade, 0)                                                \
    X(TD_STAGE_HAZE, haze, 0)                                                  \
    X(TD_STAGE_SKY, sky, 0)                                                    \
    X(TD_STAGE_RESOLVE, resolve, 0)

#define TD_STAGE_LIST(X)                                                       \
    TD_BLOCK_STAGE_LIST(X)                                                     \
    X(TD_STAGE_ENCODE, encode, 0)

typedef enum td_ray_kind {
#define TD_X_ENUM(e, name) e,
    TD_RAY_KIND_LIST(TD_X_ENUM)
#undef TD_X_ENUM
    TD_RAY_KIND_COUNT
} td_ray_kind;

typedef enum td_stage {
#define TD_X_ENUM(e, name, scratch) e,
    TD_STAGE_LIST(TD_X_ENUM)
#undef TD_X_ENUM
    TD_STAGE_COUNT
} td_stage;

/* Where a render's sun bound came from (its stats, `sun_bound`): enum, name */
#define TD_SUN_BOUND_LIST(X)                                                   \
    X(TD_SUN_BOUND_NONE, "none")   /* no shadows, or a sun it cannot bound */  \
    X(TD_SUN_BOUND_BUILT, "built") /* for this render, in the shadows stage */ \
    X(TD_SUN_BOUND_KEPT, "kept")   /* from an earlier render (opts.sunlit) */

typedef enum td_sun_bound {
#define TD_X_ENUM(e, name) e,
    TD_SUN_BOUND_LIST(TD_X_ENUM)
#undef TD_X_ENUM
    TD_SUN_BOUND_COUNT
} td_sun_bound;

const char *td_ray_kind_name(td_ray_kind k);
const char *td_stage_name(td_stage s);
const char *td_sun_bound_name(td_sun_bound b);

typedef struct td_render_stats {
    uint64_t rays[TD_RAY_KIND_COUNT];
    uint64_t steps;            /* tracer steps over all rays */
    uint64_t kind_steps[TD_RAY_KIND_COUNT]; /* the same by kind of ray (primary: with the
                                               horizon bins built for them) */
    uint64_t coherent_rays;    /* camera rays started from a horizon bound (horizon.h), or
                                  from the ray below in their image column (colwalk.h) */
    uint64_t horizon_bins;     /* horizon bins built for them */
    uint64_t silhouette_rays;  /* camera rays started from the silhouette partition */
    uint64_t column_rays;      /* camera rays traced by their image column's walk (colwalk.h) */
    uint64_t silhouette_entries; /* its bounds built (wedges x strips, silhouette.h); also
                                    in steps, as the primary kind's */
    uint64_t hits;             /* camera samples that hit the terrain */
    uint64_t curved_rays;      /* camera rays traced bent */
    uint64_t curved_secondary; /* shadow and reflection rays traced bent */
    uint64_t curve_segments;   /* straight pieces the bent rays were traced as */
    uint64_t method_rays[TD_METHOD_COUNT]; /* camera rays by the method the tracer used
                                              where they ended (what `auto` chose) */
    uint64_t lod_rays[TD_LOD_MAX + 1]; /* camera rays by the level of detail they ended on */
    /* How far the picture is from the exact one: the camera hits' height above or below
     * the bilinear surface of the full grid at their x, y (0 up to rounding for bilinear
     * without level of detail), mean and max over the hits measured. The sum is kept so
     * that partial stats add up (td_render_stats_add); the mean is sum / hits. */
    double height_err_mean_m, height_err_max_m, height_err_sum_m;
    uint64_t height_err_hits;
    int stage_ran[TD_STAGE_COUNT];
    double stage_ms[TD_STAGE_COUNT];
    double total_ms;           /* wall time of td_render */
    int threads;
    td_sun_bound sun_bound;    /* where the shadow rays' sun bound (sunlit.h) came from */
} td_render_stats;

typedef struct td_render_opts {
    int threads;               /* <= 0: one per core */
    const td_image8 *drape;    /* preloaded drape; NULL: loaded from the scene's path */
    uint64_t drape_max_pixels; /* when loading it (0: 64 Mpx) */
    const atomic_int *cancel;  /* polled per block; non-zero -> TD_ECANCELED */
    const td_lod *lod;         /* coarse levels (quality.lod needs them), or NULL */
    unsigned off;              /* coherence devices turned off (TD_RENDER_OFF_*), for
                                  measuring what each one is worth; all on by default */
    td_ray *shadow_rays;       /* NULL, or width * height * samples^2 slots: each sample's
                                  shadow ray, in image order (row-major pixels, then the
                                  pixel's samples), tmax -1 where it has none; for tracing
                                  the same rays with another tracer (benchmark, CLI) */
    /* A sun bound kept across renders (sunlit.h), or NULL to build one per render. Called
     * at most once, with the render's view and the unit direction of the sun its shadow
     * rays take, when they take a bound: *out a bound of td_sunlit_build for the same
     * heights (any view of them) or NULL, valid until td_render returns and not freed by
     * it; *kept non-zero when it was not built for this call. A bound that does not fit
     * (td_sunlit_fits: another sun or grid size) is not used; the render builds its own. */
    td_status (*sunlit)(void *ctx, const td_view *v, const double sun[3], const td_sunlit **out,
                        int *kept, td_err *err);
    void *sunlit_ctx;
} td_render_opts;

#define TD_RENDER_OFF_HORIZON 1u   /* camera rays each traced from their start (no horizon,
                                      no silhouette partition; the beam is OFF_BEAM's) */
#define TD_RENDER_OFF_OCCLUSION 2u /* shadow and AO rays traced for their nearest hit */
#define TD_RENDER_OFF_SUNLIT 4u    /* shadow rays without the sun bound (sunlit.h) */
#define TD_RENDER_OFF_BEAM 8u      /* camera rays the horizon cannot bound: no beam (beam.h) */
#define TD_RENDER_OFF_COLUMNS 16u  /* an upright, level camera's columns not walked as one
                                      (colwalk.h): its rays take the horizon and the fans */
/* camera rays each traced from their start, as a pick traces them */
#define TD_RENDER_OFF_CAMERA (TD_RENDER_OFF_HORIZON | TD_RENDER_OFF_BEAM | TD_RENDER_OFF_COLUMNS)

typedef struct td_render_result {
    int32_t width, height;
    uint8_t *rgba;  /* width*height*4 (format png), rows top to bottom, else NULL */
    float *depth;   /* width*height distance from the camera in metres, +inf = nothing
                       (depth formats), else NULL */
    td_render_stats stats;
} td_render_result;

void td_render_opts_default(td_render_opts *o);

/* Adds part's counts, sums and stage times to sum, ORs the stages that ran, keeps the
 * larger height error and sets sum's mean to its height-error sum over its hits (0
 * without hits). threads and total_ms are left alone. How td_render gathers its
 * threads' stats, in thread order, and how td_render_pick fills its own. */
void td_render_stats_add(td_render_stats *sum, const td_render_stats *part);

/* Renders the scene. On success the caller owns res's buffers (td_render_result_free).
 * An error caused by a scene field names it in err->field (and at the front of the
 * message); the ranges checked are core's column of limit.h. */
td_status td_render(const td_view *v, const td_scene *s, const td_render_opts *o,
                    td_render_result *res, td_err *err);

/* Encodes the result in the scene's format (png, depth16, depth32f) and records the
 * encode stage in res->stats. depth16 stores round(distance / scale) with 65535 for
 * nothing; the scale (metres per unit) goes in a tEXt chunk `depth_scale_m` and in
 * *depth_scale_out (may be NULL). */
td_status td_render_encode(td_render_result *res, const td_scene *s, td_buf *out,
                           double *depth_scale_out, td_err *err);

void td_render_result_free(td_render_result *res);

/* One picked pixel. */
typedef struct td_pick {
    double px, py;    /* as asked */
    int hit;
    double p[3];      /* terrain point, dataset frame */
    double distance;  /* metres from the camera (orthographic: from the top plane) */
    double height_error_m; /* |z - the exact (bilinear) surface at x, y|; NaN at a void */
    int32_t ci, cj;
} td_pick;

/* Traces one camera ray per pixel of s->pick (integers are pixel centres), with the
 * scene's camera, method, surface and curvature, as td_render traces its camera rays
 * (on the full grid: no level of detail); fills out[0 .. s->npick). stats (may be NULL)
 * counts what a render counts for its camera rays (rays, steps, hits, bent rays, height
 * error), but neither methods nor lod_rays. */
td_status td_render_pick(const td_view *v, const td_scene *s, td_pick *out,
                         td_render_stats *stats, td_err *err);

#endif
