/* iso_accuracy.c: measures McGuire and Sibley's claim that an isometric height field's
 * elevation, normal and shading error is 25% lower on average than the square grid's with
 * the same samples, and strictly lower whatever the features' orientation and frequency
 * (issue 14, docs/isometric.md). Not a test: a program that prints figures.
 *
 * Four reconstructions from (about) the same number of samples:
 *   sq-tri   the square grid, two triangles per cell split SE-NW (terrad's `triangle`)
 *   sq-bil   the square grid, bilinear patches (terrad's `bilinear`)
 *   iso-sq   the isometric lattice with square rows (b = a = h: the paper's square tiles)
 *   iso-eq   the isometric lattice with equilateral triangles at the same density
 * against (a) analytic surfaces on a 64 x 64 grid of spacing h = 1, evaluated at 36864
 * random points over the middle 48 x 48 (no border effects): single sinusoids and sums of
 * two (crossed at 90 degrees) swept over orientation 0 .. 175 degrees (not 0 .. 90: the
 * square grid's diagonal makes it symmetric under a half turn only) and frequency up to
 * 0.9 Nyquist, averaged over 4 phases, amplitude set for a largest slope of 0.5;
 * Gaussian hills; a sharp ridge swept over orientation; and (b) the fixture DEMs
 * subsampled 2x, 4x, 8x (point sampling, no prefilter) against the full grid's bilinear
 * surface at 4 random points per full-grid cell. Errors: mean |dz| (analytic: in units of the
 * amplitude), mean angle between normals (degrees), mean |Lambert difference| over 4 suns
 * at 35 degrees elevation (azimuths 0, 45, 90, 135).
 *
 * Also times td_iso_trace against td_trace (incremental, triangle) on the same rays over
 * the same samples (one thread; a shared machine: indicative).
 *
 * Usage: iso-accuracy DATA_DIR OUT_DIR  (writes OUT_DIR/isometric-tables.md and
 * OUT_DIR/bench/iso-*.svg; run by hand, see docs/isometric.md; about 3 minutes), or
 * iso-accuracy DATA_DIR --timing (the trace-cost table only, to stdout), or iso-accuracy
 * DATA_DIR --lod [DEM] (the levels of detail's packed twins only, to stdout), or
 * iso-accuracy DATA_DIR --cones [DEM] (steps per ray of the square levels' methods and of
 * the lattice walk with and without its pyramid: docs/isometric.md, "Parametric"), or
 * iso-accuracy DATA_DIR --tiles DEM (map tiles on both lattices against the full grid). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "accel.h"
#include "bench_svg.h"
#include "dem.h"
#include "isogrid.h"
#include "lod.h"
#include "render.h"
#include "trace.h"

#define NREC 4
#define NFREQ 6
#define NTH 36 /* orientations 0, 5, .. 175 degrees */
#define NPHASE 4
#define NMET 3

static const char *const rec_names[NREC] = {"sq-tri", "sq-bil", "iso-sq", "iso-eq"};
static const char *const met_names[NMET] = {"elevation", "normal (deg)", "shading"};
static const double freqs[NFREQ] = {0.1, 0.2, 0.3, 0.5, 0.7, 0.9}; /* of Nyquist */
static const double phases[NPHASE] = {0.3, 1.9, 3.4, 5.1};
static const double PI = 3.14159265358979323846;

/* Uniform in [0, 1). The evaluation points are random, not on a regular grid: a grid of
 * points commensurate with the square lattice samples its cells' error unevenly (a 0.25 h
 * grid measured the square grid's error 5% low). */
static double rnd(uint64_t *s)
{
    *s = *s * 6364136223846793005ull + 1442695040888963407ull;
    return (double)(*s >> 11) / 9007199254740992.0;
}

/* The reconstructions of one surface. */
typedef struct recs {
    td_grid *sq;
    td_iso *iso[2];
} recs;

typedef struct acc {
    double sum[NMET];
    double n;
} acc;

/* An analytic surface: z and gradient at (x, y). */
typedef struct surf {
    int kind; /* 0 wave, 1 crossed sum, 2 Gaussian hills, 3 ridge */
    double th, f, ph, amp;
} surf;

static void truth(const surf *s, double x, double y, double *z, double g[2])
{
    double c = cos(s->th), sn = sin(s->th), k = 2.0 * PI * s->f;
    g[0] = g[1] = *z = 0.0;
    if (s->kind == 0 || s->kind == 1) {
        for (int w = 0; w <= s->kind; w++) {
            double cw = w ? -sn : c, sw = w ? c : sn, ph = s->ph + 1.7 * w;
            double arg = k * (x * cw + y * sw) + ph;
            *z += s->amp * sin(arg);
            g[0] += s->amp * k * cw * cos(arg);
            g[1] += s->amp * k * sw * cos(arg);
        }
    } else if (s->kind == 2) {
        static const double hills[6][4] = {{20, 22, 3, 4}, {40, 18, 5, 6}, {31, 40, 2, 3},
                                           {45, 44, 4, 5}, {16, 41, 6, 4}, {30, 28, 1.5, 2}};
        for (int i = 0; i < 6; i++) {
            double dx = x - hills[i][0], dy = y - hills[i][1], sg = hills[i][2];
            double e = hills[i][3] * exp(-(dx * dx + dy * dy) / (2 * sg * sg));
            *z += e;
            g[0] -= e * dx / (sg * sg);
            g[1] -= e * dy / (sg * sg);
        }
    } else { /* ridge crest along direction th, ph off (32, 32), half-width 4 */
        double d = -(x - 32.0) * sn + (y - 32.0) * c - s->ph, w = 4.0;
        if (fabs(d) < w) {
            double sg = d > 0 ? -1.0 : 1.0;
            *z = 2.0 * (1.0 - fabs(d) / w);
            g[0] = 2.0 / w * sg * -sn;
            g[1] = 2.0 / w * sg * c;
        }
    }
}

static double truth_z(void *ctx, double x, double y)
{
    double z, g[2];
    truth(ctx, x, y, &z, g);
    return z;
}

static void grad_normal(const double g[2], double n[3])
{
    double l = sqrt(g[0] * g[0] + g[1] * g[1] + 1.0);
    n[0] = -g[0] / l;
    n[1] = -g[1] / l;
    n[2] = 1.0 / l;
}

/* The square grid's triangle surface (SE-NW diagonal, as trace.c's `triangle`). */
static int sq_tri(const td_grid *g, double x, double y, double *z, double n[3])
{
    double fi = floor(x / g->sx), fj = floor(y / g->sy), u, v, gr[2];
    int32_t i = fi < 0 ? 0 : (fi > g->w - 2 ? g->w - 2 : (int32_t)fi);
    int32_t j = fj < 0 ? 0 : (fj > g->h - 2 ? g->h - 2 : (int32_t)fj);
    double z00 = td_grid_at(g, i, j), z10 = td_grid_at(g, i + 1, j);
    double z01 = td_grid_at(g, i, j + 1), z11 = td_grid_at(g, i + 1, j + 1);
    int ok = !(isnan(z00) || isnan(z10) || isnan(z01) || isnan(z11));
    u = x / g->sx - i;
    v = y / g->sy - j;
    if (ok && u + v <= 1.0) {
        *z = z00 + u * (z10 - z00) + v * (z01 - z00);
        gr[0] = (z10 - z00) / g->sx;
        gr[1] = (z01 - z00) / g->sy;
    } else if (ok) {
        *z = z11 + (1.0 - u) * (z01 - z11) + (1.0 - v) * (z10 - z11);
        gr[0] = (z11 - z01) / g->sx;
        gr[1] = (z11 - z10) / g->sy;
    }
    if (ok)
        grad_normal(gr, n);
    return ok;
}

static int rec_eval(const recs *R, int k, double x, double y, double *z, double n[3])
{
    int ok;
    if (k == 0)
        ok = sq_tri(R->sq, x, y, z, n);
    else if (k == 1)
        ok = td_grid_bilinear(R->sq, x, y, z, n);
    else
        ok = td_iso_eval(R->iso[k - 2], x, y, z, n);
    return ok;
}

static double shading_diff(const double n[3], const double nt[3])
{
    double s = 0.0, el = 35.0 * PI / 180.0;
    for (int a = 0; a < 4; a++) {
        double az = a * 45.0 * PI / 180.0;
        double L[3] = {sin(az) * cos(el), cos(az) * cos(el), sin(el)};
        double l1 = n[0] * L[0] + n[1] * L[1] + n[2] * L[2];
        double l2 = nt[0] * L[0] + nt[1] * L[1] + nt[2] * L[2];
        s += fabs((l1 > 0 ? l1 : 0) - (l2 > 0 ? l2 : 0));
    }
    return s / 4.0;
}

static void add_point(acc *a, double z, const double n[3], double zt, const double nt[3],
                      double zscale)
{
    double d = n[0] * nt[0] + n[1] * nt[1] + n[2] * nt[2];
    d = d > 1.0 ? 1.0 : d;
    a->sum[0] += fabs(z - zt) / zscale;
    a->sum[1] += acos(d) * 180.0 / PI;
    a->sum[2] += shading_diff(n, nt);
    a->n += 1.0;
}

static void acc_mean(const acc *a, double out[NMET])
{
    for (int m = 0; m < NMET; m++)
        out[m] = a->n > 0 ? a->sum[m] / a->n : NAN;
}

/* The four reconstructions of f on a 64 x 64 domain of spacing 1 (65 x 65 samples). */
static td_status recs_from_fn(td_iso_fn f, void *ctx, recs *R, td_err *err)
{
    td_status rc;
    double a = sqrt(2.0 / sqrt(3.0)), b = a * sqrt(3.0) / 2.0;
    memset(R, 0, sizeof *R);
    rc = td_grid_create(65, 65, 1.0, 1.0, 6, NULL, &R->sq, err);
    if (rc)
        goto out;
    for (int32_t j = 0; j < 65; j++)
        for (int32_t i = 0; i < 65; i++)
            R->sq->z[j * 65 + i] = (float)f(ctx, i, j);
    rc = td_grid_finish(R->sq, err);
    if (!rc)
        rc = td_iso_create(65, 65, 1.0, 1.0, &R->iso[0], err);
    if (!rc)
        rc = td_iso_create((int32_t)(64.0 / a) + 1, (int32_t)(64.0 / b) + 1, a, b, &R->iso[1], err);
    if (rc)
        goto out;
    td_iso_sample(R->iso[0], f, ctx);
    td_iso_sample(R->iso[1], f, ctx);
out:
    return rc;
}

static void recs_free(recs *R)
{
    td_grid_free(R->sq);
    td_iso_free(R->iso[0]);
    td_iso_free(R->iso[1]);
}

/* Mean errors of the reconstructions of analytic surface s (out[rec][metric]). */
static td_status analytic(const surf *s, double zscale, double out[NREC][NMET], td_err *err)
{
    recs R;
    acc a[NREC];
    td_status rc = recs_from_fn(truth_z, (void *)s, &R, err);
    memset(a, 0, sizeof a);
    for (uint64_t i = 0, seed = 12345; !rc && i < 192 * 192; i++) {
        double x = 8.0 + 48.0 * rnd(&seed), y = 8.0 + 48.0 * rnd(&seed);
        double zt, g[2], nt[3], z, n[3];
        truth(s, x, y, &zt, g);
        grad_normal(g, nt);
        for (int k = 0; k < NREC; k++)
            if (rec_eval(&R, k, x, y, &z, n))
                add_point(&a[k], z, n, zt, nt, zscale);
    }
    for (int k = 0; k < NREC; k++)
        acc_mean(&a[k], out[k]);
    recs_free(&R);
    return rc;
}

/* A wave-like family (kind 0 or 1) swept over frequency and orientation:
 * res[f][th][rec][met], averaged over the phases. */
static td_status sweep(int kind, double res[NFREQ][NTH][NREC][NMET], td_err *err)
{
    td_status rc = TD_OK;
    for (int fi = 0; fi < NFREQ && !rc; fi++) {
        for (int ti = 0; ti < NTH && !rc; ti++) {
            memset(res[fi][ti], 0, sizeof res[fi][ti]);
            for (int p = 0; p < NPHASE && !rc; p++) {
                double one[NREC][NMET];
                surf s = {kind, ti * 5.0 * PI / 180.0, freqs[fi] * 0.5, phases[p], 0.0};
                s.amp = 0.5 / (2.0 * PI * s.f);
                rc = analytic(&s, s.amp, one, err);
                for (int k = 0; k < NREC; k++)
                    for (int m = 0; m < NMET; m++)
                        res[fi][ti][k][m] += one[k][m] / NPHASE;
            }
        }
    }
    return rc;
}

/* --- the DEMs ----------------------------------------------------------------------- */

static td_status subsample(const td_grid *g, int32_t s, td_grid **out, td_err *err)
{
    int32_t w = (g->w - 1) / s + 1, h = (g->h - 1) / s + 1;
    td_status rc = td_grid_create(w, h, g->sx * s, g->sy * s, 8, NULL, out, err);
    if (rc)
        goto out;
    for (int32_t j = 0; j < h; j++)
        for (int32_t i = 0; i < w; i++)
            (*out)->z[(size_t)j * w + i] = td_grid_at(g, i * s, j * s);
    rc = td_grid_finish(*out, err);
out:
    return rc;
}

/* Errors of the reconstructions of g subsampled s x against g's bilinear surface, at
 * random points where every reconstruction is defined; elevation in metres. n_samples gets each
 * reconstruction's sample count. */
static td_status dem_case(const td_grid *g, int32_t s, double out[NREC][NMET],
                          long n_samples[NREC], td_err *err)
{
    recs R;
    acc a[NREC];
    td_status rc;
    double X, Y;

    memset(&R, 0, sizeof R);
    memset(a, 0, sizeof a);
    rc = subsample(g, s, &R.sq, err);
    if (!rc)
        rc = td_iso_from_grid(g, s, TD_ISO_ROWS_SQUARE, &R.iso[0], err);
    if (!rc)
        rc = td_iso_from_grid(g, s, TD_ISO_ROWS_EQUILATERAL, &R.iso[1], err);
    if (rc)
        goto out;
    X = (R.sq->w - 1) * R.sq->sx;
    Y = (R.sq->h - 1) * R.sq->sy;
    for (int k = 0; k < 2; k++) {
        X = fmin(X, (R.iso[k]->nx - 1) * R.iso[k]->a);
        Y = fmin(Y, (R.iso[k]->ny - 1) * R.iso[k]->b);
    }
    for (uint64_t i = 0, seed = 777, n = (uint64_t)(4.0 * X / g->sx * Y / g->sy); i < n; i++) {
        double x = X * rnd(&seed), y = Y * rnd(&seed), zt, nt[3], z[NREC], nr[NREC][3];
        int ok = td_grid_bilinear(g, x, y, &zt, nt);
        for (int k = 0; k < NREC && ok; k++)
            ok = rec_eval(&R, k, x, y, &z[k], nr[k]);
        for (int k = 0; k < NREC && ok; k++)
            add_point(&a[k], z[k], nr[k], zt, nt, 1.0);
    }
    for (int k = 0; k < NREC; k++)
        acc_mean(&a[k], out[k]);
    n_samples[0] = n_samples[1] = (long)R.sq->w * R.sq->h;
    for (int k = 0; k < 2; k++)
        n_samples[k + 2] = (long)td_iso_row_offset(R.iso[k]->nx, R.iso[k]->ny);
out:
    recs_free(&R);
    return rc;
}

/* --- the report --------------------------------------------------------------------- */

typedef double wave_res[NFREQ][NTH][NREC][NMET];

/* One table per metric: rows frequencies, columns the reconstructions' means over
 * orientation, the ratios to the square ones and how many orientations iso-eq wins. */
static void wave_tables(FILE *f, const char *what, wave_res res)
{
    for (int m = 0; m < NMET; m++) {
        fprintf(f, "\n%s, %s error (mean over orientations 0..175 step 5 and 4 phases):\n\n", what,
                met_names[m]);
        fprintf(f, "| f / Nyquist | sq-tri | sq-bil | iso-sq | iso-eq | iso-sq / sq-tri | "
                   "iso-eq / sq-tri | iso-eq / sq-bil | orientations iso-eq < sq-tri | "
                   "orientations iso-eq < both square |\n|---|---|---|---|---|---|---|---|---|---|\n");
        for (int fi = 0; fi < NFREQ; fi++) {
            double mean[NREC] = {0};
            int win = 0, win2 = 0;
            for (int ti = 0; ti < NTH; ti++) {
                const double *e = &res[fi][ti][0][m];
                for (int k = 0; k < NREC; k++)
                    mean[k] += res[fi][ti][k][m] / NTH;
                win += res[fi][ti][3][m] < e[0];
                win2 += res[fi][ti][3][m] < res[fi][ti][0][m] && res[fi][ti][3][m] < res[fi][ti][1][m];
            }
            fprintf(f, "| %.1f | %.4g | %.4g | %.4g | %.4g | %.3f | %.3f | %.3f | %d / %d | %d / %d |\n",
                    freqs[fi], mean[0], mean[1], mean[2], mean[3], mean[2] / mean[0],
                    mean[3] / mean[0], mean[3] / mean[1], win, NTH, win2, NTH);
        }
    }
}

static td_status orientation_svg(const char *dir, const char *name, const char *title,
                                 const char *ylabel, wave_res res, int fi, int m, td_err *err)
{
    td_bench_svg_point pts[NTH * NREC];
    td_bench_svg_chart c = {title, "orientation (degrees)", ylabel, 0, 0, 0.0, rec_names, NREC, 0};
    char path[1024];
    size_t n = 0;
    for (int ti = 0; ti < NTH; ti++)
        for (int k = 0; k < NREC; k++)
            pts[n++] = (td_bench_svg_point){ti * 5.0, res[fi][ti][k][m], k, ""};
    snprintf(path, sizeof path, "%s/bench/%s", dir, name);
    return td_bench_svg_write(path, &c, pts, n, err);
}

static td_status ratio_svg(const char *dir, wave_res res, td_err *err)
{
    static const char *const fnames[NFREQ] = {"0.1 Nyquist", "0.2", "0.3", "0.5", "0.7", "0.9"};
    td_bench_svg_point pts[NTH * NFREQ];
    td_bench_svg_chart c = {"single sinusoids: iso-eq / sq-tri, elevation error",
                            "orientation (degrees)", "ratio (below 1: isometric better)", 0, 0, 0.0,
                            fnames, NFREQ, 0};
    char path[1024];
    size_t n = 0;
    for (int fi = 0; fi < NFREQ; fi++)
        for (int ti = 0; ti < NTH; ti++)
            pts[n++] = (td_bench_svg_point){ti * 5.0, res[fi][ti][3][0] / res[fi][ti][0][0], fi, ""};
    snprintf(path, sizeof path, "%s/bench/iso-ratio-orientation.svg", dir);
    return td_bench_svg_write(path, &c, pts, n, err);
}

/* Gaussian hills and the ridge (orientation swept, 3 crest offsets). */
static td_status features(FILE *f, double ridge[NTH][NREC][NMET], td_err *err)
{
    double hills[NREC][NMET], mean[NREC][NMET] = {{0}};
    surf h = {2, 0, 0, 0, 1.0};
    td_status rc = analytic(&h, 1.0, hills, err);
    for (int ti = 0; ti < NTH && !rc; ti++) {
        memset(ridge[ti], 0, sizeof ridge[ti]);
        for (int p = 0; p < 3 && !rc; p++) {
            double one[NREC][NMET];
            surf s = {3, ti * 5.0 * PI / 180.0, 0, p * 0.37, 0};
            rc = analytic(&s, 1.0, one, err);
            for (int k = 0; k < NREC; k++)
                for (int m = 0; m < NMET; m++) {
                    ridge[ti][k][m] += one[k][m] / 3.0;
                    mean[k][m] += one[k][m] / 3.0 / NTH;
                }
        }
    }
    fprintf(f, "\nGaussian hills (6 hills, sigma 1.5 .. 6 h) and a sharp ridge (tent, half-width "
               "4 h, slope 0.5; mean over orientations 0..175 step 5 and 3 crest offsets; worst: the "
               "orientation where iso-eq / sq-tri is highest):\n\n"
               "| surface | metric | sq-tri | sq-bil | iso-sq | iso-eq | iso-sq / sq-tri | "
               "iso-eq / sq-tri | worst iso-eq / sq-tri |\n|---|---|---|---|---|---|---|---|---|\n");
    for (int m = 0; m < NMET && !rc; m++) {
        double worst = 0;
        int wt = 0;
        for (int ti = 0; ti < NTH; ti++) {
            double q = ridge[ti][3][m] / ridge[ti][0][m];
            if (ridge[ti][0][m] > 1e-9 && q > worst) { /* not where sq-tri is exact */
                worst = q;
                wt = ti * 5;
            }
        }
        fprintf(f, "| hills | %s | %.4g | %.4g | %.4g | %.4g | %.3f | %.3f | |\n", met_names[m],
                hills[0][m], hills[1][m], hills[2][m], hills[3][m], hills[2][m] / hills[0][m],
                hills[3][m] / hills[0][m]);
        fprintf(f, "| ridge | %s | %.4g | %.4g | %.4g | %.4g | %.3f | %.3f | %.3f at %d deg |\n",
                met_names[m], mean[0][m], mean[1][m], mean[2][m], mean[3][m],
                mean[2][m] / mean[0][m], mean[3][m] / mean[0][m], worst, wt);
    }
    return rc;
}

static td_status dems(FILE *f, const char *data, td_err *err)
{
    static const char *const files[] = {"trinidad-crop.f32", "picos-dtm.asc", "volcano.asc"};
    td_status rc = TD_OK;
    double res[3][3][NREC][NMET];
    long ns[3][3][NREC];
    for (int d = 0; d < 3 && !rc; d++) {
        char path[1024];
        td_grid *g = NULL;
        snprintf(path, sizeof path, "%s/%s", data, files[d]);
        rc = td_dem_load(path, NULL, &g, err);
        for (int s = 0; s < 3 && !rc; s++)
            rc = dem_case(g, 2 << s, res[d][s], ns[d][s], err);
        td_grid_free(g);
    }
    for (int m = 0; m < NMET && !rc; m++) {
        fprintf(f, "\nReal DEMs subsampled (point sampling), %s error against the full grid's "
                   "bilinear surface at 4 random points per cell%s:\n\n| DEM | subsample | samples sq / "
                   "iso-sq / iso-eq | sq-tri | sq-bil | iso-sq | iso-eq | iso-sq / sq-tri | "
                   "iso-eq / sq-tri | iso-eq / sq-bil |\n|---|---|---|---|---|---|---|---|---|---|\n",
                met_names[m], m == 0 ? " (metres)" : "");
        for (int d = 0; d < 3; d++)
            for (int s = 0; s < 3; s++) {
                const double(*e)[NMET] = res[d][s];
                fprintf(f, "| %s | %dx | %ld / %ld / %ld | %.4g | %.4g | %.4g | %.4g | %.3f | %.3f | "
                           "%.3f |\n", files[d], 2 << s, ns[d][s][0], ns[d][s][2], ns[d][s][3],
                        e[0][m], e[1][m], e[2][m], e[3][m], e[2][m] / e[0][m], e[3][m] / e[0][m],
                        e[3][m] / e[1][m]);
            }
    }
    return rc;
}

/* Seconds of one run of all rays through trace_one (kind 0 square view, 1 and 2 the
 * lattices); the steps go to *steps. */
static double time_rays(int kind, const td_view *v, td_method m, const td_iso *l, const td_ray *rays,
                        size_t n, double *steps, double *hits)
{
    struct timespec a, b;
    td_hit h;
    double st = 0, nh = 0;
    clock_gettime(CLOCK_MONOTONIC, &a);
    for (size_t i = 0; i < n; i++) {
        if (kind == 0)
            td_trace(v, m, TD_SURFACE_TRIANGLE, &rays[i], &h);
        else
            td_iso_trace(l, &rays[i], &h);
        st += h.steps;
        nh += h.t < INFINITY;
    }
    clock_gettime(CLOCK_MONOTONIC, &b);
    *steps = st / (double)n;
    *hits = nh / (double)n;
    return (double)(b.tv_sec - a.tv_sec) + 1e-9 * (double)(b.tv_nsec - a.tv_nsec);
}

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

/* Camera-like rays over grid g's extent: from above its highest point toward random
 * ground points (trace_cost's and lod_twins' rays). */
static void camera_rays(const td_grid *g, uint64_t seed, td_ray *rays, size_t n)
{
    for (size_t i = 0; i < n; i++) {
        double X = (g->w - 1) * g->sx, Y = (g->h - 1) * g->sy, dz = g->zmax - g->zmin;
        double o[3] = {X * rnd(&seed), Y * rnd(&seed), g->zmax + 0.2 * dz};
        double p[3] = {X * rnd(&seed), Y * rnd(&seed), g->zmin + 0.5 * dz};
        rays[i] = (td_ray){{o[0], o[1], o[2]}, {p[0] - o[0], p[1] - o[1], p[2] - o[2]}, 0.0, INFINITY};
    }
}

/* Rays per second of the square grid's triangle surface (incremental without acceleration,
 * and auto with max-mipmaps and planes) and of the lattices' walk, on the same rays over the
 * same samples: camera-like rays from above the highest point toward random ground points
 * (median of 5 runs, one thread). */
static td_status trace_cost(FILE *f, const char *data, td_err *err)
{
    static const char *const files[] = {"trinidad-crop.f32", "picos-dtm.asc", "volcano.asc"};
    enum { NR = 20000, NRUN = 5 };
    td_status rc = TD_OK;
    td_ray *rays = malloc(NR * sizeof *rays);
    fprintf(f, "\nTrace cost (median of %d runs of %d rays, one thread, on a shared 2-core machine: "
               "indicative): rays from above the highest point toward random points of the grid.\n\n"
               "| DEM | lattice, method | rays/s | steps/ray | hits |\n|---|---|---|---|---|\n", NRUN, NR);
    for (int d = 0; d < 3 && !rc && rays; d++) {
        char path[1024];
        td_grid *g = NULL;
        td_iso *iso[2] = {NULL, NULL};
        td_accel *ac = NULL;
        td_accel_opts ao = {1, 1, 8, 1, 1, 0};
        td_accel_stats ast;
        uint64_t seed = 31 + (uint64_t)d;
        snprintf(path, sizeof path, "%s/%s", data, files[d]);
        rc = td_dem_load(path, NULL, &g, err);
        for (int k = 0; k < 2 && !rc; k++)
            rc = td_iso_from_grid(g, 1, (td_iso_rows)k, &iso[k], err);
        if (!rc)
            rc = td_accel_build(g, &ao, &ac, &ast, err);
        if (!rc)
            camera_rays(g, seed, rays, NR);
        for (int c = 0; c < 4 && !rc; c++) {
            static const char *const names[4] = {"square, incremental (triangle)",
                                                  "square, auto with max-mipmaps and planes (triangle)",
                                                  "isometric square rows, walk", "isometric equilateral, walk"};
            td_view v = {g, c == 1 ? ac->tiles : NULL};
            double t[NRUN], steps = 0, hits = 0;
            for (int k = 0; k < NRUN; k++)
                t[k] = time_rays(c >= 2, &v, c == 1 ? TD_METHOD_AUTO : TD_METHOD_INCREMENTAL,
                                 c >= 2 ? iso[c - 2] : NULL, rays, NR, &steps, &hits);
            qsort(t, NRUN, sizeof t[0], cmp_double);
            fprintf(f, "| %s | %s | %.3g | %.1f | %.3f |\n", files[d], names[c], NR / t[NRUN / 2], steps, hits);
        }
        td_accel_free(ac);
        td_iso_free(iso[0]);
        td_iso_free(iso[1]);
        td_grid_free(g);
    }
    free(rays);
    return rc;
}

/* The two-byte vertices of isogrid.h on the DEMs' lattices (tiles of 64 x 64). */
static td_status packing(FILE *f, const char *data, td_err *err)
{
    static const char *const files[] = {"trinidad-crop.f32", "picos-dtm.asc", "volcano.asc"};
    td_status rc = TD_OK;
    fprintf(f, "\nTwo-byte vertices (tiles of 64 x 64 samples; square rows at 2x sample grid nodes "
               "only, equilateral rows at 1x interpolate between them):\n\n| DEM | lattice | samples | "
               "tiles lossless | largest error (m) | bytes per sample (float: 4) |\n|---|---|---|---|---|---|\n");
    for (int d = 0; d < 3 && !rc; d++) {
        char path[1024];
        td_grid *g = NULL;
        snprintf(path, sizeof path, "%s/%s", data, files[d]);
        rc = td_dem_load(path, NULL, &g, err);
        for (int k = 0; k < 2 && !rc; k++) {
            td_iso *l = NULL;
            td_iso_packed *p = NULL;
            rc = td_iso_from_grid(g, k ? 1 : 2, (td_iso_rows)k, &l, err);
            if (!rc)
                rc = td_iso_pack(l, 6, &p, err);
            if (!rc) {
                size_t n = td_iso_row_offset(l->nx, l->ny);
                fprintf(f, "| %s | %s %dx | %zu | %d / %d | %.3g | %.3f |\n", files[d],
                        td_iso_rows_name((td_iso_rows)k), k ? 1 : 2, n, p->lossless,
                        p->tiles_x * p->tiles_y, p->max_err, (double)p->bytes / (double)n);
            }
            td_iso_packed_free(p);
            td_iso_free(l);
        }
        td_grid_free(g);
    }
    return rc;
}

/* DEM d of the LOD tables (the three fixtures in data, then `extra` if not NULL) with 4
 * levels of detail (acceleration as `ao` asks) and their isometric twins; *name gets the
 * file's name. Past the last one, *g is NULL. */
static td_status lod_dem(const char *data, const char *extra, int d, const td_accel_opts *ao,
                         td_grid **g, td_lod **lod, const char **name, td_err *err)
{
    static const char *const files[] = {"trinidad-crop.f32", "picos-dtm.asc", "volcano.asc"};
    static char path[1024];
    td_status rc = TD_OK;
    *g = NULL;
    *lod = NULL;
    if (d < 3 || (d == 3 && extra)) {
        snprintf(path, sizeof path, "%s%s%s", d < 3 ? data : extra, d < 3 ? "/" : "", d < 3 ? files[d] : "");
        *name = strrchr(path, '/') ? strrchr(path, '/') + 1 : path;
        rc = td_dem_load(path, NULL, g, err);
        if (!rc)
            rc = td_lod_build(*g, 4, ao, lod, err);
        if (!rc)
            rc = td_lod_add_iso(*lod, *g, err);
    }
    return rc;
}

/* The levels of detail's isometric twins as core/lod.c keeps them (two-byte vertices,
 * tiles of 64 x 64): per level, the packing's error and bytes per sample against the
 * floats they decode to, and the walk's rays per second on the packed vertices against
 * the same walk on the decoded floats (same rays, same steps). `extra` (may be NULL): one
 * more DEM, e.g. the full trinidad. */
static td_status lod_twins(FILE *f, const char *data, const char *extra, td_err *err)
{
    enum { NR = 20000, NRUN = 5 };
    td_status rc = TD_OK;
    td_ray *rays = malloc(NR * sizeof *rays);
    fprintf(f, "\nThe levels of detail's isometric twins as `td_lod_add_iso` keeps them (two-byte "
               "vertices, tiles of 64 x 64; bytes per sample include the tiles' offsets and steps and "
               "the block maxima); rays/s of the walk on the packed vertices and on the floats they "
               "decode to (median of %d runs of %d camera-like rays, one thread, shared machine: "
               "indicative; same steps, same hits bit for bit).\n\n| DEM | level | samples | tiles "
               "lossless | largest error (m) | bytes/sample packed | floats | rays/s packed | floats | "
               "steps/ray |\n|---|---|---|---|---|---|---|---|---|---|\n", NRUN, NR);
    for (int d = 0; !rc && rays; d++) {
        const char *name = "";
        td_grid *g = NULL;
        td_lod *lod = NULL;
        td_accel_opts ao = {0, 0, 1, 1, 0, 0};
        rc = lod_dem(data, extra, d, &ao, &g, &lod, &name, err);
        if (!rc && !g)
            break;
        for (int k = 1; !rc && k <= lod->levels; k++) {
            const td_iso *l = lod->iso[k];
            td_iso *fl = NULL;
            double tp[NRUN], tf[NRUN], steps = 0, sf = 0, hits = 0, hf = 0;
            size_t n = td_iso_row_offset(l->nx, l->ny);
            rc = td_iso_unpack(l->packed, &fl, err);
            if (rc)
                break;
            camera_rays(lod->grid[k], 77 + (uint64_t)k, rays, NR);
            for (int r = 0; r < NRUN; r++) {
                tp[r] = time_rays(1, NULL, TD_METHOD_AUTO, l, rays, NR, &steps, &hits);
                tf[r] = time_rays(1, NULL, TD_METHOD_AUTO, fl, rays, NR, &sf, &hf);
            }
            qsort(tp, NRUN, sizeof tp[0], cmp_double);
            qsort(tf, NRUN, sizeof tf[0], cmp_double);
            fprintf(f, "| %s | %d | %zu | %d / %d | %.3g | %.3f | %.3f | %.3g | %.3g | %.1f%s |\n",
                    name, k, n, l->packed->lossless,
                    l->packed->tiles_x * l->packed->tiles_y, l->packed->max_err,
                    (double)td_iso_bytes(l) / (double)n, (double)td_iso_bytes(fl) / (double)n,
                    NR / tp[NRUN / 2], NR / tf[NRUN / 2], steps,
                    steps == sf && hits == hf ? "" : " (differ!)");
            td_iso_free(fl);
        }
        td_lod_free(lod);
        td_grid_free(g);
    }
    free(rays);
    return rc;
}

/* Mean steps per ray of the square level's methods (triangle surface) and of the lattice
 * walk on its twin, without its block pyramid (every block maximum +inf: no block is ever
 * cleared) and with it, on the same camera-like rays: what the block pyramid saves, and
 * what Paglieroni-Petersen cones (`parametric`) save over a max pyramid (`hierarchical`)
 * on the square level, i.e. what cones on the lattice could hope to save over its pyramid. */
static td_status cones(FILE *f, const char *data, const char *extra, td_err *err)
{
    static const td_method meth[4] = {TD_METHOD_INCREMENTAL, TD_METHOD_HIERARCHICAL,
                                      TD_METHOD_PARAMETRIC, TD_METHOD_AUTO};
    enum { NR = 20000 };
    td_status rc = TD_OK;
    td_ray *rays = malloc(NR * sizeof *rays);
    fprintf(f, "\nSteps per ray on the levels of detail (%d camera-like rays a level): the square "
               "level's methods (triangle surface; max-mipmaps and planes built) and the lattice walk "
               "on its isometric twin without and with its block pyramid; ms for the %d rays, one "
               "thread, shared machine: indicative.\n\n| DEM | level | square incremental | "
               "hierarchical | parametric | auto | lattice, no pyramid | lattice, pyramid | "
               "parametric / hierarchical | lattice pyramid / square parametric |\n"
               "|---|---|---|---|---|---|---|---|---|---|\n", NR, NR);
    for (int d = 0; !rc && rays; d++) {
        const char *name = "";
        td_grid *g = NULL;
        td_lod *lod = NULL;
        td_accel_opts ao;
        td_accel_opts_default(&ao);
        ao.threads = 1;
        rc = lod_dem(data, extra, d, &ao, &g, &lod, &name, err);
        if (!rc && !g)
            break;
        for (int k = 1; !rc && k <= lod->levels; k++) {
            td_iso *flat = NULL; /* the twin with its pyramid disabled */
            double st[6], hits, ms[6];
            size_t nb = 0;
            rc = td_iso_unpack(lod->iso[k]->packed, &flat, err);
            if (rc)
                break;
            for (int b = 0; b < flat->blevels; b++)
                nb += (size_t)flat->bw[b] * (size_t)flat->bh[b];
            for (size_t i = 0; i < nb; i++)
                flat->bmax[0][i] = INFINITY;
            camera_rays(lod->grid[k], 177 + (uint64_t)k, rays, NR);
            for (int m = 0; m < 4; m++)
                ms[m] = 1e3 * time_rays(0, &lod->view[k], meth[m], NULL, rays, NR, &st[m], &hits);
            ms[4] = 1e3 * time_rays(1, NULL, TD_METHOD_AUTO, flat, rays, NR, &st[4], &hits);
            ms[5] = 1e3 * time_rays(1, NULL, TD_METHOD_AUTO, lod->iso[k], rays, NR, &st[5], &hits);
            fprintf(f, "| %s | %d |", name, k);
            for (int m = 0; m < 6; m++)
                fprintf(f, " %.1f (%.0f ms) |", st[m], ms[m]);
            fprintf(f, " %.2f | %.2f |\n", st[2] / st[1], st[5] / st[2]);
            td_iso_free(flat);
        }
        td_lod_free(lod);
        td_grid_free(g);
    }
    free(rays);
    return rc;
}

/* Squared RGB differences of a and b over the pixels opaque in both; *n counts them. */
static double rgb_sse(const td_render_result *a, const td_render_result *b, uint64_t *n)
{
    double sse = 0.0;
    for (size_t i = 0; i < (size_t)a->width * (size_t)a->height; i++) {
        const uint8_t *p = a->rgba + 4 * i, *q = b->rgba + 4 * i;
        if (!p[3] || !q[3])
            continue;
        for (int c = 0; c < 3; c++)
            sse += ((double)p[c] - q[c]) * ((double)p[c] - q[c]);
        *n += 3;
    }
    return sse;
}

/* Map tiles as GET /v1/tiles makes them (256 x 256, orthographic, top down, quality.lod on,
 * the scene's defaults) on the square levels and on their isometric twins, against the
 * same tile traced on the full grid with 4 x 4 rays a pixel (the picture the level
 * stands for): PSNR of the colours, the render's height error, the primary stage's time.
 * Zooms 0-3, up to 4 tiles a zoom (the north-west ones). */
static td_status tiles(FILE *f, const char *dem, td_err *err)
{
    td_status rc;
    td_grid *g = NULL;
    td_accel *ac = NULL;
    td_lod *lod = NULL;
    td_accel_opts ao;
    td_accel_stats ast;
    td_dem_opts dopt;
    td_dem_opts_default(&dopt);
    td_accel_opts_default(&ao);
    ao.threads = 1;
    rc = td_dem_load(dem, &dopt, &g, err);
    if (!rc)
        rc = td_accel_build(g, &ao, &ac, &ast, err);
    ao.planes = 0; /* as the server builds its levels (server/tilestore.c) */
    if (!rc)
        rc = td_lod_build(g, TD_LOD_MAX, &ao, &lod, err);
    if (!rc)
        rc = td_lod_add_iso(lod, g, err);
    if (!rc)
        fprintf(f, "\nMap tiles of %s (%d x %d samples) as `GET /v1/tiles` makes them, on the square "
                   "levels and on their isometric twins, against the same tiles traced on the full grid "
                   "with 4 x 4 rays a pixel; one thread, shared machine (times indicative).\n\n"
                   "| zoom | tiles | level | PSNR square (dB) | PSNR isometric | height error mean / max, "
                   "square (m) | isometric | primary ms square | isometric |\n"
                   "|---|---|---|---|---|---|---|---|---|\n",
                strrchr(dem, '/') ? strrchr(dem, '/') + 1 : dem, (int)g->w, (int)g->h);
    for (int z = 0; z <= 3 && !rc; z++) {
        double wm = g->sx * (g->w - 1), hm = g->sy * (g->h - 1), side = wm > hm ? wm : hm;
        double t = side / (double)(1L << z), sse[2] = {0, 0}, hs[2] = {0, 0}, hx[2] = {0, 0};
        double ms[2] = {0, 0};
        uint64_t n[2] = {0, 0}, hh[2] = {0, 0};
        int ntiles = 0, level = 0;
        td_view v = {g, ac->tiles};
        for (long y = 0; y < (1L << z) && y * t < hm && ntiles < 4 && !rc; y++) {
            for (long x = 0; x < (1L << z) && x * t < wm && ntiles < 4 && !rc; x++) {
                td_scene sc;
                td_render_opts o;
                td_render_result truth = {0}, res[2] = {{0}, {0}};
                td_scene_defaults(&sc);
                sc.camera.projection = TD_PROJ_ORTHOGRAPHIC;
                sc.camera.extent[0] = (double)x * t;
                sc.camera.extent[2] = (double)(x + 1) * t;
                sc.camera.extent[3] = hm - (double)y * t;
                sc.camera.extent[1] = hm - (double)(y + 1) * t;
                sc.image.width = sc.image.height = 256;
                sc.image.format = TD_FORMAT_PNG;
                td_render_opts_default(&o);
                o.threads = 1;
                sc.quality.samples = 4;
                rc = td_render(&v, &sc, &o, &truth, err);
                sc.quality.samples = 1;
                sc.quality.lod = 1;
                o.lod = lod;
                for (int k = 0; k < 2 && !rc; k++) {
                    sc.quality.lod_grid = k ? TD_LOD_GRID_ISOMETRIC : TD_LOD_GRID_SQUARE;
                    rc = td_render(&v, &sc, &o, &res[k], err);
                    if (rc)
                        break;
                    sse[k] += rgb_sse(&truth, &res[k], &n[k]);
                    hs[k] += res[k].stats.height_err_sum_m;
                    hh[k] += res[k].stats.height_err_hits;
                    hx[k] = fmax(hx[k], res[k].stats.height_err_max_m);
                    ms[k] += res[k].stats.stage_ms[TD_STAGE_PRIMARY];
                    for (int l = 0; l <= TD_LOD_MAX; l++)
                        level = res[k].stats.lod_rays[l] ? l : level;
                }
                td_render_result_free(&truth);
                td_render_result_free(&res[0]);
                td_render_result_free(&res[1]);
                ntiles++;
            }
        }
        if (!rc)
            fprintf(f, "| %d | %d | %d | %.2f | %.2f | %.2f / %.1f | %.2f / %.1f | %.0f | %.0f |\n", z,
                    ntiles, level, 10.0 * log10(255.0 * 255.0 * (double)n[0] / sse[0]),
                    10.0 * log10(255.0 * 255.0 * (double)n[1] / sse[1]), hs[0] / (double)hh[0], hx[0],
                    hs[1] / (double)hh[1], hx[1], ms[0], ms[1]);
    }
    td_lod_free(lod);
    td_accel_free(ac);
    td_grid_free(g);
    return rc;
}

int main(int argc, char **argv)
{
    static wave_res waves, sums;
    static double ridge[NTH][NREC][NMET];
    td_err err = {{0}, {0}};
    td_status rc = TD_OK;
    char path[1024];
    FILE *f = NULL;

    if (argc == 3 && !strcmp(argv[2], "--timing")) /* the trace-cost table only, to stdout */
        return trace_cost(stdout, argv[1], &err) ? 1 : 0;
    if (argc == 4 && !strcmp(argv[2], "--tiles")) /* map tiles of one DEM, to stdout */
        return tiles(stdout, argv[3], &err) ? 1 : 0;
    if (argc >= 3 && !strcmp(argv[2], "--cones")) /* the steps table only, to stdout */
        return cones(stdout, argv[1], argc > 3 ? argv[3] : NULL, &err) ? 1 : 0;
    if (argc >= 3 && !strcmp(argv[2], "--lod")) /* the LOD twins' table only, to stdout */
        return lod_twins(stdout, argv[1], argc > 3 ? argv[3] : NULL, &err) ? 1 : 0;
    if (argc != 3) {
        fprintf(stderr, "usage: %s DATA_DIR OUT_DIR (e.g. tests/data docs) | DATA_DIR --timing | "
                        "DATA_DIR --lod [DEM] | DATA_DIR --cones [DEM] | DATA_DIR --tiles DEM\n",
                argv[0]);
        return 2;
    }
    snprintf(path, sizeof path, "%s/isometric-tables.md", argv[2]);
    f = fopen(path, "w");
    if (!f) {
        fprintf(stderr, "%s: cannot write\n", path);
        return 1;
    }
    fprintf(f, "# Isometric against square lattices: the tables\n\nWritten by `build/iso-accuracy "
               "tests/data docs` (tests/bench/iso_accuracy.c); read docs/isometric.md for what "
               "they say. sq-tri: square grid, two triangles per cell; sq-bil: square grid, "
               "bilinear; iso-sq: isometric lattice, square rows (b = a); iso-eq: isometric "
               "lattice, equilateral triangles, same density. Analytic elevation errors are in "
               "units of the amplitude, normal errors in degrees, shading errors in Lambert "
               "units (0..1).\n");
    rc = sweep(0, waves, &err);
    if (!rc)
        rc = sweep(1, sums, &err);
    if (!rc) {
        wave_tables(f, "Single sinusoids", waves);
        wave_tables(f, "Sums of two sinusoids crossed at 90 degrees", sums);
        rc = features(f, ridge, &err);
    }
    if (!rc)
        rc = dems(f, argv[1], &err);
    if (!rc)
        rc = packing(f, argv[1], &err);
    if (!rc)
        rc = lod_twins(f, argv[1], NULL, &err);
    if (!rc)
        rc = cones(f, argv[1], NULL, &err);
    if (!rc && !getenv("ISO_NO_TIMING"))
        rc = trace_cost(f, argv[1], &err);
    if (!rc)
        rc = orientation_svg(argv[2], "iso-normal-orientation.svg",
                             "single sinusoids at 0.3 Nyquist: normal error", "mean angle (degrees)",
                             waves, 2, 1, &err);
    if (!rc)
        rc = orientation_svg(argv[2], "iso-elevation-orientation.svg",
                             "single sinusoids at 0.5 Nyquist: elevation error",
                             "mean |dz| / amplitude", waves, 3, 0, &err);
    if (!rc)
        rc = ratio_svg(argv[2], waves, &err);
    fclose(f);
    if (rc)
        fprintf(stderr, "iso-accuracy: %s\n", err.msg);
    return rc ? 1 : 0;
}
