/* test_skyline.c: the skyline (core/skyline.c) against values worked by hand (a ridge
 * on a plain, the grid's edge, a wall beyond the earth's curve) and against a rendered
 * panorama of the same eye: the first terrain row of every column is the skyline's row,
 * to a pixel. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "accel.h"
#include "effects.h"
#include "camera.h"
#include "render.h"
#include "skyline.h"
#include "terrain.h"

#define DEG (M_PI / 180.0)

/* A plain at 0 m, 201 x 201 samples 10 m apart, with a north-south ridge of 100 m on
 * column 150 (x = 1500 m). */
static td_grid *ridge_grid(void)
{
    td_grid *g = NULL;
    assert_int_equal(td_grid_create(201, 201, 10.0, 10.0, 5, NULL, &g, NULL), TD_OK);
    for (int32_t j = 0; j < 201; j++)
        for (int32_t i = 0; i < 201; i++)
            g->z[(size_t)j * 201 + i] = i == 150 ? 100.0f : 0.0f;
    assert_int_equal(td_grid_finish(g, NULL), TD_OK);
    return g;
}

static void test_ridge_and_edge(void **state)
{
    td_grid *g = ridge_grid();
    td_view v = {g, NULL};
    td_skyline_opts o;
    td_skyline s;
    td_err err = {0};
    (void)state;
    td_skyline_opts_default(&o);
    o.x = 500, o.y = 1000, o.height = 10, o.curvature = 0, o.step_deg = 1;
    for (int surf = 0; surf < TD_SURFACE_COUNT; surf++) {
        o.surface = (td_surface)surf;
        assert_int_equal(td_skyline_compute(&v, &o, &s, &err), TD_OK);
        assert_int_equal(s.n, 360);
        assert_float_equal(s.eye[2], 10.0, 1e-9);
        /* east: the ridge's crest, 1000 m away, 90 m above the eye (the plane surface's
           cells next to the crest are flat-topped at 100 m: the crest is a cell nearer) */
        double near = surf == TD_SURFACE_PLANE ? 10.0 : 0.0;
        assert_float_equal(s.pt[90].azimuth, 90.0, 1e-12);
        assert_float_equal(s.pt[90].elevation, atan(90.0 / (1000.0 - near)) / DEG, 1e-6);
        assert_float_equal(s.pt[90].distance, 1000.0 - near, 0.01);
        assert_float_equal(s.pt[90].p[2], 100.0, 0.01);
        /* west: the plain ends at the grid's edge, 500 m away, 10 m below the eye */
        assert_float_equal(s.pt[270].elevation, -atan(10.0 / 500.0) / DEG, 1e-6);
        assert_float_equal(s.pt[270].distance, 500.0, 0.01);
        /* north-east at 45 degrees the ridge is sqrt(2) km away */
        assert_float_equal(s.pt[45].elevation, atan(90.0 / (sqrt(2.0) * (1000.0 - near))) / DEG, 1e-5);
        /* between azimuths: linear */
        assert_float_equal(td_skyline_elevation_at(&s, 90.5),
                           0.5 * (s.pt[90].elevation + s.pt[91].elevation), 1e-12);
        assert_float_equal(td_skyline_elevation_at(&s, -270.0), s.pt[90].elevation, 1e-12);
        td_skyline_free(&s);
    }
    /* an eye on the ground (height 0) is lifted 1 cm: the plain's edge is then 1 cm down */
    o.height = 0, o.surface = TD_SURFACE_BILINEAR;
    assert_int_equal(td_skyline_compute(&v, &o, &s, &err), TD_OK);
    assert_float_equal(s.eye[2], 0.01, 1e-12);
    assert_float_equal(s.pt[270].elevation, -atan(0.01 / 500.0) / DEG, 1e-6);
    assert_float_equal(s.pt[90].elevation, atan(99.99 / 1000.0) / DEG, 1e-6);
    td_skyline_free(&s);
    /* the eye stands on the chosen surface: halfway up the ridge's east-west cells the
       bilinear ground is 50 m, the plane surface's box 100 m (its highest corner) */
    o.x = 1495, o.height = 10;
    for (int surf = 0; surf < TD_SURFACE_COUNT; surf++) {
        o.surface = (td_surface)surf;
        assert_int_equal(td_skyline_compute(&v, &o, &s, &err), TD_OK);
        double eye = surf == TD_SURFACE_PLANE ? 110.0 : 60.0;
        assert_float_equal(s.eye[2], eye, 1e-9);
        assert_float_equal(s.pt[270].elevation, -atan(eye / 1495.0) / DEG, 1e-6);
        td_skyline_free(&s);
    }
    o.x = 500, o.surface = TD_SURFACE_BILINEAR;
    /* refused, naming the field */
    o.step_deg = 0.001;
    assert_int_equal(td_skyline_compute(&v, &o, &s, &err), TD_ERANGE);
    assert_string_equal(err.field, "step_deg");
    o.step_deg = 1, o.x = -5;
    assert_int_equal(td_skyline_compute(&v, &o, &s, &err), TD_ERANGE);
    assert_string_equal(err.field, "observer");
    o.x = 500, o.max_distance = 0;
    assert_int_equal(td_skyline_compute(&v, &o, &s, &err), TD_ERANGE);
    assert_string_equal(err.field, "max_distance");
    /* max_distance: the ridge 1000 m away is out of a 800 m reach; the plain's far edge
       at 800 m forms the skyline */
    o.max_distance = 800;
    assert_int_equal(td_skyline_compute(&v, &o, &s, &err), TD_OK);
    assert_float_equal(s.pt[90].elevation, -atan(10.0 / 800.0) / DEG, 1e-5);
    td_skyline_free(&s);
    td_grid_free(g);
}

/* The earth's curve: a 500 m wall 40 km across a sea, seen from 10 m; with curvature
 * (k = 0.13) it sinks by (1 - k) s^2 / 2R = 109.3 m. */
static void test_curvature(void **state)
{
    td_grid *g = NULL;
    td_accel *a = NULL;
    td_accel_opts ao;
    td_skyline_opts o;
    td_skyline s;
    td_err err = {0};
    (void)state;
    assert_int_equal(td_grid_create(401, 3, 100.0, 100.0, 6, NULL, &g, NULL), TD_OK);
    for (int k = 0; k < 401 * 3; k++)
        g->z[k] = k % 401 == 400 ? 500.0f : 0.0f;
    assert_int_equal(td_grid_finish(g, NULL), TD_OK);
    td_accel_opts_default(&ao);
    ao.maxmip = 1;
    assert_int_equal(td_accel_build(g, &ao, &a, NULL, NULL), TD_OK);
    td_view v = {g, a->tiles};
    td_skyline_opts_default(&o);
    o.x = 0, o.y = 100, o.height = 10;
    double s2 = 40000.0 * 40000.0, drop = (1.0 - 0.13) * s2 / (2.0 * TD_EARTH_RADIUS_M);
    assert_int_equal(td_skyline_compute(&v, &o, &s, &err), TD_OK);
    assert_int_equal(s.n, 1440);
    /* within the chords' 1/256 of a step */
    assert_float_equal(s.pt[360].elevation, atan((490.0 - drop) / 40000.0) / DEG, 0.25 / 256 + 1e-6);
    assert_float_equal(s.pt[360].distance, 40000.0, 1.0);
    td_skyline_free(&s);
    o.curvature = 0;
    assert_int_equal(td_skyline_compute(&v, &o, &s, &err), TD_OK);
    assert_float_equal(s.pt[360].elevation, atan(490.0 / 40000.0) / DEG, 1e-6);
    td_skyline_free(&s);
    td_accel_free(a);
    td_grid_free(g);
}

/* A rendered 360-degree panorama of the same eye (column k at azimuth k * step, as the
 * skyline's): in every column the first row from the top that meets terrain is the row
 * of the skyline's elevation, to a pixel. */
static void test_matches_render(void **state)
{
    td_terrain_params p;
    td_grid *g = NULL;
    td_err err = {0};
    td_skyline_opts o;
    td_skyline sk;
    td_scene sc;
    td_render_opts ro;
    td_render_result res;
    td_camera cam;
    enum { W = 720, H = 360 };
    int exact = 0;
    (void)state;
    td_terrain_params_default(&p);
    p.width = p.height = 129;
    p.spacing = 30.0;
    p.feature_m = 1500.0;
    p.relief_m = 400.0;
    p.seed = 3;
    assert_int_equal(td_terrain_generate(&p, 5, &g, &err), TD_OK);
    td_view v = {g, NULL};
    td_skyline_opts_default(&o);
    o.x = 64 * 30.0 + 3, o.y = 64 * 30.0 - 4, o.height = 15, o.step_deg = 360.0 / W;
    assert_int_equal(td_skyline_compute(&v, &o, &sk, &err), TD_OK);
    td_scene_defaults(&sc);
    sc.dataset[0] = 'x';
    sc.camera.projection = TD_PROJ_CYLINDRICAL;
    sc.camera.x = sk.eye[0], sc.camera.y = sk.eye[1], sc.camera.z = sk.eye[2];
    sc.camera.fov = 360, sc.camera.heading = (0.5 * W - 0.5) * o.step_deg;
    sc.image.width = W, sc.image.height = H, sc.image.format = TD_FORMAT_DEPTH32F;
    sc.effects.curvature = 1;
    td_render_opts_default(&ro);
    ro.threads = 2;
    memset(&res, 0, sizeof res);
    assert_int_equal(td_render(&v, &sc, &ro, &res, &err), TD_OK);
    assert_int_equal(td_camera_setup(&sc.camera, W, H, g, &cam, &err), TD_OK);
    for (int x = 0; x < W; x++) {
        int row = 0;
        while (row < H && !isfinite(res.depth[row * W + x]))
            row++;
        double py = cam.fv_px * (cam.tan_top - tan(sk.pt[x].elevation * DEG)) - 0.5;
        int want = (int)ceil(py);
        assert_true(abs(row - want) <= 1);
        exact += row == want;
    }
    assert_true(exact >= W * 95 / 100);
    td_render_result_free(&res);
    td_skyline_free(&sk);
    td_grid_free(g);
}

/* Sunrise behind a ridge: a 100 m ridge 1 km east of an eye 10 m up (5.14 degrees) on
 * a plain at 45 N, 7 E at the equinox. The sun clears it later than the almanac's
 * sunrise by the time it takes to climb the ridge's angle, and at that instant its upper
 * limb is on the skyline; to the west the plain ends 500 m away, 1.15 degrees down, so it
 * sets later than the almanac says. */
static void test_sun_behind_ridge(void **state)
{
    td_grid *g = ridge_grid();
    td_view v = {g, NULL};
    td_skyline_opts o;
    td_skyline s;
    td_skyline_sun *sun = malloc(sizeof *sun);
    td_err err = {0};
    double day;
    (void)state;
    assert_non_null(sun);
    td_skyline_opts_default(&o);
    o.x = 500, o.y = 1000, o.height = 10, o.step_deg = 0.1;
    assert_int_equal(td_skyline_compute(&v, &o, &s, &err), TD_OK);
    assert_int_equal(td_solar_parse_time("2026-03-20", "sun.date", &day, &err), TD_OK);
    assert_int_equal(td_skyline_sun_day(&s, 45.0, 7.0, day, sun, &err), TD_OK);
    assert_int_equal(sun->polar, 0);
    assert_true(sun->rise_s > sun->astro_rise_s);
    assert_true(sun->set_s > sun->astro_set_s);
    assert_int_equal(sun->nint, 1);
    /* at the terrain's sunrise the upper limb is on the ridge (1 s of climb is 0.003 deg) */
    td_sun p0, p1;
    assert_int_equal(td_solar_position(45.0, 7.0, sun->rise_s, &p0, &err), TD_OK);
    double ridge = td_skyline_elevation_at(&s, p0.azimuth_deg);
    assert_true(ridge > 4.0 && ridge < 5.2);
    assert_float_equal(p0.elevation_deg + p0.refraction_deg + TD_SUN_RADIUS_DEG, ridge, 0.005);
    /* later than the almanac by the ridge's angle: from the almanac's sunrise (centre
       0.833 deg below the astronomical horizon) the sun climbs to the ridge (less the
       refraction and radius there) at the equinox's 15 deg/h * cos(latitude) */
    double climb = ridge - p0.refraction_deg - TD_SUN_RADIUS_DEG + 0.833;
    double delay = sun->rise_s - sun->astro_rise_s;
    assert_float_equal(delay, climb / (15.0 / 3600.0 * cos(45.0 * DEG)), 0.02 * delay);
    assert_int_equal(td_solar_position(45.0, 7.0, sun->astro_rise_s, &p1, &err), TD_OK);
    assert_float_equal(p1.elevation_deg, -0.833, 0.01);
    /* the path: 5-minute samples over the solar day, seen only between rise and set */
    assert_int_equal(sun->npath, TD_SUN_PATH_MAX);
    for (int k = 0; k < sun->npath; k++)
        assert_int_equal(sun->path[k].seen, sun->path[k].t >= sun->rise_s && sun->path[k].t < sun->set_s);
    td_skyline_free(&s);
    free(sun);
    td_grid_free(g);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_ridge_and_edge),
        cmocka_unit_test(test_curvature),
        cmocka_unit_test(test_matches_render),
        cmocka_unit_test(test_sun_behind_ridge),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
