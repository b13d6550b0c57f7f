/* bench_int.h: results of `terrad bench`, shared by the measuring code (bench.c, and
 * bench_camera.c for the camera views) and the report writer (bench_report.c). Not for
 * other modules. */
#ifndef TD_BENCH_INT_H
#define TD_BENCH_INT_H

#include <stdint.h>
#include <stdio.h>

#include "accel.h"
#include "bench.h"
#include "embree_ref.h"
#include "render.h"

/* The project's shared data (not in CI): the full Trinidad DEM when it is there. */
#define TD_BENCH_SHARED_TRINIDAD TERRAD_SOURCE_DIR "/../shared/data/trinidad/dem.f32"

/* Rows of the effects table (section 5): one change to the standard scene each. */
#define TD_BENCH_EFFECT_LIST(X)                                                \
    X(TD_BENCH_EFFECT_BASE, "none (shading only)")                             \
    X(TD_BENCH_EFFECT_SHADOWS, "shadows")                                      \
    X(TD_BENCH_EFFECT_HAZE, "haze (70 km)")                                    \
    X(TD_BENCH_EFFECT_SKY, "sky")                                              \
    X(TD_BENCH_EFFECT_WATER, "water (2450 m)")                                 \
    X(TD_BENCH_EFFECT_AO, "ambient occlusion (8 rays)")                        \
    X(TD_BENCH_EFFECT_CURVATURE, "curvature (k 0.13)")                         \
    X(TD_BENCH_EFFECT_SAMPLES2, "supersampling 2 x 2")                         \
    X(TD_BENCH_EFFECT_SAMPLES4, "supersampling 4 x 4")                         \
    X(TD_BENCH_EFFECT_LOD, "level of detail")                                  \
    X(TD_BENCH_EFFECT_ALL, "all six effects")

typedef enum td_bench_effect {
#define TD_X_ENUM(e, name) e,
    TD_BENCH_EFFECT_LIST(TD_X_ENUM)
#undef TD_X_ENUM
    TD_BENCH_EFFECT_COUNT
} td_bench_effect;

const char *td_bench_effect_name(int e);

typedef struct bench_trace {
    int done;
    double seconds, rps, mean_steps, p99_steps;
    uint64_t hits;
    double agree; /* triangle surface: share of rays with Embree's hit (same_t) */
} bench_trace;

typedef struct bench_embree {
    int done;
    double build_s;
    int64_t bytes, peak_bytes;
    size_t prims;
    double rps[2];   /* rtcIntersect1, rtcIntersect16 */
    double agree[2]; /* share of rays with terrad's triangle hit */
} bench_embree;

typedef struct bench_err {
    double zmean, zmax;   /* |hit z - bilinear z at the hit's x, y|, metres */
    double nmean, nmax;   /* angle to the bilinear normal there, degrees */
    double moved;         /* rays whose hit is more than a cell diagonal from the
                             bilinear hit, or hit where it misses (or the reverse) */
    double flips;         /* of those, hit <-> miss */
    uint64_t hits;
} bench_err;

/* The views of the camera section (bench_camera.c), one row each in its tables. */
#define TD_BENCH_CAM_LIST(X)                                                   \
    X(TD_BENCH_CAM_LEVEL, "level")                                             \
    X(TD_BENCH_CAM_SUNSET, "grazing sunset")                                   \
    X(TD_BENCH_CAM_ROLLED, "rolled")                                           \
    X(TD_BENCH_CAM_DOWN, "straight down")

typedef enum td_bench_cam {
#define TD_X_ENUM(e, name) e,
    TD_BENCH_CAM_LIST(TD_X_ENUM)
#undef TD_X_ENUM
    TD_BENCH_CAM_COUNT
} td_bench_cam;

const char *td_bench_cam_name(int v);

/* The render configurations the camera section times per surface: every coherence
 * device on; the same with the sun bound kept from an earlier render of the view
 * (td_render_opts.sunlit, as the server keeps it for renders of the same heights and sun,
 * tilestore.h: its build is then not in the shadows stage; TD_BENCH_KEEP_SUN is the
 * bench's own flag, not a TD_RENDER_OFF_ bit); the shadow rays' sun bound off (the
 * occlusion query kept); every device off. A device to measure alone is a row here. */
#define TD_BENCH_KEEP_SUN (1u << 31)
#define TD_BENCH_CONF_LIST(X)                                                  \
    X(TD_BENCH_CONF_ON, "on", 0u)                                              \
    X(TD_BENCH_CONF_KEPT, "on, bound kept", TD_BENCH_KEEP_SUN)                 \
    X(TD_BENCH_CONF_NO_SUNLIT, "no sun bound", TD_RENDER_OFF_SUNLIT)           \
    X(TD_BENCH_CONF_OFF, "off",                                                \
      TD_RENDER_OFF_CAMERA | TD_RENDER_OFF_OCCLUSION | TD_RENDER_OFF_SUNLIT)

typedef enum td_bench_conf {
#define TD_X_ENUM(e, name, off) e,
    TD_BENCH_CONF_LIST(TD_X_ENUM)
#undef TD_X_ENUM
    TD_BENCH_CONF_COUNT
} td_bench_conf;

/* Sections 1-6 time the methods on given rays (td_trace, as `terrad trace`): every method
 * but silhouette, whose partition is built per camera view (on other rays it is the
 * incremental walk); section 7 times it on its camera views (TD_BENCH_COLD_LIST). */
static inline int td_bench_traced(int m) { return m != TD_METHOD_SILHOUETTE; }

/* Camera rays with no preprocessing (issue 13), timed per camera view on the bilinear
 * surface over the grid alone (no max-mipmap, no planes): the walk from each ray's start
 * (camera devices off), the walk with the horizon and beam devices (what `incremental`
 * does, and `auto` did on a cold dataset), and silhouette partitioning (its per-render
 * build counted). Enum, name, method, devices turned off. */
#define TD_BENCH_COLD_LIST(X)                                                  \
    X(TD_BENCH_COLD_WALK, "walk", TD_METHOD_INCREMENTAL, TD_RENDER_OFF_CAMERA) \
    X(TD_BENCH_COLD_HORIZON, "walk + devices", TD_METHOD_INCREMENTAL, 0u)      \
    X(TD_BENCH_COLD_SILH, "silhouette", TD_METHOD_SILHOUETTE, 0u)

typedef enum td_bench_cold {
#define TD_X_ENUM(e, name, m, off) e,
    TD_BENCH_COLD_LIST(TD_X_ENUM)
#undef TD_X_ENUM
    TD_BENCH_COLD_COUNT
} td_bench_cold;

/* One surface of one camera view, per configuration; medians over the runs. */
typedef struct bench_cam_surf {
    uint64_t prim_rays, shadow_rays;  /* rays[PRIMARY], rays[SHADOW] of the render */
    uint64_t coherent;                /* camera rays started from a horizon bound (on) */
    uint64_t hits;                    /* camera rays that hit the terrain */
    double prim_rps[TD_BENCH_CONF_COUNT], prim_steps[TD_BENCH_CONF_COUNT]; /* stage primary:
                                         rays / its time, steps a ray */
    double shadow_rps[TD_BENCH_CONF_COUNT], shadow_steps[TD_BENCH_CONF_COUNT]; /* stage shadows */
    double emb_shadow_rps;            /* rtcOccluded16 on this render's shadow rays */
    double prim_x[TD_BENCH_CONF_COUNT], shadow_x[TD_BENCH_CONF_COUNT]; /* terrad / Embree:
                                         each round's ratio, the median over rounds */
} bench_cam_surf;

typedef struct bench_cam_view {
    int done;
    td_scene_camera cam;
    double sun_az, sun_el;
    double emb_prim_rps;              /* rtcIntersect16 on the camera rays, 4 x 4 tiles */
    uint64_t emb_hits;                /* camera rays Embree's mesh hits */
    bench_cam_surf s[TD_SURFACE_COUNT];
    /* exactness on the triangle surface against Embree (reported, not judged) */
    uint64_t depth_differ[2];         /* depth32f render (horizon on, off) vs Embree's t */
    uint64_t shadow_differ;           /* td_occluded (with the render's sun bound) vs
                                         rtcOccluded16, same shadow rays */
    uint64_t emb_self_differ;         /* rtcOccluded16 vs rtcIntersect16 (a hit) on them */
    /* no preprocessing (TD_BENCH_COLD_LIST): primary stage rays/s and steps a ray */
    double cold_rps[TD_BENCH_COLD_COUNT], cold_steps[TD_BENCH_COLD_COUNT];
    uint64_t silh_entries;            /* the partition's bounds built (silhouette.h) */
    uint64_t silh_differ;             /* silhouette depths that differ from the walk's (bits) */
} bench_cam_view;

typedef struct bench_ds {
    char name[64];
    char path[512];
    int procedural, speed_done;
    td_grid *g;
    td_accel *acc;
    int32_t w, h;
    double sx, sy;
    int64_t voids;
    double cells;
    uint64_t height_bytes, maxmip_bytes, planes_bytes;
    double maxmip_s, planes_s;
    /* rays */
    int nviews, view_w, view_h;
    size_t n;
    td_ray *rays;
    double *t, *tref, *ttri;
    uint32_t *steps;
    /* results */
    bench_trace tr[TD_METHOD_COUNT][TD_SURFACE_COUNT];
    bench_embree em[TD_EMBREE_GEOM_COUNT];
    bench_err err[TD_SURFACE_COUNT];
    bench_cam_view cam[TD_BENCH_CAM_COUNT]; /* the camera section, when it ran */
} bench_ds;

typedef struct bench_k {
    int k;
    double build_s;
    uint64_t bytes;
    bench_trace tr;
} bench_k;

typedef struct bench_render {
    td_surface surface;
    int samples, lod;
    double ms, primary_ms, steps;
    uint64_t rays;
    double rmse, psnr, differ;
    double zmean, zmax; /* from a depth render (samples 1 only) */
} bench_render;

typedef struct bench_pag {
    int done, nviews, step;
    size_t rays_per_view;
    td_scene_camera cam[16];
    double steps[3][16]; /* incremental (= n_pierce), hierarchical, parametric */
    double hits[16];
    double seconds[3];
    uint64_t bytes[3];
} bench_pag;

typedef struct bench_effect {
    int kind;
    double ms;
    td_render_stats stats;
} bench_effect;

typedef struct bench_ctx {
    const td_bench_opts *o;
    int runs, build_runs;
    double t_start, total_s;
    char cpu[256], commit[64], date[64];
    int cores, dirty;
    int lanes; /* the ray packets' width (td_trace_lanes) */
    int nds;
    bench_ds ds[4];
    int nk;
    bench_k k[8];
    int nrender, render_w, render_h, lod_levels;
    uint64_t lod_bytes;
    bench_render render[24];
    bench_pag pag;
    int repro_done;
    double repro_rps, repro_min, repro_max, repro_steps; /* `terrad trace --threads 1` on trinidad's rays */
    int neffect, effects_w, effects_h;
    bench_effect effect[TD_BENCH_EFFECT_COUNT];
    int cam_w, cam_h;        /* image size of the camera section (0: it did not run) */
} bench_ctx;

double td_bench_median(double *v, int n);
void td_bench_view_camera(const td_grid *g, int k, int nviews, td_scene_camera *c);
void td_bench_paglieroni_camera(const td_grid *g, int k, td_scene_camera *c);
double td_bench_trace_loop(const td_view *v, td_method m, td_surface s, const td_ray *r, size_t n,
                           double *t, uint32_t *steps, uint64_t *steps_total, uint64_t *hits_total);
uint64_t td_bench_method_bytes(const bench_ds *d, td_method m);
/* Progress line on stderr (when verbose): fmt takes two strings. */
void td_bench_progress(const bench_ctx *b, const char *fmt, const char *a, const char *c);
/* Rays of camera c at w x h pixels, in 4 x 4 pixel blocks (w, h multiples of 4). */
td_status td_bench_camera_rays(const td_grid *g, const td_scene_camera *c, int w, int h, td_ray *out,
                               td_err *err);

/* The camera section (bench_camera.c) on dataset d (grid and d->acc built): fills
 * d->cam and b->cam_w, b->cam_h. */
td_status td_bench_camera_run(bench_ctx *b, bench_ds *d, td_err *err);
/* Its parts of the report: rows of the targets table, section 7, the summary's table. */
void td_bench_camera_targets(FILE *f, const bench_ctx *b);
void td_bench_camera_write(FILE *f, const bench_ctx *b);
void td_bench_camera_summary(FILE *f, const bench_ctx *b);

/* Writes OUT/accuracy-vs-time.md, OUT/bench-summary.md and OUT/bench/ *.svg. */
td_status td_bench_report(const bench_ctx *b, td_err *err);

#endif
