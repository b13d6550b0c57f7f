/* test_sunlit.c: the sun bound of core/sunlit.c against brute force. On procedural
 * terrain (with voids) and for suns from every quarter, steep and grazing, and along the
 * axes: every block's bound is at least its own highest sample; a point above its
 * block's bound sees the sun (td_trace finds nothing on the way); and td_occluded with
 * the bound answers as td_trace for rays from the surface, while taking fewer steps
 * than without it; with the blocks' maxima read from the max-mipmaps, from the samples,
 * and from a mix of both; and a bound kept across renders, finer on a grid of trinidad's
 * size, holds the same and ends rays sooner. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <cmocka.h>

#include "accel.h"
#include "maxmip.h"
#include "sunlit.h"
#include "terrain.h"
#include "trace.h"
#include "terrain_fixture.h"

static double rnd(uint64_t *s)
{
    *s = *s * 6364136223846793005ull + 1442695040888963407ull;
    return (double)(*s >> 11) / 9007199254740992.0;
}

static void sun_of(double az_deg, double el_deg, double sun[3])
{
    double a = az_deg * M_PI / 180.0, e = el_deg * M_PI / 180.0;
    sun[0] = sin(a) * cos(e);
    sun[1] = cos(a) * cos(e);
    sun[2] = sin(e);
}

/* Every structure for g, on `threads` threads. */
static td_accel *accel(const td_grid *g, int threads)
{
    td_accel_opts o;
    td_accel *a = NULL;
    td_accel_opts_default(&o);
    o.threads = threads;
    assert_int_equal(td_accel_build(g, &o, &a, NULL, NULL), TD_OK);
    return a;
}

/* Each 4 x 4 block's lowest corner (maxmip.h's min4), NaN where one is void, against
 * brute force over the samples. */
static void check_min4(const td_grid *g, const td_accel *a)
{
    for (size_t k = 0; k < (size_t)g->tiles_x * (size_t)g->tiles_y; k++) {
        const td_tile *t = &g->tiles[k];
        const td_maxmip *mm = a->tiles[k].maxmip;
        assert_int_equal(mm->min4_w, (t->nx + 3) / 4);
        assert_int_equal(mm->min4_h, (t->ny + 3) / 4);
        for (int32_t by = 0; by < mm->min4_h; by++)
            for (int32_t bx = 0; bx < mm->min4_w; bx++) {
                float m = INFINITY;
                int voids = 0;
                for (int32_t j = 4 * by; j <= 4 * by + 4 && j <= t->ny; j++)
                    for (int32_t i = 4 * bx; i <= 4 * bx + 4 && i <= t->nx; i++) {
                        float z = td_grid_at(g, t->i0 + i, t->j0 + j);
                        voids += isnan(z);
                        m = z < m ? z : m;
                    }
                float got = mm->min4[(size_t)by * (size_t)mm->min4_w + (size_t)bx];
                assert_true(voids ? isnan(got) : got == m);
            }
    }
}

/* The linear surface's height at (x, y) of cell (ci, cj) for a ray along d: the line
 * between the heights where the ray's horizontal line enters the cell behind the point and
 * leaves it ahead (on the cell's edges, where the surface is the bilinear patch's), as the
 * walk takes it in the ray's first cell (trace.c's linear_under). The bilinear patch's
 * height at the point is not it: a point 0.5 m above that may be under the linear surface
 * along the sun, and its ray meets nothing. */
static double linear_under_along(const td_grid *g, int32_t ci, int32_t cj, double x, double y, const double d[3])
{
    const double u = x / g->sx - ci, w = y / g->sy - cj, du = d[0] / g->sx, dw = d[1] / g->sy;
    double t_in = -INFINITY, t_out = INFINITY;
    if (du != 0.0) {
        t_in = fmax(t_in, ((du > 0.0 ? 0.0 : 1.0) - u) / du);
        t_out = fmin(t_out, ((du > 0.0 ? 1.0 : 0.0) - u) / du);
    }
    if (dw != 0.0) {
        t_in = fmax(t_in, ((dw > 0.0 ? 0.0 : 1.0) - w) / dw);
        t_out = fmin(t_out, ((dw > 0.0 ? 1.0 : 0.0) - w) / dw);
    }
    const double xa = (ci + u + t_in * du) * g->sx, ya = (cj + w + t_in * dw) * g->sy;
    const double xb = (ci + u + t_out * du) * g->sx, yb = (cj + w + t_out * dw) * g->sy;
    const double ha = td_surface_height(g, TD_SURFACE_BILINEAR, ci, cj, xa, ya);
    const double hb = td_surface_height(g, TD_SURFACE_BILINEAR, ci, cj, xb, yb);
    return t_out > t_in ? ha + (hb - ha) * (-t_in / (t_out - t_in)) : ha;
}

/* The bound's claims for one sun over grid g (with per-tile acceleration tiles, or NULL),
 * built as td_sunlit_build's `kept` says into blocks of 2^shift cells; fewer: and that it
 * saves steps (the steps with it added to *steps when not NULL). */
static size_t check_sun_as(const td_grid *g, const td_tile_accel *tiles, const double sun[3], uint64_t *seed,
                           int fewer, int kept, int shift, uint64_t *steps)
{
    size_t below = 0; /* points the shadow side holds shadowed */
    td_view v = {g, tiles};
    td_sunlit *lit = NULL;
    uint64_t with = 0, without = 0;
    assert_int_equal(td_sunlit_build(&v, sun, kept, &lit, NULL), TD_OK);
    assert_non_null(lit);
    assert_int_equal(lit->shift, shift);
    for (int32_t cj = 0; cj <= g->h - 2; cj++) /* every point's bound, that of its strip and */
        for (int32_t ci = 0; ci <= g->w - 2; ci++) { /* column, is at least its cell's top */
            double u = ci + rnd(seed), w = cj + rnd(seed), bound = td_sunlit_at(lit, u, w);
            ptrdiff_t k = td_sunlit_strip(lit, u, w);
            float c[4] = {td_grid_at(g, ci, cj), td_grid_at(g, ci + 1, cj), td_grid_at(g, ci, cj + 1),
                          td_grid_at(g, ci + 1, cj + 1)};
            assert_true(k >= 0);
            assert_true(td_sunlit_col(lit, k, ci, cj) == bound);
            if (!isnan(c[0] + c[1] + c[2] + c[3])) /* (a hole's cell: the tracer skips it) */
                assert_true(bound >= fmax(fmax(c[0], c[1]), fmax(c[2], c[3])));
        }
    for (int k = 0; k < 4000; k++) {
        double x = rnd(seed) * (g->w - 1) * g->sx, y = rnd(seed) * (g->h - 1) * g->sy;
        int32_t ci = (int32_t)(x / g->sx), cj = (int32_t)(y / g->sy);
        ci = ci > g->w - 2 ? g->w - 2 : ci;
        cj = cj > g->h - 2 ? g->h - 2 : cj;
        double bound = td_sunlit_at(lit, x / g->sx, y / g->sy);
        double ground = td_surface_height(g, TD_SURFACE_BILINEAR, ci, cj, x, y);
        td_ray r = {{x, y, bound + 1e-3 * (1.0 + fabs(bound))}, {sun[0], sun[1], sun[2]}, 0.0, INFINITY};
        td_hit h;
        uint32_t s0 = 0, s1 = 0;
        for (int s = 0; s < TD_SURFACE_COUNT; s++) { /* above the bound: nothing on the way */
            td_trace(&v, TD_METHOD_INCREMENTAL, (td_surface)s, &r, &h);
            assert_true(h.t == INFINITY);
        }
        if (isnan(ground))
            continue;
        r.o[2] = ground + 0.5; /* from just above the surface: the same answer, fewer steps */
        ptrdiff_t sk = td_sunlit_strip(lit, x / g->sx, y / g->sy);
        if (lit->lo && sk >= 0 && r.o[2] < td_sunlit_lo(lit, sk, ci, cj) - 1e-3) {
            /* below the shadow side: every surface under the point meets the ray (the
               linear surface's height under a point is the ray's own: linear_under_along) */
            for (int s = 0; s < TD_SURFACE_COUNT; s++) {
                double under = s == TD_SURFACE_LINEAR ? linear_under_along(g, ci, cj, x, y, sun)
                                                      : td_surface_height(g, (td_surface)s, ci, cj, x, y);
                td_trace(&v, TD_METHOD_INCREMENTAL, (td_surface)s, &r, &h);
                if (s == TD_SURFACE_PLANE || (!isnan(under) && r.o[2] > under + 1e-3))
                    assert_true(h.t < INFINITY);
            }
            below++;
        }
        for (int s = 0; s < TD_SURFACE_COUNT; s++) {
            td_trace(&v, TD_METHOD_AUTO, (td_surface)s, &r, &h);
            assert_int_equal(td_occluded(&v, TD_METHOD_AUTO, (td_surface)s, &r, lit, &s1), h.t < INFINITY);
            assert_int_equal(td_occluded(&v, TD_METHOD_AUTO, (td_surface)s, &r, NULL, &s0), h.t < INFINITY);
        }
        with += s1;
        without += s0;
    }
    if (fewer) /* the walks the bound ends outweigh its checks */
        assert_true(with < without);
    if (steps)
        *steps += with;
    td_sunlit_free(lit);
    return below;
}

/* check_sun_as for the grids of these tests, small enough that even a render's own bound
 * takes the finest blocks: 2 x 2 cells */
static size_t check_sun(const td_grid *g, const td_tile_accel *tiles, const double sun[3], uint64_t *seed,
                        int fewer)
{
    return check_sun_as(g, tiles, sun, seed, fewer, 0, 1, NULL);
}

static void test_sunlit_bounds(void **state)
{
    static const double suns[][2] = {{30, 35}, {135, 8}, {220, 60}, {300, 2}, {0, 20}, {90, 10},
                                     {180, 45}, {270, 3}, {10, 89}, {355.5, 1}};
    uint64_t seed = 12345;
    (void)state;
    td_grid *g = terrain(300, 220, 30.0, 6);
    g->sy = 45.0; /* unequal spacing: the dominant axis is not the larger component */
    for (int k = 0; k < 1200; k++) /* voids */
        g->z[(size_t)(rnd(&seed) * (double)g->w * (double)g->h)] = NAN;
    assert_int_equal(td_grid_finish(g, NULL), TD_OK);
    td_accel *a = accel(g, 2);
    /* the block maxima from the max-mipmaps, from the samples (no acceleration), and from
       both (every third tile without its max-mipmap) */
    size_t nt = (size_t)g->tiles_x * (size_t)g->tiles_y;
    td_tile_accel *some = calloc(nt, sizeof *some);
    assert_non_null(some);
    for (size_t k = 0; k < nt; k++)
        some[k].maxmip = k % 3 ? a->tiles[k].maxmip : NULL;
    check_min4(g, a);
    size_t below = 0;
    for (size_t k = 0; k < sizeof suns / sizeof suns[0]; k++) {
        double sun[3];
        sun_of(suns[k][0], suns[k][1], sun);
        below += check_sun(g, a->tiles, sun, &seed, 1);
        check_sun(g, k % 2 ? NULL : some, sun, &seed, 1);
        /* kept across renders: blocks of one cell on a grid this small */
        below += check_sun_as(g, k % 2 ? a->tiles : some, sun, &seed, 1, 1, 0, NULL);
    }
    assert_true(below > 100); /* the low suns' shadow side holds points (and the voids') */
    free(some);
    td_accel_free(a);
    td_grid_free(g);
}

/* A bound kept across renders (td_sunlit_build's `kept`) on a grid of trinidad's size,
 * 2401 x 1201, where a render's own bound takes 4 x 4-cell blocks to stay within its cap:
 * the kept one takes 2 x 2, its claims hold the same (check_sun_as: every block's bound
 * over its cells' tops, nothing above it on the way, td_occluded as td_trace), and its
 * shadow rays walk fewer cells. */
static void test_sunlit_kept_finer(void **state)
{
    static const double suns[][2] = {{250, 12}, {40, 35}};
    uint64_t seed = 777;
    (void)state;
    td_grid *g = terrain(2401, 1201, 30.0, 8);
    td_accel *a = accel(g, 2);
    for (size_t k = 0; k < sizeof suns / sizeof suns[0]; k++) {
        double sun[3];
        uint64_t coarse = 0, fine = 0, s0 = seed, s1 = seed;
        sun_of(suns[k][0], suns[k][1], sun);
        check_sun_as(g, a->tiles, sun, &s0, 1, 0, 2, &coarse);
        check_sun_as(g, a->tiles, sun, &s1, 1, 1, 1, &fine); /* the same points and rays */
        assert_true(fine < coarse);
        seed = s1;
    }
    td_accel_free(a);
    td_grid_free(g);
}

/* Max-mipmaps built without the blocks' minima (td_accel_opts.minima 0: terrad viewshed and
 * trace): the same codes, base and step as with them, no min4, and a sun bound on them
 * has no shadow side; its answers (check_sun: td_occluded as td_trace) still hold, as
 * for a prepared grid's tiles. */
static void test_sunlit_without_minima(void **state)
{
    uint64_t seed = 4242;
    (void)state;
    td_grid *g = terrain(200, 160, 30.0, 6);
    td_accel *with = accel(g, 1), *without = NULL;
    td_accel_opts o;
    td_accel_opts_default(&o);
    assert_int_equal(o.minima, 1);
    o.threads = 1;
    o.minima = 0;
    assert_int_equal(td_accel_build(g, &o, &without, NULL, NULL), TD_OK);
    for (size_t k = 0; k < with->ntiles; k++) {
        const td_maxmip *a = with->tiles[k].maxmip, *b = without->tiles[k].maxmip;
        size_t n = a->offset[a->levels] + (size_t)a->dim[a->levels] * (size_t)a->dim[a->levels];
        assert_non_null(a->min4);
        assert_null(b->min4);
        assert_int_equal(b->min4_w * b->min4_h, 0);
        assert_int_equal(a->levels, b->levels);
        assert_memory_equal(&a->base, &b->base, sizeof a->base);
        assert_memory_equal(&a->step, &b->step, sizeof a->step);
        assert_memory_equal(a->code, b->code, n * sizeof *a->code);
        assert_true(b->bytes < a->bytes);
    }
    double sun[3];
    sun_of(250.0, 3.0, sun); /* low over relief: the full build's bound has a shadow side */
    td_view v1 = {g, with->tiles}, v0 = {g, without->tiles};
    td_sunlit *l1 = NULL, *l0 = NULL;
    assert_int_equal(td_sunlit_build(&v1, sun, 0, &l1, NULL), TD_OK);
    assert_int_equal(td_sunlit_build(&v0, sun, 0, &l0, NULL), TD_OK);
    assert_non_null(l1->lo);
    assert_null(l0->lo);
    td_sunlit_free(l1);
    td_sunlit_free(l0);
    check_sun(g, without->tiles, sun, &seed, 1);
    td_accel_free(with);
    td_accel_free(without);
    td_grid_free(g);
}

/* Blocks larger than the grid's tiles (tiles of 2 x 2 cells, blocks of 4 x 4): the
 * maxima from the samples, block by block; the same claims (not fewer steps: on a grid
 * this small and this finely tiled the walks are short either way). */
static void test_sunlit_small_tiles(void **state)
{
    uint64_t seed = 99;
    (void)state;
    td_grid *g = terrain(61, 47, 25.0, 1);
    td_accel *a = accel(g, 1);
    check_min4(g, a); /* no voids: the plain minimum's loops; tiles of 2 cells */
    td_grid *g8 = terrain(61, 47, 25.0, 3); /* and of 8: whole blocks and an east edge */
    td_accel *a8 = accel(g8, 1);
    check_min4(g8, a8);
    td_accel_free(a8);
    td_grid_free(g8);
    for (int k = 0; k < 4; k++) {
        double sun[3];
        sun_of(20.0 + 90.0 * k, 5.0 + 10.0 * k, sun);
        check_sun(g, k % 2 ? NULL : a->tiles, sun, &seed, 0);
    }
    td_accel_free(a);
    td_grid_free(g);
}

/* A strip keeps to its own: over flat ground at 0 with one spike 1000 m high, a low sun
 * along x a little north of east; the bound is at least the spike's top less the decay
 * over the distance on the strip through it, and nothing off that strip's reach is raised
 * at all (the blocks' sweep before the strips raised a band as wide as the spike was
 * far: every block whose rays' landing windows led to it). */
static void test_sunlit_strips(void **state)
{
    td_grid *g = NULL;
    double sun[3];
    (void)state;
    assert_int_equal(td_grid_create(400, 120, 10.0, 10.0, 5, NULL, &g, NULL), TD_OK);
    for (size_t k = 0; k < (size_t)g->w * (size_t)g->h; k++)
        g->z[k] = 0.0f;
    g->z[(size_t)60 * (size_t)g->w + 300] = 1000.0f; /* the spike at sample (300, 60) */
    assert_int_equal(td_grid_finish(g, NULL), TD_OK);
    td_view v = {g, NULL};
    sun_of(80.0, 5.0, sun); /* toward the east, 10 degrees north of it, 5 degrees up */
    td_sunlit *lit = NULL;
    assert_int_equal(td_sunlit_build(&v, sun, 0, &lit, NULL), TD_OK);
    assert_non_null(lit);
    const double tan5 = tan(5.0 * M_PI / 180.0), drift = sun[1] / sun[0]; /* cells north per cell east */
    int raised = 0;
    for (int32_t i = 0; i < 300; i++)
        for (int32_t j = 0; j <= g->h - 2; j++) {
            double u = i + 0.5, w = j + 0.5, bound = td_sunlit_at(lit, u, w);
            /* where the ray from (u, w) passes x = 300, and how far it went */
            double off = w + drift * (300.0 - u) - 60.0, dist = (300.0 - u) * 10.0 / cos(10.0 * M_PI / 180.0);
            if (fabs(off) < 0.25) /* on the spike's line: shaded by it, and the bound says so */
                assert_true(bound >= 1000.0 - dist * tan5 - 1e-3);
            else if (fabs(off) > 3 * 4 + 1) /* three blocks off it: nothing above the ground */
                assert_true(bound <= 0.0f + 1e-6);
            raised += bound > 1.0;
        }
    assert_true(raised > 0 && raised < 300 * 40); /* a band along the line, not the grid */
    td_sunlit_free(lit);
    td_grid_free(g);
}

/* No bound for a sun at the zenith or below the horizon. */
static void test_sunlit_none(void **state)
{
    td_terrain_params p;
    td_grid *g = NULL;
    td_sunlit *lit = (td_sunlit *)1;
    double up[3] = {0, 0, 1}, down[3] = {0.6, 0, -0.8};
    (void)state;
    td_terrain_params_default(&p);
    p.width = 40;
    p.height = 40;
    assert_int_equal(td_terrain_generate(&p, 4, &g, NULL), TD_OK);
    td_view v = {g, NULL};
    assert_int_equal(td_sunlit_build(&v, up, 0, &lit, NULL), TD_OK);
    assert_null(lit);
    lit = (td_sunlit *)1;
    assert_int_equal(td_sunlit_build(&v, down, 0, &lit, NULL), TD_OK);
    assert_null(lit);
    td_grid_free(g);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_sunlit_bounds),
        cmocka_unit_test(test_sunlit_small_tiles),
        cmocka_unit_test(test_sunlit_without_minima),
        cmocka_unit_test(test_sunlit_strips),
        cmocka_unit_test(test_sunlit_kept_finer),
        cmocka_unit_test(test_sunlit_none),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
