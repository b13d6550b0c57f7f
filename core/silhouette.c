/* silhouette.c: the silhouette partition of one perspective view (silhouette.h has the
 * idea, the bound and why it is safe). Called by render.c once per render, before its
 * workers start; the result is read-only and shared by them.
 *
 * Layout of one fan (quadrant of directions), strips s = 0 .. ns-1 from the eye outward:
 *
 *     p[k * ns + s] = P_s of wedge k = max over s' <= s of B_s'(wedge k)   (float, rounded up)
 *
 *   wedge 0     P_0 P_1 P_2 ... P_ns-1        one row per wedge: the binary search of a
 *   wedge 1     P_0 P_1 P_2 ... P_ns-1        ray reads log2(ns) entries of its wedge's row
 *   ...
 *
 * Build: the wedges are cut into parts of up to TD_SILH_PART wedges, taken by the threads
 * from a counter; a part walks the strips from the eye outward and, per strip and wedge,
 * takes the cells the wedge's rays can cross there (both cells where a range ends on a
 * sample line; a margin for rounding), bounds them by their tiles' zmax and, only where
 * that bound could raise the wedge's running maximum, by their samples (NaN dropped):
 * terrain hidden behind a nearer silhouette is never read.
 *
 * Sizes: a fan has at most TD_SILH_ENTRIES_MAX / ns wedges and all fans together at most
 * one per TD_SILH_WEDGE_PX image columns (the paper has one per screen column); a wedge is
 * at least that many pixels' angle wide. Measured: README, Silhouette partitioning.
 * Rejected: Sakalauskas' binary tree of silhouettes (each node the nearer child's
 * silhouette): it exists to let a GPU search with a fixed number of texture reads; the
 * running maximum per wedge answers the same query (the first strip whose silhouette
 * reaches the ray) by a plain binary search in half the memory. Also rejected: one pass
 * over a part's cross range per strip shared by its wedges (every sample read, hidden or
 * not); wedges one column wide (the build 4x dearer for 2-10% of a step a ray); and a
 * branch-free binary search (conditional moves): slower on 5 of 6 views, as the rays of a
 * block share a wedge and nearly the same answer, so the branches predict well while the
 * moves chain each probe's load to the last. */
#include "silhouette.h"

#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

#define TD_SILH_PART 64              /* wedges a thread builds at once */
/* A wedge's width in image columns (at the image's mean angle per column, at least a
 * pixel's): measured by instructions (callgrind, deterministic on a shared machine) on
 * trinidad views of 640 x 400, one ray a pixel: 1 -> 2 -> 4 -> 8 -> 16 columns gave
 * 679 -> 645 -> 633 -> 634 -> 648 M instructions for the whole `terrad render` (sunset)
 * and 673 / 679 / 704 M for 4 / 8 / 16 on levi; the build halves with each doubling and
 * the walk grows by 2-10% of a step a ray. */
#define TD_SILH_WEDGE_PX 4.0
#define TD_SILH_ENTRIES_MAX (1 << 22) /* P_s per fan at most (16 MiB of floats; past it, wider wedges) */
#define TD_SILH_THREADS_MAX 64

/* max that drops a NaN (a void) in v */
static inline float fmax_nan(float m, float v) { return v > m ? v : m; }

/* min/max of non-NaN values as single instructions (libm's are calls) */
static inline double dmin(double a, double b) { return a < b ? a : b; }
static inline double dmax(double a, double b) { return a > b ? a : b; }

/* The fan of a horizontal direction (dx, dy): 0 +x, 1 +y, 2 -x, 3 -y; -1 for none. */
static int fan_of(double dx, double dy)
{
    int q = -1;
    if (fabs(dx) >= fabs(dy) && dx != 0.0)
        q = dx > 0.0 ? 0 : 2;
    else if (dy != 0.0)
        q = dy > 0.0 ? 1 : 3;
    return q;
}

/* Slope m = d_cross / d_along of the horizontal direction at azimuth a in fan q. */
static double slope_at(int q, double a)
{
    double dx = cos(a), dy = sin(a);
    return (q & 1) ? dx / ((q == 1) ? dy : -dy) : dy / ((q == 0) ? dx : -dx);
}

/* The slopes of fan q the image's azimuths [az0, az1] reach (full: every azimuth);
 * 0 if none. Within a quadrant the slope is monotone in the azimuth. */
static int fan_slopes(int q, int full, double az0, double az1, double *mlo, double *mhi)
{
    const double c = q * (M_PI / 2.0);
    int ok = 0;
    double lo = c - M_PI / 4.0, hi = c + M_PI / 4.0;
    for (int k = -2; k <= 2 && !full && !ok; k++) {
        double a = fmax(az0, c - M_PI / 4.0 + 2.0 * M_PI * k), b = fmin(az1, c + M_PI / 4.0 + 2.0 * M_PI * k);
        if (a <= b) {
            lo = a;
            hi = b;
            ok = 1;
        }
    }
    if (full || ok) {
        double m1 = slope_at(q, lo), m2 = slope_at(q, hi);
        *mlo = fmin(m1, m2);
        *mhi = fmax(m1, m2);
        *mlo -= 1e-9 * (1.0 + fabs(*mlo)); /* far above the rounding of a ray's slope */
        *mhi += 1e-9 * (1.0 + fabs(*mhi));
        ok = 1;
    }
    return ok;
}

/* Where fan f's strips lie: the first from the eye and how many to the grid's edge. */
static void fan_strips(td_silh_fan *f, const td_grid *g, const double eye[3])
{
    const int32_t na = f->axis == 0 ? g->w - 1 : g->h - 1;
    double pe;
    f->sa = f->axis == 0 ? g->sx : g->sy;
    f->ea = eye[f->axis];
    pe = fmax(-2.0, fmin((double)na + 2.0, f->ea / f->sa)); /* the eye in cells, clamped */
    if (f->sign > 0) {
        /* the strip whose far line is at or past the eye: no strip behind it is reached */
        f->first = (int32_t)ceil(pe) - 1;
        f->first = f->first < 0 ? 0 : f->first;
        f->ns = f->first < na ? na - f->first : 0;
    } else {
        f->first = (int32_t)floor(pe);
        f->first = f->first > na - 1 ? na - 1 : f->first;
        f->ns = f->first >= 0 ? f->first + 1 : 0;
    }
}

/* Along-distances (metres, >= 0) of strip s's near and far lines from the eye, each
 * widened by far more than the rounding of a ray's position (1e-9 of the eye's coordinate
 * and a cell): the walk places a ray at o + t d in doubles, so one that in reals leaves a
 * strip at once may stay on its line. Found by fuzz_render (seed silhouette-edge-down): a
 * ray 6e-17 off the vertical from an eye over the grid's last row line, whose y never
 * moves off it, hit at 11.5 m in the walk; its strip, behind the eye with its far line
 * the eye's (q_f 0), bounded it by -inf, and the partition called it a miss. */
static void strip_q(const td_silh_fan *f, int32_t s, double *qn, double *qf)
{
    int32_t c = f->first + f->sign * s;
    double a = (double)c * f->sa, b = (double)(c + 1) * f->sa, slack = 1e-9 * (fabs(f->ea) + f->sa);
    *qn = (f->sign > 0 ? a - f->ea : f->ea - b) - slack;
    *qf = (f->sign > 0 ? b - f->ea : f->ea - a) + slack;
    *qn = *qn > 0.0 ? *qn : 0.0;
}

/* ---- the build ------------------------------------------------------------------- */

typedef struct build_job {
    const td_grid *g;
    td_silhouette *s;
    double zeps;
    int nparts;
    int part_fan[TD_SILH_FANS + 1]; /* parts of fan q: [part_fan[q], part_fan[q+1]) */
    atomic_int next;
} build_job;

/* floor of a finite value well inside int32 (a cast and a correction: no libm call) */
static inline int32_t ifloor(double u)
{
    int32_t i = (int32_t)u;
    return i - ((double)i > u);
}

/* Cells [*j0, *j1] across strip s that rays of slopes [ml, mh] can cross between along-
 * distances qn and qf, clamped to the grid; 0 if none. isc = 1 / the cross spacing. A
 * cross range ending on a sample line takes the cells on both sides of it (a ray along a
 * grid line may be in either); the margin, 1e-9 of a cell and more, is far above the
 * rounding of the positions (1e-16 of their size). */
static inline int cross_cells(double ec, double isc, int32_t nc, double qn, double qf, double ml, double mh,
                              int32_t *j0, int32_t *j1)
{
    double ulo = (ec + dmin(qn * ml, qf * ml)) * isc, uhi = (ec + dmax(qn * mh, qf * mh)) * isc;
    ulo = dmax(-4.0, dmin((double)nc + 4.0, ulo)); /* NaN-free: every input is finite */
    uhi = dmax(-4.0, dmin((double)nc + 4.0, uhi));
    *j0 = ifloor(ulo - 1e-9 * (1.0 + (ulo > 0.0 ? ulo : -ulo)));
    *j1 = ifloor(uhi + 1e-9 * (1.0 + (uhi > 0.0 ? uhi : -uhi)));
    *j0 = *j0 < 0 ? 0 : *j0;
    *j1 = *j1 > nc - 1 ? nc - 1 : *j1;
    return *j0 <= *j1;
}

/* The bound B of a strip whose highest corner is M, crossed between horizontal
 * distances dn and df (silhouette.h), with its margins. */
static double strip_bound(double M, double ez, double dn, double df)
{
    double b;
    if (M == -INFINITY)
        b = -INFINITY; /* only holes: nothing to meet */
    else if (M >= ez)
        b = dn > 0.0 ? (M - ez) / dn : INFINITY;
    else
        b = (M - ez) / df;
    if (isfinite(b))
        b += 1e-12 * fabs(b);
    return b;
}

/* Highest tile zmax over cells [j0, j1] across strip c (the grid's tile records: what
 * the walk's tile test uses; they bound every corner of their cells). */
static float tiles_max(const td_grid *g, int axis, int32_t c, int32_t j0, int32_t j1)
{
    const int tl = g->tile_log2;
    float m = -INFINITY;
    for (int32_t t = j0 >> tl; t <= j1 >> tl; t++) {
        const td_tile *tt = axis ? &g->tiles[(size_t)(c >> tl) * (size_t)g->tiles_x + (size_t)t]
                                 : &g->tiles[(size_t)t * (size_t)g->tiles_x + (size_t)(c >> tl)];
        m = fmax_nan(m, tt->zmax);
    }
    return m;
}

/* Highest sample of strip c's two sample lines over cells [j0, j1] (NaN dropped). */
static float samples_max(const td_grid *g, int axis, int32_t c, int32_t j0, int32_t j1)
{
    float m = -INFINITY;
    for (int32_t x = j0; x <= j1 + 1; x++) /* through g->cz: a prepared grid's blocked copy */
        m = axis ? fmax_nan(fmax_nan(m, td_grid_sample(g, x, c)), td_grid_sample(g, x, c + 1))
                 : fmax_nan(fmax_nan(m, td_grid_sample(g, c, x)), td_grid_sample(g, c + 1, x));
    return m;
}

/* Wedges [w0, w1) of fan f (w1 - w0 <= TD_SILH_PART): every strip's bound, running max.
 * A strip's samples are read only where its tiles' zmax could raise the running maximum:
 * terrain hidden behind a nearer silhouette costs one tile record, not its samples. */
static void build_part(const build_job *job, const td_silh_fan *f, int32_t w0, int32_t w1)
{
    const td_grid *g = job->g;
    const double ez = job->s->eye[2], zeps = job->zeps;
    const double ec = job->s->eye[1 - f->axis], isc = 1.0 / (f->axis ? g->sx : g->sy);
    const int32_t nc = f->axis ? g->w - 1 : g->h - 1;
    double ml[TD_SILH_PART], mh[TD_SILH_PART], kn[TD_SILH_PART], kf[TD_SILH_PART], run[TD_SILH_PART];
    const int32_t nw = w1 - w0;
    for (int32_t k = 0; k < nw; k++) {
        double a = f->m0 + (double)(w0 + k) * f->dm, b = f->m0 + (double)(w0 + k + 1) * f->dm;
        double min2 = (a <= 0.0 && b >= 0.0) ? 0.0 : fmin(a * a, b * b), max2 = fmax(a * a, b * b);
        ml[k] = a;
        mh[k] = b;
        kn[k] = sqrt(1.0 + min2) * (1.0 - 1e-15); /* nearest distance, rounded down */
        kf[k] = sqrt(1.0 + max2) * (1.0 + 1e-15);
        run[k] = -INFINITY;
    }
    for (int32_t s = 0; s < f->ns; s++) {
        int32_t c = f->first + f->sign * s;
        double qn, qf;
        strip_q(f, s, &qn, &qf);
        for (int32_t k = 0; k < nw; k++) {
            int32_t j0, j1;
            if (cross_cells(ec, isc, nc, qn, qf, ml[k], mh[k], &j0, &j1)) {
                double dn = qn * kn[k], df = qf * kf[k];
                float mt = tiles_max(g, f->axis, c, j0, j1);
                if (mt != -INFINITY && strip_bound((double)mt + zeps, ez, dn, df) > run[k]) {
                    float M = samples_max(g, f->axis, c, j0, j1);
                    double b = M == -INFINITY ? -INFINITY : strip_bound((double)M + zeps, ez, dn, df);
                    run[k] = b > run[k] ? b : run[k];
                }
            }
            float p = (float)run[k];
            if ((double)p < run[k])
                p = nextafterf(p, INFINITY);
            f->p[(size_t)(w0 + k) * (size_t)f->ns + (size_t)s] = p;
        }
    }
}

static void *build_worker(void *arg)
{
    build_job *job = arg;
    for (;;) {
        int part = atomic_fetch_add_explicit(&job->next, 1, memory_order_relaxed), q = 0;
        if (part >= job->nparts)
            break;
        while (part >= job->part_fan[q + 1])
            q++;
        const td_silh_fan *f = &job->s->fan[q];
        int32_t w0 = (int32_t)(part - job->part_fan[q]) * TD_SILH_PART;
        int32_t w1 = w0 + TD_SILH_PART < f->nw ? w0 + TD_SILH_PART : f->nw;
        build_part(job, f, w0, w1);
    }
    return NULL;
}

/* Runs the parts on up to `threads` threads (the caller's included). */
static void build_run(build_job *job, int threads)
{
    pthread_t tid[TD_SILH_THREADS_MAX];
    int started = 1;
    for (; started < threads; started++)
        if (pthread_create(&tid[started], NULL, build_worker, job) != 0)
            break; /* the others take its parts */
    build_worker(job);
    for (int i = 1; i < started; i++)
        pthread_join(tid[i], NULL);
}

/* Sets up the fans the image reaches: slopes, strips, wedges (all fans together at most
 * one wedge per TD_SILH_WEDGE_PX image columns, each at least that many pixels' angle
 * wide). */
static void setup_fans(td_silhouette *s, const td_grid *g, const td_camera *cam)
{
    double az0 = 0.0, az1 = 0.0, mlo[TD_SILH_FANS], mhi[TD_SILH_FANS], ang[TD_SILH_FANS], total = 0.0;
    int full = !td_camera_azimuths(cam, -0.5, -0.5, cam->width - 0.5, cam->height - 0.5, &az0, &az1);
    for (int q = 0; q < TD_SILH_FANS; q++) {
        td_silh_fan *f = &s->fan[q];
        f->axis = q & 1;
        f->sign = q < 2 ? 1 : -1;
        ang[q] = 0.0;
        if (fan_slopes(q, full, az0, az1, &mlo[q], &mhi[q])) {
            fan_strips(f, g, s->eye);
            ang[q] = atan(mhi[q]) - atan(mlo[q]);
            total += ang[q];
        }
    }
    double per = TD_SILH_WEDGE_PX * fmax(cam->pixel_angle, total / (double)(cam->width > 0 ? cam->width : 1));
    for (int q = 0; q < TD_SILH_FANS; q++) {
        td_silh_fan *f = &s->fan[q];
        if (ang[q] > 0.0 && f->ns > 0) {
            double nw = ceil(ang[q] / per);
            double cap = (double)(TD_SILH_ENTRIES_MAX / f->ns);
            nw = fmax(1.0, fmin(nw, cap));
            f->nw = (int32_t)nw;
            f->m0 = mlo[q];
            f->dm = (mhi[q] - mlo[q]) / nw;
            f->idm = 1.0 / f->dm;
        } else if (ang[q] > 0.0) {
            f->nw = -1; /* reached by the image, but its rays never meet the grid */
        }
    }
}

td_status td_silhouette_build(const td_grid *g, const td_camera *cam, int threads, td_silhouette **out,
                              td_err *err)
{
    td_status rc = TD_OK;
    td_silhouette *s = NULL;
    build_job job;
    memset(&job, 0, sizeof job);
    *out = NULL;
    if (cam->projection != TD_PROJ_PERSPECTIVE || isnan(g->zmin) || g->w < 2 || g->h < 2)
        goto out;
    s = calloc(1, sizeof *s);
    if (!s) {
        rc = td_err_set(err, TD_ENOMEM, "silhouette: no memory");
        goto out;
    }
    memcpy(s->eye, cam->o, sizeof s->eye);
    setup_fans(s, g, cam);
    for (int q = 0; q < TD_SILH_FANS && !rc; q++) {
        td_silh_fan *f = &s->fan[q];
        size_t n = f->nw > 0 ? (size_t)f->nw * (size_t)f->ns : 0;
        job.part_fan[q + 1] = job.part_fan[q] + (f->nw > 0 ? (f->nw + TD_SILH_PART - 1) / TD_SILH_PART : 0);
        if (n && !(f->p = malloc(n * sizeof *f->p)))
            rc = td_err_set(err, TD_ENOMEM, "silhouette: no memory for %zu bounds", n);
        s->entries += n;
        s->bytes += n * sizeof *f->p;
    }
    threads = threads < 1 ? 1 : (threads > TD_SILH_THREADS_MAX ? TD_SILH_THREADS_MAX : threads);
    if (rc)
        goto out;
    job.g = g;
    job.s = s;
    job.zeps = 1e-6 * (1.0 + fmax(fabs((double)g->zmin), fabs((double)g->zmax))); /* trace.c's */
    job.nparts = job.part_fan[TD_SILH_FANS];
    atomic_init(&job.next, 0);
    build_run(&job, threads);
    *out = s;
    s = NULL;
out:
    td_silhouette_free(s);
    return rc;
}

double td_silhouette_clear(const td_silhouette *s, const double d[3], uint32_t *steps)
{
    double t = 0.0;
    int q = fan_of(d[0], d[1]);
    const td_silh_fan *f = q >= 0 ? &s->fan[q] : NULL;
    if (f && f->nw < 0) {
        t = INFINITY; /* the fan's rays leave the grid behind them */
    } else if (f && f->nw > 0) {
        double along = f->sign * d[f->axis], m = d[1 - f->axis] / along;
        double u = (m - f->m0) * f->idm;
        int32_t k = u >= 0.0 && u < (double)f->nw ? ifloor(u) : -1;
        if (k >= 0) {
            const float *row = f->p + (size_t)k * (size_t)f->ns;
            double e = d[2] / sqrt(d[0] * d[0] + d[1] * d[1]); /* finite: |d_xy| >= |along| > 0 */
            int32_t lo = 0, hi = f->ns;
            uint32_t n = 0;
            while (lo < hi) { /* the first strip whose running bound reaches e */
                int32_t mid = lo + (hi - lo) / 2;
                n++;
                if ((double)row[mid] >= e)
                    hi = mid;
                else
                    lo = mid + 1;
            }
            *steps += n;
            if (lo == f->ns) {
                t = INFINITY;
            } else {
                double qn, qf;
                strip_q(f, lo, &qn, &qf);
                t = qn / along * (1.0 - 1e-12);
            }
        }
    }
    return t;
}

void td_silhouette_free(td_silhouette *s)
{
    if (s) {
        for (int q = 0; q < TD_SILH_FANS; q++)
            free(s->fan[q].p);
        free(s);
    }
}
