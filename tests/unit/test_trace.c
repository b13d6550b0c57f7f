/* test_trace.c: unit tests of the tracers and their acceleration structures: analytic
 * hits on flat and single-cell terrain, every method against a brute-force
 * double-precision triangle reference, methods agreeing with one another on every
 * surface, the cone bound of every parameter plane checked cell against cell, the
 * max-mipmap and EDT against brute force, holes, and ray validation. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <cmocka.h>

#include "accel.h"
#include "edt.h"
#include "maxmip.h"
#include "planes.h"
#include "sunlit.h"
#include "surface.h"
#include "terrain.h"
#include "trace.h"
#include "terrain_fixture.h"

static void _fail_msg_near(double a, double b, double eps, const char *what, const char *file, int line)
{
    print_error("%s:%d: %s = %.17g, expected %.17g within %g\n", file, line, what, a, b, eps);
    _fail(file, line);
}

/* cmocka 1.1.5 (Debian 12) has no assert_double_equal. */
#define assert_double_equal(a, b, eps) assert_near_impl((a), (b), (eps), #a, __FILE__, __LINE__)
static void assert_near_impl(double a, double b, double eps, const char *what, const char *file, int line)
{
    if (!(fabs(a - b) <= eps))
        _fail_msg_near(a, b, eps, what, file, line);
}

static double rnd(uint64_t *s)
{
    *s = *s * 6364136223846793005ull + 1442695040888963407ull;
    return (double)(*s >> 11) / 9007199254740992.0;
}

static td_grid *make_grid(int32_t w, int32_t h, double sx, double sy, int tile_log2)
{
    td_grid *g = NULL;
    assert_int_equal(td_grid_create(w, h, sx, sy, tile_log2, NULL, &g, NULL), TD_OK);
    return g;
}

static td_accel *build_all(const td_grid *g, int k)
{
    td_accel *a = NULL;
    td_accel_opts o;
    td_accel_opts_default(&o);
    o.planes_k = k;
    o.threads = 2;
    assert_int_equal(td_accel_build(g, &o, &a, NULL, NULL), TD_OK);
    return a;
}

static td_grid *procedural(int32_t w, int32_t h, uint64_t seed, int tile_log2)
{
    return terrain_seeded(w, h, 25.0, seed, tile_log2);
}

/* Double-precision Moller-Trumbore, inclusive edges. */
static double tri_ref(const double o[3], const double d[3], const double a[3], const double b[3],
                      const double c[3])
{
    double e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    double pv[3] = {d[1] * e2[2] - d[2] * e2[1], d[2] * e2[0] - d[0] * e2[2], d[0] * e2[1] - d[1] * e2[0]};
    double det = e1[0] * pv[0] + e1[1] * pv[1] + e1[2] * pv[2];
    double t = INFINITY;
    if (det != 0.0) {
        double inv = 1.0 / det, tv[3] = {o[0] - a[0], o[1] - a[1], o[2] - a[2]};
        double u = (tv[0] * pv[0] + tv[1] * pv[1] + tv[2] * pv[2]) * inv;
        double q[3] = {tv[1] * e1[2] - tv[2] * e1[1], tv[2] * e1[0] - tv[0] * e1[2], tv[0] * e1[1] - tv[1] * e1[0]};
        double v = (d[0] * q[0] + d[1] * q[1] + d[2] * q[2]) * inv;
        double tt = (e2[0] * q[0] + e2[1] * q[1] + e2[2] * q[2]) * inv;
        if (u >= -1e-9 && v >= -1e-9 && u + v <= 1.0 + 1e-9 && tt >= 0.0)
            t = tt;
    }
    return t;
}

/* Every cell of the grid, both triangles (small grids only). */
static double brute_triangle(const td_grid *g, const td_ray *r)
{
    double best = INFINITY;
    for (int32_t j = 0; j + 1 < g->h; j++) {
        for (int32_t i = 0; i + 1 < g->w; i++) {
            double z00 = td_grid_at(g, i, j), z10 = td_grid_at(g, i + 1, j);
            double z01 = td_grid_at(g, i, j + 1), z11 = td_grid_at(g, i + 1, j + 1);
            if (isnan(z00) || isnan(z10) || isnan(z01) || isnan(z11))
                continue;
            double A[3] = {i * g->sx, j * g->sy, z00}, B[3] = {(i + 1) * g->sx, j * g->sy, z10};
            double C[3] = {i * g->sx, (j + 1) * g->sy, z01}, D[3] = {(i + 1) * g->sx, (j + 1) * g->sy, z11};
            best = fmin(best, fmin(tri_ref(r->o, r->d, A, B, C), tri_ref(r->o, r->d, B, D, C)));
        }
    }
    return best;
}

/* A ray aimed at a random point of the relief's box, from a random origin: grazing,
 * steep, oblique or looking up. */
static void random_ray(const td_grid *g, uint64_t *s, td_ray *r)
{
    double W = (g->w - 1) * g->sx, H = (g->h - 1) * g->sy, Z = g->zmax - g->zmin;
    double target[3] = {W * rnd(s), H * rnd(s), g->zmin + Z * rnd(s)};
    int kind = (int)(rnd(s) * 4.0);
    r->o[0] = -0.2 * W + 1.4 * W * rnd(s);
    r->o[1] = -0.2 * H + 1.4 * H * rnd(s);
    if (kind == 0) /* grazing: nearly level with the target */
        r->o[2] = target[2] + 0.01 * Z * (rnd(s) - 0.3);
    else if (kind == 1) /* from high above */
        r->o[2] = g->zmax + 3.0 * Z * rnd(s);
    else if (kind == 2) /* oblique */
        r->o[2] = g->zmax + 0.3 * Z * rnd(s);
    else /* from low down, looking up */
        r->o[2] = g->zmin + 0.5 * Z * rnd(s);
    for (int i = 0; i < 3; i++)
        r->d[i] = target[i] - r->o[i];
    if (r->d[0] == 0.0 && r->d[1] == 0.0 && r->d[2] == 0.0)
        r->d[2] = -1.0;
    r->tmin = 0.0;
    r->tmax = INFINITY;
}

static int same_t(double a, double b, double len)
{
    return (isinf(a) && isinf(b)) || fabs(a - b) <= 1e-6 * (1.0 + len + fabs(a));
}

static void test_flat_analytic(void **state)
{
    (void)state;
    td_grid *g = make_grid(9, 7, 10.0, 20.0, 2);
    for (int k = 0; k < 63; k++)
        g->z[k] = 100.0f;
    assert_int_equal(td_grid_finish(g, NULL), TD_OK);
    td_accel *a = build_all(g, 4);
    td_view v = {g, a->tiles};
    for (int m = 0; m < TD_METHOD_COUNT; m++) {
        for (int s = 0; s < TD_SURFACE_COUNT; s++) {
            td_hit h;
            td_ray down = {{33.0, 47.0, 250.0}, {0.0, 0.0, -2.0}, 0.0, INFINITY};
            td_trace(&v, (td_method)m, (td_surface)s, &down, &h);
            assert_double_equal(h.t, 75.0, 1e-9);
            assert_double_equal(h.n[2], 1.0, 1e-6);
            assert_int_equal(h.ci, 3);
            assert_int_equal(h.cj, 2);
            /* 45 degrees toward north-east from above the south-west corner */
            td_ray diag = {{0.0, 0.0, 130.0}, {3.0, 4.0, -5.0}, 0.0, INFINITY};
            td_trace(&v, (td_method)m, (td_surface)s, &diag, &h);
            assert_double_equal(h.t, 6.0, 1e-9);
            assert_double_equal(h.p[2], 100.0, 1e-9);
            /* up-going ray misses, horizontal ray above misses */
            td_ray up = {{40.0, 40.0, 120.0}, {1.0, 0.5, 0.1}, 0.0, INFINITY};
            td_trace(&v, (td_method)m, (td_surface)s, &up, &h);
            assert_true(isinf(h.t));
            /* tmax before the surface: miss */
            down.tmax = 70.0;
            td_trace(&v, (td_method)m, (td_surface)s, &down, &h);
            assert_true(isinf(h.t));
        }
    }
    td_accel_free(a);
    td_grid_free(g);
}

/* One cell with a twisted bilinear patch: the hit must solve the quadratic exactly. */
static void test_single_cell_bilinear(void **state)
{
    (void)state;
    td_grid *g = make_grid(2, 2, 1.0, 1.0, 1);
    g->z[0] = 0.0f; /* z00 */
    g->z[1] = 1.0f; /* z10 */
    g->z[2] = 1.0f; /* z01 */
    g->z[3] = 0.0f; /* z11: saddle z = a + b - 2ab */
    assert_int_equal(td_grid_finish(g, NULL), TD_OK);
    td_accel *a = build_all(g, 3);
    td_view v = {g, a->tiles};
    uint64_t seed = 5;
    for (int n = 0; n < 2000; n++) {
        td_ray r = {{rnd(&seed), rnd(&seed), 2.0}, {rnd(&seed) - 0.5, rnd(&seed) - 0.5, -1.0}, 0.0, INFINITY};
        /* reference: dense bracketing then bisection in double */
        double tref = INFINITY, prev = NAN, tp = 0.0;
        for (int k = 0; k <= 20000; k++) {
            double t = 3.0 * k / 20000.0;
            double x = r.o[0] + t * r.d[0], y = r.o[1] + t * r.d[1], z = r.o[2] + t * r.d[2];
            if (x < 0 || y < 0 || x > 1 || y > 1)
                continue;
            double f = z - (x + y - 2 * x * y);
            if (!isnan(prev) && prev > 0 && f <= 0) {
                double lo = tp, hi = t;
                for (int it = 0; it < 200; it++) {
                    double mid = 0.5 * (lo + hi);
                    double xm = r.o[0] + mid * r.d[0], ym = r.o[1] + mid * r.d[1];
                    double fm = r.o[2] + mid * r.d[2] - (xm + ym - 2 * xm * ym);
                    if (fm > 0) lo = mid; else hi = mid;
                }
                tref = 0.5 * (lo + hi);
                break;
            }
            prev = f;
            tp = t;
        }
        for (int m = 0; m < TD_METHOD_COUNT; m++) {
            td_hit h;
            td_trace(&v, (td_method)m, TD_SURFACE_BILINEAR, &r, &h);
            if (isinf(tref)) {
                assert_true(isinf(h.t));
            } else {
                assert_double_equal(h.t, tref, 1e-9);
                double x = h.p[0], y = h.p[1];
                assert_double_equal(h.p[2], x + y - 2 * x * y, 1e-9);
            }
        }
    }
    td_accel_free(a);
    td_grid_free(g);
}

/* td_quad_hit on quadratics whose lowest point over the segment is a hair above or below
 * zero while both ends are well above it (fa, fb > 0: the case its quick rejection takes):
 * a dip between positive ends is a hit at a root, a hump or a sag that stays above zero
 * is none. f(s) = chord(s) + A s (s - L), the minimum from its vertex (or an end). */
static void test_quad_hit_sag(void **state)
{
    (void)state;
    uint64_t seed = 11;
    int hits = 0, misses = 0;
    for (int n = 0; n < 100000; n++) {
        const double L = 0.01 + 3.0 * rnd(&seed), fa = 1e-3 + 50.0 * rnd(&seed), fb = 1e-3 + 50.0 * rnd(&seed);
        /* the twist that puts the sag's vertex at f = gap (convex, A > 0), or a hump (A < 0) */
        const int hump = n % 5 == 0;
        const double gap = (rnd(&seed) - 0.5) * 1e-6 * (fa + fb);
        /* the vertex of chord + A s (s - L) is at sv = L / 2 - (fb - fa) / (2 A L); A by
           bisection (f there falls as A grows, once sv is inside the segment) */
        double A;
        if (hump) {
            A = -(0.1 + 100.0 * rnd(&seed));
        } else {
            double lo = 0.0, hi = 1e12;
            for (int it = 0; it < 100; it++) {
                double m = 0.5 * (lo + hi), sv = 0.5 * L - (fb - fa) / (2.0 * m * L);
                double fv = (sv > 0.0 && sv < L) ? fa + (fb - fa) * sv / L + m * sv * (sv - L) : (fa < fb ? fa : fb);
                if (fv > gap)
                    lo = m;
                else
                    hi = m;
            }
            A = 0.5 * (lo + hi);
        }
        double fmin = fa < fb ? fa : fb;
        const double sv = 0.5 * L - (fb - fa) / (2.0 * A * L);
        if (A > 0.0 && sv > 0.0 && sv < L)
            fmin = fa + (fb - fa) * sv / L + A * sv * (sv - L);
        if (fabs(fmin) <= 1e-9 * (fa + fb + fabs(A) * L * L))
            continue; /* within rounding of touching: either answer holds */
        double t = NAN;
        const int hit = td_quad_hit(2.0, fa, 2.0 + L, fb, A, &t);
        assert_int_equal(hit, fmin <= 0.0);
        if (hit) {
            const double s = t - 2.0, f = fa + (fb - fa) * s / L + A * s * (s - L);
            assert_true(s >= 0.0 && s <= L);
            assert_true(fabs(f) <= 1e-6 * (fa + fb + A * L * L));
            hits++;
        } else {
            misses++;
        }
    }
    assert_true(hits > 5000 && misses > 5000);
}

/* All methods against a brute-force double triangle reference; all surfaces across
 * methods. Tiles of 8 cells so seams are crossed constantly. */
static void test_methods_vs_reference(void **state)
{
    (void)state;
    td_grid *g = procedural(61, 45, 11, 3);
    /* punch holes: a block and a row */
    for (int32_t j = 10; j < 16; j++)
        for (int32_t i = 20; i < 27; i++)
            g->z[(size_t)j * 61 + (size_t)i] = NAN;
    for (int32_t i = 0; i < 61; i++)
        g->z[(size_t)30 * 61 + (size_t)i] = (i % 3) ? g->z[(size_t)30 * 61 + (size_t)i] : NAN;
    assert_int_equal(td_grid_finish(g, NULL), TD_OK);
    td_accel *a = build_all(g, 8);
    td_view v = {g, a->tiles};
    uint64_t seed = 99;
    long hits = 0, bad = 0;
    for (int n = 0; n < 3000; n++) {
        td_ray r;
        random_ray(g, &seed, &r);
        double tref = brute_triangle(g, &r);
        double len = 1e4;
        hits += isfinite(tref);
        for (int m = 0; m < TD_METHOD_COUNT; m++) {
            td_hit h;
            td_trace(&v, (td_method)m, TD_SURFACE_TRIANGLE, &r, &h);
            if (!same_t(h.t, tref, len)) {
                print_message("ray %d method %s: got %.17g want %.17g\n", n, td_method_name(m), h.t, tref);
                bad++;
            }
        }
        for (int s = 0; s < TD_SURFACE_COUNT; s++) {
            td_hit h0, h;
            td_trace(&v, TD_METHOD_INCREMENTAL, (td_surface)s, &r, &h0);
            for (int m = 1; m < TD_METHOD_COUNT; m++) {
                td_trace(&v, (td_method)m, (td_surface)s, &r, &h);
                if (!same_t(h.t, h0.t, len)) {
                    print_message("ray %d %s/%s: got %.17g incremental %.17g\n", n, td_method_name(m),
                                  td_surface_name(s), h.t, h0.t);
                    bad++;
                }
            }
        }
    }
    print_message("%ld of 3000 rays hit\n", hits);
    assert_true(hits > 1000);
    assert_int_equal(bad, 0);
    td_accel_free(a);
    td_grid_free(g);
}

/* The cone of every cell bounds every other cell of the tile by the footprint gap. */
static void test_planes_bound(void **state)
{
    (void)state;
    const int ks[] = {1, 2, 5, 16, 64};
    td_grid *g = procedural(33, 33, 3, 5);
    g->sy = 37.0; /* non-square cells */
    g->z[(size_t)7 * 33 + 9] = NAN;
    assert_int_equal(td_grid_finish(g, NULL), TD_OK);
    const td_tile *t = &g->tiles[0];
    float *H = malloc(sizeof(float) * (size_t)t->nx * (size_t)t->ny);
    td_grid_cell_max(g, t, H);
    for (size_t ki = 0; ki < sizeof ks / sizeof ks[0]; ki++) {
        td_planes *p = NULL;
        assert_int_equal(td_planes_build(g, 0, ks[ki], &p, NULL), TD_OK);
        long violations = 0;
        double mean_slope = 0.0;
        for (int32_t cj = 0; cj < t->ny; cj++) {
            for (int32_t ci = 0; ci < t->nx; ci++) {
                const td_cone c = td_planes_cone(p, ci, cj);
                mean_slope += td_cone_slope(p, c);
                for (int32_t qj = 0; qj < t->ny; qj++) {
                    for (int32_t qi = 0; qi < t->nx; qi++) {
                        double gx = fmax(abs(qi - ci) - 1, 0) * g->sx, gy = fmax(abs(qj - cj) - 1, 0) * g->sy;
                        double bound = td_cone_apex(p, c) + td_cone_slope(p, c) * sqrt(gx * gx + gy * gy);
                        if ((double)H[(size_t)qj * (size_t)t->nx + (size_t)qi] > bound)
                            violations++;
                    }
                }
            }
        }
        assert_int_equal(violations, 0);
        assert_true(isfinite(mean_slope));
        td_planes_free(p);
    }
    free(H);
    td_grid_free(g);
}

/* Flat terrain: zmin == zmax, slice spacing 0; all-void tile: nothing to hit. */
static void test_planes_degenerate(void **state)
{
    (void)state;
    td_grid *g = make_grid(17, 9, 5.0, 5.0, 3);
    for (int k = 0; k < 17 * 9; k++)
        g->z[k] = (k % 17) >= 9 ? NAN : 42.0f;
    assert_int_equal(td_grid_finish(g, NULL), TD_OK);
    td_planes *p = NULL;
    assert_int_equal(td_planes_build(g, 0, 16, &p, NULL), TD_OK);
    for (int c = 0; c < 64; c++) {
        const td_cone q = td_planes_cone(p, c % 8, c / 8);
        assert_true(td_cone_apex(p, q) >= 42.0);
        assert_true(isfinite(td_cone_slope(p, q)) && td_cone_slope(p, q) >= 0.0);
    }
    td_planes_free(p);
    assert_int_equal(td_planes_build(g, 1, 16, &p, NULL), TD_OK); /* cells 8..15: holes */
    for (int c = 0; c < 64; c++)
        assert_true(td_cone_apex(p, td_planes_cone(p, c % 8, c / 8)) == -INFINITY);
    td_planes_free(p);
    td_accel *a = build_all(g, 16);
    td_view v = {g, a->tiles};
    for (int m = 0; m < TD_METHOD_COUNT; m++) {
        td_hit h;
        td_ray r = {{0.0, 20.0, 45.0}, {1.0, 0.0, -0.1}, 0.0, INFINITY}; /* meets z=42 at x=30 */
        td_trace(&v, (td_method)m, TD_SURFACE_BILINEAR, &r, &h);
        assert_double_equal(h.t, 30.0, 1e-9);
        td_ray r2 = {{41.0, 20.0, 50.0}, {1.0, 0.0, -0.1}, 0.0, INFINITY}; /* over the holes */
        td_trace(&v, (td_method)m, TD_SURFACE_TRIANGLE, &r2, &h);
        assert_true(isinf(h.t));
    }
    td_accel_free(a);
    td_grid_free(g);
}

static void check_maxmip(const td_grid *g, size_t tile)
{
    td_maxmip *m = NULL;
    assert_int_equal(td_maxmip_build(g, tile, &m, NULL), TD_OK);
    const td_tile *t = &g->tiles[tile];
    float *H = malloc(sizeof(float) * (size_t)t->nx * (size_t)t->ny);
    td_grid_cell_max(g, t, H);
    for (int L = 1; L <= m->levels; L++) {
        for (int32_t bj = 0; bj < m->dim[L]; bj++) {
            for (int32_t bi = 0; bi < m->dim[L]; bi++) {
                float want = -INFINITY;
                for (int32_t cj = bj << L; cj < ((bj + 1) << L) && cj < t->ny; cj++)
                    for (int32_t ci = bi << L; ci < ((bi + 1) << L) && ci < t->nx; ci++)
                        want = fmaxf(want, H[(size_t)cj * (size_t)t->nx + (size_t)ci]);
                double got = td_maxmip_bound(m, L, bi, bj);
                if (want > -INFINITY) { /* never below, at most a step above */
                    assert_true(got >= (double)want);
                    assert_true(got - (double)want <= m->step * (1.0 + 1e-9));
                    assert_true((double)want > m->base);
                } else { /* holes only: code 0, below every real maximum (above) */
                    assert_true(got == m->base);
                }
            }
        }
    }
    free(H);
    td_maxmip_free(m);
}

/* A max-mipmap's codes against the maxima they stand for: never below, at most a step
 * above, a block of holes (or beyond a partial tile) at code 0 below every real maximum;
 * heights offset to huge coordinates (the step keeps above a decode's rounding there)
 * and a flat tile (no range to split). */
static void test_maxmip_and_edt(void **state)
{
    (void)state;
    const double offsets[] = {0.0, 1e7, -3e9, 1e30, -1e36};
    for (int flat = 0; flat < 2; flat++) {
        for (size_t oi = 0; oi < sizeof offsets / sizeof offsets[0]; oi++) {
            td_grid *g = procedural(40, 23, 8, 4); /* partial edge tiles */
            for (size_t k = 0; k < (size_t)g->w * (size_t)g->h; k++)
                g->z[k] = (float)((flat ? 100.0 : (double)g->z[k]) + offsets[oi]);
            g->z[(size_t)3 * (size_t)g->w + 35] = NAN; /* a hole in the tile below */
            assert_int_equal(td_grid_finish(g, NULL), TD_OK);
            check_maxmip(g, 2); /* the east tile of the first row: 7 x 16 cells */
            td_grid_free(g);
        }
    }
}

/* A whole grid's max-mipmaps, built into td_accel's one buffer (td_maxmip_build_into),
 * are each tile's own build (td_maxmip_build_opts) to the bit: shape, scale, codes and
 * minima, on partial edge tiles and a hole, with and without the minima; and the tiles'
 * codes and minima do not overlap in the buffer. */
static void test_accel_maxmip_store(void **state)
{
    (void)state;
    td_grid *g = procedural(40, 23, 8, 4); /* 3 x 2 tiles, partial on the east and north */
    g->z[(size_t)3 * (size_t)g->w + 35] = NAN;
    assert_int_equal(td_grid_finish(g, NULL), TD_OK);
    for (int minima = 0; minima < 2; minima++) {
        td_accel *a = NULL;
        td_accel_opts o;
        td_accel_opts_default(&o);
        o.planes = 0;
        o.minima = minima;
        o.threads = 2;
        assert_int_equal(td_accel_build(g, &o, &a, NULL, NULL), TD_OK);
        for (size_t t = 0; t < a->ntiles; t++) {
            const td_maxmip *m = a->tiles[t].maxmip;
            td_maxmip *r = NULL;
            size_t codes, mins;
            assert_int_equal(td_maxmip_build_opts(g, t, minima, &r, NULL), TD_OK);
            td_maxmip_sizes(g, t, minima, &codes, &mins);
            assert_int_equal(m->levels, r->levels);
            assert_true(m->base == r->base && m->step == r->step);
            assert_int_equal(m->bytes, r->bytes);
            for (int l = 1; l <= r->levels; l++) {
                assert_int_equal(m->dim[l], r->dim[l]);
                assert_int_equal(m->offset[l], r->offset[l]);
            }
            assert_int_equal(codes, r->offset[r->levels] + (size_t)r->dim[r->levels] * (size_t)r->dim[r->levels]);
            assert_memory_equal(m->code, r->code, codes * sizeof *m->code);
            assert_int_equal(m->min4_w, r->min4_w);
            assert_int_equal(m->min4_h, r->min4_h);
            assert_int_equal(mins, (size_t)r->min4_w * (size_t)r->min4_h);
            if (minima) {
                assert_memory_equal(m->min4, r->min4, mins * sizeof *m->min4); /* NaN bits too */
            } else {
                assert_null(m->min4);
                assert_int_equal(mins, 0);
            }
            if (t + 1 < a->ntiles) { /* the next tile's codes and minima start past these */
                assert_true(m->code + codes <= a->tiles[t + 1].maxmip->code);
                if (minima)
                    assert_true(m->min4 + mins <= a->tiles[t + 1].maxmip->min4);
            }
            td_maxmip_free(r);
        }
        td_accel_free(a);
    }
    td_grid_free(g);
}

/* Plane surface: a wall hit has a horizontal normal facing the ray. */
static void test_plane_walls(void **state)
{
    (void)state;
    td_grid *g = make_grid(5, 2, 10.0, 10.0, 2);
    float z[10] = {0, 0, 50, 50, 0, 0, 0, 50, 50, 0};
    for (int k = 0; k < 10; k++)
        g->z[k] = z[k];
    assert_int_equal(td_grid_finish(g, NULL), TD_OK);
    td_accel *a = build_all(g, 4);
    td_view v = {g, a->tiles};
    for (int m = 0; m < TD_METHOD_COUNT; m++) {
        td_hit h;
        td_ray r = {{0.0, 5.0, 10.0}, {1.0, 0.0, 0.0}, 0.0, INFINITY};
        td_trace(&v, (td_method)m, TD_SURFACE_PLANE, &r, &h);
        /* cell 0 has top 0; cell 1 has top 50: wall at x = 10 */
        assert_double_equal(h.t, 10.0, 1e-12);
        assert_double_equal(h.n[0], -1.0, 1e-6);
        assert_double_equal(h.n[2], 0.0, 1e-6);
    }
    td_accel_free(a);
    td_grid_free(g);
}

static void test_validate(void **state)
{
    (void)state;
    td_err err;
    td_ray ok = {{0, 0, 0}, {1, 0, 0}, 0.0, INFINITY};
    assert_int_equal(td_ray_validate(&ok, &err), TD_OK);
    td_ray r = ok;
    r.d[1] = NAN;
    assert_int_equal(td_ray_validate(&r, &err), TD_ERANGE);
    assert_non_null(strstr(err.msg, "dy"));
    r = ok;
    r.o[2] = INFINITY;
    assert_int_equal(td_ray_validate(&r, &err), TD_ERANGE);
    assert_non_null(strstr(err.msg, "oz"));
    r = ok;
    r.d[0] = 0.0;
    assert_int_equal(td_ray_validate(&r, &err), TD_ERANGE);
    r = ok;
    r.tmax = NAN;
    assert_int_equal(td_ray_validate(&r, &err), TD_ERANGE);
    td_method m;
    td_surface s;
    assert_int_equal(td_method_parse("parametric", &m), TD_OK);
    assert_int_equal(m, TD_METHOD_PARAMETRIC);
    assert_int_equal(td_surface_parse("bilinear", &s), TD_OK);
    assert_int_equal(s, TD_SURFACE_BILINEAR);
    assert_int_equal(td_method_parse("fast", &m), TD_EINVAL);
}

/* The accelerated methods take fewer steps than the walk over an oblique view. */
static void test_steps_fewer(void **state)
{
    (void)state;
    td_grid *g = procedural(257, 257, 21, 6);
    td_accel *a = build_all(g, 16);
    td_view v = {g, a->tiles};
    double steps[TD_METHOD_COUNT] = {0};
    for (int py = 0; py < 32; py++) {
        for (int px = 0; px < 32; px++) {
            td_ray r = {{-100.0, -100.0, g->zmax + 300.0},
                        {1.0 + (px - 16) / 40.0, 1.0 - (px - 16) / 40.0, -0.05 - py / 200.0}, 0.0, INFINITY};
            for (int m = 0; m < TD_METHOD_COUNT; m++) {
                td_hit h;
                td_trace(&v, (td_method)m, TD_SURFACE_TRIANGLE, &r, &h);
                steps[m] += h.steps;
            }
        }
    }
    print_message("steps/ray: incremental %.1f hierarchical %.1f parametric %.1f auto %.1f\n",
                  steps[0] / 1024, steps[1] / 1024, steps[2] / 1024, steps[3] / 1024);
    assert_true(steps[TD_METHOD_HIERARCHICAL] < 0.5 * steps[TD_METHOD_INCREMENTAL]);
    assert_true(steps[TD_METHOD_PARAMETRIC] < 0.5 * steps[TD_METHOD_INCREMENTAL]);
    td_accel_free(a);
    td_grid_free(g);
}

/* A packet test at both widths (td_trace_set_lanes 4, then 8): where the build or the
 * processor has no eight-lane instance (or under valgrind, which runs no AVX-512), both runs
 * take four lanes. */
static void at_each_width(void (*body)(void))
{
    static const int widths[] = {4, 8};
    for (size_t i = 0; i < sizeof widths / sizeof widths[0]; i++) {
        int used = td_trace_set_lanes(widths[i]);
        assert_true(used == widths[i] || used == 4);
        body();
    }
    assert_int_equal(td_trace_set_lanes(4), 4);
    td_trace_set_lanes(0);
}

/* A fan from one origin (td_trace_fan, with its packets of four or eight rays) and parallel rays
 * (td_occluded_par) give, bit for bit, what td_trace_from and td_occluded give each ray,
 * on every method and surface: from above, from below the crests, with t_clear 0, real
 * bounds (from half the way to 1 - 1e-12 of it), +inf, with grazing directions and
 * directions along sample rows, columns and diagonals; a grid with voids; more rays than
 * one batch holds. */
static void batches_same(void)
{
    td_grid *g = procedural(193, 161, 33, 5);
    for (int32_t i = 40; i < 60; i++)
        g->z[(size_t)70 * (size_t)g->w + (size_t)i] = NAN; /* a void across the middle */
    assert_int_equal(td_grid_finish(g, NULL), TD_OK);
    td_accel *a = build_all(g, 8);
    td_view v = {g, a->tiles};
    uint64_t seed = 77;
    const double origins[2][3] = {{-300.0, -250.0, g->zmax + 400.0},
                                  {2400.0, 2000.0, 0.5 * (g->zmin + g->zmax)}};
    enum { N = 150 };
    static struct {
        double d[3], t_clear;
    } fan[N];
    static td_fan f;
    static td_fan_hits fh;
    static td_hit hits[N];
    static double po[N][3], zb[N];
    uint8_t occ[N];
    for (int oi = 0; oi < 2; oi++) {
        for (int k = 0; k < N; k++) { /* toward a point of the relief's box; every 7th grazing */
            double t[3] = {(g->w - 1) * g->sx * rnd(&seed), (g->h - 1) * g->sy * rnd(&seed),
                           g->zmin + (g->zmax - g->zmin) * rnd(&seed)};
            if (k % 7 == 0)
                t[2] = origins[oi][2] - 1e-3 * hypot(t[0] - origins[oi][0], t[1] - origins[oi][1]);
            for (int i = 0; i < 3; i++)
                fan[k].d[i] = t[i] - origins[oi][i];
            if (k % 11 == 5) /* along a sample row, along a column, through sample points */
                fan[k].d[1] = 0.0;
            else if (k % 13 == 6)
                fan[k].d[0] = 0.0;
            else if (k % 17 == 7)
                fan[k].d[1] = copysign(fan[k].d[0] / g->sx * g->sy, fan[k].d[1]);
            po[k][0] = (g->w - 1) * g->sx * rnd(&seed);
            po[k][1] = (g->h - 1) * g->sy * rnd(&seed);
            po[k][2] = g->zmin + (g->zmax - g->zmin) * rnd(&seed);
        }
        for (int m = 0; m < TD_METHOD_COUNT; m++) {
            for (int sf = 0; sf < TD_SURFACE_COUNT; sf++) {
                for (int k = 0; k < N; k++) { /* t_clear: 0, +inf, or before the hit */
                    static const double before[] = {0.9, 0.5, 0.999, 1.0 - 1e-12, 0.97};
                    td_ray r = {{origins[oi][0], origins[oi][1], origins[oi][2]},
                                {fan[k].d[0], fan[k].d[1], fan[k].d[2]}, 0.0, INFINITY};
                    td_hit h;
                    td_trace(&v, (td_method)m, (td_surface)sf, &r, &h);
                    fan[k].t_clear = k % 3 == 0 ? 0.0 : (k % 3 == 1 ? INFINITY : before[k % 5] * h.t);
                    if (!isfinite(fan[k].t_clear))
                        fan[k].t_clear = k % 3 == 1 ? INFINITY : 0.0;
                }
                for (int k0 = 0; k0 < N; k0 += TD_FAN_MAX) { /* fans of TD_FAN_MAX, the last short */
                    int nf = N - k0 < TD_FAN_MAX ? N - k0 : TD_FAN_MAX;
                    for (int k = 0; k < nf; k++) {
                        f.dx[k] = fan[k0 + k].d[0], f.dy[k] = fan[k0 + k].d[1], f.dz[k] = fan[k0 + k].d[2];
                        f.t_clear[k] = fan[k0 + k].t_clear;
                    }
                    td_trace_fan(&v, (td_method)m, (td_surface)sf, origins[oi], nf, &f, &fh);
                    for (int k = 0; k < nf; k++) {
                        td_fan_hit(&fh, k, &hits[k0 + k]);
                        zb[k0 + k] = fh.zb[k];
                    }
                }
                int hit_count = 0;
                for (int k = 0; k < N; k++) {
                    td_ray r = {{origins[oi][0], origins[oi][1], origins[oi][2]},
                                {fan[k].d[0], fan[k].d[1], fan[k].d[2]}, 0.0, INFINITY};
                    td_hit h;
                    td_trace_from(&v, (td_method)m, (td_surface)sf, &r, fan[k].t_clear, &h);
                    assert_memory_equal(&h, &hits[k], sizeof h);
                    hit_count += h.t < INFINITY;
                    double z = NAN; /* the fan's exact-surface height: the grid's, bit for bit */
                    if (!(h.t < INFINITY && td_grid_bilinear_cell(g, h.ci, h.cj, h.p[0], h.p[1], &z, NULL)))
                        z = NAN;
                    assert_memory_equal(&z, &zb[k], sizeof z);
                }
                assert_true(hit_count > N / 6); /* the rays do meet the terrain */
                /* parallel rays along the fan's first direction, from points of the relief
                   (packets of four or eight and, for the last two or six, a short one) */
                uint32_t s1 = 0, s2 = 0;
                td_occluded_par(&v, (td_method)m, (td_surface)sf, fan[1].d, N, (const double(*)[3])po, NULL,
                                occ, &s1);
                int occluded = 0;
                for (int k = 0; k < N; k++) {
                    td_ray r = {{po[k][0], po[k][1], po[k][2]}, {fan[1].d[0], fan[1].d[1], fan[1].d[2]}, 0.0,
                                INFINITY};
                    int o1 = td_occluded(&v, (td_method)m, (td_surface)sf, &r, NULL, &s2);
                    assert_int_equal(o1, occ[k]);
                    occluded += o1;
                }
                assert_true(s1 > 0 && s2 > 0);
                assert_true(occluded > 0 && occluded < N);
            }
        }
    }
    td_accel_free(a);
    td_grid_free(g);
}

static void test_batches_same(void **state)
{
    (void)state;
    at_each_width(batches_same);
}

/* Shadow rays in packets (td_occluded_par: four or eight lanes walk their cells together, ending
 * on a hit, at the grid's edge, or above the sun bound) answer as td_occluded does each
 * ray, with the bound and without: suns from every quarter, steep, grazing and along the
 * axes and diagonals, from just above the surface (as a render's shadow rays start, on
 * slopes that face the sun and that do not), from below it and from high above, over
 * voids; 57 rays: fourteen packets of four or seven of eight (every other one a point
 * four or eight times), then one ray alone. */
static void occluded_packets(void)
{
    td_grid *g = procedural(150, 130, 91, 5);
    for (int32_t i = 30; i < 50; i++)
        g->z[(size_t)60 * (size_t)g->w + (size_t)i] = NAN;
    assert_int_equal(td_grid_finish(g, NULL), TD_OK);
    td_accel *a = build_all(g, 8);
    td_view v = {g, a->tiles};
    static const double suns[][2] = {{30, 35}, {135, 4}, {220, 60}, {300, 1}, {0, 20}, {90, 10}, {45, 15}, {180, 80}};
    enum { N = 57 };
    const int lanes = td_trace_lanes();
    double o[N][3];
    uint8_t occ[N];
    uint64_t seed = 5;
    int shadowed = 0, lit_count = 0;
    for (size_t si = 0; si < sizeof suns / sizeof suns[0]; si++) {
        double az = suns[si][0] * M_PI / 180.0, el = suns[si][1] * M_PI / 180.0;
        double d[3] = {sin(az) * cos(el), cos(az) * cos(el), sin(el)};
        td_sunlit *lit = NULL;
        assert_int_equal(td_sunlit_build(&v, d, 0, &lit, NULL), TD_OK);
        assert_non_null(lit);
        for (int k = 0; k < N; k++) {
            double x = (g->w - 1) * g->sx * rnd(&seed), y = (g->h - 1) * g->sy * rnd(&seed), z = NAN;
            td_grid_bilinear(g, x, y, &z, NULL);
            o[k][0] = x;
            o[k][1] = y; /* mostly just above the ground; some under it, some far above */
            o[k][2] = isnan(z) || k % 9 == 4 ? g->zmax + 50.0 : (k % 7 == 3 ? z - 1.0 : z + 1e-3 * (k % 4));
        }
        for (int k = 0; k < N; k++) /* every other packet one point in every lane: low suns
                                       prove all its lanes shadowed, and no lane walks */
            if (k / lanes % 2 == 1)
                memcpy(o[k], o[k - k % lanes], sizeof o[k]);
        for (int m = 0; m < TD_METHOD_COUNT; m++)
            for (int sf = 0; sf < TD_SURFACE_COUNT; sf++) {
                uint32_t s1 = 0, s2 = 0;
                td_occluded_par(&v, (td_method)m, (td_surface)sf, d, N, (const double(*)[3])o, lit, occ, &s1);
                for (int k = 0; k < N; k++) {
                    td_ray r = {{o[k][0], o[k][1], o[k][2]}, {d[0], d[1], d[2]}, 0.0, INFINITY};
                    assert_int_equal(td_occluded(&v, (td_method)m, (td_surface)sf, &r, lit, &s2), occ[k]);
                    assert_int_equal(td_occluded(&v, (td_method)m, (td_surface)sf, &r, NULL, &s2), occ[k]);
                    shadowed += occ[k];
                    lit_count += !occ[k];
                }
            }
        td_sunlit_free(lit);
    }
    assert_true(shadowed > 500 && lit_count > 500); /* both answers, many times */
    td_accel_free(a);
    td_grid_free(g);
}

static void test_occluded_packets(void **state)
{
    (void)state;
    at_each_width(occluded_packets);
}

/* The packets' cell intersections where the scalar ones branch: on a grid of saddles
 * (corners 0 and 10 m alternating), horizontal rays along and beside the cells' diagonals
 * (through sample points, or just off them) at heights below, at and above the patches'
 * 5 m crests, in both directions, each started a few cells before as a fan of one ray
 * (a packet with one lane): bilinear and linear rays that dip under the surface inside a
 * cell and rise out of it with f of one sign at both ends, triangle rays split at the
 * diagonal, plane rays that meet walls and tops; started inside a cell, on its sample lines
 * and at a sample point. Each gives td_trace_from's hit bit for bit. */
static void fan_cells(void)
{
    td_grid *g = make_grid(24, 24, 3.0, 2.0, 3);
    for (int32_t j = 0; j < g->h; j++)
        for (int32_t i = 0; i < g->w; i++)
            g->z[(size_t)j * (size_t)g->w + (size_t)i] = (i + j) % 2 ? 10.0f : 0.0f;
    assert_int_equal(td_grid_finish(g, NULL), TD_OK);
    td_accel *a = build_all(g, 8);
    td_view v = {g, a->tiles};
    static const double heights[] = {1.0, 4.0, 4.9, 4.999999, 5.0, 5.000001, 6.0};
    static const double offsets[] = {0.0, 0.1, -0.3, 1e-9};
    int hits = 0, tried = 0;
    for (int sf = 0; sf < TD_SURFACE_COUNT; sf++) {
        for (int hi = 0; hi < 7; hi++) {
            for (int oi = 0; oi < 4; oi++) {
                for (int dir = 0; dir < 12; dir++) { /* +u+v, -u-v, +u-v, -u+v; 3 starts */
                    double su = dir % 2 ? -1.0 : 1.0, sv = dir % 4 < 2 ? su : -su;
                    double u0 = 12.0 - 3.0 * su + offsets[oi], v0 = 12.0 - 3.0 * sv;
                    /* a start in a cell, on its sample lines (at a sample point when on the
                       diagonal), and one cell on */
                    td_fan f = {.dx = {su * g->sx}, .dy = {sv * g->sy}, .dz = {0.0},
                                .t_clear = {1.5 + 0.5 * (dir / 4)}};
                    td_fan_hits fh;
                    const double o[3] = {u0 * g->sx, v0 * g->sy, heights[hi]};
                    td_ray r = {{o[0], o[1], o[2]}, {f.dx[0], f.dy[0], f.dz[0]}, 0.0, INFINITY};
                    td_hit hf, h1;
                    td_trace_fan(&v, TD_METHOD_AUTO, (td_surface)sf, o, 1, &f, &fh);
                    td_fan_hit(&fh, 0, &hf);
                    td_trace_from(&v, TD_METHOD_AUTO, (td_surface)sf, &r, f.t_clear[0], &h1);
                    assert_memory_equal(&hf, &h1, sizeof hf);
                    hits += h1.t < INFINITY;
                    tried++;
                }
            }
        }
    }
    assert_true(hits > tried / 2 && hits < tried);
    td_accel_free(a);
    td_grid_free(g);
}

static void test_fan_cells(void **state)
{
    (void)state;
    at_each_width(fan_cells);
}

/* The same hit as td_trace, from any t_clear before it: t, point, normal and cell. */
static void assert_same_hit(const td_hit *a, const td_hit *b)
{
    assert_memory_equal(&a->t, &b->t, sizeof a->t);
    assert_memory_equal(a->p, b->p, sizeof a->p);
    assert_memory_equal(a->n, b->n, sizeof a->n);
    assert_int_equal(a->ci, b->ci);
    assert_int_equal(a->cj, b->cj);
}

/* Ray r on surface sf: every method's td_trace gives the incremental walk's hit, and so
 * does td_trace_from (and, with fans, a fan of one ray) from every t_clear = tc0, tc0 +
 * dt, .. before the hit and tc_max. Returns the incremental walk's t; *moved counts the
 * starts that took fewer steps. */
static double assert_walks_agree(const td_view *v, td_surface sf, const td_ray *r, double tc0, double dt,
                                 double tc_max, int fans, int *moved)
{
    td_hit href;
    td_trace(v, TD_METHOD_INCREMENTAL, sf, r, &href);
    for (int m = 0; m < TD_METHOD_COUNT; m++) {
        td_hit h0, h1;
        if (m == TD_METHOD_SILHOUETTE)
            continue;
        td_trace(v, (td_method)m, sf, r, &h0);
        assert_same_hit(&href, &h0);
        for (double tc = tc0; tc < h0.t && tc < tc_max; tc += dt) {
            td_trace_from(v, (td_method)m, sf, r, tc, &h1);
            assert_same_hit(&h0, &h1);
            if (fans) {
                td_fan f = {.dx = {r->d[0]}, .dy = {r->d[1]}, .dz = {r->d[2]}, .t_clear = {tc}};
                td_fan_hits fh;
                td_trace_fan(v, (td_method)m, sf, r->o, 1, &f, &fh);
                td_fan_hit(&fh, 0, &h1);
                assert_same_hit(&h0, &h1);
                *moved += h1.steps < h0.steps;
            }
        }
    }
    return href.t;
}

/* Shadow rays from o[0 .. n) along the sun: td_occluded with the bound lit and without it,
 * and td_occluded_par in one batch, answer as td_trace. Returns how many are lit. */
static int assert_shadows_agree(const td_view *v, td_surface sf, const td_sunlit *lit, const double sun[3],
                                const double (*o)[3], int n)
{
    uint8_t occ[64];
    uint32_t steps = 0;
    int lit_rays = 0;
    assert_true(n <= 64);
    td_occluded_par(v, TD_METHOD_AUTO, sf, sun, n, o, lit, occ, &steps);
    for (int k = 0; k < n; k++) {
        td_ray r = {{o[k][0], o[k][1], o[k][2]}, {sun[0], sun[1], sun[2]}, 0.0, INFINITY};
        td_hit h;
        td_trace(v, TD_METHOD_AUTO, sf, &r, &h);
        assert_int_equal(td_occluded(v, TD_METHOD_AUTO, sf, &r, lit, &steps), h.t < INFINITY);
        assert_int_equal(td_occluded(v, TD_METHOD_AUTO, sf, &r, NULL, &steps), h.t < INFINITY);
        assert_int_equal(occ[k], h.t < INFINITY);
        lit_rays += h.t == INFINITY;
    }
    return lit_rays;
}

/* assert_shadows_agree on every surface of the finished grid g, with the sun at azimuth
 * az and elevation el (degrees) and its bound, which must have a shadow side (the claims
 * these cases hold). Returns the lit rays over the surfaces. */
static int shadow_rays_agree(const td_grid *g, double az, double el, const double (*o)[3], int n)
{
    td_accel *a = build_all(g, TD_PLANES_K_DEFAULT);
    td_view v = {g, a->tiles};
    const double sun[3] = {sin(az * M_PI / 180.0) * cos(el * M_PI / 180.0),
                           cos(az * M_PI / 180.0) * cos(el * M_PI / 180.0), sin(el * M_PI / 180.0)};
    td_sunlit *lit = NULL;
    int lit_rays = 0;
    assert_int_equal(td_sunlit_build(&v, sun, 0, &lit, NULL), TD_OK);
    assert_non_null(lit);
    assert_non_null(lit->lo);
    for (int sf = 0; sf < TD_SURFACE_COUNT; sf++)
        lit_rays += assert_shadows_agree(&v, (td_surface)sf, lit, sun, o, n);
    td_sunlit_free(lit);
    td_accel_free(a);
    return lit_rays;
}

/* Rays within an ulp of a grid line: their position, rounded, lands on the line's other
 * side long before the walk crosses it, and a walk that finds its cell from a position
 * skipped what was left of the cell the ray was still in (fuzz_render: a straight-down
 * camera ray on a row's line, sy = 4/3, met a column's side 2.5 m under the top of the
 * one it was in, from a start with the beam on and from a parametric jump). Nearly
 * vertical rays from points on the row and column lines of a plane that rises north and
 * falls east, and of one that falls north with a 5 m plateau on it (the jump's case),
 * every surface and method: each method td_trace's hit as the incremental walk's, and
 * from every t_clear before it (td_trace_from, a fan's packet) the same. */
static void test_from_near_line(void **state)
{
    (void)state;
    /* tiny horizontal parts, the first the fuzzer's camera ray's */
    static const double dir[4][2] = {{3.7681813499433066e-17, 4.8264690903895654e-17},
                                     {-1e-16, 4.8e-17},
                                     {4.8e-17, -1e-15},
                                     {-3.7e-17, -1e-16}};
    int moved = 0;
    for (int step = 0; step < 2; step++) {
        td_grid *g = make_grid(8, 10, 1.0, 4.0 / 3.0, 3 + step);
        for (int32_t j = 0; j < g->h; j++)
            for (int32_t i = 0; i < g->w; i++)
                g->z[(size_t)j * (size_t)g->w + (size_t)i] =
                    (float)(step ? 200 + 3 * i - 3 * j + (abs(i - 7) + abs(j - 5) < 6 ? 5 : 0) : 200 - 3 * i + 3 * j);
        assert_int_equal(td_grid_finish(g, NULL), TD_OK);
        td_accel *a = build_all(g, TD_PLANES_K_DEFAULT); /* the fuzzer's cones */
        td_view v = {g, a->tiles};
        for (int sf = 0; sf < TD_SURFACE_COUNT; sf++)
            for (int at = 0; at < 3 * 6 * 8 * 4 * 2; at++) {
                /* on row j's line (y = j sy as rounded) between samples or at one, or on
                   column i's line between rows; 227 or 228 m up (over the plateau's 226 m,
                   the plane's 227 m) */
                int kind = at % 3, i = 1 + at / 3 % 6, j = 1 + at / 18 % 8, d = at / 144 % 4;
                const double o[3] = {kind == 0 ? i + 0.5 : (double)i, kind == 2 ? (j + 0.5) * g->sy : j * g->sy,
                                     227.0 + at / 576 + (step == 0)};
                td_ray r = {{o[0], o[1], o[2]}, {dir[d][0], dir[d][1], -1.0}, 0.0, INFINITY};
                double t = assert_walks_agree(&v, (td_surface)sf, &r, 0.75, 1.5, INFINITY, 1, &moved);
                assert_true(t > 0.0 && t < 60.0);
            }
        td_accel_free(a);
        td_grid_free(g);
    }
    assert_true(moved > 1000); /* the starts did skip cells */
}

/* A start from a t_clear after the ray's clip (the eye over the highest sample: the walk
 * starts where the ray comes down to it) in a cell the ray entered before that clip: the
 * walk starts in the cell of t_clear (walk_col, walk_row), not in the one the rounded
 * position at the clip names. fuzz_render (seed row-line-clip, a level camera's driver):
 * an eye on row line 6 as the frame computes it (y = 80, sy = 13.333333333333332: V =
 * 6.000000000000001) looking west and down, d_y = -6.6e-17, crosses the row line 180 m
 * along the ray; its clip starts 107 m along, where its position rounds below the line,
 * and a silhouette start (t_clear 110) walked the row below, on the plane surface 3 m
 * lower: hit at 178.8 m instead of 176.1. Every t_clear from 0 to the hit, every method,
 * surface and a fan of the ray give td_trace's hit. */
static void test_from_after_clip(void **state)
{
    int moved = 0;
    (void)state;
    td_grid *g = make_grid(25, 24, 10.0, 13.333333333333332, 5);
    for (int32_t j = 0; j < g->h; j++)
        for (int32_t i = 0; i < g->w; i++)
            g->z[(size_t)j * (size_t)g->w + (size_t)i] = (float)(200 + 2 * i + 3 * j);
    assert_int_equal(td_grid_finish(g, NULL), TD_OK);
    td_accel *a = build_all(g, TD_PLANES_K_DEFAULT);
    td_view v = {g, a->tiles};
    const td_ray r = {{200.0, 80.0, 410.5}, {-0.35728959974141805, -6.5633034703794984e-17, -0.93399365196805118},
                      0.0, INFINITY};
    for (int sf = 0; sf < TD_SURFACE_COUNT; sf++) {
        double t = assert_walks_agree(&v, (td_surface)sf, &r, 0.0, 0.5, INFINITY, 1, &moved);
        assert_true(t > 170.0 && t < 180.0);
    }
    td_accel_free(a);
    td_grid_free(g);
}

/* test_from_near_line's rounding for shallow rays along a row's or a column's line: a
 * block of cells left through its side finds the cell along the other axis from the
 * position (leave_box_at), which rounds onto the line before the ray crosses it. A grid
 * of 48 x 48 samples of a plane with plateaus, rays from 2 m over its highest sample
 * descending 1 in 20 to 1 in 3 along row and column lines (sy = 4/3: the lines' values
 * rounded) with a sideways part of 1e-17 to 1e-15, both ways: every method and surface
 * gives the incremental walk's hit, from its start and from t_clear before it. */
static void test_along_line(void **state)
{
    (void)state;
    td_grid *g = make_grid(48, 48, 1.0, 4.0 / 3.0, 4);
    for (int32_t j = 0; j < g->h; j++)
        for (int32_t i = 0; i < g->w; i++)
            g->z[(size_t)j * (size_t)g->w + (size_t)i] =
                (float)(200 + (i % 16 < 9 && j % 12 < 7 ? 5 : 0) + (i + j) / 4);
    assert_int_equal(td_grid_finish(g, NULL), TD_OK);
    td_accel *a = build_all(g, TD_PLANES_K_DEFAULT);
    td_view v = {g, a->tiles};
    static const double side[] = {1e-17, -5e-17, 1e-16, -1e-15}, fall[] = {0.05, 0.12, 0.33};
    int hits = 0;
    for (int sf = 0; sf < TD_SURFACE_COUNT; sf++)
        for (int at = 0; at < 2 * 2 * 8 * 4 * 3; at++) {
            /* along a row (axis 0) or a column, east/north or back, line k */
            int axis = at % 2, back = at / 2 % 2, k = 5 + 5 * (at / 4 % 8), e = at / 32 % 4, f = at / 128;
            double along = back ? -1.0 : 1.0, line = axis ? k * g->sx : k * g->sy;
            double start = back ? 46.5 : 0.5;
            td_ray r = {{axis ? line : start * g->sx, axis ? start * g->sy : line, (double)g->zmax + 2.0},
                        {axis ? side[e] : along, axis ? along : side[e], -fall[f]},
                        0.0,
                        INFINITY};
            hits += assert_walks_agree(&v, (td_surface)sf, &r, 1.0, 3.0, 60.0, 0, NULL) < INFINITY;
        }
    assert_true(hits > 300);
    td_accel_free(a);
    td_grid_free(g);
}

/* Rays through sample points, diagonally (|dx| = |dy|), over a saddle of plane-surface
 * columns: at a sample point the walk steps diagonally, touching the two columns beside it
 * at that point only; the max-mipmap's walk, leaving a block across one line, found its
 * cell along the other from the rounded position, a cell short, and met the column beside
 * the point (fuzz_render: 10.32 m against the walk's 11.47, a camera looking straight down
 * from off the grid, seed diagonal-vertex). Every surface and method gives the incremental
 * walk's hit, from its start and from t_clear before it. */
static void test_through_vertices(void **state)
{
    (void)state;
    td_grid *g = make_grid(16, 14, 1.0, 1.0, 3);
    for (int32_t j = 0; j < g->h; j++)
        for (int32_t i = 0; i < g->w; i++)
            g->z[(size_t)j * (size_t)g->w + (size_t)i] = (float)(200.0 + 0.5 * abs(i - 5) * abs(j - 7));
    assert_int_equal(td_grid_finish(g, NULL), TD_OK);
    td_accel *a = build_all(g, TD_PLANES_K_DEFAULT);
    td_view v = {g, a->tiles};
    static const double z0[] = {212.35294117647058, 210.0, 214.7, 205.25};
    static const double fall[] = {0.72836196215411597 / 0.48450430962325092, 0.5, 2.0, 0.25};
    int hits = 0;
    for (int sf = 0; sf < TD_SURFACE_COUNT; sf++)
        for (int at = 0; at < 2 * 16 * 4 * 4; at++) {
            /* from off the west edge up to the north-east, or down to the south-east */
            int anti = at % 2, k = at / 2 % 16, zi = at / 32 % 4, fi = at / 128;
            td_ray r = {{-4.0, anti ? 13.0 + k : (double)k - 3.0, z0[zi]},
                        {0.48450430962325092, anti ? -0.48450430962325092 : 0.48450430962325092,
                         -0.48450430962325092 * fall[fi]},
                        0.0,
                        INFINITY};
            hits += assert_walks_agree(&v, (td_surface)sf, &r, 0.5, 1.0, 40.0, 0, NULL) < INFINITY;
        }
    assert_true(hits > 500);
    td_accel_free(a);
    td_grid_free(g);
}

/* Shadow rays from the walls of plane columns that face the sun, beside a void: the
 * origin lies on the column's line and the walk, leaving the wall toward the sun, starts
 * in the cell before it (a hole here) and finds the ray lit; the sun bound's shadow side
 * took the column behind the wall, whose lowest sample is above the origin, and called it
 * shadowed (fuzz_render, seed wall-beside-void: half the pixels of a view looking down at
 * the walls). A grid rising north, a void column and row, the sun low in the west: rays
 * from points low on the walls east of the void, under the lowest sample of their
 * blocks (and, for the other surfaces, from the same
 * points) answer as td_trace with the bound and without, one by one and in a batch. */
static void test_shadow_from_wall(void **state)
{
    (void)state;
    td_grid *g = make_grid(14, 19, 1000.0, 750.0, 3);
    double o[16][3];
    for (int32_t j = 0; j < g->h; j++)
        for (int32_t i = 0; i < g->w; i++)
            g->z[(size_t)j * (size_t)g->w + (size_t)i] = i == 7 || j == 9 ? NAN : (float)(200 + 3 * j);
    assert_int_equal(td_grid_finish(g, NULL), TD_OK);
    for (int k = 0; k < 16; k++) { /* rows 10 .. 17, on and between sample rows */
        o[k][0] = 8000.0, o[k][1] = (10 + k / 2) * 750.0 + 375.0 * (k % 2), o[k][2] = 192.0 + 3.0 * (10 + k / 2);
    }
    /* the plane's walls, at least, see the sun */
    assert_true(shadow_rays_agree(g, 258.0, 10.0, (const double(*)[3])o, 16) >= 16);
    td_grid_free(g);
}

/* Shadow rays that leave the grid through its last cells: with 15 rows of cells and the
 * sun bound's blocks 2 cells tall, the last block reaches a cell past the grid, and its
 * lowest sample (of the cells that are there) made the shadow side claim rays that leave
 * the grid through the missing cell, with nothing under them: a view of terrain rising
 * toward a low sun had pixels on the grid's last half row called shadowed (fuzz_render,
 * seed edge-block). Points a hair over every surface in that half row: as
 * td_trace with the bound and without, one by one and in a batch. */
static void test_shadow_at_edge(void **state)
{
    (void)state;
    td_grid *g = make_grid(24, 16, 1.0, 0.75, 3);
    double o[40][3];
    for (int32_t j = 0; j < g->h; j++)
        for (int32_t i = 0; i < g->w; i++)
            g->z[(size_t)j * (size_t)g->w + (size_t)i] = (float)(200.0 + 4.5 * i + 0.5 * j);
    assert_int_equal(td_grid_finish(g, NULL), TD_OK);
    for (int k = 0; k < 40; k++) { /* row 14, v 14.945; over the cell's highest corner */
        int i = 2 + 2 * (k / 4);
        o[k][0] = i + 0.14 + 0.15 * (k % 4), o[k][1] = 11.209239130434783;
        o[k][2] = 200.0 + 4.5 * (i + 1) + 0.5 * 15 + 0.015;
    }
    /* rays that leave the grid before the terrain rises to them */
    assert_true(shadow_rays_agree(g, 81.6901, 10.0, (const double(*)[3])o, 40) >= 40);
    td_grid_free(g);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_flat_analytic),       cmocka_unit_test(test_single_cell_bilinear),
        cmocka_unit_test(test_quad_hit_sag),
        cmocka_unit_test(test_methods_vs_reference), cmocka_unit_test(test_planes_bound),
        cmocka_unit_test(test_planes_degenerate),   cmocka_unit_test(test_maxmip_and_edt),
        cmocka_unit_test(test_accel_maxmip_store),
        cmocka_unit_test(test_plane_walls),         cmocka_unit_test(test_validate),
        cmocka_unit_test(test_steps_fewer),         cmocka_unit_test(test_batches_same),
        cmocka_unit_test(test_occluded_packets),
        cmocka_unit_test(test_fan_cells),           cmocka_unit_test(test_from_near_line),
        cmocka_unit_test(test_along_line),          cmocka_unit_test(test_through_vertices),
        cmocka_unit_test(test_shadow_from_wall),    cmocka_unit_test(test_shadow_at_edge),
        cmocka_unit_test(test_from_after_clip),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
