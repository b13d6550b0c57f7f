/* bench_camera.c: section 7 of `terrad bench`, camera views (issue 12): terrad's camera
 * and shadow rays against Embree's rtcIntersect16 and rtcOccluded16 on the same rays,
 * one thread each, with the coherence devices on and off; and that section's parts of
 * the report (a row group of the targets table, section 7, the summary's table).
 *
 * Callers: td_bench_run (bench.c) runs td_bench_camera_run once per real DEM (trinidad,
 * picos, levi) after d->acc is built (max-mipmaps and parameter planes, one thread, as
 * for the speed section); td_bench_report (bench_report.c) calls the three writers.
 *
 * Views (cam_defs): per dataset four cameras, 512 x 512 pixels (32 x 32 with --quick),
 * 70 degrees field of view, inside the grid, around the highest sample of its middle
 * half and looking toward it (every view has relief): level (pitch 0, 300 m above the
 * ground, 15% of the shorter extent from the peak), grazing sunset (pitch -3, 200 m up,
 * 20% away, the sun 3 degrees high and 22 degrees left of the heading: looking toward
 * it), rolled (pitch -10, roll 35, 400 m up) and straight down (pitch -80, so the
 * vanishing point of verticals is inside the image; 10% of the shorter extent up, at
 * least 300 m, 3% from the peak). Over a void the height is taken above the highest
 * sample instead of the ground. Positions in whole metres, headings in tenths of a
 * degree: the report's views table is the exact scene.
 *
 * Timing, per view, in `runs` interleaved rounds, medians over rounds; every timed call
 * warm (an untimed call on the same data just before it; see emb_warm_ms):
 *   for each surface: td_render (one thread, method auto, one sample, PNG, shadows on
 *     with the view's sun) in each configuration of TD_BENCH_CONF_LIST (bench_int.h:
 *     every device on; the sun bound off; every device off); terrad's rate is
 *     rays[kind] / stage_ms[stage] (primary: camera ray setup, horizon bins and tracing;
 *     shadows: the sun bound's build and the shadow rays), steps a ray
 *     kind_steps[kind] / rays[kind]; x Embree is each round's terrad / Embree, the median
 *     over the rounds (paired_x);
 *     then rtcOccluded16 on that surface's shadow rays: td_render_opts.shadow_rays of an
 *     untimed render, the slots with a ray kept in image order, 16 consecutive a packet;
 *   then rtcIntersect16 on the camera rays (td_camera_ray of every pixel centre, which
 *     is what the render traces), ordered in 4 x 4 pixel tiles so each packet is
 *     coherent. Embree's rays are clipped and converted (td_embree_prepare) before its
 *     clock starts: only the tracing calls are timed, Embree's triangle mesh built with
 *     one thread.
 *   then, on the grid alone (no max-mipmap, no planes), the camera rays on the bilinear
 *     surface in each row of TD_BENCH_COLD_LIST (bench_int.h: the walk from each ray's
 *     start, the walk with the horizon and beam, silhouette partitioning with its build):
 *     issue 13's question, what no preprocessing costs; the first round also counts the
 *     silhouette depths that differ from the walk's (reported; the tests judge); the
 *     report also spreads section 1's build times over 1, 10 and 100 frames of `auto`.
 * Exactness (triangle surface, untimed, reported and never judged: the oracle tests
 * judge): a depth32f render (horizon on, and off) against Embree's t on the same rays, a
 * disagreement being a hit against a miss or distances more than 1e-4 of Embree's apart;
 * td_occluded (the query the render makes, with the sun bound the render builds) against
 * rtcOccluded16 on the triangle render's shadow rays; and rtcOccluded16 against
 * rtcIntersect16 on those rays (Embree's two calls on one mesh; a check of
 * td_embree_occluded16).
 *
 * Rejected: timing the render's wall time (shading would dilute both devices' worth);
 * Embree's shadow packets in 4 x 4 tiles (the rays come in image order, 16 consecutive
 * along a row are parallel and neighbours: coherent enough).
 *
 * First measurement (2026-11-29, commit 8e65f194, a 2-core EPYC shared with other work,
 * 5 runs, 259 s for the whole `terrad bench`): with every device on, terrad's camera rays
 * run at 0.20-0.44x rtcIntersect16 (Embree 14-42 M rays/s here) in 1.1-8 steps a ray,
 * shadow rays at 0.20-0.89x rtcOccluded16; 0 of 3.1 M camera rays and 2 of 1.7 M shadow
 * rays differ from Embree, both shadow rays Embree's error (the double reference: miss). */
#include "bench_int.h"
#include "clock.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "camera.h"
#include "sunlit.h"

static const char *const cam_names[] = {
#define TD_X_NAME(e, name) name,
    TD_BENCH_CAM_LIST(TD_X_NAME)
#undef TD_X_NAME
};

const char *td_bench_cam_name(int v)
{
    return v >= 0 && v < TD_BENCH_CAM_COUNT ? cam_names[v] : "unknown";
}

/* Each view's camera, placed around the highest sample of the grid's middle half (the
 * peak, grid_peak; so that every view has relief in it): bearing from the peak to the
 * camera (degrees clockwise from north) and distance as a fraction of the shorter extent
 * (the position then kept 2% of the extent inside the grid), height above the ground there (the larger of agl_m and
 * agl_frac of the shorter extent), pitch, roll; heading toward the peak; the sun's
 * azimuth relative to the heading, its elevation. */
static const struct cam_def {
    double bearing, dist_frac, agl_m, agl_frac, pitch, roll, sun_rel, sun_el;
} cam_defs[TD_BENCH_CAM_COUNT] = {
    {200, 0.15, 300, 0.0, 0, 0, 60, 35},     /* level */
    {100, 0.20, 200, 0.0, -3, 0, -22, 3},    /* grazing sunset, looking toward the sun */
    {320, 0.15, 400, 0.0, -10, 35, 100, 30}, /* rolled */
    {200, 0.03, 300, 0.1, -80, 0, 135, 40},  /* straight down, the peak in the upper half */
};

static const unsigned conf_off[TD_BENCH_CONF_COUNT] = {
#define TD_X_OFF(e, name, off) off,
    TD_BENCH_CONF_LIST(TD_X_OFF)
#undef TD_X_OFF
};

#define DEPTH_REL_TOL 1e-4

/* Timings kept per round: per surface the primary and the shadows stage of each
 * configuration, Embree occluded; then Embree's camera rays. */
#define NCONF TD_BENCH_CONF_COUNT
#define NQ_SURF (2 * NCONF + 1)
#define NQ_COLD0 (TD_SURFACE_COUNT * NQ_SURF + 1) /* then one timing per TD_BENCH_COLD_LIST row */
#define NQ (NQ_COLD0 + TD_BENCH_COLD_COUNT)
#define Q_PRIM(s, k) ((s) * NQ_SURF + (k))
#define Q_SHADOW(s, k) ((s) * NQ_SURF + NCONF + (k))
#define Q_EOCC(s) ((s) * NQ_SURF + 2 * NCONF)
#define Q_EPRIM (TD_SURFACE_COUNT * NQ_SURF)

typedef struct cam_run {
    bench_ctx *b;
    bench_cam_view *v;        /* the view being measured */
    td_view view;             /* grid + every structure (what `auto` sees) */
    td_view cold;             /* the grid alone (no preprocessing) */
    const td_embree *emb;     /* triangle mesh */
    int w, h;
    size_t n;                 /* camera rays, one a pixel */
    td_ray *rays;             /* camera rays in 4 x 4 tiles */
    td_embree_ray *er;        /* the same, prepared for Embree */
    double *t;                /* Embree's t (n) */
    td_ray *slots;            /* td_render_opts.shadow_rays (n slots) */
    td_ray *sh_tri;           /* the triangle render's shadow rays (exactness) */
    size_t nsh[TD_SURFACE_COUNT];
    td_embree_ray *esh[TD_SURFACE_COUNT]; /* each surface's shadow rays, prepared */
    uint8_t *occ;             /* Embree's occluded answers (n) */
    uint64_t prim_rays[TD_SURFACE_COUNT][NCONF], shadow_rays[TD_SURFACE_COUNT][NCONF];
    double *ms;               /* NQ x runs timings */
    td_sunlit **kept;         /* the view's sun bound, kept across its renders (TD_BENCH_KEEP_SUN) */
} cam_run;

/* td_render_opts.sunlit of the renders with TD_BENCH_KEEP_SUN: the view's bound, built
 * by the first such render (an untimed one, cam_capture) and kept for the next, as the
 * server keeps one (td_snapshot_sunlit). */
static td_status keep_sun(void *ctx, const td_view *v, const double sun[3], const td_sunlit **out, int *kept,
                          td_err *err)
{
    td_sunlit **k = ctx;
    td_status rc = TD_OK;
    *kept = td_sunlit_fits(*k, v, sun);
    if (!*kept) {
        td_sunlit_free(*k);
        *k = NULL;
        rc = td_sunlit_build(v, sun, 1, k, err);
    }
    *out = *k;
    return rc;
}

/* ---- measuring -------------------------------------------------------------------- */

/* The position of the highest sample in the middle half of the grid (a quarter of it
 * from each edge, so the views look into the grid; the first of equals; voids skipped). */
static void grid_peak(const td_grid *g, double *x, double *y)
{
    float best = -INFINITY;
    int32_t bi = g->w / 2, bj = g->h / 2;
    for (int32_t j = g->h / 4; j <= g->h - 1 - g->h / 4; j++)
        for (int32_t i = g->w / 4; i <= g->w - 1 - g->w / 4; i++)
            if (td_grid_at(g, i, j) > best) { /* false for NaN */
                best = td_grid_at(g, i, j);
                bi = i;
                bj = j;
            }
    *x = bi * g->sx;
    *y = bj * g->sy;
}

static double clampd(double v, double lo, double hi) { return v < lo ? lo : v > hi ? hi : v; }

static void cam_view_setup(const td_grid *g, int k, bench_cam_view *v)
{
    const struct cam_def *q = &cam_defs[k];
    double ex = (g->w - 1) * g->sx, ey = (g->h - 1) * g->sy, m = fmin(ex, ey), px, py, x, y, ground;
    double a = q->bearing * M_PI / 180.0;
    td_scene_camera *c = &v->cam;
    grid_peak(g, &px, &py);
    x = clampd(px + q->dist_frac * m * sin(a), 0.02 * ex, 0.98 * ex);
    y = clampd(py + q->dist_frac * m * cos(a), 0.02 * ey, 0.98 * ey);
    ground = td_camera_ground(g, x, y);
    memset(c, 0, sizeof *c);
    c->pos_kind = TD_POS_XYZ;
    c->projection = TD_PROJ_PERSPECTIVE;
    /* whole metres and tenths of a degree: the views table prints the exact camera */
    c->x = round(x);
    c->y = round(y);
    c->z = round((isnan(ground) ? (double)g->zmax : ground) + fmax(q->agl_m, q->agl_frac * m));
    c->heading = round(10.0 * fmod(atan2(px - x, py - y) * 180.0 / M_PI + 360.0, 360.0)) / 10.0;
    c->pitch = q->pitch;
    c->roll = q->roll;
    c->fov = 70.0;
    v->sun_az = fmod(c->heading + q->sun_rel + 360.0, 360.0);
    v->sun_el = q->sun_el;
}

/* One render of the view with one thread, method m on view tv (the shadows run in the
 * colour formats only); res is the caller's to free. */
static td_status cam_render_on(const cam_run *c, const td_view *tv, td_method m, td_surface s, td_format fmt,
                               unsigned off, td_ray *slots, td_render_result *res, td_err *err)
{
    td_scene sc;
    td_render_opts ro;
    td_scene_defaults(&sc);
    sc.camera = c->v->cam;
    sc.image.width = c->w;
    sc.image.height = c->h;
    sc.image.format = fmt;
    sc.quality.method = m;
    sc.quality.surface = s;
    sc.quality.samples = 1;
    sc.effects.sun_azimuth = c->v->sun_az;
    sc.effects.sun_elevation = c->v->sun_el;
    sc.effects.shadows = 1;
    td_render_opts_default(&ro);
    ro.threads = 1;
    ro.off = off & ~TD_BENCH_KEEP_SUN;
    ro.shadow_rays = slots;
    if (off & TD_BENCH_KEEP_SUN) {
        ro.sunlit = keep_sun;
        ro.sunlit_ctx = c->kept;
    }
    memset(res, 0, sizeof *res);
    return td_render(tv, &sc, &ro, res, err);
}

/* `auto` with every structure (what sections 1-6 built). */
static td_status cam_render(const cam_run *c, td_surface s, td_format fmt, unsigned off, td_ray *slots,
                            td_render_result *res, td_err *err)
{
    return cam_render_on(c, &c->view, TD_METHOD_AUTO, s, fmt, off, slots, res, err);
}

/* Surface s's shadow rays (an untimed render, every device on), in image order,
 * prepared for Embree; the triangle surface's are also kept for td_occluded. */
static td_status cam_capture(cam_run *c, td_surface s, td_err *err)
{
    td_render_result res;
    size_t k = 0;
    /* (with the bound kept: the first capture builds it, untimed) */
    td_status rc = cam_render(c, s, TD_FORMAT_PNG, TD_BENCH_KEEP_SUN, c->slots, &res, err);
    if (rc)
        goto out;
    for (size_t p = 0; p < c->n; p++)
        if (c->slots[p].tmax >= 0.0)
            c->slots[k++] = c->slots[p]; /* in place: k <= p */
    if (k != res.stats.rays[TD_RAY_SHADOW]) {
        rc = td_err_set(err, TD_EINVAL, "bench: the render kept %zu shadow rays and counted %llu", k,
                        (unsigned long long)res.stats.rays[TD_RAY_SHADOW]);
        goto out;
    }
    c->nsh[s] = k;
    c->esh[s] = malloc((k ? k : 1) * sizeof *c->esh[s]);
    if (!c->esh[s]) {
        rc = td_err_set(err, TD_ENOMEM, "bench: out of memory for %zu shadow rays", k);
        goto out;
    }
    td_embree_prepare(c->emb, c->slots, k, c->esh[s]);
    if (s == TD_SURFACE_TRIANGLE)
        memcpy(c->sh_tri, c->slots, k * sizeof *c->sh_tri);
out:
    td_render_result_free(&res);
    return rc;
}

/* Pixel (row-major index) of the k-th ray in 4 x 4 tile order (w a multiple of 4). */
static size_t tile_pixel(size_t k, int w)
{
    size_t blk = k / 16, in = k % 16, bw = (size_t)w / 4;
    return ((blk / bw) * 4 + in / 4) * (size_t)w + (blk % bw) * 4 + in % 4;
}

/* terrad's distance a against Embree's b: a hit against a miss, or too far apart. */
static int depth_differs(double a, double b)
{
    if (isinf(a) || isinf(b))
        return isinf(a) != isinf(b);
    return fabs(a - b) > DEPTH_REL_TOL * fabs(b);
}

/* The triangle render's shadow rays: td_occluded as the render asks it (with the sun
 * bound built for the rays' direction, the sun's) against rtcOccluded16, and
 * rtcOccluded16 against rtcIntersect16. Overwrites c->t. */
static td_status cam_exact_shadows(cam_run *c, td_err *err)
{
    const size_t n = c->nsh[TD_SURFACE_TRIANGLE];
    const td_embree_ray *er = c->esh[TD_SURFACE_TRIANGLE];
    td_sunlit *lit = NULL;
    td_status rc = n ? td_sunlit_build(&c->view, c->sh_tri[0].d, 0, &lit, err) : TD_OK;
    if (rc)
        goto out;
    td_embree_occluded16(c->emb, er, n, c->occ);
    td_embree_trace16(c->emb, er, n, c->t);
    for (size_t k = 0; k < n; k++) {
        uint32_t steps = 0;
        int ours = td_occluded(&c->view, TD_METHOD_AUTO, TD_SURFACE_TRIANGLE, &c->sh_tri[k], lit, &steps);
        c->v->shadow_differ += ours != c->occ[k];
        c->v->emb_self_differ += c->occ[k] != (c->t[k] < INFINITY);
    }
out:
    td_sunlit_free(lit);
    return rc;
}

/* Exactness on the triangle surface (see the top of the file). */
static td_status cam_exact(cam_run *c, td_err *err)
{
    td_status rc = TD_OK;
    bench_cam_view *v = c->v;
    td_embree_trace16(c->emb, c->er, c->n, c->t);
    for (size_t k = 0; k < c->n; k++)
        v->emb_hits += c->t[k] < INFINITY;
    for (int off = 0; off < 2 && rc == TD_OK; off++) {
        td_render_result res;
        rc = cam_render(c, TD_SURFACE_TRIANGLE, TD_FORMAT_DEPTH32F, off ? TD_RENDER_OFF_CAMERA : 0, NULL, &res,
                        err);
        for (size_t k = 0; k < c->n && rc == TD_OK; k++)
            v->depth_differ[off] += (uint64_t)depth_differs(res.depth[tile_pixel(k, c->w)], c->t[k]);
        td_render_result_free(&res);
    }
    if (rc == TD_OK)
        rc = cam_exact_shadows(c, err);
    return rc;
}

static const struct cold_conf {
    td_method m;
    unsigned off;
} cold_confs[TD_BENCH_COLD_COUNT] = {
#define TD_X_COLD(e, name, m, off) {m, off},
    TD_BENCH_COLD_LIST(TD_X_COLD)
#undef TD_X_COLD
};

/* Camera rays of the view on the grid alone (bilinear, depth32f: no effects), one thread,
 * in configuration k of TD_BENCH_COLD_LIST; res is the caller's to free. */
static td_status cam_cold_render(const cam_run *c, int k, td_render_result *res, td_err *err)
{
    return cam_render_on(c, &c->cold, cold_confs[k].m, TD_SURFACE_BILINEAR, TD_FORMAT_DEPTH32F, cold_confs[k].off,
                         NULL, res, err);
}

/* Every no-preprocessing configuration once (round r): the primary stage's time; in the
 * first round also the steps, the partition's entries and its depths against the walk's
 * (bit for bit: the method's claim, reported here, judged by the oracle tests). */
static td_status cam_cold_round(cam_run *c, int r, td_err *err)
{
    td_status rc = TD_OK;
    td_render_result res[TD_BENCH_COLD_COUNT];
    memset(res, 0, sizeof res);
    for (int k = 0; k < TD_BENCH_COLD_COUNT && rc == TD_OK; k++) {
        rc = cam_cold_render(c, k, &res[k], err);
        if (rc == TD_OK) {
            const td_render_stats *st = &res[k].stats;
            c->ms[(size_t)(NQ_COLD0 + k) * (size_t)c->b->runs + (size_t)r] = st->stage_ms[TD_STAGE_PRIMARY];
            c->v->cold_steps[k] = st->rays[TD_RAY_PRIMARY]
                                      ? (double)st->kind_steps[TD_RAY_PRIMARY] / (double)st->rays[TD_RAY_PRIMARY]
                                      : NAN;
            if (k == TD_BENCH_COLD_SILH)
                c->v->silh_entries = st->silhouette_entries;
        }
    }
    for (size_t p = 0; rc == TD_OK && r == 0 && p < c->n; p++)
        c->v->silh_differ += memcmp(&res[TD_BENCH_COLD_SILH].depth[p], &res[TD_BENCH_COLD_WALK].depth[p],
                                    sizeof(float)) != 0;
    for (int k = 0; k < TD_BENCH_COLD_COUNT; k++)
        td_render_result_free(&res[k]);
    return rc;
}

/* Counts of the first round's renders (the same every round). */
static void cam_counts(cam_run *c, int s, int k, const td_render_stats *st)
{
    bench_cam_surf *o = &c->v->s[s];
    uint64_t pr = st->rays[TD_RAY_PRIMARY], sr = st->rays[TD_RAY_SHADOW];
    c->prim_rays[s][k] = pr;
    c->shadow_rays[s][k] = sr;
    o->prim_steps[k] = pr ? (double)st->kind_steps[TD_RAY_PRIMARY] / (double)pr : NAN;
    o->shadow_steps[k] = sr ? (double)st->kind_steps[TD_RAY_SHADOW] / (double)sr : NAN;
    if (k == TD_BENCH_CONF_ON) {
        o->prim_rays = pr;
        o->shadow_rays = sr;
        o->coherent = st->coherent_rays;
        o->hits = st->hits;
    }
}

static double ms_since(double t0) { return (td_clock_s() - t0) * 1e3; }

/* Embree's call on n prepared rays (occlusion, or the nearest hit), untimed once and then
 * timed: ms of the second call. The first warms the caches and TLB for Embree's BVH, as
 * the renders before a timed render warm terrad's grid and structures; timed cold, after
 * a dozen renders, Embree ran 1.5-4x slower here (trinidad 8-12 against 20-40 M rays/s on
 * the same rays; 2026-12-01), which made terrad look that much faster than it is. */
static double emb_warm_ms(const cam_run *c, const td_embree_ray *r, size_t n, int occlusion)
{
    double t0 = 0;
    for (int pass = 0; pass < 2; pass++) {
        t0 = td_clock_s();
        if (occlusion)
            td_embree_occluded16(c->emb, r, n, c->occ);
        else
            td_embree_trace16(c->emb, r, n, c->t);
    }
    return ms_since(t0);
}

/* Round r: per surface an untimed render (warming terrad's side as emb_warm_ms warms
 * Embree's), that surface in every configuration, Embree on its shadow rays; then Embree
 * on the camera rays; then the grid-only configurations, after an untimed render of the
 * first. */
static td_status cam_round(cam_run *c, int r, td_err *err)
{
    td_status rc = TD_OK;
    const size_t runs = (size_t)c->b->runs, rr = (size_t)r;
    for (int s = 0; s < TD_SURFACE_COUNT && rc == TD_OK; s++) {
        for (int k = -1; k < NCONF && rc == TD_OK; k++) {
            td_render_result res;
            rc = cam_render(c, (td_surface)s, TD_FORMAT_PNG, conf_off[k < 0 ? 0 : k], NULL, &res, err);
            if (rc == TD_OK && k >= 0) {
                c->ms[(size_t)Q_PRIM(s, k) * runs + rr] = res.stats.stage_ms[TD_STAGE_PRIMARY];
                c->ms[(size_t)Q_SHADOW(s, k) * runs + rr] = res.stats.stage_ms[TD_STAGE_SHADOWS];
                if (r == 0)
                    cam_counts(c, s, k, &res.stats);
            }
            td_render_result_free(&res);
        }
        c->ms[(size_t)Q_EOCC(s) * runs + rr] = emb_warm_ms(c, c->esh[s], c->nsh[s], 1);
    }
    c->ms[(size_t)Q_EPRIM * runs + rr] = emb_warm_ms(c, c->er, c->n, 0);
    if (rc == TD_OK) {
        td_render_result warm;
        rc = cam_cold_render(c, 0, &warm, err);
        td_render_result_free(&warm);
    }
    if (rc == TD_OK)
        rc = cam_cold_round(c, r, err);
    return rc;
}

/* rays per second, NaN without rays or time */
static double per_s(uint64_t n, double ms) { return n > 0 && ms > 0 ? (double)n / (ms * 1e-3) : NAN; }

/* a / b, NaN unless both are finite and positive */
static double quot(double a, double b) { return a > 0 && b > 0 && isfinite(a) && isfinite(b) ? a / b : NAN; }

/* terrad's rate over Embree's, each round's (ms ta[r] for na rays against tb[r] for nb),
 * the median over the rounds; NaN unless every round has both. Paired by round, the ratio
 * drops the drift of a shared machine's speed from one round to the next, which the ratio
 * of the two medians keeps. q: room for `runs` doubles. */
static double paired_x(const double *ta, uint64_t na, const double *tb, uint64_t nb, int runs, double *q)
{
    int m = 0;
    for (int r = 0; r < runs; r++) {
        double x = quot(per_s(na, ta[r]), per_s(nb, tb[r]));
        if (!isnan(x))
            q[m++] = x;
    }
    return m == runs && m > 0 ? td_bench_median(q, m) : NAN;
}

/* The medians of the rounds (td_bench_median sorts in place: the paired ratios first) */
static void cam_medians(cam_run *c)
{
    const int runs = c->b->runs;
    bench_cam_view *v = c->v;
    double *q = malloc((size_t)runs * sizeof *q);
    for (int s = 0; s < TD_SURFACE_COUNT; s++) {
        bench_cam_surf *o = &v->s[s];
        for (int k = 0; k < NCONF; k++) {
            o->prim_x[k] = o->shadow_x[k] = NAN;
            if (!q)
                continue; /* out of memory: the report shows "-" */
            o->prim_x[k] = paired_x(c->ms + (size_t)Q_PRIM(s, k) * (size_t)runs, c->prim_rays[s][k],
                                    c->ms + (size_t)Q_EPRIM * (size_t)runs, c->n, runs, q);
            o->shadow_x[k] = paired_x(c->ms + (size_t)Q_SHADOW(s, k) * (size_t)runs, c->shadow_rays[s][k],
                                      c->ms + (size_t)Q_EOCC(s) * (size_t)runs, c->nsh[s], runs, q);
        }
    }
    free(q);
    for (int s = 0; s < TD_SURFACE_COUNT; s++) {
        bench_cam_surf *o = &v->s[s];
        for (int k = 0; k < NCONF; k++) {
            double pm = td_bench_median(c->ms + (size_t)Q_PRIM(s, k) * (size_t)runs, runs);
            double sm = td_bench_median(c->ms + (size_t)Q_SHADOW(s, k) * (size_t)runs, runs);
            o->prim_rps[k] = per_s(c->prim_rays[s][k], pm);
            o->shadow_rps[k] = per_s(c->shadow_rays[s][k], sm);
        }
        o->emb_shadow_rps = per_s(c->nsh[s], td_bench_median(c->ms + (size_t)Q_EOCC(s) * (size_t)runs, runs));
    }
    v->emb_prim_rps = per_s(c->n, td_bench_median(c->ms + (size_t)Q_EPRIM * (size_t)runs, runs));
    for (int k = 0; k < TD_BENCH_COLD_COUNT; k++)
        v->cold_rps[k] = per_s(c->n, td_bench_median(c->ms + (size_t)(NQ_COLD0 + k) * (size_t)runs, runs));
}

static void cam_free_shadows(cam_run *c)
{
    for (int s = 0; s < TD_SURFACE_COUNT; s++) {
        free(c->esh[s]);
        c->esh[s] = NULL;
        c->nsh[s] = 0;
    }
}

/* View k of dataset d: rays, shadow rays, exactness, then the timed rounds. */
static td_status cam_view(cam_run *c, bench_ds *d, int k, td_err *err)
{
    td_status rc;
    bench_cam_view *v = &d->cam[k];
    memset(v, 0, sizeof *v);
    memset(c->prim_rays, 0, sizeof c->prim_rays);
    memset(c->shadow_rays, 0, sizeof c->shadow_rays);
    c->v = v;
    cam_view_setup(d->g, k, v);
    td_bench_progress(c->b, "%s: camera view %s", d->name, td_bench_cam_name(k));
    rc = td_bench_camera_rays(d->g, &v->cam, c->w, c->h, c->rays, err);
    if (rc == TD_OK)
        td_embree_prepare(c->emb, c->rays, c->n, c->er);
    for (int s = 0; s < TD_SURFACE_COUNT && rc == TD_OK; s++)
        rc = cam_capture(c, (td_surface)s, err);
    if (rc == TD_OK)
        rc = cam_exact(c, err);
    for (int r = 0; r < c->b->runs && rc == TD_OK; r++)
        rc = cam_round(c, r, err);
    if (rc == TD_OK) {
        cam_medians(c);
        v->done = 1;
    }
    cam_free_shadows(c);
    td_sunlit_free(*c->kept);
    *c->kept = NULL;
    return rc;
}

static td_status cam_alloc(cam_run *c, td_err *err)
{
    td_status rc = TD_OK;
    c->rays = malloc(c->n * sizeof *c->rays);
    c->er = malloc(c->n * sizeof *c->er);
    c->t = malloc(c->n * sizeof *c->t);
    c->slots = malloc(c->n * sizeof *c->slots);
    c->sh_tri = malloc(c->n * sizeof *c->sh_tri);
    c->occ = malloc(c->n * sizeof *c->occ);
    c->ms = malloc((size_t)NQ * (size_t)c->b->runs * sizeof *c->ms);
    if (!c->rays || !c->er || !c->t || !c->slots || !c->sh_tri || !c->occ || !c->ms)
        rc = td_err_set(err, TD_ENOMEM, "bench: out of memory for %zu camera rays", c->n);
    return rc;
}

static void cam_free(cam_run *c)
{
    cam_free_shadows(c);
    free(c->rays);
    free(c->er);
    free(c->t);
    free(c->slots);
    free(c->sh_tri);
    free(c->occ);
    free(c->ms);
}

td_status td_bench_camera_run(bench_ctx *b, bench_ds *d, td_err *err)
{
    td_status rc;
    cam_run c;
    td_embree *emb = NULL;
    td_embree_opts eo;
    td_sunlit *kept = NULL;
    memset(&c, 0, sizeof c);
    c.b = b;
    c.kept = &kept;
    c.w = c.h = b->o->quick ? 32 : 512;
    c.n = (size_t)c.w * (size_t)c.h;
    c.view.grid = d->g;
    c.view.accel = d->acc->tiles;
    c.cold.grid = d->g;
    c.cold.accel = NULL;
    td_bench_progress(b, "%s: camera views, building Embree's %s", d->name, "triangle mesh (one thread)");
    td_embree_opts_default(&eo);
    eo.threads = 1;
    rc = td_embree_build_opts(d->g, &eo, &emb, NULL, err);
    if (rc == TD_OK)
        rc = cam_alloc(&c, err);
    c.emb = emb;
    for (int k = 0; k < TD_BENCH_CAM_COUNT && rc == TD_OK; k++)
        rc = cam_view(&c, d, k, err);
    if (rc == TD_OK) {
        b->cam_w = c.w;
        b->cam_h = c.h;
    }
    cam_free(&c);
    td_embree_free(emb);
    return rc;
}

/* ---- report ----------------------------------------------------------------------- */

/* Millions of rays a second to 4 significant digits ("-" for none): precise enough that
 * the ratio printed beside it can be checked from the printed numbers. */
static const char *mrate(char *buf, size_t n, double r)
{
    if (r > 0 && isfinite(r))
        snprintf(buf, n, "%.4g", r / 1e6);
    else
        snprintf(buf, n, "-");
    return buf;
}

static const char *fixed(char *buf, size_t n, double v, int prec)
{
    if (isfinite(v))
        snprintf(buf, n, "%.*f", prec, v);
    else
        snprintf(buf, n, "-");
    return buf;
}

/* terrad in configuration k / Embree, for camera (shadow = 0) or shadow rays (paired_x) */
static double cam_ratio(const bench_cam_view *v, int s, int shadow, int k)
{
    const bench_cam_surf *o = &v->s[s];
    return shadow ? o->shadow_x[k] : o->prim_x[k];
}

/* The surface with the highest (best = 1) or lowest ratio in configuration k; NaN if none. */
static double cam_pick(const bench_cam_view *v, int shadow, int best, int k, int *s_out)
{
    double r = NAN;
    for (int s = 0; s < TD_SURFACE_COUNT; s++) {
        double q = cam_ratio(v, s, shadow, k);
        if (!isnan(q) && (isnan(r) || (best ? q > r : q < r))) {
            r = q;
            *s_out = s;
        }
    }
    return r;
}

static void cam_write_views(FILE *f, const bench_ctx *b)
{
    fprintf(f,
            "### The views\n\nEach row is a scene: `{\"dataset\": .., \"camera\": {\"position\": {\"x\": .., "
            "\"y\": .., \"z\": ..}, \"heading\": .., \"pitch\": .., \"roll\": .., \"fov\": 70}, \"image\": "
            "{\"width\": %d, \"height\": %d}, \"quality\": {\"method\": \"auto\", \"surface\": ..}, \"effects\": "
            "{\"sun\": {\"azimuth\": .., \"elevation\": ..}, \"shadows\": true}}`, and `terrad render SCENE -o OUT"
            " --threads 1 --rays R --shadow-rays S` writes the camera and shadow rays timed here (the numbers "
            "below are exact).\n\n| dataset | view | camera x, y, z (m) | heading | pitch | roll | sun azimuth, "
            "elevation | camera rays | hits (triangle) | started from a horizon or beam bound (triangle) "
            "|\n|---|---|---|---|---|---|---|---|---|---|\n", b->cam_w, b->cam_h);
    for (int k = 0; k < b->nds; k++) {
        const bench_ds *d = &b->ds[k];
        for (int q = 0; q < TD_BENCH_CAM_COUNT; q++) {
            const bench_cam_view *v = &d->cam[q];
            const bench_cam_surf *t = &v->s[TD_SURFACE_TRIANGLE];
            if (!v->done)
                continue;
            fprintf(f, "| %s | %s | %.0f, %.0f, %.0f | %.1f | %.0f | %.0f | %.1f, %.0f | %llu | %.1f%% | %.1f%% |\n",
                    d->name, td_bench_cam_name(q), v->cam.x, v->cam.y, v->cam.z, v->cam.heading, v->cam.pitch,
                    v->cam.roll, v->sun_az, v->sun_el, (unsigned long long)t->prim_rays,
                    t->prim_rays ? 100.0 * (double)t->hits / (double)t->prim_rays : 0,
                    t->prim_rays ? 100.0 * (double)t->coherent / (double)t->prim_rays : 0);
        }
    }
    fprintf(f, "\n");
}

/* One row: camera rays with the devices on and off (the sun bound does not touch them),
 * shadow rays in every configuration. */
static void cam_write_row(FILE *f, const bench_ds *d, int q, int s)
{
    enum { ON = TD_BENCH_CONF_ON, KEPT = TD_BENCH_CONF_KEPT, NS = TD_BENCH_CONF_NO_SUNLIT, OFF = TD_BENCH_CONF_OFF };
    const bench_cam_view *v = &d->cam[q];
    const bench_cam_surf *o = &v->s[s];
    char a[8][32], r[6][16], st[5][16];
    fprintf(f, "| %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %llu | %s | %s | %s | %s | %s | %s | %s | %s | %s "
               "| %s | %s | %s |\n",
            d->name, td_bench_cam_name(q), td_surface_name((td_surface)s), mrate(a[0], 32, o->prim_rps[ON]),
            mrate(a[1], 32, o->prim_rps[OFF]), mrate(a[2], 32, v->emb_prim_rps),
            fixed(r[0], 16, cam_ratio(v, s, 0, ON), 2), fixed(r[1], 16, cam_ratio(v, s, 0, OFF), 2),
            fixed(st[0], 16, o->prim_steps[ON], 2), fixed(st[1], 16, o->prim_steps[OFF], 2),
            (unsigned long long)o->shadow_rays, mrate(a[3], 32, o->shadow_rps[ON]), mrate(a[7], 32, o->shadow_rps[KEPT]),
            mrate(a[4], 32, o->shadow_rps[NS]), mrate(a[5], 32, o->shadow_rps[OFF]), mrate(a[6], 32, o->emb_shadow_rps),
            fixed(r[2], 16, cam_ratio(v, s, 1, ON), 2), fixed(r[5], 16, cam_ratio(v, s, 1, KEPT), 2),
            fixed(r[3], 16, cam_ratio(v, s, 1, NS), 2), fixed(r[4], 16, cam_ratio(v, s, 1, OFF), 2),
            fixed(st[2], 16, o->shadow_steps[ON], 2), fixed(st[3], 16, o->shadow_steps[NS], 2),
            fixed(st[4], 16, o->shadow_steps[OFF], 2));
}

static void cam_write_table(FILE *f, const bench_ctx *b)
{
    fprintf(f, "### Camera views: rays per second against Embree, one thread\n\n"
               "M rays/s; *on*: every coherence device on (camera rays: the horizon and beam bounds, and a level camera's "
               "image columns walked as one, colwalk.h; shadow rays: the "
               "occlusion query, the sun bound and the packets of four that walk the rays' first cells and end them "
               "against the bound; the shadows stage includes the bound's build); *kept*: the same with the sun "
               "bound kept from an earlier render of the view (`td_render_opts.sunlit`: what the server does for "
               "renders and map tiles of the same heights and sun, `X-Terrad-Sun-Bound: kept`; the same rays, "
               "steps and answers, the build not in the stage, as Embree's is not in its time); *no sun*: the sun "
               "bound off (`TD_RENDER_OFF_SUNLIT`, and with it the packets), "
               "the occlusion query kept; *off*: every device off; x Embree = terrad / Embree on the same rays, "
               "taken in each round (both sides timed within about a second) and the median over rounds, so it "
               "can differ a little from the ratio of the two medians beside it; "
               "steps per shadow ray count the cells a packet walked, then the one-ray walk's steps.\n\n"
               "| dataset | view | surface | camera M rays/s, on | off | Embree rtcIntersect16 | x Embree, on | "
               "off | steps per camera ray, on | off | shadow rays | shadow M rays/s, on | kept | no sun | off | Embree "
               "rtcOccluded16 | x Embree, on | kept | no sun | off | steps per shadow ray, on | no sun | off |\n"
               "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for (int k = 0; k < b->nds; k++)
        for (int q = 0; q < TD_BENCH_CAM_COUNT; q++)
            for (int s = 0; s < TD_SURFACE_COUNT && b->ds[k].cam[q].done; s++)
                cam_write_row(f, &b->ds[k], q, s);
    fprintf(f, "\n");
}

/* Over every view: camera rays, depth differences (horizon on, off), shadow rays,
 * occluded differences (triangle surface). */
static void cam_totals(const bench_ctx *b, uint64_t tot[5])
{
    memset(tot, 0, 5 * sizeof *tot);
    for (int k = 0; k < b->nds; k++) {
        for (int q = 0; q < TD_BENCH_CAM_COUNT; q++) {
            const bench_cam_view *v = &b->ds[k].cam[q];
            if (!v->done)
                continue;
            tot[0] += v->s[TD_SURFACE_TRIANGLE].prim_rays;
            tot[1] += v->depth_differ[0];
            tot[2] += v->depth_differ[1];
            tot[3] += v->s[TD_SURFACE_TRIANGLE].shadow_rays;
            tot[4] += v->shadow_differ;
        }
    }
}

static void cam_write_exact(FILE *f, const bench_ctx *b)
{
    uint64_t tot[5];
    fprintf(f, "### Exactness against Embree (triangle surface)\n\n"
               "Reported, not judged (the oracle tests judge, with the double-precision reference for "
               "Embree's own errors): camera rays whose depth32f distance and Embree's t are a hit against a "
               "miss or more than %g of the distance apart; shadow rays on which td_occluded (the render's "
               "query, with its sun bound) and rtcOccluded16 disagree; and, as a check of the Embree side, "
               "shadow rays on which rtcOccluded16 and rtcIntersect16 disagree.\n\n"
               "| dataset | view | camera rays | hits, terrad / Embree | depth differs, horizon on | off | shadow "
               "rays | occluded differs | Embree occluded vs intersect |\n|---|---|---|---|---|---|---|---|---|\n",
            DEPTH_REL_TOL);
    for (int k = 0; k < b->nds; k++) {
        for (int q = 0; q < TD_BENCH_CAM_COUNT; q++) {
            const bench_cam_view *v = &b->ds[k].cam[q];
            const bench_cam_surf *t = &v->s[TD_SURFACE_TRIANGLE];
            if (!v->done)
                continue;
            fprintf(f, "| %s | %s | %llu | %llu / %llu | %llu | %llu | %llu | %llu | %llu |\n", b->ds[k].name,
                    td_bench_cam_name(q), (unsigned long long)t->prim_rays, (unsigned long long)t->hits,
                    (unsigned long long)v->emb_hits, (unsigned long long)v->depth_differ[0],
                    (unsigned long long)v->depth_differ[1], (unsigned long long)t->shadow_rays,
                    (unsigned long long)v->shadow_differ, (unsigned long long)v->emb_self_differ);
        }
    }
    cam_totals(b, tot);
    fprintf(f, "\nIn all: %llu of %llu camera rays differ with the horizon on (%llu with it off), %llu of %llu "
               "shadow rays.\n\n", (unsigned long long)tot[1], (unsigned long long)tot[0],
            (unsigned long long)tot[2], (unsigned long long)tot[4], (unsigned long long)tot[3]);
}

/* Issue 13: the camera rays with no preprocessing (TD_BENCH_COLD_LIST). */
static void cam_write_cold(FILE *f, const bench_ctx *b)
{
    fprintf(f, "### Without preprocessing: silhouette partitioning against the walk (issue 13)\n\n"
               "The same views' camera rays on the grid alone (no max-mipmap, no planes: a cold dataset), "
               "bilinear surface, depth32f, one thread, medians of the rounds' primary stage: the walk from each "
               "ray's start (camera devices off), the walk with the horizon and beam devices (their bounds "
               "from samples and tiles' zmax: method `incremental`), and method `silhouette` (its partition "
               "built in the stage, its entries counted as steps). Silhouette depths against the walk's are "
               "compared bit for bit.\n\n"
               "| dataset | view | walk M rays/s | walk + devices | silhouette | silhouette / walk + devices | "
               "steps a ray: walk | walk + devices | silhouette | partition entries | depths differing |\n"
               "|---|---|---|---|---|---|---|---|---|---|---|\n");
    for (int k = 0; k < b->nds; k++) {
        for (int q = 0; q < TD_BENCH_CAM_COUNT; q++) {
            const bench_cam_view *v = &b->ds[k].cam[q];
            char a[3][32], r[16], st[3][16];
            if (!v->done)
                continue;
            fprintf(f, "| %s | %s | %s | %s | %s | %s | %s | %s | %s | %llu | %llu |\n", b->ds[k].name,
                    td_bench_cam_name(q), mrate(a[0], 32, v->cold_rps[TD_BENCH_COLD_WALK]),
                    mrate(a[1], 32, v->cold_rps[TD_BENCH_COLD_HORIZON]),
                    mrate(a[2], 32, v->cold_rps[TD_BENCH_COLD_SILH]),
                    fixed(r, 16, quot(v->cold_rps[TD_BENCH_COLD_SILH], v->cold_rps[TD_BENCH_COLD_HORIZON]), 2),
                    fixed(st[0], 16, v->cold_steps[TD_BENCH_COLD_WALK], 2),
                    fixed(st[1], 16, v->cold_steps[TD_BENCH_COLD_HORIZON], 2),
                    fixed(st[2], 16, v->cold_steps[TD_BENCH_COLD_SILH], 2), (unsigned long long)v->silh_entries,
                    (unsigned long long)v->silh_differ);
        }
    }
    fprintf(f, "\n");
}

/* Milliseconds a frame of n camera rays at r rays a second, plus build_s seconds spread
 * over `frames` frames; NaN without a rate. */
static double frame_ms(size_t n, double r, double build_s, int frames)
{
    return r > 0 && isfinite(r) ? 1e3 * ((double)n / r + build_s / frames) : NAN;
}

/* Issue 13: what no preprocessing saves. A frame's camera rays with silhouette (nothing
 * built) against `auto` (bilinear, every device on) with its structures' build time
 * (whole grid, one thread, section 1's medians) spread over 1, 10 and 100 frames. */
static void cam_write_amortised(FILE *f, const bench_ctx *b)
{
    static const int frames[3] = {1, 10, 100};
    fprintf(f, "### What no preprocessing saves: a frame's camera rays, builds amortised (issue 13)\n\n"
               "Milliseconds of the primary stage a frame (%d x %d rays, bilinear, one thread, the medians "
               "above): silhouette on the grid alone (its partition built every frame) against `auto` with "
               "its structures (the horizon device, hierarchical steps), their build time (the whole grid, "
               "one thread, section 1's medians) spread over 1, 10 and 100 frames: max-mipmaps alone (what "
               "`auto`'s camera rays use), and max-mipmaps and parameter planes (what `auto` builds). "
               "Parametric alone is not timed on camera views.\n\n"
               "| dataset | view | silhouette ms a frame | auto + max-mipmap build, over 1 | 10 | 100 frames "
               "| auto + both builds, over 1 | 10 | 100 frames |\n|---|---|---|---|---|---|---|---|---|\n",
            b->cam_w, b->cam_h);
    for (int k = 0; k < b->nds; k++) {
        const bench_ds *d = &b->ds[k];
        for (int q = 0; q < TD_BENCH_CAM_COUNT; q++) {
            const bench_cam_view *v = &d->cam[q];
            const size_t n = (size_t)b->cam_w * (size_t)b->cam_h;
            const double ra = v->s[TD_SURFACE_BILINEAR].prim_rps[TD_BENCH_CONF_ON];
            char c[7][16];
            if (!v->done)
                continue;
            fprintf(f, "| %s | %s | %s |", d->name, td_bench_cam_name(q),
                    fixed(c[0], 16, frame_ms(n, v->cold_rps[TD_BENCH_COLD_SILH], 0.0, 1), 2));
            for (int both = 0; both < 2; both++)
                for (int fr = 0; fr < 3; fr++)
                    fprintf(f, " %s |", fixed(c[1 + both * 3 + fr], 16,
                                              frame_ms(n, ra, d->maxmip_s + (both ? d->planes_s : 0.0), frames[fr]),
                                              2));
            fprintf(f, "\n");
        }
    }
    fprintf(f, "\n");
}

void td_bench_camera_write(FILE *f, const bench_ctx *b)
{
    if (b->cam_w > 0) {
        fprintf(f, "## 7. Camera views: coherent camera and shadow rays against Embree\n\n");
        fprintf(f,
                "Issue 12's measurement. Per dataset four views at %d x %d pixels, 70 degrees field of view, one "
                "ray per pixel (tables below), one thread on each side, terrad's method `auto` with every "
                "structure built as for section 1, Embree's triangle mesh. Per view and surface, each of %d rounds"
                " renders (`td_render`, PNG, shadows on with the view's sun) with every coherence device on, with "
                "the sun bound off, and with every device off (`TD_RENDER_OFF_CAMERA | TD_RENDER_OFF_OCCLUSION | "
                "TD_RENDER_OFF_SUNLIT`), then Embree traces the same rays: rtcOccluded16 on the render's shadow "
                "rays (`td_render_opts.shadow_rays`, image order, 16 consecutive rays a packet) and, once a round,"
                " rtcIntersect16 on the camera rays (`td_camera_ray` of every pixel centre, as `terrad render "
                "--rays` writes them, in packets of 4 x 4 pixel tiles). terrad's rate is the stage's rays over its"
                " `stages_ms` (primary: ray setup, horizon bins and tracing; shadows: the sun bound's build and "
                "the shadow rays), Embree's the rays over the time of its tracing calls alone (rays clipped to the"
                " grid's box and converted before the clock starts; a ray that misses the box is masked off in its"
                " packet and costs Embree nothing, while terrad's time includes its ray setup). Medians over the "
                "rounds. Shadow rays start on the rendered surface; on the other surfaces than triangle Embree "
                "traces them against its mesh all the same. Targets (issue 12): camera rays at least 3x "
                "rtcIntersect16 and shadow rays at least 3x rtcOccluded16 on every surface, at most 2 steps per "
                "camera ray.\n\n",
                b->cam_w, b->cam_h, b->runs);
        cam_write_views(f, b);
        cam_write_table(f, b);
        cam_write_exact(f, b);
        cam_write_cold(f, b);
        cam_write_amortised(f, b);
    }
}

/* Worst and best ratio of dataset d over its views and surfaces (devices on). */
static void cam_extremes(const bench_ds *d, int shadow, double *lo, int lo_at[2], double *hi, int hi_at[2])
{
    *lo = *hi = NAN;
    for (int q = 0; q < TD_BENCH_CAM_COUNT; q++) {
        int s = 0;
        double r;
        if (!d->cam[q].done)
            continue;
        r = cam_pick(&d->cam[q], shadow, 0, TD_BENCH_CONF_ON, &s);
        if (!isnan(r) && (isnan(*lo) || r < *lo)) {
            *lo = r;
            lo_at[0] = q, lo_at[1] = s;
        }
        r = cam_pick(&d->cam[q], shadow, 1, TD_BENCH_CONF_ON, &s);
        if (!isnan(r) && (isnan(*hi) || r > *hi)) {
            *hi = r;
            hi_at[0] = q, hi_at[1] = s;
        }
    }
}

/* Mean steps per camera ray over d's views and surfaces (devices on), and the most. */
static double cam_steps(const bench_ds *d, double *most, int at[2])
{
    double sum = 0;
    int n = 0;
    *most = NAN;
    for (int q = 0; q < TD_BENCH_CAM_COUNT; q++)
        for (int s = 0; s < TD_SURFACE_COUNT && d->cam[q].done; s++) {
            double st = d->cam[q].s[s].prim_steps[TD_BENCH_CONF_ON];
            if (isnan(st))
                continue;
            sum += st;
            n++;
            if (isnan(*most) || st > *most) {
                *most = st;
                at[0] = q, at[1] = s;
            }
        }
    return n ? sum / n : NAN;
}

void td_bench_camera_targets(FILE *f, const bench_ctx *b)
{
    static const char *const what[2] = {"camera rays >= 3x Embree's rtcIntersect16, camera views, every surface",
                                        "shadow rays >= 3x Embree's rtcOccluded16, camera views, every surface"};
    for (int k = 0; k < b->nds && b->cam_w > 0; k++) {
        const bench_ds *d = &b->ds[k];
        for (int sh = 0; sh < 2; sh++) {
            int lo_at[2] = {0, 0}, hi_at[2] = {0, 0};
            double lo, hi;
            cam_extremes(d, sh, &lo, lo_at, &hi, hi_at);
            if (isnan(lo))
                continue;
            fprintf(f, "| %s | %s | worst %.2fx (%s, %s), best %.2fx (%s, %s) | %s |\n", what[sh], d->name, lo,
                    td_bench_cam_name(lo_at[0]), td_surface_name((td_surface)lo_at[1]), hi,
                    td_bench_cam_name(hi_at[0]), td_surface_name((td_surface)hi_at[1]),
                    lo >= 3 ? "**met**" : "**not met**");
        }
        {
            int at[2] = {0, 0};
            double most, mean = cam_steps(d, &most, at);
            if (!isnan(mean))
                fprintf(f, "| <= 2 steps per camera ray on average, camera views | %s | %.2f over views and "
                           "surfaces (most %.2f: %s, %s) | %s |\n", d->name, mean, most,
                        td_bench_cam_name(at[0]), td_surface_name((td_surface)at[1]),
                        mean <= 2 ? "**met**" : "**not met**");
        }
    }
}

/* The summary's row of one view: the best surface for camera and for shadow rays. */
static void cam_summary_row(FILE *f, const bench_ds *d, int q, int met[4])
{
    const bench_cam_view *v = &d->cam[q];
    int sp = 0, ss = 0, sk = 0;
    double rp = cam_pick(v, 0, 1, TD_BENCH_CONF_ON, &sp), rs = cam_pick(v, 1, 1, TD_BENCH_CONF_ON, &ss);
    double rk = cam_pick(v, 1, 1, TD_BENCH_CONF_KEPT, &sk), st = v->s[sp].prim_steps[TD_BENCH_CONF_ON];
    char a[16], c[16], e[16], g[16];
    fprintf(f, "| %s | %s | %s (%s) | %s (%s) | %s (%s) | %s |\n", d->name, td_bench_cam_name(q),
            fixed(a, sizeof a, rp, 2), td_surface_name((td_surface)sp), fixed(c, sizeof c, rs, 2),
            td_surface_name((td_surface)ss), fixed(g, sizeof g, rk, 2), td_surface_name((td_surface)sk),
            fixed(e, sizeof e, st, 2));
    met[0] += rp >= 3;
    met[1] += rs >= 3;
    met[2] += st <= 2;
    met[3] += rk >= 3;
}

void td_bench_camera_summary(FILE *f, const bench_ctx *b)
{
    int met[4] = {0, 0, 0, 0}, n = 0;
    uint64_t tot[5];
    if (b->cam_w > 0) {
        fprintf(f, "\nCamera views (issue 12; section 7 of the report): %d x %d pixels, 70 degrees, one thread on "
                   "each side, the same rays; terrad with its coherence devices on, on the best surface of each "
                   "view (every surface, and the devices off, in the report).\n\n", b->cam_w, b->cam_h);
        fprintf(f, "| dataset | view | camera rays x rtcIntersect16 (surface) | shadow rays x rtcOccluded16 "
                   "(surface) | the same, sun bound kept (surface) | steps per camera ray (that surface) "
                   "|\n|---|---|---|---|---|---|\n");
        for (int k = 0; k < b->nds; k++)
            for (int q = 0; q < TD_BENCH_CAM_COUNT; q++)
                if (b->ds[k].cam[q].done) {
                    cam_summary_row(f, &b->ds[k], q, met);
                    n++;
                }
        fprintf(f, "\n- Targets (issue 12): camera rays 3x rtcIntersect16 (met in %d of %d views), shadow rays 3x "
                   "rtcOccluded16 (met in %d of %d with the sun bound built per render, %d of %d with it kept from "
                   "an earlier render, as the server keeps it for the same heights and sun), at most 2 steps per "
                   "camera ray (met in %d of %d); each on the view's best surface, where the issue asks for every "
                   "surface.\n",
                met[0], n, met[1], n, met[3], n, met[2], n);
        cam_totals(b, tot);
        fprintf(f, "- Exactness on the triangle surface against Embree (reported, the oracle tests judge): %llu of "
                   "%llu camera rays and %llu of %llu shadow rays disagree.\n", (unsigned long long)tot[1],
                (unsigned long long)tot[0], (unsigned long long)tot[4], (unsigned long long)tot[3]);
    }
}
