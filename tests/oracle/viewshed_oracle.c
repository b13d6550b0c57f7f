/* viewshed_oracle.c: td_viewshed held to the double-precision reference (reference.c), and
 * gdal_viewshed's answers judged by it.
 *
 *   viewshed_oracle DEM [--targets K] [--seed S]
 *       For observers on the highest sample (a peak), the lowest (a pit), the grid's
 *       south-west corner (or the valid sample nearest it), beside a void when the DEM has
 *       any, 0.3 cells east and 0.2 north of the peak (under it, in its cell), and a random
 *       point, on every surface: the viewshed (method auto), then K
 *       random targets (and every target within 3 cells of the observer) re-traced by
 *       td_ref_trace on the same segment (td_viewshed_ray) and by td_occluded with every
 *       method; then from the peak again with Earth curvature (k = 0.13), judged on a
 *       grid lowered here by c s^2 (viewshed.h's model). A visible answer agrees when the
 *       reference finds no hit, hidden when it finds one; the other answer is a tie when
 *       the reference's hit never definitely crosses the surface, or a clear segment comes
 *       within the float band of it before the target's last tenth of a cell (oracle.c's
 *       band: 1 mm plus float32 rounding, times 1 + the steepest slope). Every viewshed
 *       (the horizon sweep, core/vsweep.c) is also held byte for byte to the one cast a
 *       sample gives (algo cast). Exit 1 on any other answer.
 *   viewshed_oracle DEM --gdal RAW X Y H [--surface S]
 *       RAW: gdal_viewshed's output as raw bytes in file order (255 seen, 0 not, else
 *       outside). Prints the agreement with terrad in per cent of the samples both answer
 *       and, per disagreement, what the reference says (scripts/viewshed-bench, `make bench`). */
#include <float.h>
#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "accel.h"
#include "dem.h"
#include "reference.h"
#include "viewshed.h"

typedef struct oracle {
    td_grid *g;
    td_accel *acc;
    td_view v;
    double eps;
    uint64_t agree, tie, wrong, methods_wrong;
    uint64_t sweep_same, sweep_wrong; /* the sweep's bytes against the per-sample cast's */
} oracle;

static uint64_t rnd(uint64_t *s)
{
    *s = *s * 6364136223846793005ull + 1442695040888963407ull;
    return *s >> 17;
}

/* The reference's word on the segment r: 1 visible (no exact hit), 0 hidden; *band set
 * when the other answer is a tie too. Hidden: the segment never definitely crosses the
 * surface. Visible: it comes within the band of the surface before the last tenth of a
 * cell (every segment comes within the band at its end, where it meets its target: that
 * is no excuse for a hidden answer). */
static int ref_visible(const oracle *o, td_surface s, const td_ray *r, td_ref_hit *h, int *band)
{
    td_ref_trace(o->g, s, r, o->eps, h);
    *band = h->t < INFINITY && !(h->t_strict < INFINITY);
    if (!(h->t < INFINITY) && h->t_near < INFINITY) {
        td_ref_hit h2;
        td_ray r2 = *r;
        double lh = hypot(r->d[0], r->d[1]), cut = lh > 0 ? 0.1 * fmin(o->g->sx, o->g->sy) / lh : 0;
        r2.tmax = r->tmax - fmin(cut, 0.5);
        td_ref_trace(o->g, s, &r2, o->eps, &h2);
        *band = h2.t_near < INFINITY;
    }
    return !(h->t < INFINITY);
}

/* Judges one target of a viewshed (out: its byte, one observer). */
static void judge_target(oracle *o, td_surface s, const double eye[3], int32_t i, int32_t j,
                         uint8_t got)
{
    td_ray r;
    td_ref_hit h;
    int kind = td_viewshed_ray(o->g, s, eye[0], eye[1], eye[2], i, j, 0.0, &r), want, clear, band;
    if (kind != 0) {
        int ok = (kind < 0) == (got == TD_VS_OUTSIDE);
        o->agree += ok;
        o->wrong += !ok;
        return;
    }
    clear = ref_visible(o, s, &r, &h, &band);
    /* the rule's own part (docs/viewshed.md "Under the surface is not a line of sight"): a
     * segment that starts under the surface is blocked though it may cross nothing (the
     * linear surface's chord under an eye off its sample may be over the eye). Judged on
     * the reference's heights (td_ref_gap), not core's td_viewshed_starts_under: under at
     * the start by more than T, or on the surface there within T and under by more than T
     * 2^-20 of the segment on (it crossed the surface in between: blocked either way). A
     * start on the surface within T that does not go under is a tie. T is 2^-40 of the
     * eye's height (4e-9 m at 4,300 m): 256 times core's tolerance, hundreds of times the
     * rounding of either side's height (a few ulps), and far under the gap a segment from
     * an eye on the ground opens at the start (2^-30 of its rise over the ground's: 1e-7 m
     * for 100 m). */
    double T = 0x1p-40 * (1.0 + fabs(r.o[2])), g0 = td_ref_gap(o->g, s, &r, r.tmin);
    int under = g0 < -T || (g0 <= T && r.tmin < 0x1p-20 && td_ref_gap(o->g, s, &r, 0x1p-20) < -T);
    band = band || (!under && fabs(g0) <= T);
    want = clear && !under;
    if (want == (got == 1)) {
        o->agree++;
    } else if (band) {
        o->tie++;
    } else {
        o->wrong++;
        printf("  WRONG %s: target (%d, %d) from (%.17g, %.17g, %.17g): terrad %s, reference %s (t %.17g)\n",
               td_surface_name(s), (int)i, (int)j, eye[0], eye[1], eye[2], got ? "visible" : "hidden",
               want ? "visible" : "hidden", h.t);
    }
    for (int m = 0; m < TD_METHOD_COUNT; m++) { /* every method, same segment */
        uint32_t steps = 0;
        if ((!td_occluded(&o->v, (td_method)m, s, &r, NULL, &steps)) != clear && !band) {
            o->methods_wrong++;
            printf("  WRONG %s/%s: target (%d, %d) from (%.17g, %.17g, %.17g)\n", td_method_name((td_method)m),
                   td_surface_name(s), (int)i, (int)j, eye[0], eye[1], eye[2]);
        }
    }
}

/* The observers of the test: peak, pit, corner, void edge, beside the peak, random (x, y in
 * metres); *beside: the index of the one beside the peak (-1: none). */
static int pick_observers(const td_grid *g, uint64_t *seed, td_vs_point *p, int *beside)
{
    int32_t hi = -1, lo = -1, corner = -1, edge = -1;
    int n = 0;
    for (int32_t k = 0; k < g->w * g->h; k++) {
        int32_t i = k % g->w, j = k / g->w;
        float z = g->z[k];
        /* the cell north-east of the sample has a surface (every surface's, the plane's too) */
        if (isnan(td_viewshed_ground(g, TD_SURFACE_PLANE, i * g->sx, j * g->sy)) || i == g->w - 1 ||
            j == g->h - 1)
            continue;
        hi = hi < 0 || z > g->z[hi] ? k : hi;
        lo = lo < 0 || z < g->z[lo] ? k : lo;
        if (edge < 0 && i > 0 && j > 0 && (isnan(g->z[k - 1]) || isnan(g->z[k - g->w])))
            edge = k; /* holes to its west or south */
        corner = corner < 0 ? k : corner;
    }
    for (int c = 0; c < 4; c++) {
        int32_t k = c == 0 ? hi : c == 1 ? lo : c == 2 ? corner : edge;
        if (k >= 0)
            p[n++] = (td_vs_point){(k % g->w) * g->sx, (k / g->w) * g->sy};
    }
    *beside = hi >= 0 ? n : -1;
    if (hi >= 0) /* where a click near the peak lands: inside its north-east cell, under the peak */
        p[n++] = (td_vs_point){(hi % g->w + 0.3) * g->sx, (hi / g->w + 0.2) * g->sy};
    for (int tries = 0; tries < 1000; tries++) {
        td_vs_point q = {(double)(rnd(seed) % 100000) / 1e5 * (g->w - 1) * g->sx,
                         (double)(rnd(seed) % 100000) / 1e5 * (g->h - 1) * g->sy};
        if (!isnan(td_viewshed_ground(g, TD_SURFACE_PLANE, q.x, q.y))) {
            p[n++] = q;
            break;
        }
    }
    return n;
}

/* Options of a one-observer viewshed (two threads). */
static void one_observer(td_viewshed_opts *vo, const td_vs_point *p, double height, td_surface s)
{
    td_viewshed_opts_default(vo);
    vo->obs = p;
    vo->nobs = 1;
    vo->height = height;
    vo->surface = s;
    vo->threads = 2;
}

/* The grid lowered by c s^2 about p, computed here as the curvature model says (viewshed.h),
 * and a view of it through the dataset's max-mipmaps (upper bounds of it too). */
static td_grid *lowered(const td_grid *g, td_vs_point p, double c)
{
    td_grid *l = NULL;
    if (td_grid_create(g->w, g->h, g->sx, g->sy, g->tile_log2, NULL, &l, NULL))
        return NULL;
    for (int32_t j = 0; j < g->h; j++)
        for (int32_t i = 0; i < g->w; i++) {
            double dx = i * g->sx - p.x, dy = j * g->sy - p.y;
            size_t k = (size_t)j * g->w + i;
            l->z[k] = (float)((double)g->z[k] - c * (dx * dx + dy * dy));
        }
    if (td_grid_finish(l, NULL)) {
        td_grid_free(l);
        l = NULL;
    }
    return l;
}

/* The sweep's viewshed out (stats st) of options vo against the one cast a sample gives:
 * every byte. */
static int sweep_vs_cast(oracle *o, const td_viewshed_opts *vo, const uint8_t *out, const td_viewshed_stats *st)
{
    size_t n = (size_t)o->g->w * o->g->h;
    uint8_t *cast = malloc(n);
    td_viewshed_opts co = *vo;
    td_viewshed_stats cst;
    td_err err;
    int ok = cast != NULL;
    co.algo = TD_VS_ALGO_CAST;
    if (ok && td_viewshed(&o->v, &co, cast, &cst, &err)) {
        printf("  cast viewshed refused: %s\n", err.msg);
        ok = 0;
    }
    for (size_t k = 0; ok && k < n; k++) {
        int same = cast[k] == out[k];
        o->sweep_same += same;
        if (!same && o->sweep_wrong++ < 10)
            printf("  SWEEP WRONG %s: target (%d, %d): sweep %d, cast %d\n", td_surface_name(vo->surface),
                   (int)(k % o->g->w), (int)(o->g->h - 1 - k / o->g->w), out[k], cast[k]);
    }
    if (ok)
        printf("  %-8s sweep: %.1f%% of the samples decided without a cast\n", td_surface_name(vo->surface),
               100.0 * (double)st->swept / (double)(st->inside ? st->inside : 1));
    free(cast);
    return ok;
}

/* One observer on one surface (with curvature k = 0.13 when curv): the viewshed (the
 * sweep's, held to the cast's byte for byte), then the targets judged (with curvature,
 * on the lowered grid). */
static int check_observer(oracle *o, td_surface s, td_vs_point p, double height, int curv, int targets,
                          uint64_t *seed, uint8_t *out)
{
    td_viewshed_opts vo;
    td_viewshed_stats st;
    td_err err;
    oracle low = *o, *jo = curv ? &low : o;
    td_tile_accel *bound = NULL;
    double eye[3];
    int ok = 0;
    one_observer(&vo, &p, height, s);
    vo.curvature = curv;
    if (td_viewshed(&o->v, &vo, out, &st, &err)) {
        printf("  viewshed from (%g, %g) on %s refused: %s\n", p.x, p.y, td_surface_name(s), err.msg);
        return 0;
    }
    if (!sweep_vs_cast(o, &vo, out, &st))
        return 0;
    if (curv) {
        size_t n = (size_t)o->g->tiles_x * o->g->tiles_y;
        low.g = lowered(o->g, p, (1.0 - vo.k) / (2.0 * TD_EARTH_RADIUS_M));
        bound = calloc(n, sizeof *bound);
        if (!low.g || !bound)
            goto out;
        for (size_t k = 0; k < n; k++)
            bound[k].maxmip = o->acc->tiles[k].maxmip;
        low.v.grid = low.g;
        low.v.accel = bound;
        low.agree = low.tie = low.wrong = low.methods_wrong = 0;
    }
    eye[0] = p.x;
    eye[1] = p.y;
    eye[2] = td_viewshed_ground(jo->g, s, p.x, p.y) + height;
    for (int k = 0; k < targets; k++) {
        int32_t i = (int32_t)(rnd(seed) % (uint64_t)o->g->w), j = (int32_t)(rnd(seed) % (uint64_t)o->g->h);
        judge_target(jo, s, eye, i, j, out[(size_t)(o->g->h - 1 - j) * o->g->w + i]);
    }
    for (int32_t dj = -3; dj <= 3; dj++) /* the observer's own cells and their neighbours */
        for (int32_t di = -3; di <= 3; di++) {
            int32_t i = (int32_t)floor(p.x / o->g->sx) + di, j = (int32_t)floor(p.y / o->g->sy) + dj;
            if (i >= 0 && j >= 0 && i < o->g->w && j < o->g->h)
                judge_target(jo, s, eye, i, j, out[(size_t)(o->g->h - 1 - j) * o->g->w + i]);
        }
    printf("  %-8s from (%9.2f, %9.2f) +%.0f m%s: %5.1f%% of %" PRIu64 " samples seen, %.1f steps a ray\n",
           td_surface_name(s), p.x, p.y, height, curv ? ", curvature" : "",
           100.0 * (double)st.visible / (double)(st.inside ? st.inside : 1), st.inside,
           (double)st.steps / (double)(st.rays ? st.rays : 1));
    ok = 1;
out:
    if (curv) {
        o->agree += low.agree;
        o->tie += low.tie;
        o->wrong += low.wrong;
        o->methods_wrong += low.methods_wrong;
        td_grid_free(low.g);
    }
    free(bound);
    return ok;
}

static int load(const char *path, oracle *o)
{
    td_dem_opts dopt;
    td_accel_opts ao;
    td_err err;
    double X, Y, scale;
    td_dem_opts_default(&dopt);
    dopt.tile_log2 = 5; /* seams often */
    if (td_dem_load(path, &dopt, &o->g, &err)) {
        fprintf(stderr, "viewshed_oracle: %s\n", err.msg);
        return 0;
    }
    td_accel_opts_default(&ao);
    ao.maxmip = ao.planes = 1;
    ao.threads = 2;
    if (td_accel_build(o->g, &ao, &o->acc, NULL, &err)) {
        fprintf(stderr, "viewshed_oracle: %s\n", err.msg);
        return 0;
    }
    o->v.grid = o->g;
    o->v.accel = o->acc->tiles;
    X = (o->g->w - 1) * o->g->sx;
    Y = (o->g->h - 1) * o->g->sy;
    scale = fmax(fmax(X, Y), fmax(fabs(o->g->zmin), fabs(o->g->zmax)));
    o->eps = (1e-3 + 2.0 * FLT_EPSILON * scale) * (1.0 + td_ref_max_slope(o->g));
    return 1;
}

static int run_check(oracle *o, int targets, uint64_t seed)
{
    td_vs_point obs[6];
    int beside, n = pick_observers(o->g, &seed, obs, &beside), ok = 1;
    uint8_t *out = malloc((size_t)o->g->w * o->g->h);
    if (!out)
        return 0;
    for (int k = 0; k < n; k++)
        for (int s = 0; s < TD_SURFACE_COUNT; s++)
            ok &= check_observer(o, (td_surface)s, obs[k], k == 1 ? 10.0 : 2.0, 0, targets, &seed, out);
    for (int s = 0; s < TD_SURFACE_COUNT; s++) /* from the peak, over the curved Earth */
        ok &= check_observer(o, (td_surface)s, obs[0], 2.0, 1, targets, &seed, out);
    /* beside the peak on the ground: the segments that leave it uphill start under the
     * surface (the rule's start-under part, judged on the reference's heights) */
    for (int s = 0; s < TD_SURFACE_COUNT && beside >= 0; s++)
        ok &= check_observer(o, (td_surface)s, obs[beside], 0.0, 0, targets, &seed, out);
    printf("targets judged: %" PRIu64 " agree, %" PRIu64 " ties (float band %.3g m), %" PRIu64
           " wrong; td_occluded by each method on the same segments: %" PRIu64 " wrong\n",
           o->agree, o->tie, o->eps, o->wrong, o->methods_wrong);
    printf("the sweep against one cast a sample: %" PRIu64 " samples the same, %" PRIu64 " different\n",
           o->sweep_same, o->sweep_wrong);
    free(out);
    return ok && o->wrong == 0 && o->methods_wrong == 0 && o->agree > 0 && o->sweep_wrong == 0 &&
           o->sweep_same > 0;
}

/* --gdal: gdal_viewshed's bytes against terrad's, the disagreements judged. */
static int run_gdal(oracle *o, const char *raw, td_vs_point p, double height, td_surface s)
{
    size_t n = (size_t)o->g->w * o->g->h;
    uint8_t *gd = malloc(n), *out = malloc(n);
    FILE *f = fopen(raw, "rb");
    td_viewshed_opts vo;
    td_viewshed_stats st;
    td_err err;
    uint64_t both = 0, same = 0, verdict[2][3] = {{0}}; /* [gdal visible][gdal wrong, tie, terrad wrong] */
    double eye[3];
    int ok = gd && out && f && fread(gd, 1, n, f) == n, shown = 0, ties_shown = 0;
    if (f)
        fclose(f);
    one_observer(&vo, &p, height, s);
    if (!ok || td_viewshed(&o->v, &vo, out, &st, &err)) {
        fprintf(stderr, "viewshed_oracle: %s\n", ok ? err.msg : "cannot read the GDAL raster");
        ok = 0;
        goto out;
    }
    eye[0] = p.x;
    eye[1] = p.y;
    eye[2] = td_viewshed_ground(o->g, s, p.x, p.y) + height;
    for (size_t k = 0; k < n; k++) {
        int32_t i = (int32_t)(k % o->g->w), j = o->g->h - 1 - (int32_t)(k / o->g->w);
        td_ray r;
        td_ref_hit h;
        int want, band;
        if (out[k] == TD_VS_OUTSIDE || (gd[k] != 0 && gd[k] != 255))
            continue;
        both++;
        if ((out[k] == 1) == (gd[k] == 255)) {
            same++;
            continue;
        }
        if (td_viewshed_ray(o->g, s, eye[0], eye[1], eye[2], i, j, 0.0, &r) != 0)
            continue;
        want = ref_visible(o, s, &r, &h, &band);
        verdict[gd[k] == 255][band ? 1 : want == (out[k] == 1) ? 0 : 2]++;
        if (band && ties_shown < 3 && getenv("ORACLE_SHOW_TIES")) {
            double t = h.t < INFINITY ? h.t : h.t_near;
            printf("  tie: sample (col %d, row %d), terrad %s, segment within %.3g m of the surface at t %.9f "
                   "(%.3f, %.3f, %.4f; cell %d %d)\n", (int)i, (int)(o->g->h - 1 - j), out[k] ? "visible" : "hidden",
                   o->eps, t, (r.o[0] + t * r.d[0]) / o->g->sx, (r.o[1] + t * r.d[1]) / o->g->sy, r.o[2] + t * r.d[2],
                   (int)h.ci, (int)h.cj);
            ties_shown++;
        }
        if (!band && shown < 3 && want != (gd[k] == 255)) {
            double t = h.t < INFINITY ? h.t : 0.5, x = r.o[0] + t * r.d[0], y = r.o[1] + t * r.d[1];
            printf("  e.g. sample (col %d, row %d): gdal %s, terrad and the reference %s",
                   (int)i, (int)(o->g->h - 1 - j), gd[k] ? "visible" : "hidden", want ? "visible" : "hidden");
            if (h.t < INFINITY) {
                const td_grid *g = o->g;
                printf(": the segment meets the %s surface at (%.1f, %.1f, %.2f), %.0f m from the eye, in the "
                       "cell whose corners are %.2f %.2f %.2f %.2f m\n",
                       td_surface_name(s), x, y, r.o[2] + t * r.d[2], td_ref_dist(&r, 0, t),
                       td_grid_at(g, h.ci, h.cj), td_grid_at(g, h.ci + 1, h.cj), td_grid_at(g, h.ci, h.cj + 1),
                       td_grid_at(g, h.ci + 1, h.cj + 1));
            } else
                printf(": the segment clears the surface all the way\n");
            shown++;
        }
    }
    printf("%s: agreement %.2f%% of %" PRIu64 " samples both answer; %" PRIu64 " differ. By the reference: "
           "gdal visible, wrong %" PRIu64 ", tie %" PRIu64 ", terrad wrong %" PRIu64 "; gdal hidden, wrong %" PRIu64
           ", tie %" PRIu64 ", terrad wrong %" PRIu64 "\n",
           td_surface_name(s), 100.0 * (double)same / (double)(both ? both : 1), both, both - same,
           verdict[1][0], verdict[1][1], verdict[1][2], verdict[0][0], verdict[0][1], verdict[0][2]);
out:
    free(gd);
    free(out);
    return ok;
}

int main(int argc, char **argv)
{
    oracle o;
    int ok = 0, targets = 3000;
    uint64_t seed = 18;
    memset(&o, 0, sizeof o);
    if (argc < 2 || !load(argv[1], &o))
        goto out;
    if (argc >= 7 && !strcmp(argv[2], "--gdal")) {
        td_surface s = TD_SURFACE_BILINEAR;
        if (argc >= 9 && !strcmp(argv[7], "--surface") && td_surface_parse(argv[8], &s)) {
            fprintf(stderr, "viewshed_oracle: unknown surface %s\n", argv[8]);
            goto out;
        }
        ok = run_gdal(&o, argv[3], (td_vs_point){atof(argv[4]), atof(argv[5])}, atof(argv[6]), s);
        goto out;
    }
    for (int a = 2; a + 1 < argc; a += 2) {
        if (!strcmp(argv[a], "--targets"))
            targets = atoi(argv[a + 1]);
        else if (!strcmp(argv[a], "--seed"))
            seed = strtoull(argv[a + 1], NULL, 10);
    }
    printf("%s: %d x %d samples, spacing %.3f x %.3f m, float band %.3g m\n", argv[1], (int)o.g->w,
           (int)o.g->h, o.g->sx, o.g->sy, o.eps);
    ok = run_check(&o, targets, seed);
out:
    td_accel_free(o.acc);
    td_grid_free(o.g);
    return ok ? 0 : 1;
}
