/* test_camera.c: cameras (core/camera.c) and picking (td_render_pick): hand-computed
 * projections for the pinhole frame (heading, pitch, roll), the photogrammetric camera
 * against its pinhole equivalent, the orthographic extent, lon/lat and AGL positions;
 * ray/project round trips; and "a known terrain point projects to the known pixel and
 * picking that pixel returns the point" on procedural terrain, for every surface. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "camera.h"
#include "render.h"
#include "terrain.h"

static td_grid *terrain(int32_t n, double relief)
{
    td_terrain_params p;
    td_grid *g = NULL;
    td_err err = {0};
    td_terrain_params_default(&p);
    p.width = p.height = n;
    p.spacing = 30.0;
    p.feature_m = 3000.0;
    p.relief_m = relief;
    p.base_m = 100.0;
    p.seed = 7;
    assert_int_equal(td_terrain_generate(&p, 5, &g, &err), TD_OK);
    return g;
}

static void pinhole(td_scene_camera *c, double x, double y, double z, double h, double p, double r,
                    double fov)
{
    td_scene s;
    td_scene_defaults(&s);
    *c = s.camera;
    c->x = x;
    c->y = y;
    c->z = z;
    c->heading = h;
    c->pitch = p;
    c->roll = r;
    c->fov = fov;
}

static void test_known_projection(void **state)
{
    td_grid *g = terrain(33, 100.0);
    td_scene_camera sc;
    td_camera cam;
    td_err err = {0};
    double px, py;
    (void)state;

    /* fov 90 on 100 px: focal length 50 px. Looking north from the origin. */
    pinhole(&sc, 0, 0, 0, 0, 0, 0, 90);
    assert_int_equal(td_camera_setup(&sc, 100, 100, g, &cam, &err), TD_OK);
    assert_float_equal(cam.focal_px, 50.0, 1e-9);
    double p1[3] = {10, 100, 20};
    assert_true(td_camera_project(&cam, p1, &px, &py));
    assert_float_equal(px, 54.5, 1e-9); /* 50 + 50 * 10/100 - 0.5 */
    assert_float_equal(py, 39.5, 1e-9); /* 50 - 50 * 20/100 - 0.5 */
    double behind[3] = {0, -10, 0};
    assert_false(td_camera_project(&cam, behind, &px, &py));

    /* heading 90 looks east: a point due east is at the centre */
    pinhole(&sc, 0, 0, 0, 90, 0, 0, 90);
    assert_int_equal(td_camera_setup(&sc, 100, 100, g, &cam, &err), TD_OK);
    double east[3] = {100, 0, 0}, north_of_east[3] = {100, 10, 0};
    assert_true(td_camera_project(&cam, east, &px, &py));
    assert_float_equal(px, 49.5, 1e-9);
    assert_float_equal(py, 49.5, 1e-9);
    assert_true(td_camera_project(&cam, north_of_east, &px, &py));
    assert_true(px < 49.5); /* north is on the left when looking east */

    /* pitch 45 up: a point at 45 degrees elevation is at the centre */
    pinhole(&sc, 0, 0, 0, 0, 45, 0, 90);
    assert_int_equal(td_camera_setup(&sc, 100, 100, g, &cam, &err), TD_OK);
    double up45[3] = {0, 100, 100};
    assert_true(td_camera_project(&cam, up45, &px, &py));
    assert_float_equal(px, 49.5, 1e-9);
    assert_float_equal(py, 49.5, 1e-9);

    /* roll 90 (banked right): a point straight above the axis appears on the left */
    pinhole(&sc, 0, 0, 0, 0, 0, 90, 90);
    assert_int_equal(td_camera_setup(&sc, 100, 100, g, &cam, &err), TD_OK);
    double above[3] = {0, 100, 10};
    assert_true(td_camera_project(&cam, above, &px, &py));
    assert_float_equal(px, 44.5, 1e-9);
    assert_float_equal(py, 49.5, 1e-9);
    td_grid_free(g);
}

static void test_ray_project_round_trip(void **state)
{
    td_grid *g = terrain(33, 100.0);
    td_scene_camera sc;
    td_camera cam;
    td_err err = {0};
    (void)state;
    pinhole(&sc, 100, -50, 800, 33, -20, 12, 57);
    assert_int_equal(td_camera_setup(&sc, 320, 200, g, &cam, &err), TD_OK);
    for (int k = 0; k < 20; k++) {
        double px = -0.5 + k * 16.7, py = 199.4 - k * 9.3, q[3], rx, ry;
        td_ray r;
        td_camera_ray(&cam, px, py, &r);
        assert_float_equal(r.d[0] * r.d[0] + r.d[1] * r.d[1] + r.d[2] * r.d[2], 1.0, 1e-12);
        for (int c = 0; c < 3; c++)
            q[c] = r.o[c] + 1234.5 * r.d[c];
        assert_true(td_camera_project(&cam, q, &rx, &ry));
        assert_float_equal(rx, px, 1e-7);
        assert_float_equal(ry, py, 1e-7);
    }
    td_grid_free(g);
}

/* td_camera_dirs, from the columns' abscissas (computed once for all rows, as a render's
 * block does), gives td_camera_ray's directions bit for bit: the render's camera rays and
 * `terrad render --rays` (td_camera_ray) are the same rays. Sub-pixel columns, rolled and
 * pitched cameras, a wide field of view. */
static void test_dirs_match_ray(void **state)
{
    td_grid *g = terrain(33, 100.0);
    td_scene_camera sc;
    td_camera cam;
    td_err err = {0};
    const double views[3][4] = {{33, -20, 12, 57}, {280, -3, 0, 70}, {140, -80, 35, 170}};
    (void)state;
    for (int v = 0; v < 3; v++) {
        pinhole(&sc, 100, -50, 800, views[v][0], views[v][1], views[v][2], views[v][3]);
        assert_int_equal(td_camera_setup(&sc, 331, 203, g, &cam, &err), TD_OK);
        double px[64], ax[64], dx[64], dy[64], dz[64];
        for (int k = 0; k < 64; k++)
            px[k] = 100 + k * 0.375 - 0.5; /* columns 100 .. 123, 8 sub-columns a pixel (3/8 apart) */
        td_camera_abscissas(&cam, px, 64, ax);
        for (int row = 0; row < 203; row += 29) {
            double py = row + 0.125 - 0.5;
            td_camera_dirs(&cam, py, ax, 64, dx, dy, dz);
            for (int k = 0; k < 64; k++) {
                td_ray r;
                td_camera_ray(&cam, px[k], py, &r);
                assert_memory_equal(&r.d[0], &dx[k], sizeof dx[k]);
                assert_memory_equal(&r.d[1], &dy[k], sizeof dy[k]);
                assert_memory_equal(&r.d[2], &dz[k], sizeof dz[k]);
            }
        }
    }
    td_grid_free(g);
}

static void test_photogrammetric_matches_pinhole(void **state)
{
    td_grid *g = terrain(33, 100.0);
    td_scene_camera a, b;
    td_camera ca, cb;
    td_err err = {0};
    (void)state;
    /* focal 50 mm, pixel 0.05 mm: 1000 px focal length; 800 px wide */
    pinhole(&b, 10, 20, 900, 0, 0, 0, 60);
    b.photogrammetric = 1;
    b.azimuth = 40.0;
    b.tilt = 70.0;   /* 20 degrees below the horizon */
    b.swing = 185.0; /* 5 degrees of roll */
    b.focal_mm = 50.0;
    b.pixel_mm = 0.05;
    double fov = 2.0 * atan(400.0 / 1000.0) * 180.0 / M_PI;
    pinhole(&a, 10, 20, 900, 40.0, -20.0, 5.0, fov);
    assert_int_equal(td_camera_setup(&a, 800, 600, g, &ca, &err), TD_OK);
    assert_int_equal(td_camera_setup(&b, 800, 600, g, &cb, &err), TD_OK);
    assert_float_equal(cb.focal_px, 1000.0, 1e-9);
    double p[3] = {600, 700, 300}, ax, ay, bx, by;
    assert_true(td_camera_project(&ca, p, &ax, &ay));
    assert_true(td_camera_project(&cb, p, &bx, &by));
    assert_float_equal(ax, bx, 1e-7);
    assert_float_equal(ay, by, 1e-7);
    /* tilt 0 looks straight down */
    b.tilt = 0.0;
    assert_int_equal(td_camera_setup(&b, 800, 600, g, &cb, &err), TD_OK);
    assert_float_equal(cb.fwd[2], -1.0, 1e-12);
    td_grid_free(g);
}

static void test_orthographic(void **state)
{
    td_grid *g = terrain(33, 100.0);
    td_scene s;
    td_camera cam;
    td_err err = {0};
    double px, py;
    td_ray r;
    (void)state;
    td_scene_defaults(&s);
    s.camera.projection = TD_PROJ_ORTHOGRAPHIC;
    s.camera.extent[0] = 100;
    s.camera.extent[1] = 200;
    s.camera.extent[2] = 500;
    s.camera.extent[3] = 400;
    assert_int_equal(td_camera_setup(&s.camera, 200, 100, g, &cam, &err), TD_OK);
    double p[3] = {101, 399, 0};
    assert_true(td_camera_project(&cam, p, &px, &py));
    assert_float_equal(px, 0.0, 1e-9); /* pixel (0, 0) is the north-west corner */
    assert_float_equal(py, 0.0, 1e-9);
    td_camera_ray(&cam, 199, 99, &r);
    assert_float_equal(r.o[0], 499, 1e-9);
    assert_float_equal(r.o[1], 201, 1e-9);
    assert_true(r.o[2] > g->zmax);
    assert_float_equal(r.d[2], -1.0, 0.0);
    /* an empty extent is refused, naming the field */
    s.camera.extent[2] = 50;
    assert_int_equal(td_camera_setup(&s.camera, 200, 100, g, &cam, &err), TD_ERANGE);
    assert_string_equal(err.field, "camera.extent");
    assert_memory_equal(err.msg, "camera.extent: ", 15); /* the text still names it */
    td_grid_free(g);
}

static void test_positions(void **state)
{
    td_grid *g = terrain(33, 100.0);
    td_scene_camera sc;
    td_camera cam;
    td_err err = {0};
    (void)state;
    pinhole(&sc, 0, 0, 0, 0, 0, 0, 60);
    /* agl over a sample: ground is that sample's height */
    sc.pos_kind = TD_POS_XY_AGL;
    sc.x = 300;
    sc.y = 450;
    sc.agl = 25;
    assert_int_equal(td_camera_setup(&sc, 10, 10, g, &cam, &err), TD_OK);
    assert_float_equal(cam.o[2], td_grid_at(g, 10, 15) + 25.0, 1e-4);
    /* outside the grid there is no ground */
    sc.x = -10;
    assert_int_equal(td_camera_setup(&sc, 10, 10, g, &cam, &err), TD_ERANGE);
    assert_non_null(strstr(err.msg, "agl"));
    assert_string_equal(err.field, "camera.position.agl");
    /* lon/lat needs a lon/lat georeference */
    sc.pos_kind = TD_POS_LONLAT_ALT;
    sc.lon = 10.001;
    sc.lat = 45.002;
    sc.alt = 1000;
    assert_int_equal(td_camera_setup(&sc, 10, 10, g, &cam, &err), TD_EUNSUPPORTED);
    assert_string_equal(err.field, "camera.position.lon");
    g->geo.kind = TD_GEO_LONLAT;
    g->geo.x0 = 10.0;
    g->geo.y0 = 45.0;
    g->geo.dx = g->geo.dy = 0.0005; /* per 30 m sample */
    assert_int_equal(td_camera_setup(&sc, 10, 10, g, &cam, &err), TD_OK);
    assert_float_equal(cam.o[0], 60.0, 1e-6);  /* 2 samples east */
    assert_float_equal(cam.o[1], 120.0, 1e-6); /* 4 samples north */
    assert_float_equal(cam.o[2], 1000.0, 0.0);
    td_grid_free(g);
}

/* A terrain sample seen from above and aside projects to a pixel; picking that pixel
 * finds the sample again. Samples are exact points of every surface. */
static void test_project_then_pick(void **state)
{
    td_grid *g = terrain(65, 400.0);
    td_scene s;
    td_camera cam;
    td_err err = {0};
    (void)state;
    const int32_t si = 40, sj = 22;
    double P[3] = {si * g->sx, sj * g->sy, td_grid_at(g, si, sj)};

    td_scene_defaults(&s);
    s.dataset[0] = 'x';
    s.image.width = 320;
    s.image.height = 240;
    s.camera.x = P[0] - 300;
    s.camera.y = P[1] - 500;
    s.camera.z = g->zmax + 900;
    /* aim the camera's axis exactly at P: P must land on the image centre */
    double dx = P[0] - s.camera.x, dy = P[1] - s.camera.y, dz = P[2] - s.camera.z;
    s.camera.heading = atan2(dx, dy) * 180.0 / M_PI;
    s.camera.pitch = atan2(dz, hypot(dx, dy)) * 180.0 / M_PI;
    s.camera.fov = 50;
    assert_int_equal(td_camera_setup(&s.camera, 320, 240, g, &cam, &err), TD_OK);
    double px, py;
    assert_true(td_camera_project(&cam, P, &px, &py));
    assert_float_equal(px, 159.5, 1e-6);
    assert_float_equal(py, 119.5, 1e-6);

    /* and an off-centre sample, for every surface and method */
    const int32_t ti = 30, tj = 31;
    double Q[3] = {ti * g->sx, tj * g->sy, td_grid_at(g, ti, tj)};
    double qx, qy;
    assert_true(td_camera_project(&cam, Q, &qx, &qy));
    assert_true(qx > -0.5 && qx < 319.5 && qy > -0.5 && qy < 239.5);
    td_view v = {g, NULL};
    for (int surf = 0; surf < TD_SURFACE_COUNT; surf++) {
        if (surf == TD_SURFACE_PLANE)
            continue; /* the plane surface's top is the cell's highest corner, not the sample */
        td_pick pk[2];
        td_render_stats st;
        s.quality.method = TD_METHOD_INCREMENTAL;
        s.quality.surface = (td_surface)surf;
        s.image.format = TD_FORMAT_PICK;
        s.npick = 2;
        s.pick[0][0] = px;
        s.pick[0][1] = py;
        s.pick[1][0] = qx;
        s.pick[1][1] = qy;
        assert_int_equal(td_render_pick(&v, &s, pk, &st, &err), TD_OK);
        assert_int_equal(st.rays[TD_RAY_PRIMARY], 2);
        assert_true(pk[0].hit && pk[1].hit);
        for (int c = 0; c < 3; c++) {
            assert_float_equal(pk[0].p[c], P[c], 0.05);
            assert_float_equal(pk[1].p[c], Q[c], 0.05);
        }
        double d = sqrt(dx * dx + dy * dy + dz * dz);
        assert_float_equal(pk[0].distance, d, 0.05);
    }
    td_grid_free(g);
}

/* The cylindrical camera (issue 19): known pixels, ray -> project round trips over the
 * whole image including the seam of a 360-degree panorama, fov_v, and what it refuses. */
static void test_cylindrical(void **state)
{
    td_grid *g = terrain(33, 100.0);
    td_scene s;
    td_camera cam;
    td_err err = {0};
    td_ray r;
    double px, py;
    (void)state;
    td_scene_defaults(&s);
    s.camera.projection = TD_PROJ_CYLINDRICAL;
    s.camera.x = 500, s.camera.y = 400, s.camera.z = 1000;
    s.camera.fov = 360;
    assert_int_equal(td_camera_setup(&s.camera, 360, 100, g, &cam, &err), TD_OK);
    /* f = 360 / 2 pi px per radian; the centre row at the horizon */
    double east[3] = {1500, 400, 1000}, south_up[3] = {500, -600, 1000 + 1000 * tan(10 * M_PI / 180)};
    assert_true(td_camera_project(&cam, east, &px, &py));
    assert_float_equal(px, 269.5, 1e-9);
    assert_float_equal(py, 49.5, 1e-9);
    assert_true(td_camera_project(&cam, south_up, &px, &py)); /* on the seam: an edge */
    assert_true(fabs(px - -0.5) < 1e-9 || fabs(px - 359.5) < 1e-9);
    assert_float_equal(py, 49.5 - 360 / (2 * M_PI) * tan(10 * M_PI / 180), 1e-9);
    double above[3] = {500, 400, 2000};
    assert_false(td_camera_project(&cam, above, &px, &py));
    /* a column is an azimuth: pixel 179.5 looks due north, level */
    td_camera_ray(&cam, 179.5, 49.5, &r);
    assert_float_equal(r.d[0], 0.0, 1e-12);
    assert_float_equal(r.d[1], 1.0, 1e-12);
    assert_float_equal(r.d[2], 0.0, 1e-12);
    /* round trips everywhere, both sides of the seam included */
    for (int k = 0; k <= 100; k++) {
        double qx = -0.5 + 1e-7 + (360.0 - 2e-7) * k / 100.0, qy = -0.5 + 100.0 * k / 101.0, q[3];
        td_camera_ray(&cam, qx, qy, &r);
        for (int c = 0; c < 3; c++)
            q[c] = r.o[c] + 777.0 * r.d[c];
        assert_true(td_camera_project(&cam, q, &px, &py));
        assert_float_equal(px, qx, 1e-6);
        assert_float_equal(py, qy, 1e-6);
    }
    /* the seam: the left edge of pixel 0 and the right edge of pixel W-1 are one ray */
    td_ray a, b;
    td_camera_ray(&cam, -0.5, 20, &a);
    td_camera_ray(&cam, 359.5, 20, &b);
    for (int c = 0; c < 3; c++)
        assert_float_equal(a.d[c], b.d[c], 1e-12);
    /* fov_v: the rows span pitch +- fov_v / 2 exactly */
    s.camera.fov = 90, s.camera.heading = 30, s.camera.pitch = 5, s.camera.fov_v = 40;
    assert_int_equal(td_camera_setup(&s.camera, 200, 50, g, &cam, &err), TD_OK);
    td_camera_ray(&cam, -0.5, -0.5, &a);   /* top-left corner */
    td_camera_ray(&cam, 199.5, 49.5, &b);  /* bottom-right corner */
    assert_float_equal(asin(a.d[2]) * 180 / M_PI, 25.0, 1e-9);
    assert_float_equal(asin(b.d[2]) * 180 / M_PI, -15.0, 1e-9);
    assert_float_equal(atan2(a.d[0], a.d[1]) * 180 / M_PI, -15.0, 1e-9);
    assert_float_equal(atan2(b.d[0], b.d[1]) * 180 / M_PI, 75.0, 1e-9);
    /* refused, naming the field */
    s.camera.fov_v = 170; /* 5 + 85: the zenith */
    assert_int_equal(td_camera_setup(&s.camera, 200, 50, g, &cam, &err), TD_ERANGE);
    assert_string_equal(err.field, "camera.fov_v");
    s.camera.fov_v = 0, s.camera.roll = 3;
    assert_int_equal(td_camera_setup(&s.camera, 200, 50, g, &cam, &err), TD_EINVAL);
    assert_string_equal(err.field, "camera.roll");
    s.camera.roll = 0, s.camera.fov = 361;
    assert_int_equal(td_camera_setup(&s.camera, 200, 50, g, &cam, &err), TD_ERANGE);
    assert_string_equal(err.field, "camera.fov");
    td_grid_free(g);
}

/* A panorama's pick round trip: terrain samples all round the eye project to pixels of a
 * 360-degree panorama, and picking those pixels finds the samples (every surface but
 * plane; curvature on, which on a 1 km grid bends nothing by a pixel). Then the seam in a
 * render: the same panorama turned by k columns' angle is the same picture shifted by k
 * columns, wrapping round. */
static void test_cylindrical_pick_and_seam(void **state)
{
    td_grid *g = terrain(65, 400.0);
    td_scene s;
    td_camera cam;
    td_err err = {0};
    td_view v = {g, NULL};
    (void)state;
    td_scene_defaults(&s);
    s.dataset[0] = 'x';
    s.camera.projection = TD_PROJ_CYLINDRICAL;
    s.camera.x = 32 * g->sx + 7, s.camera.y = 32 * g->sy - 5, s.camera.z = g->zmax + 300;
    s.camera.fov = 360, s.camera.heading = 11, s.camera.pitch = -30;
    s.effects.curvature = 1;
    s.image.width = 720, s.image.height = 300, s.image.format = TD_FORMAT_PICK;
    assert_int_equal(td_camera_setup(&s.camera, 720, 300, g, &cam, &err), TD_OK);
    const int32_t ij[6][2] = {{40, 22}, {10, 50}, {60, 60}, {5, 5}, {33, 12}, {50, 31}};
    s.npick = 6;
    for (int k = 0; k < 6; k++) {
        double P[3] = {ij[k][0] * g->sx, ij[k][1] * g->sy, td_grid_at(g, ij[k][0], ij[k][1])};
        assert_true(td_camera_project(&cam, P, &s.pick[k][0], &s.pick[k][1]));
        assert_true(s.pick[k][1] > -0.5 && s.pick[k][1] < 299.5);
    }
    for (int surf = 1; surf < TD_SURFACE_COUNT; surf++) {
        td_pick pk[6];
        s.quality.surface = (td_surface)surf;
        assert_int_equal(td_render_pick(&v, &s, pk, NULL, &err), TD_OK);
        for (int k = 0; k < 6; k++) {
            assert_true(pk[k].hit);
            assert_float_equal(pk[k].p[0], ij[k][0] * g->sx, 0.05);
            assert_float_equal(pk[k].p[1], ij[k][1] * g->sy, 0.05);
            assert_float_equal(pk[k].p[2], td_grid_at(g, ij[k][0], ij[k][1]), 0.05);
        }
    }
    /* the seam: turned by 5 columns (0.5 degree each) */
    td_render_opts o;
    td_render_result a, b;
    int32_t W = 720, H = 300, differ = 0;
    td_render_opts_default(&o);
    o.threads = 2;
    s.npick = 0;
    s.image.format = TD_FORMAT_DEPTH32F;
    memset(&a, 0, sizeof a), memset(&b, 0, sizeof b);
    assert_int_equal(td_render(&v, &s, &o, &a, &err), TD_OK);
    s.camera.heading += 5 * 0.5;
    assert_int_equal(td_render(&v, &s, &o, &b, &err), TD_OK);
    for (int32_t y = 0; y < H; y++)
        for (int32_t x = 0; x < W; x++) {
            float da = a.depth[y * W + (x + 5) % W], db = b.depth[y * W + x];
            differ += !(da == db || fabsf(da - db) <= 1e-3f * da);
        }
    assert_true(differ < W * H / 500); /* rounding of the azimuth may move an edge pixel */
    td_render_result_free(&a);
    td_render_result_free(&b);
    td_grid_free(g);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_known_projection),
        cmocka_unit_test(test_ray_project_round_trip),
        cmocka_unit_test(test_dirs_match_ray),
        cmocka_unit_test(test_photogrammetric_matches_pinhole),
        cmocka_unit_test(test_orthographic),
        cmocka_unit_test(test_positions),
        cmocka_unit_test(test_project_then_pick),
        cmocka_unit_test(test_cylindrical),
        cmocka_unit_test(test_cylindrical_pick_and_seam),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
