/* test_isogrid.c: the isometric lattice of core/isogrid.c. Layout and sampling; planes
 * reproduced exactly (heights and normals); every sample reproduced at its vertex; the
 * triangle the lattice's point location picks agrees with an independent triangulation
 * (tests/oracle/iso_reference.c); two-byte packing lossless on integer DEMs and within
 * half a step otherwise; and td_iso_trace against the double-precision reference on
 * random rays over a real DEM and a bumpy surface with holes, and on hard cases: rays
 * along each of the three families of lattice lines, through vertices, vertical, grazing
 * a peak, on flat terrain, from below (two-sided), from outside, through holes; every
 * downward ray over the lattice hits (watertight). */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <cmocka.h>

#include "dem.h"
#include "lod.h"
#include "isogrid.h"
#include "iso_reference.h"

/* Under the address sanitizer (Debug, about 20x slower: 157 s of CI's ASan tree on a
 * 2-core Zen 3) a quarter of the random rays; the plain build, which CI runs too, traces
 * them all. */
#if defined(__SANITIZE_ADDRESS__)
#define RANDOM_RAYS_SHARE 4
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define RANDOM_RAYS_SHARE 4
#endif
#endif
#ifndef RANDOM_RAYS_SHARE
#define RANDOM_RAYS_SHARE 1
#endif

static double rnd(uint64_t *s)
{
    *s = *s * 6364136223846793005ull + 1442695040888963407ull;
    return (double)(*s >> 11) / 9007199254740992.0;
}

static double plane_fn(void *ctx, double x, double y)
{
    (void)ctx;
    return 3.0 + 0.25 * x - 0.125 * y;
}

static double bumpy_fn(void *ctx, double x, double y)
{
    int holes = ctx != NULL;
    double z = 40.0 * sin(0.21 * x + 0.4) * cos(0.17 * y) + 15.0 * sin(0.9 * x * 0.37 + y * 0.5);
    if (holes && ((x > 20 && x < 27 && y > 30 && y < 40) || (fabs(y - 13.0) < 1.5)))
        z = NAN;
    return z;
}

static double cm_fn(void *ctx, double x, double y) /* centimetre data, as many DEMs */
{
    (void)ctx;
    return 1375.07 + nearbyint(100.0 * 40.0 * (1.0 + sin(0.3 * x) * cos(0.2 * y))) / 100.0;
}

static double flat_fn(void *ctx, double x, double y)
{
    (void)ctx;
    (void)x;
    (void)y;
    return 5.0;
}

static td_iso *make(int32_t nx, int32_t ny, double a, double b, td_iso_fn f, void *ctx)
{
    td_iso *l = NULL;
    assert_int_equal(td_iso_create(nx, ny, a, b, &l, NULL), TD_OK);
    td_iso_sample(l, f, ctx);
    return l;
}

static void test_iso_layout(void **state)
{
    (void)state;
    td_iso *l = make(5, 4, 2.0, 3.0, plane_fn, NULL);
    td_err err;
    assert_int_equal(td_iso_row_offset(5, 0), 0);
    assert_int_equal(td_iso_row_offset(5, 1), 5);
    assert_int_equal(td_iso_row_offset(5, 2), 11);
    assert_int_equal(td_iso_row_offset(5, 4), 22); /* 4 rows: 5 + 6 + 5 + 6 samples */
    assert_int_equal(td_iso_row_len(l, 1), 6);
    assert_true(td_iso_x(l, 0, 3) == 6.0);
    assert_true(td_iso_x(l, 1, 0) == 0.0);
    assert_true(td_iso_x(l, 1, 1) == 1.0);
    assert_true(td_iso_x(l, 1, 4) == 7.0);
    assert_true(td_iso_x(l, 1, 5) == 8.0);
    assert_true(td_iso_at(l, 1, 2) == (float)plane_fn(NULL, 3.0, 3.0));
    assert_true(l->zmin == (float)plane_fn(NULL, 0.0, 9.0));
    assert_true(l->zmax == (float)plane_fn(NULL, 8.0, 0.0));
    td_iso_free(l);
    l = NULL;
    assert_int_equal(td_iso_create(1, 5, 1.0, 1.0, &l, &err), TD_EINVAL);
    assert_null(l);
    assert_int_equal(td_iso_create(5, 5, 0.0, 1.0, &l, &err), TD_EINVAL);
    assert_int_equal(td_iso_create(5, 5, 1.0, NAN, &l, &err), TD_EINVAL);
    assert_string_equal(td_iso_rows_name(TD_ISO_ROWS_EQUILATERAL), "equilateral");
}

/* A plane is reproduced exactly (its samples are exact in float here), normals too. */
static void test_iso_planes(void **state)
{
    (void)state;
    uint64_t seed = 7;
    const double sp[2][2] = {{2.0, 2.0}, {2.0, 1.75}};
    for (int v = 0; v < 2; v++) {
        td_iso *l = make(17, 13, sp[v][0], sp[v][1], plane_fn, NULL);
        double nz = 1.0 / sqrt(0.25 * 0.25 + 0.125 * 0.125 + 1.0);
        for (int k = 0; k < 5000; k++) {
            double x = rnd(&seed) * 16 * l->a, y = rnd(&seed) * 12 * l->b, z, n[3];
            if (k < 40) { /* on lattice lines and vertices */
                int32_t r = k % 12, c = k % 16;
                x = td_iso_x(l, r, c);
                y = r * l->b;
            }
            assert_true(td_iso_eval(l, x, y, &z, n));
            assert_true(fabs(z - plane_fn(NULL, x, y)) <= 1e-12 * (1.0 + fabs(z)));
            assert_true(fabs(n[0] - (-0.25 * nz)) < 1e-12);
            assert_true(fabs(n[1] - (0.125 * nz)) < 1e-12);
            assert_true(fabs(n[2] - nz) < 1e-12);
        }
        td_iso_free(l);
    }
}

/* Every sample at its vertex; every point's height as the reference triangulation's. */
static void test_iso_triangulation(void **state)
{
    (void)state;
    uint64_t seed = 11;
    td_iso *l = make(33, 29, 1.5, 1.5 * sqrt(3.0) / 2.0, bumpy_fn, NULL);
    for (int32_t r = 0; r < l->ny; r++)
        for (int32_t c = 0; c < td_iso_row_len(l, r); c++) {
            double z;
            assert_true(td_iso_eval(l, td_iso_x(l, r, c), r * l->b, &z, NULL));
            assert_true(z == (double)td_iso_at(l, r, c));
        }
    for (int k = 0; k < 20000; k++) {
        double x = rnd(&seed) * 32 * l->a, y = rnd(&seed) * 28 * l->b, z, zr;
        if (k % 4 == 0) /* on a line of the u - Y/2 or u + Y/2 families */
            x = (floor(rnd(&seed) * 30) + (k % 8 ? 0.5 : -0.5) * y / l->b) * l->a;
        if (k % 7 == 0) /* on a row */
            y = floor(rnd(&seed) * 28) * l->b;
        if (x < 0 || x > 32 * l->a)
            continue;
        assert_true(td_iso_eval(l, x, y, &z, NULL));
        zr = td_iso_ref_height(l, x, y);
        assert_false(isnan(zr));
        assert_true(fabs(z - zr) <= 1e-9 * 60.0);
    }
    td_iso_free(l);
}

static td_grid *load(const char *name)
{
    char path[1024];
    td_grid *g = NULL;
    td_err err;
    snprintf(path, sizeof path, "%s/%s", TERRAD_TEST_DATA, name);
    assert_int_equal(td_dem_load(path, NULL, &g, &err), TD_OK);
    return g;
}

static void test_iso_from_grid(void **state)
{
    (void)state;
    td_grid *g = load("volcano.asc");
    td_iso *l = NULL;
    assert_int_equal(td_iso_from_grid(g, 2, TD_ISO_ROWS_SQUARE, &l, NULL), TD_OK);
    assert_int_equal(l->nx, (g->w - 1) / 2 + 1);
    assert_int_equal(l->ny, (g->h - 1) / 2 + 1);
    for (int32_t r = 0; r < l->ny; r++) /* every sample on a grid node */
        for (int32_t c = 0; c < td_iso_row_len(l, r); c++) {
            int32_t i = (int32_t)lround(td_iso_x(l, r, c) / g->sx);
            assert_true(td_iso_at(l, r, c) == td_grid_at(g, i, 2 * r));
        }
    td_iso_free(l);
    assert_int_equal(td_iso_from_grid(g, 1, TD_ISO_ROWS_EQUILATERAL, &l, NULL), TD_OK);
    assert_true(fabs(l->a * l->b - g->sx * g->sy) < 1e-9 * g->sx * g->sy); /* same density */
    assert_true(fabs(l->b / l->a - sqrt(3.0) / 2.0) < 1e-12);
    assert_true((l->nx - 1) * l->a <= (g->w - 1) * g->sx + 1e-9);
    assert_true((l->ny - 1) * l->b <= (g->h - 1) * g->sy + 1e-9);
    assert_true(l->zmin >= g->zmin && l->zmax <= g->zmax);
    td_iso_free(l);
    assert_int_equal(td_iso_from_grid(g, 0, TD_ISO_ROWS_SQUARE, &l, NULL), TD_EINVAL);
    td_grid_free(g);
}

static void test_iso_pack(void **state)
{
    (void)state;
    td_grid *g = load("volcano.asc"); /* whole metres */
    td_iso *l = NULL, *u = NULL;
    td_iso_packed *p = NULL;
    size_t n;
    assert_int_equal(td_iso_from_grid(g, 2, TD_ISO_ROWS_SQUARE, &l, NULL), TD_OK);
    assert_int_equal(td_iso_pack(l, 3, &p, NULL), TD_OK);
    n = td_iso_row_offset(l->nx, l->ny);
    assert_int_equal(p->lossless, p->tiles_x * p->tiles_y);
    assert_true(p->max_err == 0.0);
    assert_int_equal(p->bytes, 2 * n + 16 * (size_t)p->tiles_x * (size_t)p->tiles_y);
    assert_int_equal(td_iso_unpack(p, &u, NULL), TD_OK);
    assert_memory_equal(u->z, l->z, n * sizeof(float));
    td_iso_packed_free(p);
    td_iso_free(u);
    td_iso_free(l);
    td_grid_free(g);

    /* decimal data: float32 heights of centimetre values are coded exactly */
    l = make(70, 50, 1.0, 1.0, cm_fn, NULL);
    assert_int_equal(td_iso_pack(l, 4, &p, NULL), TD_OK);
    assert_int_equal(p->lossless, p->tiles_x * p->tiles_y);
    assert_true(p->max_err == 0.0);
    assert_int_equal(td_iso_unpack(p, &u, NULL), TD_OK);
    assert_memory_equal(u->z, l->z, td_iso_row_offset(l->nx, l->ny) * sizeof(float));
    td_iso_packed_free(p);
    td_iso_free(u);
    td_iso_free(l);

    /* lossy: heights with every fraction, voids kept */
    l = make(70, 50, 1.0, 1.0, bumpy_fn, (void *)1);
    assert_int_equal(td_iso_pack(l, 4, &p, NULL), TD_OK);
    assert_true(p->lossless < p->tiles_x * p->tiles_y);
    assert_int_equal(td_iso_unpack(p, &u, NULL), TD_OK);
    n = td_iso_row_offset(l->nx, l->ny);
    double worst = 0.0, step = 0.0;
    for (size_t i = 0; i < (size_t)p->tiles_x * p->tiles_y; i++)
        step = fmax(step, p->step[i]);
    for (size_t i = 0; i < n; i++) {
        assert_int_equal(isnan(u->z[i]), isnan(l->z[i]));
        if (!isnan(l->z[i]))
            worst = fmax(worst, fabs((double)u->z[i] - l->z[i]));
    }
    assert_true(worst == p->max_err);
    assert_true(worst > 0.0 && worst <= step / 2 + 1e-5);
    assert_true(step < 110.0 / 65534 * 1.01); /* the range is about 110 m */
    td_iso_packed_free(p);
    td_iso_free(u);
    assert_int_equal(td_iso_pack(l, 0, &p, NULL), TD_EINVAL);
    td_iso_free(l);
}

typedef struct tally {
    int agree, tie, wrong;
} tally;

/* td_iso_trace on lattice l against the reference on `fl`: l itself when it holds
 * floats, its decoded heights (td_iso_unpack) when it is packed, and then the walk on the
 * packed vertices must answer bit for bit what it answers on their decoded floats. */
static void judge_on(const td_iso *l, const td_iso *fl, const td_ray *r, tally *t)
{
    td_hit h;
    td_iso_ref_hit ref;
    double eps = 1e-6 * (1.0 + fmax(fabs(l->zmin), fabs(l->zmax)));
    td_iso_trace(l, r, &h);
    if (fl != l) {
        td_hit hf;
        td_iso_trace(fl, r, &hf);
        assert_true(h.t == hf.t || (isnan(h.t) && isnan(hf.t)));
        assert_true(h.t == INFINITY || (h.n[0] == hf.n[0] && h.n[1] == hf.n[1] &&
                                        h.n[2] == hf.n[2] && h.ci == hf.ci && h.cj == hf.cj));
        assert_int_equal(h.steps, hf.steps);
    }
    td_iso_ref_trace(fl, r, eps, &ref);
    td_iso_ref_verdict v = td_iso_ref_judge(fl, r, &ref, h.t, eps);
    if (v == TD_ISO_REF_WRONG)
        print_message("wrong: o %.17g %.17g %.17g d %.17g %.17g %.17g t %.17g ref %.17g "
                      "[%.17g, %.17g]\n", r->o[0], r->o[1], r->o[2], r->d[0], r->d[1], r->d[2],
                      h.t, ref.t, ref.t_near, ref.t_strict);
    t->agree += v == TD_ISO_REF_AGREE;
    t->tie += v == TD_ISO_REF_TIE;
    t->wrong += v == TD_ISO_REF_WRONG;
    if (h.t < INFINITY) { /* the hit lies on the (valid) triangle it names */
        double tv[3][3], e1[3], e2[3], n[3];
        assert_true(h.t >= r->tmin && h.t <= r->tmax);
        assert_true(h.n[2] > 0.0f);
        assert_true(td_iso_triangle(l, h.cj, h.ci, tv));
        for (int k = 0; k < 3; k++) {
            e1[k] = tv[1][k] - tv[0][k];
            e2[k] = tv[2][k] - tv[0][k];
        }
        n[0] = e1[1] * e2[2] - e1[2] * e2[1];
        n[1] = e1[2] * e2[0] - e1[0] * e2[2];
        n[2] = e1[0] * e2[1] - e1[1] * e2[0];
        double zp = tv[0][2] - (n[0] * (h.p[0] - tv[0][0]) + n[1] * (h.p[1] - tv[0][1])) / n[2];
        assert_true(fabs(h.p[2] - zp) <= 1e-6 * (1.0 + fabs(zp)));
    }
}

static void judge(const td_iso *l, const td_ray *r, tally *t) { judge_on(l, l, r, t); }

/* Random rays from above the lattice toward points on it and beyond. */
static void random_rays_on(const td_iso *l, const td_iso *fl, int n, uint64_t *seed, tally *t)
{
    double X = (l->nx - 1) * l->a, Y = (l->ny - 1) * l->b, dz = l->zmax - l->zmin + 1.0;
    n /= RANDOM_RAYS_SHARE;
    for (int k = 0; k < n; k++) {
        double o[3] = {(rnd(seed) * 1.4 - 0.2) * X, (rnd(seed) * 1.4 - 0.2) * Y,
                       l->zmin + rnd(seed) * 1.5 * dz};
        double p[3] = {rnd(seed) * X, rnd(seed) * Y, l->zmin + rnd(seed) * dz};
        td_ray r = {{o[0], o[1], o[2]}, {p[0] - o[0], p[1] - o[1], p[2] - o[2]}, 0.0, INFINITY};
        if (k % 5 == 0)
            r.tmax = 0.5 + rnd(seed);
        if (k % 9 == 0) /* steep */
            r.d[0] *= 0.01, r.d[1] *= 0.01;
        judge_on(l, fl, &r, t);
    }
}

static void random_rays(const td_iso *l, int n, uint64_t *seed, tally *t)
{
    random_rays_on(l, l, n, seed, t);
}

static void test_iso_rays_reference(void **state)
{
    (void)state;
    uint64_t seed = 2024;
    tally t = {0, 0, 0};
    td_grid *g = load("volcano.asc");
    td_iso *l = NULL;
    for (int v = 0; v < 2; v++) {
        assert_int_equal(td_iso_from_grid(g, 1, (td_iso_rows)v, &l, NULL), TD_OK);
        random_rays(l, 6000, &seed, &t);
        td_iso_free(l);
    }
    td_grid_free(g);
    g = load("picos-dtm.asc"); /* voids in rows and blocks, lon/lat spacing */
    assert_int_equal(td_iso_from_grid(g, 4, TD_ISO_ROWS_SQUARE, &l, NULL), TD_OK);
    random_rays(l, 3000, &seed, &t);
    td_iso_free(l);
    td_grid_free(g);
    l = make(48, 56, 1.0, sqrt(3.0) / 2.0, bumpy_fn, (void *)1); /* with holes */
    random_rays(l, 6000, &seed, &t);
    td_iso_free(l);
    print_message("random rays: %d agree, %d ties, %d wrong\n", t.agree, t.tie, t.wrong);
    assert_int_equal(t.wrong, 0);
    assert_true(t.agree >= 20900 / RANDOM_RAYS_SHARE);
}

/* Hard cases on lattice m (the reference on fl, see judge_on): rays along each of the
 * three families of lattice lines, at vertices, vertical, grazing a sample, downward
 * everywhere (watertight), from below, outside and under the lattice, starting on it. */
static void hard_rays(const td_iso *m, const td_iso *fl, uint64_t *seed_, tally *t)
{
    uint64_t seed = *seed_;
    double X = (m->nx - 1) * m->a, Y = (m->ny - 1) * m->b;
    for (int k = 0; k < 600; k++) {
        int32_t r = 1 + k % (m->ny - 2), c = 1 + (k * 7) % (m->nx - 2);
        double vx = td_iso_x(m, r, c), vy = r * m->b, vz = td_iso_at(m, r, c);
        double z0 = vz + 30.0 * rnd(&seed) - 15.0;
        td_ray rays[5] = {
            {{-1.0, vy, z0}, {1.0, 0.0, 0.01 * (rnd(&seed) - 0.5)}, 0.0, INFINITY}, /* along a row */
            {{vx, vy, z0}, {0.5 * m->a, m->b, -0.2}, -30.0, INFINITY},  /* along a u - Y/2 line */
            {{vx, vy, z0}, {-0.5 * m->a, m->b, -0.2}, -30.0, INFINITY}, /* along a u + Y/2 line */
            {{vx + 3.0, vy + 2.0, vz + 3.0}, {-3.0, -2.0, -3.0}, 0.0, INFINITY}, /* at a vertex */
            {{vx, vy, vz + 10.0}, {0.0, 0.0, -1.0}, 0.0, INFINITY}, /* vertical on a vertex */
        };
        for (int q = 0; q < 5; q++)
            judge_on(m, fl, &rays[q], t);
    }
    for (int k = 0; k < 400; k++) { /* grazing: just over / at / under a sample */
        int32_t r = 1 + k % (m->ny - 2), c = 1 + (k * 3) % (m->nx - 2);
        double vx = td_iso_x(m, r, c), vy = r * m->b, vz = td_iso_at(m, r, c);
        double off = (k % 3 - 1) * 1e-9;
        td_ray g = {{vx - 10.0, vy - 7.0, vz + off}, {10.0, 7.0, 0.0}, 0.0, 2.0};
        judge_on(m, fl, &g, t);
    }
    /* from outside, starting below, downward everywhere: every such ray hits */
    for (int k = 0; k < 2000; k++) {
        double x = rnd(&seed) * X, y = rnd(&seed) * Y;
        if (k % 10 == 0)
            x = floor(x / m->a) * m->a; /* on even-row columns */
        td_ray dn = {{x, y, 200.0}, {0.3 * (rnd(&seed) - 0.5), 0.3 * (rnd(&seed) - 0.5), -1.0}, 0.0,
                     INFINITY};
        td_hit h;
        td_iso_trace(m, &dn, &h);
        if (dn.o[0] + 250 * dn.d[0] >= 0 && dn.o[0] + 250 * dn.d[0] <= X &&
            dn.o[1] + 250 * dn.d[1] >= 0 && dn.o[1] + 250 * dn.d[1] <= Y)
            assert_true(h.t < INFINITY); /* watertight: the ground track stays inside */
        judge_on(m, fl, &dn, t);
    }
    /* two-sided: from below, a ray hits where it comes up through the surface */
    double zc;
    assert_true(td_iso_eval(m, X / 2, Y / 2, &zc, NULL));
    td_ray below = {{X / 2, Y / 2, -100.0}, {0.0, 0.0, 2.0}, 0.0, INFINITY};
    td_hit h;
    td_iso_trace(m, &below, &h);
    assert_true(fabs(h.t - (zc + 100.0) / 2.0) < 1e-9);
    below.d[2] = -1.0; /* and never going down */
    td_iso_trace(m, &below, &h);
    assert_true(h.t == INFINITY);
    td_ray outside = {{-10.0, Y / 3, 300.0}, {1.0, 0.0, 0.0}, 0.0, INFINITY};
    td_iso_trace(m, &outside, &h);
    assert_true(h.t == INFINITY);
    td_ray under = {{-10.0, Y / 3, -300.0}, {1.0, 0.0, 0.0}, 0.0, INFINITY};
    td_iso_trace(m, &under, &h); /* under the lattice all along: no walls */
    assert_true(h.t == INFINITY);
    td_ray on = {{X / 2, Y / 2, zc}, {1.0, 0.5, 3.0}, 0.0, INFINITY};
    td_iso_trace(m, &on, &h); /* starting on it */
    assert_true(h.t == 0.0);
    judge_on(m, fl, &below, t);
    judge_on(m, fl, &under, t);
    judge_on(m, fl, &on, t);
    *seed_ = seed;
}

static void test_iso_hardcases(void **state)
{
    (void)state;
    tally t = {0, 0, 0};
    uint64_t seed = 99;
    td_iso *l = make(40, 40, 1.0, 1.0, bumpy_fn, NULL);
    td_iso *e = make(40, 44, 1.0, sqrt(3.0) / 2.0, bumpy_fn, NULL);
    td_iso *L[2] = {l, e};
    for (int v = 0; v < 2; v++)
        hard_rays(L[v], L[v], &seed, &t);
    td_iso_free(l);
    td_iso_free(e);

    /* flat terrain: exact hits, touching rays, rays along the surface */
    l = make(20, 20, 2.0, 2.0, flat_fn, NULL);
    td_ray d45 = {{3.0, 4.0, 10.0}, {1.0, 1.0, -1.0}, 0.0, INFINITY};
    td_hit h;
    td_iso_trace(l, &d45, &h);
    assert_true(h.t == 5.0);
    assert_true(h.n[2] == 1.0f && h.n[0] == 0.0f && h.n[1] == 0.0f);
    td_ray level = {{-5.0, 7.0, 5.0}, {1.0, 0.2, 0.0}, 0.0, INFINITY};
    td_iso_trace(l, &level, &h);
    assert_true(h.t == 5.0); /* touches where it enters */
    td_ray over = {{-5.0, 7.0, 5.0 + 1e-9}, {1.0, 0.2, 0.0}, 0.0, INFINITY};
    td_iso_trace(l, &over, &h);
    assert_true(h.t == INFINITY);
    judge(l, &d45, &t);
    judge(l, &level, &t);
    judge(l, &over, &t);
    td_iso_free(l);

    /* holes: a ray over a hole passes; one aimed into it lands beyond it or misses */
    l = make(48, 56, 1.0, sqrt(3.0) / 2.0, bumpy_fn, (void *)1);
    for (int k = 0; k < 500; k++) {
        td_ray r = {{22.0 + 4.0 * rnd(&seed), 32.0 + 6.0 * rnd(&seed), 100.0},
                    {rnd(&seed) - 0.5, rnd(&seed) - 0.5, -0.2 - rnd(&seed)}, 0.0, INFINITY};
        judge(l, &r, &t);
    }
    td_iso_free(l);
    print_message("hard cases: %d agree, %d ties, %d wrong\n", t.agree, t.tie, t.wrong);
    assert_int_equal(t.wrong, 0);
}

/* Rays through a vertex on a hole's border, level at the vertex's height, crossing the
 * surface there from below to above or back, at 72 headings (the walk passes the hole's
 * corner in segments a few ulps long: the crossing at the vertex must not be forgotten),
 * and along the three line families next to the hole. */
static void test_iso_hole_corners(void **state)
{
    (void)state;
    tally t = {0, 0, 0};
    td_iso *l = NULL;
    assert_int_equal(td_iso_create(30, 30, 1.0, 1.0, &l, NULL), TD_OK);
    td_iso_sample(l, bumpy_fn, NULL);
    for (int32_t r = 4; r < 26; r += 5) /* single voids, each making a hole of six triangles */
        for (int32_t c = 4; c < 26; c += 5)
            l->z[td_iso_row_offset(l->nx, r) + (size_t)c] = NAN;
    td_iso_finish(l);
    for (int32_t r = 4; r < 26; r += 5) {
        for (int32_t c = 4; c < 26; c += 5) {
            static const int32_t nb[6][2] = {{0, -1}, {0, 1}, {-1, 0}, {-1, 1}, {1, 0}, {1, 1}};
            for (int k = 0; k < 6; k++) { /* the void's neighbours (either row parity) */
                int32_t vr = r + nb[k][0], vc = c + nb[k][1] - (nb[k][0] != 0 && !(r & 1));
                double vx = td_iso_x(l, vr, vc), vy = vr * l->b, vz = td_iso_at(l, vr, vc);
                for (int h = 0; h < 72; h++) {
                    double ang = h * (M_PI / 36.0) + 0.01;
                    td_ray ray = {{vx - 3.0 * cos(ang), vy - 3.0 * sin(ang), vz}, {cos(ang), sin(ang), 0.0},
                                  0.0, 6.0};
                    judge(l, &ray, &t);
                }
            }
        }
    }
    td_iso_free(l);
    print_message("hole corners: %d agree, %d ties, %d wrong\n", t.agree, t.tie, t.wrong);
    assert_int_equal(t.wrong, 0);
    assert_true(t.agree > t.tie);
}

/* The pyramid's sizes, and every block maximum at every level bounds the surface over its
 * box (checked at random points, vertices included). */
static void test_iso_blocks(void **state)
{
    (void)state;
    uint64_t seed = 5;
    td_iso *l = make(45, 37, 1.0, sqrt(3.0) / 2.0, bumpy_fn, (void *)1);
    assert_int_equal(l->bw[0], (45 - 2) / 8 + 1); /* 6 x 5 -> 3 x 3 -> 2 x 2 -> 1 x 1 */
    assert_int_equal(l->bh[0], (37 - 2) / 8 + 1);
    assert_int_equal(l->blevels, 4);
    assert_int_equal(l->bw[3], 1);
    assert_int_equal(l->bh[3], 1);
    assert_true(l->bmax[3][0] == l->zmax);
    for (int k = 0; k < 40000; k++) {
        double x = rnd(&seed) * 44 * l->a, y = rnd(&seed) * 36 * l->b, z;
        if (k % 3 == 0) { /* a vertex */
            int32_t r = (int32_t)(rnd(&seed) * 37), c = (int32_t)(rnd(&seed) * td_iso_row_len(l, r));
            x = td_iso_x(l, r, c);
            y = r * l->b;
        }
        if (!td_iso_eval(l, x, y, &z, NULL))
            continue;
        for (int lv = 0; lv < l->blevels; lv++) { /* every block whose closed box holds the point */
            double S = 8 << lv;
            for (int32_t j = 0; j < l->bh[lv]; j++)
                for (int32_t i = 0; i < l->bw[lv]; i++)
                    if (x >= i * S * l->a && x <= (i + 1) * S * l->a && y >= j * S * l->b &&
                        y <= (j + 1) * S * l->b)
                        assert_true(z <= l->bmax[lv][j * l->bw[lv] + i]);
        }
    }
    td_iso_free(l);
}

/* A packed lattice and the floats it decodes to (td_iso_unpack): the same heights, block
 * maxima, heights and normals anywhere; bytes per sample about 2. */
static td_iso *packed_twin(const td_iso *l, int tile_log2, td_iso **fl)
{
    td_iso *p = NULL;
    size_t n = td_iso_row_offset(l->nx, l->ny), nb = 0;
    uint64_t seed = 17;
    assert_int_equal(td_iso_pack_lattice(l, tile_log2, &p, NULL), TD_OK);
    assert_null(p->z);
    assert_int_equal(td_iso_unpack(p->packed, fl, NULL), TD_OK);
    for (int k = 0; k < p->blevels; k++)
        nb += (size_t)p->bw[k] * (size_t)p->bh[k];
    assert_memory_equal(p->bmax[0], (*fl)->bmax[0], nb * sizeof(float));
    assert_true(p->zmin == (*fl)->zmin && p->zmax == (*fl)->zmax);
    assert_int_equal(td_iso_bytes(p), p->packed->bytes + nb * sizeof(float));
    assert_int_equal(td_iso_bytes(*fl), n * sizeof(float) + nb * sizeof(float));
    for (int k = 0; k < 2000; k++) {
        double x = rnd(&seed) * (l->nx - 1) * l->a, y = rnd(&seed) * (l->ny - 1) * l->b;
        double z = 0, zf = 0, nn[3] = {0}, nf[3] = {0};
        int ok = td_iso_eval(p, x, y, &z, nn);
        assert_int_equal(ok, td_iso_eval(*fl, x, y, &zf, nf));
        assert_true(!ok || (z == zf && nn[0] == nf[0] && nn[1] == nf[1] && nn[2] == nf[2]));
        if (ok) { /* within the packing's error of the original surface */
            double zo;
            assert_true(td_iso_eval(l, x, y, &zo, NULL));
            assert_true(fabs(z - zo) <= p->packed->max_err * (1 + 1e-9) + 1e-6 * fabs(zo));
        }
    }
    return p;
}

/* The walk on two-byte vertices: against the reference on the decoded heights, and bit for
 * bit what it answers on those heights as floats; lossless, lossy, voids, both row
 * spacings, and the levels of detail's twins. */
static void test_iso_packed_trace(void **state)
{
    (void)state;
    uint64_t seed = 4242;
    tally t = {0, 0, 0};
    td_iso *fl = NULL, *p;
    td_iso *l = make(40, 40, 1.0, 1.0, bumpy_fn, NULL);
    td_iso *e = make(40, 44, 1.0, sqrt(3.0) / 2.0, bumpy_fn, NULL);
    td_iso *L[2] = {l, e};
    for (int v = 0; v < 2; v++) {
        p = packed_twin(L[v], 3, &fl);
        assert_true(p->packed->max_err > 0.0); /* every fraction: lossy */
        hard_rays(p, fl, &seed, &t);
        td_iso_free(p);
        td_iso_free(fl);
        td_iso_free(L[v]);
    }
    l = make(48, 56, 1.0, sqrt(3.0) / 2.0, bumpy_fn, (void *)1); /* with holes */
    p = packed_twin(l, 4, &fl);
    random_rays_on(p, fl, 4000, &seed, &t);
    td_iso_free(p);
    td_iso_free(fl);
    td_iso_free(l);
    td_grid *g = load("volcano.asc");
    assert_int_equal(td_iso_from_grid(g, 1, TD_ISO_ROWS_SQUARE, &l, NULL), TD_OK);
    p = packed_twin(l, 6, &fl);
    assert_true(p->packed->max_err == 0.0); /* whole metres: lossless */
    assert_true(td_iso_bytes(p) < 0.55 * td_iso_bytes(fl));
    random_rays_on(p, fl, 3000, &seed, &t);
    td_iso_free(p);
    td_iso_free(fl);
    td_iso_free(l);
    td_lod *lod = NULL;
    td_accel_opts ao = {0, 0, 1, 1, 0, 0};
    assert_int_equal(td_lod_build(g, 3, &ao, &lod, NULL), TD_OK);
    assert_int_equal(td_lod_add_iso(lod, g, NULL), TD_OK);
    for (int k = 1; k <= lod->levels; k++) {
        assert_int_equal(td_iso_unpack(lod->iso[k]->packed, &fl, NULL), TD_OK);
        random_rays_on(lod->iso[k], fl, 1500, &seed, &t);
        td_iso_free(fl);
    }
    td_lod_free(lod);
    td_grid_free(g);
    g = load("picos-dtm.asc"); /* voids, centimetres: lossy in most tiles */
    assert_int_equal(td_iso_from_grid(g, 4, TD_ISO_ROWS_SQUARE, &l, NULL), TD_OK);
    p = packed_twin(l, 6, &fl);
    random_rays_on(p, fl, 3000, &seed, &t);
    td_iso_free(p);
    td_iso_free(fl);
    td_iso_free(l);
    td_grid_free(g);
    print_message("packed: %d agree, %d ties, %d wrong\n", t.agree, t.tie, t.wrong);
    assert_int_equal(t.wrong, 0);
    assert_true(t.agree >= 20000 / RANDOM_RAYS_SHARE);
}

/* The levels of detail's isometric twins: even rows are the square level's samples, odd
 * rows the finer level's filtered samples between them; td_lod_iso_trace names the square
 * level's cell under the hit. */
static void test_iso_lod_twin(void **state)
{
    (void)state;
    td_grid *g = load("volcano.asc");
    td_lod *lod = NULL;
    td_accel_opts ao = {0, 0, 1, 1, 0, 0};
    uint64_t seed = 3;
    assert_int_equal(td_lod_build(g, 3, &ao, &lod, NULL), TD_OK);
    assert_int_equal(lod->levels, 3);
    assert_null(lod->iso[1]); /* on demand only */
    uint64_t before = lod->bytes;
    assert_int_equal(td_lod_add_iso(lod, g, NULL), TD_OK);
    assert_true(lod->bytes > before);
    for (int k = 1; k <= lod->levels; k++) {
        const td_grid *sq = lod->grid[k], *fine = k == 1 ? g : lod->grid[k - 1];
        const td_iso *l = lod->iso[k];
        assert_non_null(l);
        assert_int_equal(l->nx, sq->w);
        assert_int_equal(l->ny, sq->h);
        assert_true(l->a == sq->sx && l->b == sq->sy);
        assert_null(l->z); /* two-byte vertices only, within the packing's error */
        assert_non_null(l->packed);
        double tol = l->packed->max_err;
        double step = 0.0;
        for (size_t i = 0; i < (size_t)l->packed->tiles_x * (size_t)l->packed->tiles_y; i++)
            step = fmax(step, l->packed->step[i]);
        assert_true(tol <= step / 2 + 1e-4); /* half a step, plus the float's rounding */
        print_message("level %d: packed error %.3g m, step up to %.3g m\n", k, tol, step);
        for (int32_t r = 0; r < l->ny; r += 2)
            for (int32_t c = 0; c < l->nx; c++)
                assert_true(fabs(td_iso_at(l, r, c) - td_grid_at(sq, c, r)) <= tol);
        /* an odd row's inner sample: the 1-2-1 mean around the finer node (2c - 1, 2r) */
        int32_t r = 1, c = 2, i = 2 * c - 1, j = 2 * r;
        double sum = 0, w = 0;
        for (int dj = -1; dj <= 1; dj++)
            for (int di = -1; di <= 1; di++) {
                double wt = (di ? 1.0 : 2.0) * (dj ? 1.0 : 2.0);
                sum += wt * td_grid_at(fine, i + di, j + dj);
                w += wt;
            }
        assert_true(fabs(td_iso_at(l, r, c) - sum / w) < 1e-4 + tol);
        for (int n = 0; n < 200; n++) {
            double X = (sq->w - 1) * sq->sx, Y = (sq->h - 1) * sq->sy;
            td_ray ray = {{rnd(&seed) * X, rnd(&seed) * Y, g->zmax + 50.0},
                          {rnd(&seed) - 0.5, rnd(&seed) - 0.5, -1.0}, 0.0, INFINITY};
            td_hit h, hi;
            td_lod_iso_trace(lod, k, &ray, &h);
            td_iso_trace(l, &ray, &hi);
            assert_true(h.t == hi.t);
            if (h.t < INFINITY) {
                assert_true(h.ci >= 0 && h.ci <= sq->w - 2 && h.cj >= 0 && h.cj <= sq->h - 2);
                assert_true(h.p[0] >= h.ci * sq->sx - 1e-9 && h.p[0] <= (h.ci + 1) * sq->sx + 1e-9);
                assert_true(h.p[1] >= h.cj * sq->sy - 1e-9 && h.p[1] <= (h.cj + 1) * sq->sy + 1e-9);
            }
        }
    }
    assert_int_equal(td_lod_grid_name(TD_LOD_GRID_ISOMETRIC)[0], 'i');
    td_lod_grid gg = TD_LOD_GRID_ISOMETRIC;
    assert_int_equal(td_lod_grid_parse("square", &gg), TD_OK);
    assert_int_equal(gg, TD_LOD_GRID_SQUARE);
    assert_int_equal(td_lod_grid_parse("hex", &gg), TD_EINVAL);
    td_lod_free(lod);
    td_grid_free(g);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_iso_layout),
        cmocka_unit_test(test_iso_planes),
        cmocka_unit_test(test_iso_triangulation),
        cmocka_unit_test(test_iso_from_grid),
        cmocka_unit_test(test_iso_pack),
        cmocka_unit_test(test_iso_rays_reference),
        cmocka_unit_test(test_iso_hardcases),
        cmocka_unit_test(test_iso_packed_trace),
        cmocka_unit_test(test_iso_hole_corners),
        cmocka_unit_test(test_iso_blocks),
        cmocka_unit_test(test_iso_lod_twin),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
