/* viewshed.c: viewsheds and lines of sight by ray casts (the rule, the curvature model and
 * the output are in viewshed.h).
 *
 * Each answer is what td_occluded (any hit, no hit point) says of the segment from the
 * eye to the target: there is no reference plane and no interpolation of horizons to
 * disagree with the tracers. Two ways to get it (td_vs_algo): `cast`, one segment a
 * target sample and observer; `sweep` (the default), vsweep.c's exact horizon sweep,
 * which proves most answers from an upper envelope of the projected edges and casts the
 * segments it cannot prove with the same td_viewshed_cast. The oracle tests
 * (tests/oracle/viewshed_oracle.c) trace the same segments (td_viewshed_ray) with the
 * double-precision reference and hold the sweep to the cast byte for byte.
 *
 * Layout: per observer an `eye` (its view: the dataset's, or with curvature a lowered
 * copy of the grid skipped through the dataset's max-mipmaps, built in setup_eyes).
 * Cast: workers take rows of samples from an atomic counter and, per sample, ask every
 * eye of the pass in range (one pass for all observers, or one an observer with
 * curvature). Sweep: one observer at a time, its four cones over up to four threads,
 * its answers added to the counts (vs_sweep_run). The plane surface is always cast
 * (vsweep.h). docs/viewshed.md has the measured figures against gdal_viewshed. */
#include "viewshed.h"

#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "accel.h"
#include "bigalloc.h"
#include "clock.h"
#include "limit.h"
#include "vsweep.h"

static const char *const td_vs_algo_names[] = {
#define TD_X_NAME(e, name) name,
    TD_VS_ALGO_LIST(TD_X_NAME)
#undef TD_X_NAME
};

const char *td_vs_algo_name(td_vs_algo a)
{
    return (unsigned)a < TD_VS_ALGO_COUNT ? td_vs_algo_names[a] : "unknown";
}

td_status td_vs_algo_parse(const char *name, td_vs_algo *out)
{
    int i = td_name_index(td_vs_algo_names, TD_VS_ALGO_COUNT, name);
    if (i >= 0)
        *out = (td_vs_algo)i;
    return i >= 0 ? TD_OK : TD_EINVAL;
}

static const td_limit_row td_vs_limit_rows[TD_VS_LIMIT_COUNT] = {
#define TD_X_ROW(id, path, min, api_max, max) {path, min, api_max, max},
    TD_VS_LIMIT_LIST(TD_X_ROW)
#undef TD_X_ROW
};

const td_limit_row *td_vs_limit_get(td_vs_limit id)
{
    return (unsigned)id < TD_VS_LIMIT_COUNT ? &td_vs_limit_rows[id] : NULL;
}

void td_viewshed_opts_default(td_viewshed_opts *o)
{
    memset(o, 0, sizeof *o);
    o->max_distance = INFINITY;
    o->k = 0.13;
    o->surface = TD_SURFACE_BILINEAR;
    o->method = TD_METHOD_AUTO;
}

void td_los_opts_default(td_los_opts *o)
{
    memset(o, 0, sizeof *o);
    o->k = 0.13;
    o->surface = TD_SURFACE_BILINEAR;
    o->method = TD_METHOD_AUTO;
}

static int32_t cell_of(double c, double s, int32_t n)
{
    double f = floor(c / s);
    return f < 0 ? 0 : (f > n - 2 ? n - 2 : (int32_t)f);
}

double td_viewshed_ground(const td_grid *g, td_surface s, double x, double y)
{
    double z = NAN;
    if (x >= 0 && y >= 0 && x <= (g->w - 1) * g->sx && y <= (g->h - 1) * g->sy) {
        int32_t ci = cell_of(x, g->sx, g->w), cj = cell_of(y, g->sy, g->h);
        z = td_surface_height(g, s, ci, cj, x, y);
        /* On a grid line the surfaces but the plane's half-open columns agree across
         * it: a point on the edge of a hole stands on the cell beside it. */
        for (int k = 1; k < 4 && isnan(z) && s != TD_SURFACE_PLANE; k++) {
            int32_t di = (k & 1) && x == ci * g->sx && ci > 0, dj = (k & 2) && y == cj * g->sy && cj > 0;
            if ((k & 1) == di && (k & 2) == 2 * dj)
                z = td_surface_height(g, s, ci - di, cj - dj, x, y);
        }
    }
    return z;
}

/* The surface height at sample (i, j): the sample's own (any surface meets it there), or
 * for the plane surface the top of the column the sample belongs to (grid.h's
 * half-open columns: the one north-east of it, clamped at the east and north edges). */
static double sample_ground(const td_grid *g, td_surface s, int32_t i, int32_t j)
{
    if (s != TD_SURFACE_PLANE)
        return td_grid_at(g, i, j);
    return td_surface_height(g, s, i < g->w - 1 ? i : g->w - 2, j < g->h - 1 ? j : g->h - 2,
                             i * g->sx, j * g->sy);
}

/* x (metres, in [0, (n - 1) s]) moved down by the ulps that put x / s past n - 1: the
 * last row's y = 21 sy with sy = 40 / 3 has y / sy = 21 + 1 ulp, just off the grid to the
 * tracer (which divides) and to the sweep. For an eye there (setup_eyes) the two parted
 * along the grid's edge; for a target on the last row (td_viewshed_ray), a segment along
 * that row from an eye on it left the grid half way to the tracer's clip, which then
 * missed the terrain that blocks it (fuzz_viewshed, seeds corner-ulp-west and edge-row).
 * At most a few ulps; a point inside stays as it is. */
static double into_grid(double x, double s, int32_t n)
{
    while (x > 0.0 && x / s > (double)(n - 1))
        x = nextafter(x, 0.0);
    return x;
}

int td_viewshed_ray(const td_grid *g, td_surface s, double ex, double ey, double ez, int32_t i,
                    int32_t j, double target_height, td_ray *r)
{
    double x = into_grid(i * g->sx, g->sx, g->w), y = into_grid(j * g->sy, g->sy, g->h);
    double z = sample_ground(g, s, i, j);
    int rc = 0;
    if (isnan(z)) {
        rc = -1;
    } else if (x == ex && y == ey) {
        rc = 1;
    } else {
        r->o[0] = ex;
        r->o[1] = ey;
        r->o[2] = ez;
        r->d[0] = x - ex;
        r->d[1] = y - ey;
        r->d[2] = z + target_height - ez;
        r->tmin = TD_LOS_TEPS;
        r->tmax = 1.0 - TD_LOS_TEPS;
    }
    return rc;
}

/* The linear surface along the ray's line through cell (ci, cj) at t: the chord between
 * the line's entry and exit heights (as the tracer's linear_under), or the bilinear
 * patch under a vertical line or one that only touches the cell. */
static double linear_along(const td_grid *g, int32_t ci, int32_t cj, const td_ray *r, double t)
{
    double a0 = r->o[0] / g->sx - ci, b0 = r->o[1] / g->sy - cj, da = r->d[0] / g->sx, db = r->d[1] / g->sy;
    double tin = -INFINITY, tout = INFINITY, h;
    if (da != 0.0) {
        tin = fmax(tin, fmin(-a0 / da, (1.0 - a0) / da));
        tout = fmin(tout, fmax(-a0 / da, (1.0 - a0) / da));
    }
    if (db != 0.0) {
        tin = fmax(tin, fmin(-b0 / db, (1.0 - b0) / db));
        tout = fmin(tout, fmax(-b0 / db, (1.0 - b0) / db));
    }
    if (!(tout > tin) || !isfinite(tin) || !isfinite(tout)) {
        h = td_surface_height(g, TD_SURFACE_BILINEAR, ci, cj, r->o[0] + t * r->d[0], r->o[1] + t * r->d[1]);
    } else {
        double hin = td_surface_height(g, TD_SURFACE_BILINEAR, ci, cj, r->o[0] + tin * r->d[0],
                                       r->o[1] + tin * r->d[1]);
        double hout = td_surface_height(g, TD_SURFACE_BILINEAR, ci, cj, r->o[0] + tout * r->d[0],
                                        r->o[1] + tout * r->d[1]);
        h = hin + (hout - hin) * ((t - tin) / (tout - tin));
    }
    return h;
}

/* The segment's height over surface s at t (NaN for the plane, over a hole) */
static double gap_at(const td_grid *g, td_surface s, const td_ray *r, double t)
{
    double x = r->o[0] + t * r->d[0], y = r->o[1] + t * r->d[1], z = NAN;
    int32_t ci = cell_of(x, g->sx, g->w), cj = cell_of(y, g->sy, g->h);
    if (s != TD_SURFACE_PLANE)
        z = s == TD_SURFACE_LINEAR ? linear_along(g, ci, cj, r, t) : td_surface_height(g, s, ci, cj, x, y);
    return r->o[2] + t * r->d[2] - z;
}

double td_viewshed_start_gap(const td_grid *g, td_surface s, const td_ray *r)
{
    return gap_at(g, s, r, r->tmin);
}

/* Under by more than rounding at the start; or within rounding there and clearly under
 * 2^-20 of the segment on (where the tracer's start decides by rounding, a segment
 * leaving the eye into the ground would otherwise count as a line of sight if it never
 * came out: an eye 1e-7 m over a steep slope, test_vsweep's test_low_eye). A crossing
 * between the two, either way, would block it too. */
int td_viewshed_starts_under(const td_grid *g, td_surface s, const td_ray *r)
{
    /* NaN (the plane, a hole: nothing to be under) compares false */
    double tol = 0x1p-48 * (1.0 + fabs(r->o[2])), gap = td_viewshed_start_gap(g, s, r);
    return gap < -tol || (gap <= tol && r->tmin < 0x1p-20 && gap_at(g, s, r, 0x1p-20) < -16.0 * tol);
}

int td_viewshed_cast(const td_view *v, td_surface s, td_method m, double ex, double ey, double ez,
                     int32_t i, int32_t j, double target_height, uint32_t *steps)
{
    td_ray r;
    int kind = td_viewshed_ray(v->grid, s, ex, ey, ez, i, j, target_height, &r);
    if (kind == 0)
        kind = !td_viewshed_starts_under(v->grid, s, &r) && !td_occluded(v, m, s, &r, NULL, steps);
    else if (kind > 0)
        kind = 2;
    return kind;
}

td_status td_vs_from_lonlat(const td_grid *g, double lon, double lat, const char *field, double *x,
                            double *y, td_err *err)
{
    td_status rc = TD_OK;
    if (g->geo.kind != TD_GEO_LONLAT)
        rc = td_err_field(err, TD_EUNSUPPORTED, field, "the dataset has no lon/lat georeference; give x, y");
    else if (!isfinite(lon) || !isfinite(lat))
        rc = td_err_field(err, TD_ERANGE, field, "lon and lat must be finite");
    if (rc == TD_OK) {
        *x = (lon - g->geo.x0) / g->geo.dx * g->sx;
        *y = (lat - g->geo.y0) / g->geo.dy * g->sy;
    }
    return rc;
}

/* An observer (or los end) at p: inside the grid and over the surface. */
static td_status check_point(const td_grid *g, td_surface s, td_vs_point p, const char *field,
                             td_err *err)
{
    td_status rc = TD_OK;
    double X = (g->w - 1) * g->sx, Y = (g->h - 1) * g->sy;
    if (!(p.x >= 0 && p.x <= X && p.y >= 0 && p.y <= Y))
        rc = td_err_field(err, TD_ERANGE, field, "(%g, %g) is outside the grid [0, %g] x [0, %g] m",
                          p.x, p.y, X, Y);
    else if (isnan(td_viewshed_ground(g, s, p.x, p.y)))
        rc = td_err_field(err, TD_ERANGE, field, "(%g, %g) is over a void (no surface there)", p.x, p.y);
    return rc;
}

static td_status check_common(const td_grid *g, td_surface s, td_method m, int curvature, double k,
                              td_err *err)
{
    td_status rc = TD_OK;
    if (g->w < 2 || g->h < 2)
        rc = td_err_set(err, TD_EINVAL, "the grid needs at least 2 x 2 samples");
    else if ((unsigned)s >= TD_SURFACE_COUNT)
        rc = td_err_field(err, TD_EINVAL, "surface", "unknown surface %d", (int)s);
    else if ((unsigned)m >= TD_METHOD_COUNT)
        rc = td_err_field(err, TD_EINVAL, "method", "unknown method %d", (int)m);
    else if (curvature && td_limit_check(TD_LIMIT_CURVATURE_K, k, err))
        rc = td_err_field(err, TD_ERANGE, "curvature.k", "%g is outside %g .. %g", k,
                          td_limit_get(TD_LIMIT_CURVATURE_K)->min, td_limit_get(TD_LIMIT_CURVATURE_K)->max);
    return rc;
}

static td_status check_height(double h, const char *field, td_err *err)
{
    const td_limit_row *row = td_vs_limit_get(TD_VS_LIMIT_HEIGHT);
    td_status rc = TD_OK;
    if (!(h >= row->min && h <= row->max))
        rc = td_err_field(err, TD_ERANGE, field, "%g m is outside %g .. %g", h, row->min, row->max);
    return rc;
}

td_status td_viewshed_check(const td_grid *g, const td_viewshed_opts *o, td_err *err)
{
    td_status rc = check_common(g, o->surface, o->method, o->curvature, o->k, err);
    char field[32];
    if (!rc && !(o->nobs >= td_vs_limit_get(TD_VS_LIMIT_OBSERVERS)->min && o->nobs <= TD_VS_MAX_OBSERVERS))
        rc = td_err_field(err, TD_ERANGE, "observers", "%d observers: give 1 .. %d", o->nobs, TD_VS_MAX_OBSERVERS);
    if (!rc && !o->obs)
        rc = td_err_field(err, TD_EINVAL, "observers", "no observer list");
    for (int k = 0; !rc && k < o->nobs; k++) {
        if (o->nobs == 1)
            snprintf(field, sizeof field, "observer");
        else
            snprintf(field, sizeof field, "observers[%d]", k);
        rc = check_point(g, o->surface, o->obs[k], field, err);
    }
    if (!rc)
        rc = check_height(o->height, "height", err);
    if (!rc)
        rc = check_height(o->target_height, "target_height", err);
    if (!rc && !(o->max_distance > 0)) /* +inf is none; NaN fails */
        rc = td_err_field(err, TD_ERANGE, "max_distance", "must be > 0 m (leave it out for no limit)");
    return rc;
}

/* ---- curvature: a lowered copy of the grid per observer ------------------------------ */

/* One observer's eye and the view its segments are traced on. */
typedef struct eye {
    double x, y, z;
    double ground; /* z - height: the surface under the eye */
    td_grid *lowered; /* with curvature, else NULL (the dataset's view is used) */
    td_accel *acc;       /* built for the lowered grid (parametric, or nothing resident) */
    td_tile_accel *bound; /* or the dataset's max-mipmaps, borrowed (see lowered_view) */
    td_view view;
} eye;

/* c of the curvature drop c*s^2, 0 without curvature. */
static double drop_coef(int curvature, double k)
{
    return curvature ? (1.0 - k) / (2.0 * TD_EARTH_RADIUS_M) : 0.0;
}

/* The grid lowered by c*s^2 about (px, py), with the acceleration method m needs. */
static td_status lowered_view(const td_view *v, td_method m, double c, double px, double py,
                              int threads, eye *e, td_err *err)
{
    const td_grid *g = v->grid;
    td_accel_opts ao;
    td_status rc = td_grid_create(g->w, g->h, g->sx, g->sy, g->tile_log2, NULL, &e->lowered, err);
    if (rc)
        goto out;
    for (int32_t j = 0; j < g->h; j++) {
        double dy = j * g->sy - py;
        for (int32_t i = 0; i < g->w; i++) {
            double dx = i * g->sx - px;
            size_t k = (size_t)j * (size_t)g->w + (size_t)i;
            e->lowered->z[k] = (float)((double)g->z[k] - c * (dx * dx + dy * dy));
        }
    }
    e->lowered->geo = g->geo;
    rc = td_grid_finish(e->lowered, err);
    if (rc)
        goto out;
    e->view.grid = e->lowered;
    if (v->accel && m != TD_METHOD_PARAMETRIC) {
        /* The dataset's max-mipmaps bound the lowered heights too (they only fall), and a
         * bound is all a skip needs (DESIGN.md: never skip a hit): borrow them, tile by
         * tile as resident, instead of building new ones per observer. Not the planes:
         * their slices are measured from the tile's own zmin. */
        size_t n = (size_t)g->tiles_x * (size_t)g->tiles_y;
        e->bound = calloc(n, sizeof *e->bound);
        if (!e->bound) {
            rc = td_err_set(err, TD_ENOMEM, "viewshed: out of memory");
            goto out;
        }
        for (size_t i = 0; i < n; i++)
            e->bound[i].maxmip = v->accel[i].maxmip;
        e->view.accel = e->bound;
        goto out;
    }
    td_accel_opts_for(m, &ao);
    ao.threads = threads;
    ao.minima = 0; /* no sun bound to read them */
    if (ao.maxmip || ao.planes)
        rc = td_accel_build(e->lowered, &ao, &e->acc, NULL, err);
    e->view.accel = e->acc ? e->acc->tiles : NULL;
out:
    return rc;
}

static void free_eyes(eye *eyes, int n)
{
    for (int k = 0; eyes && k < n; k++) {
        td_accel_free(eyes[k].acc);
        free(eyes[k].bound);
        td_grid_free(eyes[k].lowered);
    }
    free(eyes);
}

/* Each observer's eye: its ground (on its own view: the lowered grid is not lowered under
 * the observer, s = 0 there) plus height. */
static td_status setup_eyes(const td_view *v, const td_vs_point *p, int n, double height,
                            int curvature, double k, td_surface s, td_method m, int threads,
                            eye **out, td_err *err)
{
    td_status rc = TD_OK;
    double c = drop_coef(curvature, k);
    eye *eyes = calloc((size_t)n, sizeof *eyes);
    if (!eyes) {
        rc = td_err_set(err, TD_ENOMEM, "viewshed: out of memory for %d observers", n);
        goto out;
    }
    for (int i = 0; i < n && !rc; i++) {
        eye *e = &eyes[i];
        e->view = *v;
        e->x = into_grid(p[i].x, v->grid->sx, v->grid->w);
        e->y = into_grid(p[i].y, v->grid->sy, v->grid->h);
        if (c != 0.0)
            rc = lowered_view(v, m, c, e->x, e->y, threads, e, err);
        e->ground = td_viewshed_ground(e->view.grid, s, e->x, e->y);
        e->z = e->ground + height;
    }
out:
    if (rc) {
        free_eyes(eyes, n);
        eyes = NULL;
    }
    *out = eyes;
    return rc;
}

/* ---- the viewshed: rows across workers ------------------------------------------------ */

typedef struct vs_ctx {
    const td_grid *g;
    const eye *eyes; /* neyes observers this pass */
    int neyes;
    int merge;       /* add to out's counts (a later pass) instead of writing them */
    int direct;      /* the sweep writes out itself (vs_sweep_run: one observer, every sample) */
    const td_viewshed_opts *o;
    double maxd2;
    uint8_t *out;
    atomic_int next;
} vs_ctx;

typedef struct vs_worker {
    vs_ctx *c;
    pthread_t th;
    uint64_t rays, steps;
    int cancelled;
} vs_worker;

/* One sample (i, j) against every observer of the pass in range: its output byte. */
static uint8_t vs_sample(vs_worker *w, int32_t i, int32_t j)
{
    const vs_ctx *c = w->c;
    const td_viewshed_opts *o = c->o;
    int count = 0, in_range = 0, isvoid = 0;
    for (int k = 0; k < c->neyes && !isvoid; k++) {
        const eye *e = &c->eyes[k];
        double dx = i * c->g->sx - e->x, dy = j * c->g->sy - e->y;
        int kind;
        uint32_t steps;
        if (dx * dx + dy * dy > c->maxd2)
            continue;
        in_range = 1;
        steps = 0;
        kind = td_viewshed_cast(&e->view, o->surface, o->method, e->x, e->y, e->z, i, j, o->target_height, &steps);
        if (kind < 0) {
            isvoid = 1;
        } else {
            count += kind > 0;
            w->rays += kind < 2;
            w->steps += steps;
        }
    }
    return isvoid || !in_range ? TD_VS_OUTSIDE : (uint8_t)count;
}

/* A later pass's byte v into out's (counts add; outside only where outside for all). */
static uint8_t vs_merge(uint8_t old, uint8_t v)
{
    return v == TD_VS_OUTSIDE ? old : old == TD_VS_OUTSIDE ? v : (uint8_t)(old + v);
}

static void *vs_work(void *arg)
{
    vs_worker *w = arg;
    vs_ctx *c = w->c;
    const td_grid *g = c->g;
    for (;;) {
        int row;
        if (c->o->cancel && atomic_load_explicit(c->o->cancel, memory_order_relaxed)) {
            w->cancelled = 1;
            break;
        }
        row = atomic_fetch_add_explicit(&c->next, 1, memory_order_relaxed);
        if (row >= g->h)
            break;
        for (int32_t i = 0; i < g->w; i++) {
            uint8_t *o = &c->out[(size_t)row * (size_t)g->w + (size_t)i], v = vs_sample(w, i, g->h - 1 - row);
            *o = c->merge ? vs_merge(*o, v) : v;
        }
    }
    return NULL;
}

static int thread_count(int asked, int32_t rows)
{
    int n = asked > 0 ? asked : td_cpu_count();
    if (n > 256)
        n = 256;
    return n > rows ? (int)rows : n;
}

/* Runs nthreads workers (the caller's thread the first; a thread that cannot be started
 * leaves its rows to the others) and sums their counters into st. */
static td_status vs_run(vs_ctx *c, int nthreads, td_viewshed_stats *st, td_err *err)
{
    td_status rc = TD_OK;
    vs_worker *ws = calloc((size_t)nthreads, sizeof *ws);
    int started;
    if (!ws) {
        rc = td_err_set(err, TD_ENOMEM, "viewshed: out of memory");
        goto out;
    }
    for (int k = 0; k < nthreads; k++)
        ws[k].c = c;
    for (started = 1; started < nthreads; started++)
        if (pthread_create(&ws[started].th, NULL, vs_work, &ws[started]) != 0)
            break;
    vs_work(&ws[0]);
    for (int k = 1; k < started; k++)
        pthread_join(ws[k].th, NULL);
    st->threads = started;
    for (int k = 0; k < started; k++) {
        st->rays += ws[k].rays;
        st->steps += ws[k].steps;
        if (ws[k].cancelled)
            rc = td_err_set(err, TD_ECANCELED, "viewshed: cancelled");
    }
out:
    free(ws);
    return rc;
}

/* The samples inside and seen, from the finished output. */
static void vs_count(const td_grid *g, const uint8_t *out, td_viewshed_stats *st)
{
    size_t n = (size_t)g->w * (size_t)g->h;
    for (int32_t j = 0; j < g->h; j++) { /* a row's counts in 32 bits: a loop that vectorises */
        const uint8_t *row = &out[(size_t)j * (size_t)g->w];
        uint32_t outside = 0, zero = 0;
        for (int32_t i = 0; i < g->w; i++) {
            outside += row[i] == TD_VS_OUTSIDE;
            zero += row[i] == 0;
        }
        st->inside += (uint32_t)g->w - outside;
        st->visible += (uint32_t)g->w - outside - zero;
    }
    st->samples = n;
    st->visible_area_m2 = (double)st->visible * g->sx * g->sy;
}

/* ---- the viewshed by the horizon sweep (vsweep.h), one observer at a time -------------- */

/* Adds eye e's answers vis (south-based) to the pass's counts in out: the samples within
 * max_distance that are not void (the sweep wrote no others; never the plane surface, so
 * a sample's ground is its own height). Without max_distance or voids a row is added
 * whole, a loop the compiler vectorises (this pass was 46 instructions a sample). */
static void vs_sweep_add(const vs_ctx *c, const eye *e, const uint8_t *vis)
{
    const td_grid *g = c->g, *ge = e->view.grid;
    int all = c->maxd2 == INFINITY && ge->voids == 0;
    for (int32_t j = 0; j < g->h; j++) {
        double dy = j * g->sy - e->y;
        uint8_t *row = &c->out[(size_t)(g->h - 1 - j) * (size_t)g->w];
        const uint8_t *vrow = &vis[(size_t)j * (size_t)g->w];
        const float *zrow = &ge->z[(size_t)j * (size_t)g->w];
        if (all) {
            for (int32_t i = 0; i < g->w; i++)
                row[i] = (uint8_t)((row[i] == TD_VS_OUTSIDE ? 0 : row[i]) + vrow[i]);
            continue;
        }
        for (int32_t i = 0; i < g->w; i++) {
            double dx = i * g->sx - e->x;
            if (dx * dx + dy * dy > c->maxd2 || isnan(zrow[i]))
                continue;
            row[i] = (uint8_t)((row[i] == TD_VS_OUTSIDE ? 0 : row[i]) + vrow[i]);
        }
    }
}

static td_status vs_sweep_run(vs_ctx *c, int nthreads, uint8_t *vis, td_viewshed_stats *st, td_err *err)
{
    const td_viewshed_opts *o = c->o;
    td_status rc = TD_OK;
    int direct = c->direct;
    if (!c->merge && !direct)
        memset(c->out, TD_VS_OUTSIDE, (size_t)c->g->w * (size_t)c->g->h);
    for (int k = 0; k < c->neyes && rc == TD_OK; k++) {
        const eye *e = &c->eyes[k];
        td_vsweep_job job = {&e->view, o->surface, o->method, e->x, e->y, e->z, e->ground,
                             o->target_height, c->maxd2, nthreads, o->cancel, direct};
        td_vsweep_stats vst;
        rc = td_vsweep(&job, direct ? c->out : vis, &vst, err);
        st->swept += vst.swept;
        st->rays += vst.rays;
        st->steps += vst.steps;
        st->blocks += vst.blocks;
        st->facing += vst.facing;
        if (rc == TD_OK && !direct)
            vs_sweep_add(c, e, vis);
    }
    st->threads = nthreads < 4 ? nthreads : 4;
    return rc;
}

/* Without curvature one pass asks every observer per sample; with it, one pass an
 * observer, so that one lowered grid at a time is resident (64 observers over trinidad
 * would otherwise hold 64 copies, 0.7 GB), each pass adding its counts. */
td_status td_viewshed(const td_view *v, const td_viewshed_opts *o, uint8_t *out,
                      td_viewshed_stats *st, td_err *err)
{
    const td_grid *g = v->grid;
    eye *eyes = NULL;
    vs_ctx c;
    int nthreads = thread_count(o->threads, g->h), per = o->curvature ? 1 : o->nobs;
    int sweep = o->algo == TD_VS_ALGO_SWEEP && o->surface != TD_SURFACE_PLANE;
    /* one observer, no max_distance, no voids: the sweep writes every sample, its 0 or 1
     * being the count, straight into out (no memset of out, no vis, no vs_sweep_add: 2.9 MB
     * of fresh pages and two passes on trinidad) */
    int direct = sweep && o->nobs == 1 && o->max_distance == INFINITY && g->voids == 0;
    uint8_t *vis = NULL;
    td_status rc;

    memset(st, 0, sizeof *st);
    rc = td_viewshed_check(g, o, err);
    if (rc == TD_OK && sweep && !direct && !(vis = td_bigalloc_scratch((size_t)g->w * (size_t)g->h)))
        rc = td_err_set(err, TD_ENOMEM, "viewshed: out of memory");
    for (int first = 0; rc == TD_OK && first < o->nobs; first += per) {
        double t0 = td_clock_s(), t1;
        rc = setup_eyes(v, o->obs + first, per, o->height, o->curvature, o->k, o->surface, o->method,
                        nthreads, &eyes, err);
        if (rc)
            break;
        t1 = td_clock_s();
        memset(&c, 0, sizeof c);
        c.g = g;
        c.eyes = eyes;
        c.neyes = per;
        c.merge = first > 0;
        c.direct = direct;
        c.o = o;
        c.maxd2 = o->max_distance * o->max_distance;
        c.out = out;
        atomic_init(&c.next, 0);
        rc = sweep ? vs_sweep_run(&c, nthreads, vis, st, err) : vs_run(&c, nthreads, st, err);
        st->setup_ms += 1e3 * (t1 - t0);
        st->trace_ms += 1e3 * (td_clock_s() - t1);
        free_eyes(eyes, per);
        eyes = NULL;
    }
    if (rc == TD_OK)
        vs_count(g, out, st);
    free(vis);
    return rc;
}

void td_viewshed_gray(const uint8_t *counts, size_t n, uint8_t *gray)
{
    for (size_t k = 0; k < n; k++)
        gray[k] = counts[k] == TD_VS_OUTSIDE ? 128 : (counts[k] ? 255 : 0);
}

/* ---- line of sight ---------------------------------------------------------------------- */

/* The profile: n points evenly spaced from a to b (at most one a cell, at most
 * TD_LOS_PROFILE_MAX), ground and line heights in the dataset frame. */
static void los_profile(const td_grid *g, const td_los_opts *o, double c, td_los_result *res)
{
    double cell = g->sx < g->sy ? g->sx : g->sy;
    double D = res->distance;
    int n = (int)ceil(D / cell) + 1;
    if (n > TD_LOS_PROFILE_MAX)
        n = TD_LOS_PROFILE_MAX;
    if (n < 2)
        n = 2;
    for (int k = 0; k < n; k++) {
        double f = (double)k / (n - 1);
        double x = o->a.x + f * (o->b.x - o->a.x), y = o->a.y + f * (o->b.y - o->a.y);
        double s = f * D;
        td_los_point *p = &res->profile[k];
        p->s = s;
        p->ground = td_viewshed_ground(g, o->surface, x, y);
        /* straight in the lowered frame; in the dataset's, the chord sags by c s (D - s) */
        p->line = res->eye_a[2] + f * (res->eye_b[2] - res->eye_a[2]) - c * s * (D - s);
    }
    res->nprofile = n;
}

td_status td_los(const td_view *v, const td_los_opts *o, td_los_result *res, td_err *err)
{
    const td_grid *g = v->grid;
    double c = drop_coef(o->curvature, o->k);
    eye *e = NULL;
    td_ray r;
    td_hit hit;
    double zb;
    td_status rc;

    memset(res, 0, sizeof *res);
    rc = check_common(g, o->surface, o->method, o->curvature, o->k, err);
    if (!rc)
        rc = check_point(g, o->surface, o->a, "from", err);
    if (!rc)
        rc = check_point(g, o->surface, o->b, "to", err);
    if (!rc)
        rc = check_height(o->height_a, "from.height", err);
    if (!rc)
        rc = check_height(o->height_b, "to.height", err);
    if (!rc)
        rc = setup_eyes(v, &o->a, 1, o->height_a, o->curvature, o->k, o->surface, o->method, 1, &e, err);
    if (rc)
        goto out;
    res->distance = hypot(o->b.x - o->a.x, o->b.y - o->a.y);
    res->eye_a[0] = o->a.x;
    res->eye_a[1] = o->a.y;
    res->eye_a[2] = e->z;
    res->eye_b[0] = o->b.x;
    res->eye_b[1] = o->b.y;
    /* b's ground in the lowered frame (what the segment is traced to), and in the
     * dataset's (what is reported) */
    zb = td_viewshed_ground(e->view.grid, o->surface, o->b.x, o->b.y) + o->height_b;
    res->eye_b[2] = td_viewshed_ground(g, o->surface, o->b.x, o->b.y) + o->height_b;
    los_profile(g, o, c, res);
    res->visible = 1;
    if (res->distance == 0 && zb == e->z)
        goto out; /* the same point */
    r.o[0] = e->x;
    r.o[1] = e->y;
    r.o[2] = e->z;
    r.d[0] = o->b.x - e->x;
    r.d[1] = o->b.y - e->y;
    r.d[2] = zb - e->z;
    r.tmin = TD_LOS_TEPS;
    r.tmax = 1.0 - TD_LOS_TEPS;
    td_trace(&e->view, o->method, o->surface, &r, &hit);
    res->steps = hit.steps;
    if (!isfinite(hit.t) && td_viewshed_starts_under(e->view.grid, o->surface, &r)) {
        /* under the surface from the eye on, and no crossing: blocked where it starts */
        hit.t = r.tmin;
        for (int k = 0; k < 3; k++)
            hit.p[k] = r.o[k] + r.tmin * r.d[k];
    }
    if (isfinite(hit.t)) {
        double s = hit.t * res->distance;
        res->visible = 0;
        res->block[0] = hit.p[0];
        res->block[1] = hit.p[1];
        res->block[2] = hit.p[2] + c * s * s;
        res->block_s = s;
        res->block_dist = hit.t * sqrt(r.d[0] * r.d[0] + r.d[1] * r.d[1] + r.d[2] * r.d[2]);
    }
out:
    free_eyes(e, 1);
    return rc;
}
