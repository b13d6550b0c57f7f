/* test_peaks.c: summits by prominence (core/peaks.c) on two cones whose col is known,
 * and which of them a view sees: a summit hidden behind a nearer, higher one is not
 * listed; seen side by side, both are; and a panorama sees them through its seam. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "peaks.h"

/* 171 x 171 samples 10 m apart: cone A (1000 m, sample (50, 50)) and cone B (800 m,
 * (120, 50)), slopes of 10 m a cell, on a floor at 0. Along row 50 the col is at
 * column 95 (A's side 1000 - 450 = B's side 800 - 250): 550 m. */
static td_grid *cones(void)
{
    td_grid *g = NULL;
    assert_int_equal(td_grid_create(171, 171, 10.0, 10.0, 5, NULL, &g, NULL), TD_OK);
    for (int32_t j = 0; j < 171; j++)
        for (int32_t i = 0; i < 171; i++) {
            double a = 1000.0 - 10.0 * hypot(i - 50, j - 50), b = 800.0 - 10.0 * hypot(i - 120, j - 50);
            g->z[(size_t)j * 171 + i] = (float)fmax(0.0, fmax(a, b));
        }
    assert_int_equal(td_grid_finish(g, NULL), TD_OK);
    return g;
}

static void test_prominence(void **state)
{
    td_grid *g = cones();
    td_summits *s = NULL;
    td_err err = {0};
    (void)state;
    assert_int_equal(td_summits_find(g, &s, &err), TD_OK);
    assert_int_equal(s->n, 2);
    assert_int_equal(s->s[0].i, 50);
    assert_int_equal(s->s[0].j, 50);
    assert_float_equal(s->s[0].prominence, 1000.0, 1e-3); /* above the floor */
    assert_int_equal(s->s[0].col_i, -1);
    assert_int_equal(s->s[1].i, 120);
    assert_float_equal(s->s[1].z, 800.0, 1e-3);
    assert_float_equal(s->s[1].prominence, 250.0, 1e-3);
    assert_int_equal(s->s[1].col_i, 95);
    assert_int_equal(s->s[1].col_j, 50);
    td_summits_free(s);
    td_grid_free(g);
}

static size_t seen_in(const td_view *v, const td_summits *s, td_scene *sc, td_peak_seen *out)
{
    size_t n = 0;
    uint64_t rays = 0;
    td_err err = {0};
    assert_int_equal(td_peaks_visible(v, sc, s, 100.0, out, 8, &n, &rays, &err), TD_OK);
    assert_true(rays >= n);
    return n;
}

static void test_visible(void **state)
{
    td_grid *g = cones();
    td_view v = {g, NULL};
    td_summits *s = NULL;
    td_err err = {0};
    td_scene sc;
    td_peak_seen out[8];
    (void)state;
    assert_int_equal(td_summits_find(g, &s, &err), TD_OK);
    td_scene_defaults(&sc);
    sc.dataset[0] = 'x';
    /* from the west along row 50, looking east: B (800 m, 1.2 km) is behind A (1000 m,
       0.5 km) */
    sc.camera.x = 0, sc.camera.y = 500, sc.camera.z = 10;
    sc.camera.heading = 90, sc.camera.pitch = 30, sc.camera.fov = 90;
    assert_int_equal(seen_in(&v, s, &sc, out), 1);
    assert_int_equal(out[0].summit->i, 50);
    assert_float_equal(out[0].distance, 500.0, 1e-9);
    /* its pixel is where the camera projects it */
    td_camera cam;
    double px, py;
    assert_int_equal(td_camera_setup(&sc.camera, 640, 480, g, &cam, &err), TD_OK);
    assert_true(td_camera_project(&cam, out[0].p, &px, &py));
    assert_float_equal(out[0].px, px, 1e-9);
    assert_float_equal(out[0].py, py, 1e-9);
    /* from the north, the two side by side: both seen, highest prominence first */
    sc.camera.x = 850, sc.camera.y = 1650, sc.camera.z = 500;
    sc.camera.heading = 180, sc.camera.pitch = 5, sc.camera.fov = 90;
    assert_int_equal(seen_in(&v, s, &sc, out), 2);
    assert_int_equal(out[0].summit->i, 50);
    assert_int_equal(out[1].summit->i, 120);
    /* looking away: none */
    sc.camera.heading = 0;
    assert_int_equal(seen_in(&v, s, &sc, out), 0);
    /* a panorama from the west with curvature, heading east (A and B off its seam)
       and heading west (both across the seam at +-180): A only, each time */
    sc.camera.projection = TD_PROJ_CYLINDRICAL;
    sc.camera.x = 0, sc.camera.y = 500, sc.camera.z = 10;
    sc.camera.fov = 360, sc.camera.pitch = 20;
    sc.effects.curvature = 1;
    sc.camera.heading = 90;
    assert_int_equal(seen_in(&v, s, &sc, out), 1);
    assert_int_equal(out[0].summit->i, 50);
    assert_float_equal(out[0].px, 319.5, 1e-6);
    sc.camera.heading = 270;
    assert_int_equal(seen_in(&v, s, &sc, out), 1);
    assert_true(out[0].px < 0.5 || out[0].px > 638.5);
    /* higher up, B shows above A: both */
    sc.camera.z = 2000;
    sc.camera.pitch = -20;
    assert_int_equal(seen_in(&v, s, &sc, out), 2);
    td_summits_free(s);
    td_grid_free(g);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_prominence),
        cmocka_unit_test(test_visible),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
