/* test_viewshed.c: core/viewshed.c on tiny DEMs whose answers are worked out by hand in
 * the comments (flat ground, an observer on a peak, in a pit, at the grid's corner, on a
 * void's edge, a target on a cliff's edge, max_distance, Earth curvature, cumulative
 * counts, the refusals), every method, and td_los's blocking point and profile. The
 * double-precision reference checks real DEMs in tests/oracle/viewshed_oracle.c. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <cmocka.h>

#include "accel.h"
#include "viewshed.h"
#include "vs_fixture.h"

/* A w x h grid, spacing 10 m, heights from f(i, j) (south-based j), with max-mipmaps and
 * planes (tiles of 4 cells, so the methods cross seams). */
static void make(fixture *fx, int32_t w, int32_t h, double (*f)(int32_t i, int32_t j))
{
    assert_int_equal(td_grid_create(w, h, 10.0, 10.0, 2, NULL, &fx->g, NULL), TD_OK);
    for (int32_t j = 0; j < h; j++)
        for (int32_t i = 0; i < w; i++)
            fx->g->z[(size_t)j * w + i] = (float)f(i, j);
    fixture_finish(fx);
}

/* Runs a viewshed; out in file order. */
static td_vs_algo run_algo = TD_VS_ALGO_SWEEP; /* what run() asks for */

static td_status run(const fixture *fx, const td_vs_point *obs, int n, double h, double th,
                     td_surface s, td_method m, uint8_t *out, td_viewshed_stats *st, td_err *e)
{
    td_viewshed_opts o;
    td_viewshed_opts_default(&o);
    o.obs = obs;
    o.nobs = n;
    o.height = h;
    o.target_height = th;
    o.surface = s;
    o.method = m;
    o.algo = run_algo;
    o.threads = 2;
    return td_viewshed(&fx->v, &o, out, st, e);
}

/* The byte of sample (i, j), j south-based. */
static uint8_t at(const fixture *fx, const uint8_t *out, int32_t i, int32_t j)
{
    return out[(size_t)(fx->g->h - 1 - j) * fx->g->w + i];
}

static double flat(int32_t i, int32_t j) { (void)i; (void)j; return 100.0; }

/* A 5 x 5 case seen from p (on a sample), eye h up, on the surfaces from s0, every
 * method and both algorithms (the sweep and one cast a sample): the samples seen are
 * those where seen(i, j) (south-based j) is non-zero. */
typedef struct vs_case {
    double (*height)(int32_t i, int32_t j);
    td_vs_point p;
    double h;
    td_surface s0;
    int (*seen)(int32_t i, int32_t j);
} vs_case;

static void check_case(const vs_case *c)
{
    fixture fx;
    uint8_t out[25];
    td_viewshed_stats st;
    make(&fx, 5, 5, c->height);
    for (int a = 0; a < TD_VS_ALGO_COUNT * TD_SURFACE_COUNT * TD_METHOD_COUNT; a++) {
        int s = a / TD_METHOD_COUNT % TD_SURFACE_COUNT, m = a % TD_METHOD_COUNT;
        uint64_t n = 0;
        run_algo = (td_vs_algo)(a / (TD_METHOD_COUNT * TD_SURFACE_COUNT));
        if (s < (int)c->s0)
            continue;
        {
            assert_int_equal(run(&fx, &c->p, 1, c->h, 0.0, (td_surface)s, (td_method)m, out, &st, NULL), TD_OK);
            for (int32_t j = 0; j < 5; j++)
                for (int32_t i = 0; i < 5; i++) {
                    assert_int_equal(at(&fx, out, i, j), c->seen(i, j) != 0);
                    n += c->seen(i, j) != 0;
                }
            assert_int_equal(st.visible, n);
            assert_int_equal(st.inside, 25);
            /* the sample under the observer is not traced; the sweep casts what it cannot
             * prove (here, within two cells, about all) */
            assert_int_equal(st.rays + st.swept, 24);
            assert_true(run_algo == TD_VS_ALGO_SWEEP || st.swept == 0);
            assert_true(fabs(st.visible_area_m2 - 100.0 * (double)n) < 1e-9);
        }
    }
    run_algo = TD_VS_ALGO_SWEEP;
    unmake(&fx);
}

static int all(int32_t i, int32_t j) { (void)i; (void)j; return 1; }

/* Flat ground, eye 2 m up: every segment stays above the ground but at its target, so
 * everything is seen, on every surface and method. */
static void test_flat_all_visible(void **state)
{
    const vs_case c = {flat, {20, 20}, 2.0, TD_SURFACE_PLANE, all};
    (void)state;
    check_case(&c);
}

/* A pyramid z = 100 - 10 max(|i-2|, |j-2|): its faces are planes and the diagonal cells
 * bend below their chords, so from 1 m over the top everything is seen (worked for the
 * diagonal: line - surface = h(1 - t/2) + 10t(1 - t) >= 0 in the first cell). */
static double peak(int32_t i, int32_t j)
{
    int32_t a = abs(i - 2), b = abs(j - 2);
    return 100.0 - 10.0 * (a > b ? a : b);
}

static void test_observer_on_peak(void **state)
{
    const vs_case c = {peak, {20, 20}, 1.0, TD_SURFACE_LINEAR, all};
    (void)state;
    check_case(&c);
}

/* A one-sample pit (z = 0 at (3, 3), 100 elsewhere), the eye 1 m over its bottom. To an
 * edge neighbour (10 m away, 100 m up) the line rises 1 + 99u over the ground's 100u: seen.
 * To a diagonal neighbour the bilinear patch is 100(2t - t^2) against 1 + 99t: below the
 * line only for t < 0.01, hidden. The triangle split (SE-NW) runs straight from the pit to
 * its NW and SE neighbours (seen) and bulges to the NE and SW ones (200t: hidden); the
 * linear surface along a corner-to-corner ray is straight 0 -> 100: all 8 seen. Beyond the
 * ring the line is at 50.5 m where the wall is 100: hidden. */
static double pit(int32_t i, int32_t j) { return i == 3 && j == 3 ? 0.0 : 100.0; }

static void test_observer_in_pit(void **state)
{
    static const struct {
        td_surface s;
        int ring[8]; /* E, NE, N, NW, W, SW, S, SE */
    } want[] = {
        {TD_SURFACE_BILINEAR, {1, 0, 1, 0, 1, 0, 1, 0}},
        {TD_SURFACE_TRIANGLE, {1, 0, 1, 1, 1, 0, 1, 1}},
        {TD_SURFACE_LINEAR, {1, 1, 1, 1, 1, 1, 1, 1}},
    };
    static const int di[8] = {1, 1, 0, -1, -1, -1, 0, 1}, dj[8] = {0, 1, 1, 1, 0, -1, -1, -1};
    fixture fx;
    uint8_t out[49];
    td_viewshed_stats st;
    td_vs_point p = {30, 30};
    (void)state;
    make(&fx, 7, 7, pit);
    for (size_t c = 0; c < sizeof want / sizeof want[0]; c++)
        for (int m = 0; m < TD_METHOD_COUNT; m++) {
            int n = 1;
            assert_int_equal(run(&fx, &p, 1, 1.0, 0.0, want[c].s, (td_method)m, out, &st, NULL), TD_OK);
            assert_int_equal(at(&fx, out, 3, 3), 1);
            for (int k = 0; k < 8; k++) {
                assert_int_equal(at(&fx, out, 3 + di[k], 3 + dj[k]), want[c].ring[k]);
                n += want[c].ring[k];
            }
            assert_int_equal(st.visible, (uint64_t)n); /* nothing beyond the ring */
        }
    unmake(&fx);
}

/* The observer at the grid's south-west corner sample, a 50 m wall along x = 20 on flat
 * ground 0: the line to the wall's top is 26 m up at x = 10 and 26(1 - u) over the ramp,
 * seen; behind the wall the line is far below 50: hidden. */
static double wall(int32_t i, int32_t j) { (void)j; return i == 2 ? 50.0 : 0.0; }
static int up_to_wall(int32_t i, int32_t j) { (void)j; return i <= 2; }

static void test_observer_at_corner(void **state)
{
    const vs_case c = {wall, {0, 0}, 2.0, TD_SURFACE_LINEAR, up_to_wall};
    (void)state;
    check_case(&c);
}

/* Flat ground with a void sample at (3, 3): the four cells around it are holes, which
 * segments cross as if nothing were there. An observer on the sample (2, 2), at the holes'
 * corner, stands on the cells beside them: everything but the void is seen; the void is
 * "outside". Inside a hole cell, or on the void itself, the observer is refused. */
static double holed(int32_t i, int32_t j) { return i == 3 && j == 3 ? NAN : 0.0; }

static void test_observer_on_void_edge(void **state)
{
    fixture fx;
    uint8_t out[25];
    td_viewshed_stats st;
    td_vs_point p = {20, 20}, in_hole = {25, 25}, on_void = {30, 30};
    td_err e;
    (void)state;
    make(&fx, 5, 5, holed);
    for (int m = 0; m < TD_METHOD_COUNT; m++) {
        assert_int_equal(run(&fx, &p, 1, 1.0, 0.0, TD_SURFACE_BILINEAR, (td_method)m, out, &st, NULL), TD_OK);
        for (int32_t j = 0; j < 5; j++)
            for (int32_t i = 0; i < 5; i++)
                assert_int_equal(at(&fx, out, i, j), i == 3 && j == 3 ? TD_VS_OUTSIDE : 1);
        assert_int_equal(st.visible, 24);
        assert_int_equal(st.inside, 24);
    }
    assert_int_equal(run(&fx, &in_hole, 1, 1.0, 0.0, TD_SURFACE_BILINEAR, TD_METHOD_AUTO, out, &st, &e), TD_ERANGE);
    assert_string_equal(e.field, "observer");
    assert_int_equal(run(&fx, &on_void, 1, 1.0, 0.0, TD_SURFACE_TRIANGLE, TD_METHOD_AUTO, out, &st, &e), TD_ERANGE);
    assert_string_equal(e.field, "observer");
    unmake(&fx);
}

/* A plateau at 100 m (i <= 3) falling to 0 (i >= 4) over one cell. From below, eye at
 * (60, 10) 2 m up: to the cliff's edge (30, 10, 100) the line is 100 - 3.27d over the
 * slope's 100 - 10d (d metres past the edge): seen; to (20, 10) the line crosses x = 30
 * at 75.5 m: hidden, unless the target stands 40 m up (105.5 m there; with 30 m, 98 m:
 * still hidden). From the plateau's far end the foot is hidden (25.5 m at the edge). */
static double cliff(int32_t i, int32_t j) { (void)j; return i <= 3 ? 100.0 : 0.0; }

static void test_target_on_cliff_edge(void **state)
{
    fixture fx;
    uint8_t out[21];
    td_viewshed_stats st;
    td_vs_point below = {60, 10}, top = {0, 10}, both[2] = {{0, 10}, {60, 10}};
    (void)state;
    make(&fx, 7, 3, cliff);
    for (int s = TD_SURFACE_LINEAR; s < TD_SURFACE_COUNT; s++)
        for (int m = 0; m < TD_METHOD_COUNT; m++) {
            td_surface S = (td_surface)s;
            td_method M = (td_method)m;
            assert_int_equal(run(&fx, &below, 1, 2.0, 0.0, S, M, out, &st, NULL), TD_OK);
            assert_int_equal(at(&fx, out, 3, 1), 1);
            assert_int_equal(at(&fx, out, 2, 1), 0);
            assert_int_equal(at(&fx, out, 4, 1), 1);
            assert_int_equal(run(&fx, &below, 1, 2.0, 30.0, S, M, out, &st, NULL), TD_OK);
            assert_int_equal(at(&fx, out, 2, 1), 0);
            assert_int_equal(run(&fx, &below, 1, 2.0, 40.0, S, M, out, &st, NULL), TD_OK);
            assert_int_equal(at(&fx, out, 2, 1), 1);
            assert_int_equal(run(&fx, &top, 1, 2.0, 0.0, S, M, out, &st, NULL), TD_OK);
            assert_int_equal(at(&fx, out, 3, 1), 1);
            assert_int_equal(at(&fx, out, 4, 1), 0);
            /* cumulative: the edge is seen by both, the plateau and the foot by one */
            assert_int_equal(run(&fx, both, 2, 2.0, 0.0, S, M, out, &st, NULL), TD_OK);
            assert_int_equal(at(&fx, out, 3, 1), 2);
            assert_int_equal(at(&fx, out, 1, 1), 1);
            assert_int_equal(at(&fx, out, 5, 1), 1);
        }
    unmake(&fx);
}

/* An eye on the ground (height 0): a segment that runs under the surface is no line of
 * sight even when it never crosses it (the tracer counts crossings, and one that leaves
 * the eye into the ground and stays there until its target has none: such targets read
 * visible before td_viewshed_starts_under). Where the segment lies in the surface (to a
 * neighbour along a straight edge) a touch is decided by rounding: not asserted.
 *   Dome: z = 10i - i^2 along x (0, 9, 16, 21, 24, 25, 24, 21, 16 m; every row alike),
 *   strictly concave, so from the eye on sample (1, 2) the segment to any sample two or
 *   more columns away is under the surface between (to (3, j): 15 m at x = 20, ground
 *   16 m), uphill, over the top and down the far side: hidden.
 *   Pit (above), eye on its bottom: beyond the ring every segment is under the 100 m
 *   ground from x = 40 (or y) on (to (5, 3): 50 m there), hidden; so are the diagonal
 *   neighbours on the bilinear surface (ground 100(2t - t^2) over the line's 100t) and
 *   the NE and SW ones on the triangle surface (200t over 100t).
 *   Cliff (below), eye at its foot (40, 10): to the plateau's (2, 1) the segment is at
 *   50 m at x = 30 where the ground is 100: hidden (and (1, 1), (0, 1)). From the edge
 *   (30, 10) the foot (50, 10), (60, 10) is seen: the face falls faster than the line.
 * td_los agrees: from the dome's eye to (40, 20), blocked at the eye (s = 0). */
static double dome(int32_t i, int32_t j) { (void)j; return 10.0 * i - (double)i * i; }

static void test_eye_on_ground(void **state)
{
    fixture fx;
    uint8_t out[63];
    td_viewshed_stats st;
    td_vs_point on_dome = {10, 20}, in_pit = {30, 30}, foot = {40, 10}, edge = {30, 10};
    (void)state;
    for (int a = 0; a < TD_VS_ALGO_COUNT; a++)
        for (int s = TD_SURFACE_LINEAR; s < TD_SURFACE_COUNT; s++)
            for (int m = 0; m < TD_METHOD_COUNT; m++) {
                td_surface S = (td_surface)s;
                td_method M = (td_method)m;
                run_algo = (td_vs_algo)a;
                make(&fx, 9, 5, dome);
                assert_int_equal(run(&fx, &on_dome, 1, 0.0, 0.0, S, M, out, &st, NULL), TD_OK);
                for (int32_t j = 0; j < 5; j++)
                    for (int32_t i = 3; i < 9; i++)
                        assert_int_equal(at(&fx, out, i, j), 0);
                unmake(&fx);
                make(&fx, 7, 7, pit);
                assert_int_equal(run(&fx, &in_pit, 1, 0.0, 0.0, S, M, out, &st, NULL), TD_OK);
                for (int32_t j = 0; j < 7; j++)
                    for (int32_t i = 0; i < 7; i++)
                        if (abs(i - 3) > 1 || abs(j - 3) > 1)
                            assert_int_equal(at(&fx, out, i, j), 0);
                if (S != TD_SURFACE_LINEAR) {
                    assert_int_equal(at(&fx, out, 4, 4), 0);
                    assert_int_equal(at(&fx, out, 2, 2), 0);
                }
                if (S == TD_SURFACE_BILINEAR) {
                    assert_int_equal(at(&fx, out, 2, 4), 0);
                    assert_int_equal(at(&fx, out, 4, 2), 0);
                }
                unmake(&fx);
                make(&fx, 7, 3, cliff);
                assert_int_equal(run(&fx, &foot, 1, 0.0, 0.0, S, M, out, &st, NULL), TD_OK);
                for (int32_t i = 0; i <= 2; i++)
                    assert_int_equal(at(&fx, out, i, 1), 0);
                assert_int_equal(run(&fx, &edge, 1, 0.0, 0.0, S, M, out, &st, NULL), TD_OK);
                assert_int_equal(at(&fx, out, 5, 1), 1);
                assert_int_equal(at(&fx, out, 6, 1), 1);
                unmake(&fx);
            }
    run_algo = TD_VS_ALGO_SWEEP;
    {
        td_los_opts o;
        td_los_result *r = malloc(sizeof *r);
        assert_non_null(r);
        make(&fx, 9, 5, dome);
        td_los_opts_default(&o);
        o.a = on_dome;
        o.b = (td_vs_point){40, 20};
        assert_int_equal(td_los(&fx.v, &o, r, NULL), TD_OK);
        assert_false(r->visible);
        assert_true(r->block_s < 1e-6);
        free(r);
        unmake(&fx);
    }
}

/* max_distance 15 m from the centre of flat ground: the centre, its 4 edge neighbours
 * (10 m) and 4 diagonal ones (14.1 m) are inside, the rest outside. */
static void test_max_distance(void **state)
{
    fixture fx;
    uint8_t out[25], gray[25];
    td_viewshed_stats st;
    td_viewshed_opts o;
    td_vs_point p = {20, 20};
    (void)state;
    make(&fx, 5, 5, flat);
    td_viewshed_opts_default(&o);
    o.obs = &p;
    o.nobs = 1;
    o.height = 2;
    o.max_distance = 15;
    assert_int_equal(td_viewshed(&fx.v, &o, out, &st, NULL), TD_OK);
    assert_int_equal(st.inside, 9);
    assert_int_equal(st.visible, 9);
    td_viewshed_gray(out, 25, gray);
    for (int32_t j = 0; j < 5; j++)
        for (int32_t i = 0; i < 5; i++)
            assert_int_equal(gray[(4 - j) * 5 + i], abs(i - 2) <= 1 && abs(j - 2) <= 1 ? 255 : 128);
    unmake(&fx);
}

/* A 40 km strip of sea-level ground (100 m spacing), eye 10 m up, k = 0.13: the ground
 * falls by c s^2, c = 0.87 / (2 R); the horizon is at sqrt(h / c) = 12102 m, and a target
 * T metres up is seen out to sqrt(h / c) + sqrt(T / c) (24204 m for T = 10). Without
 * curvature all is seen. */
static double sea(int32_t i, int32_t j) { (void)i; (void)j; return 0.0; }

static void test_curvature(void **state)
{
    td_grid *g;
    td_accel *a;
    td_accel_opts ao;
    td_view v;
    td_viewshed_opts o;
    td_viewshed_stats st;
    td_vs_point p = {0, 100};
    uint8_t *out = malloc(401 * 3);
    (void)state;
    assert_non_null(out);
    assert_int_equal(td_grid_create(401, 3, 100.0, 100.0, 6, NULL, &g, NULL), TD_OK);
    for (int k = 0; k < 401 * 3; k++)
        g->z[k] = (float)sea(0, 0);
    assert_int_equal(td_grid_finish(g, NULL), TD_OK);
    td_accel_opts_default(&ao);
    ao.maxmip = 1;
    assert_int_equal(td_accel_build(g, &ao, &a, NULL, NULL), TD_OK);
    v.grid = g;
    v.accel = a->tiles;
    td_viewshed_opts_default(&o);
    o.obs = &p;
    o.nobs = 1;
    o.height = 10;
    assert_int_equal(td_viewshed(&v, &o, out, &st, NULL), TD_OK);
    assert_int_equal(st.visible, 401 * 3);
    o.curvature = 1;
    for (int th = 0; th <= 10; th += 10) {
        double reach = th ? 24204.0 : 12102.0;
        o.target_height = th;
        for (int m = 0; m < TD_METHOD_COUNT; m++) {
            o.method = (td_method)m;
            assert_int_equal(td_viewshed(&v, &o, out, &st, NULL), TD_OK);
            for (int32_t i = 0; i < 401; i++) {
                double s = i * 100.0;
                if (s < reach - 100)
                    assert_int_equal(out[401 + i], 1);
                else if (s > reach + 100)
                    assert_int_equal(out[401 + i], 0);
            }
        }
    }
    /* two observers 40 km apart, each with its own lowered grid (one pass each): seen by
     * one within 12.1 km of either, by none between, never by both */
    {
        td_vs_point two[2] = {{0, 100}, {40000, 100}};
        o.obs = two;
        o.nobs = 2;
        o.target_height = 0;
        o.method = TD_METHOD_AUTO;
        assert_int_equal(td_viewshed(&v, &o, out, &st, NULL), TD_OK);
        for (int32_t i = 0; i < 401; i++) {
            double s = i * 100.0, near = s < 20000 ? s : 40000 - s;
            if (near < 12002)
                assert_int_equal(out[401 + i], 1);
            else if (near > 12202)
                assert_int_equal(out[401 + i], 0);
        }
        assert_int_equal(st.inside, 401 * 3);
    }
    free(out);
    td_accel_free(a);
    td_grid_free(g);
}

/* Refusals name the field. */
static void test_refusals(void **state)
{
    fixture fx;
    uint8_t out[25];
    td_viewshed_stats st;
    td_viewshed_opts o;
    td_vs_point p = {20, 20}, two[2] = {{20, 20}, {41, 0}};
    td_err e;
    (void)state;
    make(&fx, 5, 5, flat);
    td_viewshed_opts_default(&o);
    o.obs = &p;
    o.nobs = 1;
    o.height = -1;
    assert_int_equal(td_viewshed(&fx.v, &o, out, &st, &e), TD_ERANGE);
    assert_string_equal(e.field, "height");
    o.height = 1;
    o.target_height = NAN;
    assert_int_equal(td_viewshed(&fx.v, &o, out, &st, &e), TD_ERANGE);
    assert_string_equal(e.field, "target_height");
    o.target_height = 0;
    o.max_distance = 0;
    assert_int_equal(td_viewshed(&fx.v, &o, out, &st, &e), TD_ERANGE);
    assert_string_equal(e.field, "max_distance");
    o.max_distance = INFINITY;
    o.curvature = 1;
    o.k = 1.5;
    assert_int_equal(td_viewshed(&fx.v, &o, out, &st, &e), TD_ERANGE);
    assert_string_equal(e.field, "curvature.k");
    o.curvature = 0;
    o.obs = two;
    o.nobs = 2;
    assert_int_equal(td_viewshed(&fx.v, &o, out, &st, &e), TD_ERANGE);
    assert_string_equal(e.field, "observers[1]");
    o.nobs = TD_VS_MAX_OBSERVERS + 1;
    assert_int_equal(td_viewshed(&fx.v, &o, out, &st, &e), TD_ERANGE);
    assert_string_equal(e.field, "observers");
    unmake(&fx);
}

/* Line of sight over the cliff, eyes 2 m up at (0, 10) and (60, 10): the line
 * z = 102 - (5/3) x meets the plateau at x = 1.2 going east, and going west meets the
 * slope 400 - 10x at x = 35.76 (24.24 m from the start, 42.4 m up). */
static void test_los_cliff(void **state)
{
    fixture fx;
    td_los_opts o;
    td_los_result *r = malloc(sizeof *r);
    td_err e;
    (void)state;
    assert_non_null(r);
    make(&fx, 7, 3, cliff);
    td_los_opts_default(&o);
    o.a = (td_vs_point){0, 10};
    o.b = (td_vs_point){60, 10};
    o.height_a = o.height_b = 2;
    for (int m = 0; m < TD_METHOD_COUNT; m++) {
        o.method = (td_method)m;
        o.a = (td_vs_point){0, 10};
        o.b = (td_vs_point){60, 10};
        assert_int_equal(td_los(&fx.v, &o, r, NULL), TD_OK);
        assert_false(r->visible);
        assert_true(fabs(r->block[0] - 1.2) < 1e-6 && fabs(r->block[2] - 100.0) < 1e-6);
        assert_true(fabs(r->block_s - 1.2) < 1e-6);
        assert_true(fabs(r->distance - 60.0) < 1e-12);
        assert_int_equal(r->nprofile, 7);
        assert_true(r->profile[0].ground == 100.0 && r->profile[6].ground == 0.0);
        assert_true(fabs(r->profile[3].line - 52.0) < 1e-9); /* 102 - 50 at x = 30 */
        o.a = (td_vs_point){60, 10};
        o.b = (td_vs_point){0, 10};
        assert_int_equal(td_los(&fx.v, &o, r, NULL), TD_OK);
        assert_false(r->visible);
        assert_true(fabs(r->block[0] - 298.0 / (10.0 - 5.0 / 3.0)) < 1e-6);
        assert_true(fabs(r->block_s - (60.0 - 298.0 / (10.0 - 5.0 / 3.0))) < 1e-6);
        o.b = (td_vs_point){40, 10}; /* the foot of the cliff */
        assert_int_equal(td_los(&fx.v, &o, r, NULL), TD_OK);
        assert_true(r->visible);
    }
    o.b = (td_vs_point){70, 10};
    assert_int_equal(td_los(&fx.v, &o, r, &e), TD_ERANGE);
    assert_string_equal(e.field, "to");
    o.b = (td_vs_point){40, 10};
    o.height_a = -1;
    assert_int_equal(td_los(&fx.v, &o, r, &e), TD_ERANGE);
    assert_string_equal(e.field, "from.height");
    free(r);
    unmake(&fx);
}

/* With curvature the chord between two eyes at sea level, 40 km apart, 10 m up, sags by
 * c s (D - s) and meets the ground (it is below the horizon of both: 2 x 12102 < 40000);
 * the blocking point, reported in the dataset's frame, is on the ground (0 m). */
static void test_los_curvature(void **state)
{
    td_grid *g;
    td_view v;
    td_los_opts o;
    td_los_result *r = malloc(sizeof *r);
    double c = 0.87 / (2 * TD_EARTH_RADIUS_M);
    (void)state;
    assert_non_null(r);
    assert_int_equal(td_grid_create(401, 3, 100.0, 100.0, 6, NULL, &g, NULL), TD_OK);
    memset(g->z, 0, 401 * 3 * sizeof *g->z);
    assert_int_equal(td_grid_finish(g, NULL), TD_OK);
    v.grid = g;
    v.accel = NULL;
    td_los_opts_default(&o);
    o.a = (td_vs_point){0, 100};
    o.b = (td_vs_point){40000, 100};
    o.height_a = o.height_b = 10;
    o.method = TD_METHOD_INCREMENTAL;
    assert_int_equal(td_los(&v, &o, r, NULL), TD_OK);
    assert_true(r->visible);
    o.curvature = 1;
    assert_int_equal(td_los(&v, &o, r, NULL), TD_OK);
    assert_false(r->visible);
    assert_true(fabs(r->block[2]) < 1e-3);
    /* 10 - c s (D - s) = 0: the first root */
    assert_true(fabs(r->block_s - (40000 - sqrt(40000.0 * 40000.0 - 40.0 / c)) / 2) < 1.0);
    assert_int_equal(r->nprofile, 401); /* one point a cell: the middle one at 20 km */
    assert_true(fabs(r->profile[200].line - (10 - c * 20000.0 * 20000.0)) < 1e-6);
    free(r);
    td_grid_free(g);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_flat_all_visible),
        cmocka_unit_test(test_observer_on_peak),
        cmocka_unit_test(test_observer_in_pit),
        cmocka_unit_test(test_observer_at_corner),
        cmocka_unit_test(test_observer_on_void_edge),
        cmocka_unit_test(test_target_on_cliff_edge),
        cmocka_unit_test(test_eye_on_ground),
        cmocka_unit_test(test_max_distance),
        cmocka_unit_test(test_curvature),
        cmocka_unit_test(test_refusals),
        cmocka_unit_test(test_los_cliff),
        cmocka_unit_test(test_los_curvature),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
