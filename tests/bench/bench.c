/* bench.c: the accuracy-vs-time benchmark (see bench.h); the report is written by
 * bench_report.c from the results gathered here.
 *
 * What is measured, and how:
 *   - Rays. Per dataset, `views` oblique pinhole views (camera inside the grid at 40% of
 *     the half extent from the centre, above the highest sample, looking at the centre
 *     25 degrees down, 60 degrees fov; the top row looks about 2 degrees below the
 *     horizon), one ray per pixel, ordered in 4 x 4 pixel blocks so that 16-wide packets
 *     are coherent. Every tracer and Embree trace this one array.
 *   - Tracing loop: exactly `terrad trace`'s worker (td_trace over the array, one thread,
 *     t and steps kept per ray), timed around the loop only; `terrad trace --threads 1
 *     --stats` on the file `--write-rays` writes reproduces a row.
 *   - Every figure is the median of `runs` repetitions; builds are single-threaded for
 *     terrad and Embree alike.
 *   - Error reference: the bilinear surface (see bench_report.c for the reasons), per
 *     ray at the hit point, and per picture against the bilinear 4 x 4 supersampled
 *     render of the same view.
 *   - Camera views (section 7, issue 12): bench_camera.c, on the real DEMs, with the
 *     structures built here.
 * Memory: one dataset's grid and structures at a time, except the small Blanca scene. */
#include "bench.h"
#include "clock.h"
#include "bench_int.h"
#include "cli.h"

#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include <jansson.h>

#include "embree_ref.h"
#include "camera.h"
#include "dem.h"
#include "maxmip.h"
#include "planes.h"
#include "terrain.h"

static const char *const section_names[] = {
#define TD_X_NAME(e, name) name,
    TD_BENCH_SECTION_LIST(TD_X_NAME)
#undef TD_X_NAME
};

const char *td_bench_section_name(td_bench_section s)
{
    return (unsigned)s < TD_BENCH_SECTION_COUNT ? section_names[s] : "unknown";
}

td_status td_bench_section_parse(const char *name, td_bench_section *out)
{
    int k = td_name_index(section_names, TD_BENCH_SECTION_COUNT, name);
    if (k >= 0)
        *out = (td_bench_section)k;
    return k >= 0 ? TD_OK : TD_EINVAL;
}

static int file_exists(const char *p)
{
    struct stat st;
    return stat(p, &st) == 0 && S_ISREG(st.st_mode);
}

void td_bench_opts_default(td_bench_opts *o)
{
    memset(o, 0, sizeof *o);
    o->out_dir = "docs";
    if (file_exists(TD_BENCH_SHARED_TRINIDAD))
        snprintf(o->trinidad, sizeof o->trinidad, "%s", TD_BENCH_SHARED_TRINIDAD);
    else
        snprintf(o->trinidad, sizeof o->trinidad, "%s/tests/data/N37W105.hgt", TERRAD_SOURCE_DIR);
    snprintf(o->picos, sizeof o->picos, "%s/tests/data/picos-dtm.asc", TERRAD_SOURCE_DIR);
    snprintf(o->levi, sizeof o->levi, "%s/data/levi/topography.png", TERRAD_SOURCE_DIR);
    snprintf(o->scene_dem, sizeof o->scene_dem, "%s/data/trinidad/blanca.f32", TERRAD_SOURCE_DIR);
    o->procedural = 4096;
    o->runs = 5;
    o->sections = (1u << TD_BENCH_SECTION_COUNT) - 1;
    o->rays_dataset = "trinidad";
}

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

static int cmp_u32(const void *a, const void *b)
{
    uint32_t x = *(const uint32_t *)a, y = *(const uint32_t *)b;
    return x < y ? -1 : x > y;
}

double td_bench_median(double *v, int n)
{
    double m = NAN;
    if (n > 0) {
        qsort(v, (size_t)n, sizeof *v, cmp_double);
        m = n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
    }
    return m;
}

void td_bench_progress(const bench_ctx *b, const char *fmt, const char *a, const char *c)
{
    if (b->o->verbose) {
        fprintf(stderr, "terrad-bench: [%6.1f s] ", td_clock_s() - b->t_start);
        fprintf(stderr, fmt, a, c);
        fputc('\n', stderr);
    }
}

/* ---- datasets and rays ------------------------------------------------------------ */

static td_status load_dataset(bench_ds *d, const char *name, const char *path, td_err *err)
{
    td_status rc;
    td_dem_opts dopts;
    snprintf(d->name, sizeof d->name, "%s", name);
    snprintf(d->path, sizeof d->path, "%s", path);
    td_dem_opts_default(&dopts);
    rc = td_dem_load(path, &dopts, &d->g, err);
    return rc;
}

static td_status make_procedural(bench_ds *d, int side, td_err *err)
{
    td_terrain_params p;
    td_terrain_params_default(&p);
    p.width = side;
    p.height = side;
    p.spacing = 30.0;
    p.seed = 8;
    snprintf(d->name, sizeof d->name, "procedural");
    snprintf(d->path, sizeof d->path, "td_terrain_generate %d x %d, 30 m, seed 8, defaults", side, side);
    d->procedural = 1;
    return td_terrain_generate(&p, TD_TILE_LOG2_DEFAULT, &d->g, err);
}

/* The k-th oblique view of a dataset (see the top of the file). */
void td_bench_view_camera(const td_grid *g, int k, int nviews, td_scene_camera *c)
{
    double ex = (g->w - 1) * g->sx, ey = (g->h - 1) * g->sy, m = ex < ey ? ex : ey;
    double a = (45.0 + 360.0 * k / nviews) * M_PI / 180.0;
    memset(c, 0, sizeof *c);
    c->pos_kind = TD_POS_XYZ;
    c->projection = TD_PROJ_PERSPECTIVE;
    c->x = 0.5 * ex + 0.4 * 0.5 * m * sin(a);
    c->y = 0.5 * ey + 0.4 * 0.5 * m * cos(a);
    c->z = (double)g->zmax + 0.05 * m;
    c->heading = fmod(45.0 + 360.0 * k / nviews + 180.0, 360.0);
    c->pitch = -25.0;
    c->roll = 0.0;
    c->fov = 60.0;
}

/* Rays of camera `c` at w x h pixels, in 4 x 4 pixel blocks (w, h multiples of 4). */
td_status td_bench_camera_rays(const td_grid *g, const td_scene_camera *c, int w, int h, td_ray *out,
                               td_err *err)
{
    td_camera cam;
    td_status rc = td_camera_setup(c, w, h, g, &cam, err);
    size_t k = 0;
    if (rc == TD_OK)
        for (int by = 0; by < h; by += 4)
            for (int bx = 0; bx < w; bx += 4)
                for (int y = by; y < by + 4; y++)
                    for (int x = bx; x < bx + 4; x++)
                        td_camera_ray(&cam, x, y, &out[k++]);
    return rc;
}

static td_status make_rays(bench_ds *d, int nviews, int w, int h, td_err *err)
{
    td_status rc = TD_OK;
    size_t per = (size_t)w * (size_t)h;
    d->nviews = nviews;
    d->view_w = w;
    d->view_h = h;
    d->n = per * (size_t)nviews;
    d->rays = malloc(d->n * sizeof *d->rays);
    d->t = malloc(d->n * sizeof *d->t);
    d->tref = malloc(d->n * sizeof *d->tref);
    d->steps = malloc(d->n * sizeof *d->steps);
    if (!d->rays || !d->t || !d->steps || !d->tref) {
        rc = td_err_set(err, TD_ENOMEM, "bench: out of memory for %zu rays", d->n);
        goto out;
    }
    for (int k = 0; k < nviews && rc == TD_OK; k++) {
        td_scene_camera c;
        td_bench_view_camera(d->g, k, nviews, &c);
        rc = td_bench_camera_rays(d->g, &c, w, h, d->rays + per * (size_t)k, err);
    }
out:
    return rc;
}

static void free_dataset(bench_ds *d)
{
    td_accel_free(d->acc);
    d->acc = NULL;
    td_grid_free(d->g);
    d->g = NULL;
    free(d->rays);
    free(d->t);
    free(d->tref);
    free(d->steps);
    d->rays = NULL;
    d->t = d->tref = NULL;
    d->steps = NULL;
}

/* ---- tracing ---------------------------------------------------------------------- */

/* `terrad trace`'s loop (cli_trace.c trace_worker), one thread; returns seconds. */
double td_bench_trace_loop(const td_view *v, td_method m, td_surface s, const td_ray *r, size_t n,
                           double *t, uint32_t *steps, uint64_t *steps_total, uint64_t *hits_total)
{
    uint64_t st = 0, hits = 0;
    double t0 = td_clock_s();
    for (size_t k = 0; k < n; k++) {
        td_hit h;
        td_trace(v, m, s, &r[k], &h);
        t[k] = h.t;
        steps[k] = h.steps;
        st += h.steps;
        hits += h.t < INFINITY;
    }
    t0 = td_clock_s() - t0;
    *steps_total = st;
    *hits_total = hits;
    return t0;
}

static double p99(uint32_t *v, size_t n)
{
    double r = 0;
    if (n > 0) {
        qsort(v, n, sizeof *v, cmp_u32);
        size_t k = (size_t)ceil(0.99 * (double)n);
        r = v[k > 0 ? k - 1 : 0];
    }
    return r;
}

/* Same hit: both miss, or both hit within 5 cm plus float rounding of the distance. */
static int same_t(double a, double b)
{
    if (isinf(a) || isinf(b))
        return isinf(a) && isinf(b);
    return fabs(a - b) <= 0.05 + 2e-6 * fabs(b);
}

/* Builds the acceleration with one thread, `runs` times; keeps the last build in d->acc
 * and the median times. */
static td_status build_accel(bench_ctx *b, bench_ds *d, td_err *err)
{
    td_status rc = TD_OK;
    double *mm = calloc((size_t)b->runs, sizeof *mm), *pl = calloc((size_t)b->runs, sizeof *pl);
    td_accel_opts ao;
    td_accel_stats st;
    if (!mm || !pl) {
        rc = td_err_set(err, TD_ENOMEM, "bench: out of memory");
        goto out;
    }
    td_accel_opts_default(&ao);
    ao.threads = 1;
    ao.planes_k = TD_PLANES_K_DEFAULT;
    for (int r = 0; r < b->runs && rc == TD_OK; r++) {
        td_accel_free(d->acc);
        d->acc = NULL;
        ao.maxmip = 1;
        ao.planes = 1;
        rc = td_accel_build(d->g, &ao, &d->acc, &st, err);
        mm[r] = st.maxmip_seconds;
        pl[r] = st.planes_seconds;
    }
    if (rc)
        goto out;
    d->maxmip_s = td_bench_median(mm, b->runs);
    d->planes_s = td_bench_median(pl, b->runs);
    d->maxmip_bytes = st.maxmip_bytes;
    d->planes_bytes = st.planes_bytes;
    d->cells = (double)(d->g->w - 1) * (double)(d->g->h - 1);
    d->height_bytes = td_grid_bytes(d->g->w, d->g->h, d->g->tile_log2);
out:
    free(mm);
    free(pl);
    return rc;
}

/* The view for one method: only the structures the method uses, so `auto` and the
 * others see exactly what `terrad trace` builds for them. */
static void method_view(const bench_ds *d, td_method m, td_tile_accel *tiles, td_view *v)
{
    v->grid = d->g;
    v->accel = NULL;
    if (m != TD_METHOD_INCREMENTAL) {
        for (size_t k = 0; k < d->acc->ntiles; k++) {
            tiles[k].maxmip = m == TD_METHOD_PARAMETRIC ? NULL : d->acc->tiles[k].maxmip;
            tiles[k].planes = m == TD_METHOD_HIERARCHICAL ? NULL : d->acc->tiles[k].planes;
        }
        v->accel = tiles;
    }
}

uint64_t td_bench_method_bytes(const bench_ds *d, td_method m)
{
    uint64_t b = d->height_bytes;
    if (m == TD_METHOD_HIERARCHICAL || m == TD_METHOD_AUTO)
        b += d->maxmip_bytes;
    if (m == TD_METHOD_PARAMETRIC || m == TD_METHOD_AUTO)
        b += d->planes_bytes;
    return b;
}

/* Error of surface s against the bilinear surface, per ray (untimed pass). */
static void surface_error(const bench_ds *d, const td_view *v, td_surface s, bench_err *e)
{
    double zs = 0, ns = 0;
    uint64_t nh = 0, moved = 0, flips = 0;
    double cell = sqrt(d->g->sx * d->g->sx + d->g->sy * d->g->sy);
    memset(e, 0, sizeof *e);
    for (size_t k = 0; k < d->n; k++) {
        td_hit h;
        double z, n[3];
        td_trace(v, TD_METHOD_HIERARCHICAL, s, &d->rays[k], &h);
        if (isinf(h.t) != isinf(d->tref[k]))
            flips++;
        else if (!isinf(h.t) && fabs(h.t - d->tref[k]) > cell)
            moved++;
        if (isinf(h.t) || !td_grid_bilinear_cell(d->g, h.ci, h.cj, h.p[0], h.p[1], &z, n))
            continue;
        double dz = fabs(h.p[2] - z);
        double c = n[0] * h.n[0] + n[1] * h.n[1] + n[2] * h.n[2];
        double ang = acos(c > 1 ? 1 : c < -1 ? -1 : c) * 180.0 / M_PI;
        zs += dz;
        ns += ang;
        e->zmax = fmax(e->zmax, dz);
        e->nmax = fmax(e->nmax, ang);
        nh++;
    }
    e->zmean = nh ? zs / (double)nh : 0;
    e->nmean = nh ? ns / (double)nh : 0;
    e->hits = nh;
    e->moved = d->n ? (double)(moved + flips) / (double)d->n : 0;
    e->flips = d->n ? (double)flips / (double)d->n : 0;
}

/* Builds both Embree scenes (one thread, `build_runs` times each, the last kept). */
static td_status build_embree(bench_ctx *b, bench_ds *d, td_embree **emb, td_err *err)
{
    td_status rc = TD_OK;
    double *bs = malloc((size_t)b->build_runs * sizeof *bs);
    if (!bs) {
        rc = td_err_set(err, TD_ENOMEM, "bench: out of memory");
        goto out;
    }
    for (int gk = 0; gk < TD_EMBREE_GEOM_COUNT && rc == TD_OK; gk++) {
        td_embree_stats st;
        bench_embree *res = &d->em[gk];
        td_bench_progress(b, "%s: building Embree's %s", d->name, td_embree_geom_name((td_embree_geom)gk));
        for (int r = 0; r < b->build_runs && rc == TD_OK; r++) {
            td_embree_free(emb[gk]);
            emb[gk] = NULL;
            td_embree_opts eo;
            td_embree_opts_default(&eo);
            eo.geom = (td_embree_geom)gk;
            eo.threads = 1;
            rc = td_embree_build_opts(d->g, &eo, &emb[gk], &st, err);
            bs[r] = st.build_seconds;
        }
        if (rc == TD_OK) {
            res->build_s = td_bench_median(bs, b->build_runs);
            res->bytes = st.bytes;
            res->peak_bytes = st.peak_bytes;
            res->prims = st.primitives;
        }
    }
out:
    free(bs);
    return rc;
}

static double agreement(const double *t, const double *ref, size_t n)
{
    size_t agree = 0;
    for (size_t k = 0; k < n; k++)
        agree += same_t(t[k], ref[k]);
    return n ? (double)agree / (double)n : 1;
}

/* Section 1 (and the per-ray errors of section 2) for one dataset. The runs are
 * interleaved: each round times every configuration once, so a burst of load from
 * elsewhere on a shared machine hits one round of all of them rather than all runs of
 * one; the median is over rounds. */
#define NTD (TD_METHOD_COUNT * TD_SURFACE_COUNT)
#define NEM (TD_EMBREE_GEOM_COUNT * 2)
static td_status run_speed(bench_ctx *b, bench_ds *d, td_err *err)
{
    td_status rc = TD_OK;
    td_tile_accel *tiles[TD_METHOD_COUNT] = {0};
    td_view views[TD_METHOD_COUNT];
    td_embree *emb[TD_EMBREE_GEOM_COUNT] = {0};
    td_embree_ray *er = NULL;
    double *secs = NULL;
    size_t nconf = NTD + NEM;

    td_bench_progress(b, "%s: building acceleration (%s)", d->name, "one thread");
    rc = build_accel(b, d, err);
    if (rc)
        goto out;
    d->ttri = malloc(d->n * sizeof *d->ttri);
    er = malloc(d->n * sizeof *er);
    secs = malloc(nconf * (size_t)b->runs * sizeof *secs);
    if (!d->ttri || !er || !secs) {
        rc = td_err_set(err, TD_ENOMEM, "bench: out of memory");
        goto out;
    }
    for (int m = 0; m < TD_METHOD_COUNT; m++) {
        tiles[m] = calloc(d->acc->ntiles, sizeof *tiles[m]);
        if (!tiles[m]) {
            rc = td_err_set(err, TD_ENOMEM, "bench: out of memory");
            goto out;
        }
        method_view(d, (td_method)m, tiles[m], &views[m]);
    }
    /* the references of the agreement and error columns */
    for (size_t k = 0; k < d->n; k++) {
        td_hit h;
        td_trace(&views[TD_METHOD_HIERARCHICAL], TD_METHOD_HIERARCHICAL, TD_SURFACE_BILINEAR, &d->rays[k], &h);
        d->tref[k] = h.t;
        td_trace(&views[TD_METHOD_HIERARCHICAL], TD_METHOD_HIERARCHICAL, TD_SURFACE_TRIANGLE, &d->rays[k], &h);
        d->ttri[k] = h.t;
    }
    for (int s = 0; s < TD_SURFACE_COUNT; s++)
        surface_error(d, &views[TD_METHOD_HIERARCHICAL], (td_surface)s, &d->err[s]);
    rc = build_embree(b, d, emb, err);
    if (rc)
        goto out;
    td_embree_prepare(emb[0], d->rays, d->n, er);

    for (int r = 0; r < b->runs; r++) {
        uint64_t wsteps, whits;
        td_bench_progress(b, "%s: tracing, round %s", d->name, r == 0 ? "1" : r == 1 ? "2" : "3+");
        /* every timed loop warm: an untimed one on the same data before the first of each
         * side (Embree's BVH is cold after terrad's loops, terrad's data after Embree's) */
        (void)td_bench_trace_loop(&views[TD_METHOD_HIERARCHICAL], TD_METHOD_HIERARCHICAL, TD_SURFACE_PLANE, d->rays,
                                  d->n, d->t, d->steps, &wsteps, &whits);
        for (int m = 0; m < TD_METHOD_COUNT; m++) {
            for (int s = 0; s < TD_SURFACE_COUNT && td_bench_traced(m); s++) {
                bench_trace *o = &d->tr[m][s];
                uint64_t steps, hits;
                secs[(size_t)(m * TD_SURFACE_COUNT + s) * (size_t)b->runs + (size_t)r] =
                    td_bench_trace_loop(&views[m], (td_method)m, (td_surface)s, d->rays, d->n, d->t,
                                        d->steps, &steps, &hits);
                if (r == 0) {
                    o->mean_steps = d->n ? (double)steps / (double)d->n : 0;
                    o->p99_steps = p99(d->steps, d->n);
                    o->hits = hits;
                    o->agree = s == TD_SURFACE_TRIANGLE ? agreement(d->t, d->ttri, d->n) : 0;
                }
            }
        }
        for (int g = 0; g < TD_EMBREE_GEOM_COUNT; g++) {
            td_embree_trace16(emb[g], er, d->n, d->t); /* warm, untimed */
            for (int w = 0; w < 2; w++) {
                double t0 = td_clock_s();
                if (w == 0)
                    td_embree_trace1(emb[g], er, d->n, d->t);
                else
                    td_embree_trace16(emb[g], er, d->n, d->t);
                secs[(size_t)(NTD + g * 2 + w) * (size_t)b->runs + (size_t)r] = td_clock_s() - t0;
                if (r == 0)
                    d->em[g].agree[w] = agreement(d->t, d->ttri, d->n);
            }
        }
    }
    for (int m = 0; m < TD_METHOD_COUNT; m++)
        for (int s = 0; s < TD_SURFACE_COUNT && td_bench_traced(m); s++) {
            bench_trace *o = &d->tr[m][s];
            o->seconds = td_bench_median(secs + (size_t)(m * TD_SURFACE_COUNT + s) * (size_t)b->runs, b->runs);
            o->rps = o->seconds > 0 ? (double)d->n / o->seconds : 0;
            o->done = 1;
        }
    for (int g = 0; g < TD_EMBREE_GEOM_COUNT; g++) {
        for (int w = 0; w < 2; w++)
            d->em[g].rps[w] = (double)d->n / td_bench_median(secs + (size_t)(NTD + g * 2 + w) * (size_t)b->runs, b->runs);
        d->em[g].done = 1;
    }
out:
    for (int g = 0; g < TD_EMBREE_GEOM_COUNT; g++)
        td_embree_free(emb[g]);
    for (int m = 0; m < TD_METHOD_COUNT; m++)
        free(tiles[m]);
    free(d->ttri);
    d->ttri = NULL;
    free(er);
    free(secs);
    return rc;
}

/* ---- K of the parameter planes ---------------------------------------------------- */

static const int k_list[] = {1, 2, 4, 8, 16, 32, 64};

static td_status run_k(bench_ctx *b, bench_ds *d, td_err *err)
{
    td_status rc = TD_OK;
    int nk = (int)(sizeof k_list / sizeof k_list[0]);
    td_accel *acc[8] = {0};
    double *bs = malloc((size_t)(nk * b->runs) * sizeof *bs);
    double *secs = malloc((size_t)(nk * b->runs) * sizeof *secs);
    if (!bs || !secs) {
        rc = td_err_set(err, TD_ENOMEM, "bench: out of memory");
        goto out;
    }
    /* builds and traces in interleaved rounds; the last round's builds are kept */
    for (int r = 0; r < b->runs && rc == TD_OK; r++) {
        td_bench_progress(b, "K sweep: round %s%s", r == 0 ? "1" : r == 1 ? "2" : "3+", "");
        for (int q = 0; q < nk && rc == TD_OK; q++) {
            td_accel_opts ao;
            td_accel_stats st;
            td_view v;
            uint64_t steps, hits;
            bench_k *res = &b->k[q];
            td_accel_opts_default(&ao);
            ao.threads = 1;
            ao.maxmip = 0;
            ao.planes = 1;
            ao.planes_k = k_list[q];
            td_accel_free(acc[q]);
            acc[q] = NULL;
            rc = td_accel_build(d->g, &ao, &acc[q], &st, err);
            if (rc)
                break;
            bs[q * b->runs + r] = st.planes_seconds;
            res->k = k_list[q];
            res->bytes = st.planes_bytes;
            v.grid = d->g;
            v.accel = acc[q]->tiles;
            secs[q * b->runs + r] = td_bench_trace_loop(&v, TD_METHOD_PARAMETRIC, TD_SURFACE_BILINEAR, d->rays,
                                                        d->n, d->t, d->steps, &steps, &hits);
            if (r == 0) {
                res->tr.mean_steps = d->n ? (double)steps / (double)d->n : 0;
                res->tr.p99_steps = p99(d->steps, d->n);
                res->tr.hits = hits;
            }
        }
    }
    if (rc)
        goto out;
    for (int q = 0; q < nk; q++) {
        bench_k *res = &b->k[q];
        res->build_s = td_bench_median(bs + q * b->runs, b->runs);
        res->tr.seconds = td_bench_median(secs + q * b->runs, b->runs);
        res->tr.rps = res->tr.seconds > 0 ? (double)d->n / res->tr.seconds : 0;
        res->tr.done = 1;
    }
    b->nk = nk;
out:
    for (int q = 0; q < nk; q++)
        td_accel_free(acc[q]);
    free(bs);
    free(secs);
    return rc;
}

/* ---- Paglieroni's Table 1 --------------------------------------------------------- */

void td_bench_paglieroni_camera(const td_grid *g, int k, td_scene_camera *c)
{
    double ex = (g->w - 1) * g->sx, ey = (g->h - 1) * g->sy, m = ex < ey ? ex : ey;
    double az = 22.5 * k, a = (az + 180.0) * M_PI / 180.0;
    memset(c, 0, sizeof *c);
    c->pos_kind = TD_POS_XYZ;
    c->projection = TD_PROJ_PERSPECTIVE;
    c->photogrammetric = 1;
    c->x = 0.5 * ex + 0.3 * m * sin(a);
    c->y = 0.5 * ey + 0.3 * m * cos(a);
    c->z = (double)g->zmax + 2000.0;
    c->azimuth = az;
    c->tilt = 72.0;
    c->swing = 180.0;
    c->focal_mm = 152.4;
    c->pixel_mm = 0.2;
}

static td_status run_paglieroni(bench_ctx *b, bench_ds *d, td_err *err)
{
    td_status rc = TD_OK;
    int step = b->o->quick ? 64 : 16, side = 512 / step, nviews = 16;
    size_t per = (size_t)side * (size_t)side, n = per * (size_t)nviews;
    td_ray *rays = malloc(n * sizeof *rays);
    double *t = malloc(n * sizeof *t), *secs = malloc((size_t)(3 * b->runs) * sizeof *secs);
    uint32_t *steps = malloc(n * sizeof *steps);
    td_tile_accel *tiles = calloc(d->acc->ntiles, sizeof *tiles);
    static const td_method ms[3] = {TD_METHOD_INCREMENTAL, TD_METHOD_HIERARCHICAL, TD_METHOD_PARAMETRIC};

    if (!rays || !t || !steps || !secs || !tiles) {
        rc = td_err_set(err, TD_ENOMEM, "bench: out of memory");
        goto out;
    }
    td_bench_progress(b, "Paglieroni: 16 views of %s%s", d->name, "");
    for (int k = 0; k < nviews && rc == TD_OK; k++) {
        td_scene_camera c;
        td_camera cam;
        td_bench_paglieroni_camera(d->g, k, &c);
        b->pag.cam[k] = c;
        rc = td_camera_setup(&c, 512, 512, d->g, &cam, err);
        for (int y = 0; y < side && rc == TD_OK; y++)
            for (int x = 0; x < side; x++)
                td_camera_ray(&cam, x * step + step / 2, y * step + step / 2,
                              &rays[per * (size_t)k + (size_t)y * (size_t)side + (size_t)x]);
    }
    if (rc)
        goto out;
    b->pag.rays_per_view = per;
    b->pag.step = step;
    for (int q = 0; q < 3; q++) {
        td_view v;
        uint64_t st, hits;
        method_view(d, ms[q], tiles, &v);
        for (int k = 0; k < nviews; k++) {
            td_bench_trace_loop(&v, ms[q], TD_SURFACE_BILINEAR, rays + per * (size_t)k, per, t,
                                steps, &st, &hits);
            b->pag.steps[q][k] = (double)st / (double)per;
            if (q == 0)
                b->pag.hits[k] = (double)hits / (double)per;
        }
        b->pag.bytes[q] = td_bench_method_bytes(d, ms[q]);
    }
    for (int r = 0; r < b->runs; r++) {
        for (int q = 0; q < 3; q++) {
            td_view v;
            uint64_t st, hits;
            method_view(d, ms[q], tiles, &v);
            secs[q * b->runs + r] = td_bench_trace_loop(&v, ms[q], TD_SURFACE_BILINEAR, rays, n, t, steps, &st, &hits);
        }
    }
    for (int q = 0; q < 3; q++)
        b->pag.seconds[q] = td_bench_median(secs + q * b->runs, b->runs);
    b->pag.nviews = nviews;
    b->pag.done = 1;
out:
    free(rays);
    free(t);
    free(steps);
    free(secs);
    free(tiles);
    return rc;
}

/* ---- renders: surfaces, samples, level of detail; effects ------------------------- */

/* One render with one thread; returns its wall time in ms (NaN on failure). */
static double render_once(const td_view *v, const td_scene *s, const td_lod *lod, td_render_result *res,
                          td_status *rcp, td_err *err)
{
    td_render_opts ro;
    td_render_opts_default(&ro);
    ro.threads = 1;
    ro.lod = lod;
    memset(res, 0, sizeof *res);
    *rcp = td_render(v, s, &ro, res, err);
    return *rcp == TD_OK ? res->stats.total_ms : NAN;
}

static void compare_images(const uint8_t *a, const uint8_t *ref, size_t npix, bench_render *r)
{
    double se = 0;
    size_t differ = 0;
    for (size_t k = 0; k < npix; k++) {
        int d = 0;
        for (int c = 0; c < 3; c++) {
            int e = (int)a[4 * k + c] - (int)ref[4 * k + c];
            se += (double)e * e;
            d |= e > 2 || e < -2;
        }
        differ += (size_t)d;
    }
    r->rmse = sqrt(se / (3.0 * (double)npix));
    r->psnr = r->rmse > 0 ? 20.0 * log10(255.0 / r->rmse) : INFINITY;
    r->differ = npix ? (double)differ / (double)npix : 0;
}

/* Hit height error of a depth render against the bilinear surface below each hit. */
static void depth_error(const td_grid *g, const td_scene *s, const float *depth, bench_render *r)
{
    td_camera cam;
    double sum = 0, mx = 0;
    uint64_t n = 0;
    if (td_camera_setup(&s->camera, s->image.width, s->image.height, g, &cam, NULL) == TD_OK) {
        for (int y = 0; y < s->image.height; y++) {
            for (int x = 0; x < s->image.width; x++) {
                double dd = depth[(size_t)y * (size_t)s->image.width + (size_t)x], z;
                td_ray ray;
                if (!isfinite(dd))
                    continue;
                td_camera_ray(&cam, x, y, &ray);
                z = td_camera_ground(g, ray.o[0] + dd * ray.d[0], ray.o[1] + dd * ray.d[1]);
                if (isnan(z))
                    continue;
                z = fabs(ray.o[2] + dd * ray.d[2] - z);
                sum += z;
                mx = fmax(mx, z);
                n++;
            }
        }
    }
    r->zmean = n ? sum / (double)n : NAN;
    r->zmax = n ? mx : NAN;
}

static td_status run_renders(bench_ctx *b, bench_ds *d, td_err *err)
{
    td_status rc = TD_OK;
    td_scene s;
    td_view v;
    td_lod *lod = NULL;
    td_accel_opts ao;
    td_render_result ref, res;
    double *ms = NULL;
    int w = b->o->quick ? 64 : 256, h = b->o->quick ? 48 : 192;
    static const int samples[3] = {1, 2, 4};

    memset(&ref, 0, sizeof ref);
    memset(&res, 0, sizeof res);
    td_accel_opts_default(&ao);
    ao.threads = 1;
    rc = td_lod_build(d->g, 4, &ao, &lod, err);
    if (rc)
        goto out;
    b->lod_bytes = lod->bytes;
    b->lod_levels = lod->levels;
    v.grid = d->g;
    v.accel = d->acc->tiles;
    td_scene_defaults(&s);
    td_bench_view_camera(d->g, 0, d->nviews, &s.camera);
    s.image.width = w;
    s.image.height = h;
    s.quality.method = TD_METHOD_AUTO;
    s.quality.surface = TD_SURFACE_BILINEAR;
    s.quality.samples = 4;
    /* sky on, as in the service's views: a ray that misses gets the sky's colour, so a
       surface that misses where the reference hits (or the reverse) counts in the image
       error by colour (without sky a miss is transparent black, alpha 0) */
    s.effects.sky = 1;
    td_bench_progress(b, "%s: reference render (bilinear, 4 x 4 samples)%s", d->name, "");
    render_once(&v, &s, NULL, &ref, &rc, err);
    if (rc)
        goto out;
    ms = malloc((size_t)(48 * b->runs) * sizeof *ms);
    if (!ms) {
        rc = td_err_set(err, TD_ENOMEM, "bench: out of memory");
        goto out;
    }
    b->nrender = 24;
    for (int r = 0; r < b->runs && rc == TD_OK; r++) {
        td_bench_progress(b, "%s: renders, round %s", d->name, r == 0 ? "1" : r == 1 ? "2" : "3+");
        for (int k = 0; k < 24 && rc == TD_OK; k++) {
            bench_render *o = &b->render[k];
            int lo = k / 12, sf = (k / 3) % 4, q = k % 3;
            s.quality.surface = (td_surface)sf;
            s.quality.samples = samples[q];
            s.quality.lod = lo;
            s.image.format = TD_FORMAT_PNG;
            ms[k * b->runs + r] = render_once(&v, &s, lo ? lod : NULL, &res, &rc, err);
            if (rc)
                break;
            ms[(24 + k) * b->runs + r] = res.stats.stage_ms[TD_STAGE_PRIMARY];
            if (r == 0) {
                o->surface = (td_surface)sf;
                o->samples = samples[q];
                o->lod = lo;
                o->rays = res.stats.rays[TD_RAY_PRIMARY];
                o->steps = o->rays ? (double)res.stats.steps / (double)o->rays : 0;
                compare_images(res.rgba, ref.rgba, (size_t)w * (size_t)h, o);
                o->zmean = o->zmax = NAN;
            }
            td_render_result_free(&res);
            memset(&res, 0, sizeof res);
            if (r == 0 && samples[q] == 1) {
                s.image.format = TD_FORMAT_DEPTH32F;
                render_once(&v, &s, lo ? lod : NULL, &res, &rc, err);
                if (rc == TD_OK)
                    depth_error(d->g, &s, res.depth, o);
                td_render_result_free(&res);
                memset(&res, 0, sizeof res);
            }
        }
    }
    if (rc)
        goto out;
    for (int k = 0; k < 24; k++) {
        b->render[k].ms = td_bench_median(ms + k * b->runs, b->runs);
        b->render[k].primary_ms = td_bench_median(ms + (24 + k) * b->runs, b->runs);
    }
    b->render_w = w;
    b->render_h = h;
out:
    td_render_result_free(&ref);
    td_render_result_free(&res);
    td_lod_free(lod);
    free(ms);
    return rc;
}

/* The standard scene (docs/gallery/trinidad-blanca-north.json without its effects,
 * one sample) and one effect at a time. */
static td_status run_effects(bench_ctx *b, td_err *err)
{
    td_status rc = TD_OK;
    td_grid *g = NULL;
    td_accel *acc = NULL;
    td_lod *lod = NULL;
    td_accel_opts ao;
    td_accel_stats ast;
    td_dem_opts dopts;
    td_view v;
    td_render_result res;
    td_scene base, *scenes = calloc(TD_BENCH_EFFECT_COUNT, sizeof *scenes);
    double *ms = malloc((size_t)TD_BENCH_EFFECT_COUNT * (TD_STAGE_COUNT + 1) * (size_t)b->runs * sizeof *ms);

    memset(&res, 0, sizeof res);
    if (!scenes || !ms) {
        rc = td_err_set(err, TD_ENOMEM, "bench: out of memory");
        goto out;
    }
    td_dem_opts_default(&dopts);
    rc = td_dem_load(b->o->scene_dem, &dopts, &g, err);
    if (rc)
        goto out;
    td_accel_opts_default(&ao);
    ao.threads = 1;
    rc = td_accel_build(g, &ao, &acc, &ast, err);
    if (rc == TD_OK)
        rc = td_lod_build(g, 4, &ao, &lod, err);
    if (rc)
        goto out;
    v.grid = g;
    v.accel = acc->tiles;
    td_scene_defaults(&base);
    if (g->geo.kind == TD_GEO_LONLAT) {
        base.camera.pos_kind = TD_POS_LONLAT_ALT;
        base.camera.lon = -105.50;
        base.camera.lat = 37.56;
        base.camera.alt = 4700;
        base.camera.heading = 5;
        base.camera.pitch = -9;
        base.camera.fov = 65;
    } else {
        td_bench_view_camera(g, 0, 4, &base.camera);
    }
    base.image.width = b->o->quick ? 96 : 640;
    base.image.height = b->o->quick ? 60 : 400;
    base.quality.method = TD_METHOD_AUTO;
    base.quality.surface = TD_SURFACE_BILINEAR;
    base.quality.samples = 1;
    base.quality.smooth_normals = 1;
    base.effects.sun_azimuth = 135;
    base.effects.sun_elevation = 30;
    b->effects_w = base.image.width;
    b->effects_h = base.image.height;
    b->neffect = 0;
    for (int k = 0; k < TD_BENCH_EFFECT_COUNT; k++) {
        td_scene *s = &scenes[k];
        *s = base;
        switch (k) {
        case TD_BENCH_EFFECT_SHADOWS: s->effects.shadows = 1; break;
        case TD_BENCH_EFFECT_HAZE: s->effects.haze = 1; s->effects.haze_visibility_km = 70; break;
        case TD_BENCH_EFFECT_SKY: s->effects.sky = 1; break;
        case TD_BENCH_EFFECT_WATER: s->effects.water = 1; s->effects.water_level = 2450; break;
        case TD_BENCH_EFFECT_AO: s->effects.ambient_occlusion = 8; break;
        case TD_BENCH_EFFECT_CURVATURE: s->effects.curvature = 1; s->effects.curvature_k = 0.13; break;
        case TD_BENCH_EFFECT_SAMPLES2: s->quality.samples = 2; break;
        case TD_BENCH_EFFECT_SAMPLES4: s->quality.samples = 4; break;
        case TD_BENCH_EFFECT_LOD: s->quality.lod = 1; s->quality.lod_pixels = 1; break;
        case TD_BENCH_EFFECT_ALL:
            s->effects.shadows = s->effects.haze = s->effects.sky = s->effects.water = 1;
            s->effects.haze_visibility_km = 70;
            s->effects.water_level = 2450;
            s->effects.ambient_occlusion = 8;
            s->effects.curvature = 1;
            s->effects.curvature_k = 0.13;
            break;
        default: break;
        }
    }
    /* rounds outer, scenes inner (see run_speed); medians of the total and of each stage */
    for (int r = 0; r < b->runs && rc == TD_OK; r++) {
        td_bench_progress(b, "effects: round %s%s", r == 0 ? "1" : r == 1 ? "2" : "3+", "");
        for (int k = 0; k < TD_BENCH_EFFECT_COUNT && rc == TD_OK; k++) {
            bench_effect *e = &b->effect[k];
            double *row = ms + (size_t)k * (TD_STAGE_COUNT + 1) * (size_t)b->runs;
            row[r] = render_once(&v, &scenes[k], lod, &res, &rc, err);
            if (rc)
                break;
            for (int st = 0; st < TD_STAGE_COUNT; st++)
                row[(size_t)(st + 1) * (size_t)b->runs + (size_t)r] = res.stats.stage_ms[st];
            if (r == 0) {
                e->kind = k;
                e->stats = res.stats;
            }
            td_render_result_free(&res);
            memset(&res, 0, sizeof res);
        }
    }
    if (rc)
        goto out;
    for (int k = 0; k < TD_BENCH_EFFECT_COUNT; k++) {
        bench_effect *e = &b->effect[k];
        double *row = ms + (size_t)k * (TD_STAGE_COUNT + 1) * (size_t)b->runs;
        e->ms = td_bench_median(row, b->runs);
        for (int st = 0; st < TD_STAGE_COUNT; st++)
            e->stats.stage_ms[st] = td_bench_median(row + (size_t)(st + 1) * (size_t)b->runs, b->runs);
    }
    b->neffect = TD_BENCH_EFFECT_COUNT;
out:
    td_render_result_free(&res);
    td_lod_free(lod);
    td_accel_free(acc);
    td_grid_free(g);
    free(scenes);
    free(ms);
    return rc;
}

/* ---- machine ---------------------------------------------------------------------- */

static void machine_info(bench_ctx *b)
{
    FILE *f = fopen("/proc/cpuinfo", "r");
    char line[512];
    snprintf(b->cpu, sizeof b->cpu, "unknown CPU");
    while (f && fgets(line, sizeof line, f)) {
        char *c = strchr(line, ':');
        if (!strncmp(line, "model name", 10) && c) {
            c++;
            while (*c == ' ')
                c++;
            c[strcspn(c, "\n")] = '\0';
            snprintf(b->cpu, sizeof b->cpu, "%s", c);
            break;
        }
    }
    if (f)
        fclose(f);
    b->cores = (int)sysconf(_SC_NPROCESSORS_ONLN);
    b->lanes = td_trace_lanes();
    snprintf(b->commit, sizeof b->commit, "unknown");
    f = popen("git -C '" TERRAD_SOURCE_DIR "' rev-parse --short=12 HEAD 2>/dev/null", "r");
    if (f) {
        if (fgets(line, sizeof line, f)) {
            line[strcspn(line, "\n")] = '\0';
            if (line[0])
                snprintf(b->commit, sizeof b->commit, "%.40s", line);
        }
        pclose(f);
    }
    f = popen("git -C '" TERRAD_SOURCE_DIR "' status --porcelain --untracked-files=no 2>/dev/null | wc -l", "r");
    if (f) {
        if (fgets(line, sizeof line, f))
            b->dirty = atoi(line) > 0;
        pclose(f);
    }
    {
        time_t now = time(NULL);
        struct tm tmv;
        gmtime_r(&now, &tmv);
        strftime(b->date, sizeof b->date, "%Y-%m-%d %H:%M UTC", &tmv);
    }
}

/* ---- the report's row through `terrad trace` ----------------------------------------- */

static td_status write_rays(const bench_ds *d, const char *path, td_err *err);

/* Runs `terrad trace --threads 1 --stats` (the terrad built beside this program) on the
 * speed rays of d (hierarchical, triangle) `runs` times: the report prints its median
 * rays/s beside the benchmark's own figure for the same row, so the claim that both
 * measure the same thing is checked on every run (left out when terrad is not there). */
static void run_repro(bench_ctx *b, const bench_ds *d)
{
    char dir[] = "/tmp/terrad-bench-XXXXXX", rays[64] = "", stats[64] = "", cmd[8192], terrad[4096];
    double *rps = malloc((size_t)b->runs * sizeof *rps);
    int ok = rps && !strchr(d->path, '\'') && td_cli_sibling("terrad", terrad, sizeof terrad) &&
             !strchr(terrad, '\'') && access(terrad, X_OK) == 0 && mkdtemp(dir) != NULL, n = 0;
    if (ok) {
        snprintf(rays, sizeof rays, "%s/rays", dir);
        snprintf(stats, sizeof stats, "%s/stats.json", dir);
        ok = write_rays(d, rays, NULL) == TD_OK;
    }
    for (int r = 0; r < b->runs && ok; r++) {
        json_t *j;
        snprintf(cmd, sizeof cmd,
                 "'%s' trace --dem '%s' --method hierarchical --surface triangle --threads 1 "
                 "--k %d --stats '%s' < '%s' > /dev/null",
                 terrad, d->path, TD_PLANES_K_DEFAULT, stats, rays);
        ok = system(cmd) == 0 && (j = json_load_file(stats, 0, NULL)) != NULL;
        if (ok) {
            rps[n++] = json_real_value(json_object_get(j, "rays_per_second"));
            b->repro_steps = json_real_value(json_object_get(j, "mean_steps"));
            json_decref(j);
        }
    }
    if (ok && n > 0) {
        b->repro_rps = td_bench_median(rps, n); /* sorts */
        b->repro_min = rps[0];
        b->repro_max = rps[n - 1];
        b->repro_done = 1;
    }
    if (rays[0] && strncmp(dir, "/tmp/terrad-bench-", 18) == 0) {
        unlink(rays);
        unlink(stats);
        rmdir(dir);
    }
    free(rps);
}

/* ---- driver ----------------------------------------------------------------------- */

static td_status write_rays(const bench_ds *d, const char *path, td_err *err)
{
    td_status rc = TD_OK;
    FILE *f = fopen(path, "wb");
    if (!f) {
        rc = td_err_set(err, TD_EIO, "%s: %s", path, strerror(errno));
        goto out;
    }
    for (size_t k = 0; k < d->n && rc == TD_OK; k++) {
        unsigned char rec[48];
        for (int c = 0; c < 6; c++) {
            double v = c < 3 ? d->rays[k].o[c] : d->rays[k].d[c - 3];
            uint64_t u;
            memcpy(&u, &v, sizeof u);
            for (int q = 0; q < 8; q++, u >>= 8)
                rec[8 * c + q] = (unsigned char)(u & 0xff);
        }
        if (fwrite(rec, 1, sizeof rec, f) != sizeof rec)
            rc = td_err_set(err, TD_EIO, "%s: write failed", path);
    }
    if (fclose(f) != 0 && rc == TD_OK)
        rc = td_err_set(err, TD_EIO, "%s: write failed", path);
out:
    return rc;
}

static td_status open_dataset(bench_ctx *b, int which, bench_ds *d, td_err *err)
{
    td_status rc;
    const td_bench_opts *o = b->o;
    memset(d, 0, sizeof *d);
    switch (which) {
    case 0: rc = load_dataset(d, "trinidad", o->trinidad, err); break;
    case 1: rc = load_dataset(d, "picos", o->picos, err); break;
    case 2: rc = load_dataset(d, "levi", o->levi, err); break;
    default: rc = make_procedural(d, o->quick ? 256 : o->procedural, err); break;
    }
    if (rc == TD_OK) {
        int nv = o->quick ? 2 : 4, w = o->quick ? 32 : 192, h = o->quick ? 24 : 144;
        rc = make_rays(d, nv, w, h, err);
    }
    return rc;
}

td_status td_bench_run(const td_bench_opts *o, td_err *err)
{
    td_status rc = TD_OK;
    bench_ctx *b = calloc(1, sizeof *b);
    /* the procedural DEM only for the sections that trace it (1, 2) */
    unsigned proc_sections = (1u << TD_BENCH_SPEED) | (1u << TD_BENCH_ERROR);
    int nds = (o->procedural > 0 || o->quick) && (o->sections & proc_sections) ? 4 : 3;

    if (!b) {
        rc = td_err_set(err, TD_ENOMEM, "bench: out of memory");
        goto out;
    }
    b->o = o;
    b->runs = o->runs < 1 ? 1 : o->runs;
    b->build_runs = b->runs;
    b->t_start = td_clock_s();
    if (o->write_rays) {
        static const char *const names[4] = {"trinidad", "picos", "levi", "procedural"};
        int which = -1;
        for (int k = 0; k < 4; k++)
            if (!strcmp(o->rays_dataset, names[k]))
                which = k;
        if (which < 0) {
            rc = td_err_set(err, TD_EINVAL, "--rays-dataset: %s is not trinidad, picos, levi or procedural",
                            o->rays_dataset);
            goto out;
        }
        rc = open_dataset(b, which, &b->ds[0], err);
        if (rc == TD_OK)
            rc = write_rays(&b->ds[0], o->write_rays, err);
        free_dataset(&b->ds[0]);
        goto out;
    }
    machine_info(b);
    for (int k = 0; k < nds && rc == TD_OK; k++) {
        bench_ds *d = &b->ds[k];
        rc = open_dataset(b, k, d, err);
        if (rc)
            break;
        b->nds = k + 1;
        td_bench_progress(b, "dataset %s: %s", d->name, d->path);
        d->w = d->g->w;
        d->h = d->g->h;
        d->voids = d->g->voids;
        d->sx = d->g->sx;
        d->sy = d->g->sy;
        if (o->sections & ((1u << TD_BENCH_SPEED) | (1u << TD_BENCH_ERROR) | (1u << TD_BENCH_QU))) {
            rc = run_speed(b, d, err);
            d->speed_done = rc == TD_OK;
        } else {
            rc = build_accel(b, d, err);
        }
        if (k == 0 && rc == TD_OK && (o->sections & (1u << TD_BENCH_SPEED)) && !o->quick) {
            td_bench_progress(b, "%s: the same rays through `terrad trace --threads 1`%s", d->name, "");
            run_repro(b, d);
        }
        if (k == 0 && rc == TD_OK && (o->sections & (1u << TD_BENCH_ERROR))) {
            rc = run_k(b, d, err);
            if (rc == TD_OK)
                rc = run_renders(b, d, err);
        }
        if (k == 0 && rc == TD_OK && (o->sections & (1u << TD_BENCH_PAGLIERONI)))
            rc = run_paglieroni(b, d, err);
        if (!d->procedural && rc == TD_OK && (o->sections & (1u << TD_BENCH_CAMERA)))
            rc = td_bench_camera_run(b, d, err);
        free_dataset(d);
    }
    if (rc == TD_OK && (o->sections & (1u << TD_BENCH_EFFECTS)))
        rc = run_effects(b, err);
    b->total_s = td_clock_s() - b->t_start;
    if (rc == TD_OK)
        rc = td_bench_report(b, err);
out:
    if (b)
        for (int k = 0; k < 4; k++)
            free_dataset(&b->ds[k]);
    free(b);
    return rc;
}
