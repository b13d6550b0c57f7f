/* test_beam.c: the beam floor of core/beam.c against brute force. On procedural terrain
 * (with voids, unequal spacing), for random eyes and descending beams of four corner
 * directions, steep and shallow, narrow and wide: every ray inside the beam (random convex
 * combinations of the corners) that meets the terrain meets it at or below the floor,
 * for every surface; started at the floor with td_trace_from it finds td_trace's hit bit
 * for bit; and the floor is at most the eye's height. Beams with a corner that does not
 * descend get no bound (+inf); a beam over no terrain gets the lowest sample (the height
 * plane's walls reach below it), an eye below every sample its own height. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <cmocka.h>

#include "accel.h"
#include "beam.h"
#include "terrain.h"
#include "trace.h"
#include "terrain_fixture.h"

static double rnd(uint64_t *s)
{
    *s = *s * 6364136223846793005ull + 1442695040888963407ull;
    return (double)(*s >> 11) / 9007199254740992.0;
}

static void unit(double d[3])
{
    double n = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    for (int k = 0; k < 3; k++)
        d[k] /= n;
}

/* Four corner directions around a centre direction of elevation el (radians, < 0) and
 * azimuth az, spread by +-w radians in azimuth and elevation. */
static void corners(double az, double el, double w, double d[4][3])
{
    for (int k = 0; k < 4; k++) {
        double a = az + ((k & 1) ? w : -w), e = el + ((k & 2) ? w : -w);
        e = e > -1e-3 ? -1e-3 : (e < -M_PI / 2 ? -M_PI / 2 : e);
        d[k][0] = cos(e) * cos(a);
        d[k][1] = cos(e) * sin(a);
        d[k][2] = sin(e);
    }
}

/* One beam: its rays' hits lie at or below its floor, and start there unchanged. */
static void check_beam(const td_view *v, const double o[3], const double d[4][3], uint64_t *seed, int *bounded)
{
    uint32_t steps = 0;
    double zf = td_beam_floor(v, o, d, 4, &steps);
    assert_true(zf <= o[2] || zf == INFINITY);
    *bounded += zf < o[2];
    for (int k = 0; k < 40; k++) {
        double l[4], sum = 0.0;
        td_ray r = {{o[0], o[1], o[2]}, {0, 0, 0}, 0.0, INFINITY};
        for (int q = 0; q < 4; q++)
            sum += l[q] = rnd(seed) + 1e-3;
        if (k < 4) /* the corners themselves */
            for (int q = 0; q < 4; q++)
                l[q] = q == k;
        for (int q = 0; q < 4; q++)
            for (int c = 0; c < 3; c++)
                r.d[c] += l[q] / (k < 4 ? 1.0 : sum) * d[q][c];
        unit(r.d);
        double t0 = zf == INFINITY ? 0.0 : (o[2] - zf) / -r.d[2] * (1.0 - 1e-12);
        for (int s = 0; s < TD_SURFACE_COUNT; s++) {
            td_hit h, hf;
            td_trace(v, TD_METHOD_AUTO, (td_surface)s, &r, &h);
            if (h.t < INFINITY)
                assert_true(h.p[2] <= zf + 1e-6 * (1.0 + fabs(zf)));
            td_trace_from(v, TD_METHOD_AUTO, (td_surface)s, &r, t0 > 0.0 ? t0 : 0.0, &hf);
            assert_memory_equal(&h.t, &hf.t, sizeof h.t);
        }
    }
}

static void test_beam_bounds(void **state)
{
    td_grid *g = terrain(300, 220, 30.0, 6);
    td_accel *a = NULL;
    td_accel_opts o;
    uint64_t seed = 777;
    int bounded = 0;
    (void)state;
    g->sy = 45.0;
    for (int k = 0; k < 1200; k++) /* voids */
        g->z[(size_t)(rnd(&seed) * (double)g->w * (double)g->h)] = NAN;
    assert_int_equal(td_grid_finish(g, NULL), TD_OK);
    td_accel_opts_default(&o);
    o.threads = 2;
    assert_int_equal(td_accel_build(g, &o, &a, NULL, NULL), TD_OK);
    td_view v = {g, a->tiles};
    for (int k = 0; k < 300; k++) {
        double eye[3] = {(rnd(&seed) * 1.2 - 0.1) * (g->w - 1) * g->sx, (rnd(&seed) * 1.2 - 0.1) * (g->h - 1) * g->sy,
                         g->zmin + rnd(&seed) * 2.0 * (g->zmax - g->zmin + 500.0)};
        double d[4][3];
        corners(rnd(&seed) * 2.0 * M_PI, -(0.05 + rnd(&seed) * 1.5), 0.002 + 0.1 * rnd(&seed), d);
        check_beam(&v, eye, d, &seed, &bounded);
    }
    assert_true(bounded > 100); /* the floor says something for most beams */
    td_accel_free(a);
    td_grid_free(g);
}

/* A corner that does not descend: no bound. A beam whose terrain lies elsewhere: the
 * lowest sample; an eye under every sample: its own height. */
static void test_beam_none(void **state)
{
    td_grid *g = terrain(40, 40, 10.0, 4);
    uint32_t steps = 0;
    double d[4][3];
    (void)state;
    td_view v = {g, NULL};
    double eye[3] = {200.0, 200.0, g->zmax + 100.0};
    corners(0.3, -0.5, 0.05, d);
    d[2][2] = 0.0;
    assert_true(td_beam_floor(&v, eye, (const double(*)[3])d, 4, &steps) == INFINITY);
    corners(0.3, -1.2, 0.05, d);
    double off[3] = {-5000.0, -5000.0, g->zmax + 100.0}; /* looking down beside the grid */
    double zf = td_beam_floor(&v, off, (const double(*)[3])d, 4, &steps);
    assert_true(zf < g->zmin && zf > g->zmin - 0.01); /* zmin less the walk's margin */
    double below[3] = {200.0, 200.0, g->zmin - 10.0}; /* under every sample, looking down */
    assert_true(td_beam_floor(&v, below, (const double(*)[3])d, 4, &steps) == below[2]);
    double over[3] = {200.0, 200.0, g->zmax + 1000.0}; /* straight over it: below the top */
    assert_true(td_beam_floor(&v, over, (const double(*)[3])d, 4, &steps) <= g->zmax + 1e-3);
    assert_true(steps > 0);
    td_grid_free(g);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_beam_bounds),
        cmocka_unit_test(test_beam_none),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
