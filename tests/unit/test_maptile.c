/* test_maptile.c: core/maptile.c on made-up grids, positions given directly (no
 * projection): a tilted plane's shading is Lambert of its known normal on every surface
 * and method; voids and positions off the grid are transparent (shaded) or 0 m with alpha
 * 0 (encodings); both encodings round-trip heights to their step and clamp beyond their
 * range; a wall casts a shadow of the length the sun's elevation gives; the level of
 * detail follows the footprint; bad specs are refused. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <cmocka.h>

#include "accel.h"
#include "lod.h"
#include "maptile.h"
#include "shade.h"

#define PX 16

/* A w x h grid with spacing s and heights f(i, j). */
static td_grid *grid(int32_t w, int32_t h, double s, double (*f)(int32_t, int32_t))
{
    td_grid *g = NULL;
    assert_int_equal(td_grid_create(w, h, s, s, 3, NULL, &g, NULL), TD_OK);
    for (int32_t j = 0; j < h; j++)
        for (int32_t i = 0; i < w; i++)
            g->z[(size_t)j * w + i] = (float)f(i, j);
    assert_int_equal(td_grid_finish(g, NULL), TD_OK);
    return g;
}

static double tilted(int32_t i, int32_t j) { return 100.0 + 0.5 * i * 10.0 - 0.25 * j * 10.0; }
static double with_void(int32_t i, int32_t j) { return i == 5 && j == 5 ? NAN : 50.0; }
static double level; /* constant()'s height */
static double constant(int32_t i, int32_t j) { (void)i, (void)j; return level; }
static double wall(int32_t i, int32_t j) { (void)j; return i == 20 ? 100.0 : 0.0; }

/* PX x PX positions on a lattice from (x0, y0) with step d (rows going south). */
static void lattice(double *xy, double x0, double y0, double d)
{
    for (int r = 0; r < PX; r++)
        for (int c = 0; c < PX; c++) {
            xy[2 * (r * PX + c)] = x0 + c * d;
            xy[2 * (r * PX + c) + 1] = y0 - r * d;
        }
}

static void test_tilted_plane(void **state)
{
    td_grid *g = grid(40, 40, 10.0, tilted);
    td_accel *a = NULL;
    td_accel_opts ao;
    double xy[2 * PX * PX], n[3] = {-0.5, 0.25, 1.0}, nl = sqrt(0.25 + 0.0625 + 1.0), sun[3];
    uint8_t rgba[4 * PX * PX];
    td_maptile_stats st;
    (void)state;
    td_accel_opts_default(&ao);
    ao.maxmip = ao.planes = 1;
    assert_int_equal(td_accel_build(g, &ao, &a, NULL, NULL), TD_OK);
    td_view v = {g, a->tiles};
    lattice(xy, 13.7, 370.3, 21.1);
    td_shade_sun_dir(300.0, 35.0, sun);
    for (int s = 0; s < TD_SURFACE_COUNT; s++)
        for (int m = 0; m < TD_METHOD_COUNT; m++) {
            td_maptile_spec sp;
            td_maptile_spec_default(&sp);
            sp.surface = (td_surface)s;
            sp.method = (td_method)m;
            memcpy(sp.sun, sun, sizeof sun);
            sp.shadows = 1; /* a plane shadows nothing of itself */
            assert_int_equal(td_maptile_render(&v, NULL, NULL, &sp, xy, PX, 21.1, rgba, NULL, &st, NULL), TD_OK);
            for (int k = 0; k < PX * PX; k++) {
                double ns = (n[0] * sun[0] + n[1] * sun[1] + n[2] * sun[2]) / nl;
                long want = lround(255.0 * (0.25 + 0.75 * fmax(0.0, ns)));
                if (s == TD_SURFACE_PLANE)
                    want = lround(255.0 * (0.25 + 0.75 * sun[2])); /* flat tops */
                assert_int_equal(rgba[4 * k + 3], 255);
                assert_true(labs((long)rgba[4 * k] - want) <= 1);
            }
            assert_int_equal(st.primary_rays, PX * PX);
            assert_int_equal(st.pixels_with_data, PX * PX);
        }
    td_accel_free(a);
    td_grid_free(g);
}

static void test_no_data(void **state)
{
    td_grid *g = grid(12, 12, 10.0, with_void);
    td_view v = {g, NULL};
    double xy[2 * PX * PX];
    uint8_t rgba[4 * PX * PX];
    td_maptile_stats st;
    (void)state;
    lattice(xy, -25.0, 130.0, 10.0); /* from off the grid's west and north edges over the void */
    xy[0] = NAN;
    for (int s = 0; s < TD_MAPSTYLE_COUNT; s++) {
        td_maptile_spec sp;
        td_maptile_spec_default(&sp);
        sp.style = (td_mapstyle)s;
        assert_int_equal(td_maptile_render(&v, NULL, NULL, &sp, xy, PX, 10.0, rgba, NULL, &st, NULL), TD_OK);
        for (int k = 0; k < PX * PX; k++) {
            double x = xy[2 * k], y = xy[2 * k + 1];
            int off = !(x >= 0 && x <= 110 && y >= 0 && y <= 110);
            int hole = !off && x > 40 && x < 60 && y > 40 && y < 60; /* the cells around sample (5, 5) */
            if (off || hole) {
                assert_int_equal(rgba[4 * k + 3], 0);
                if (s == TD_MAPSTYLE_SHADED)
                    assert_true(rgba[4 * k] == 0 && rgba[4 * k + 1] == 0 && rgba[4 * k + 2] == 0);
                else
                    assert_true(isnan(td_maptile_decode((td_mapstyle)s, &rgba[4 * k])));
                if (s != TD_MAPSTYLE_SHADED) { /* 0 m under alpha 0 */
                    uint8_t o[4] = {rgba[4 * k], rgba[4 * k + 1], rgba[4 * k + 2], 255};
                    assert_true(td_maptile_decode((td_mapstyle)s, o) == 0.0);
                }
            } else if (x > 40.5 && x < 59.5 && y > 40.5 && y < 59.5) {
                /* never here: covered by hole */
            } else if (!(x >= 40 && x <= 60 && y >= 40 && y <= 60)) {
                assert_int_equal(rgba[4 * k + 3], 255);
            }
        }
    }
    td_grid_free(g);
}

static void test_encodings(void **state)
{
    static const double h[] = {0.0, 1234.56789, -432.1, 8848.86, -10000.0, 1e-3};
    (void)state;
    for (size_t i = 0; i < sizeof h / sizeof h[0]; i++) {
        double f = h[i];
        td_grid *g;
        td_view v;
        double xy[2 * PX * PX];
        uint8_t rgba[4 * PX * PX];
        td_maptile_stats st;
        td_maptile_spec sp;
        level = f;
        g = grid(4, 4, 1.0, constant);
        v.grid = g;
        v.accel = NULL;
        lattice(xy, 0.5, 2.5, 0.1);
        for (int s = 1; s < TD_MAPSTYLE_COUNT; s++) {
            double step = s == TD_MAPSTYLE_TERRAIN_RGB ? 0.1 : 1.0 / 256.0, got;
            td_maptile_spec_default(&sp);
            sp.style = (td_mapstyle)s;
            assert_int_equal(td_maptile_render(&v, NULL, NULL, &sp, xy, PX, 0.1, rgba, NULL, &st, NULL), TD_OK);
            got = td_maptile_decode((td_mapstyle)s, rgba);
            if (s == TD_MAPSTYLE_TERRARIUM && f < -32768.0)
                assert_true(got == -32768.0); /* clamped */
            else
                assert_true(fabs(got - (double)(float)f) <= 0.5 * step + 1e-9);
        }
        td_grid_free(g);
    }
}

/* A ridge of samples 100 m high at x = 200 m (0 m a cell either side); the sun in the west
 * at 30 degrees: the ground east of it is in shadow up to 100 / tan(30) = 173.2 m beyond
 * its crest, x = 373.2 m. */
static void test_wall_shadow(void **state)
{
    td_grid *g = grid(64, 8, 10.0, wall);
    td_view v = {g, NULL};
    double xy[2 * PX * PX];
    uint8_t rgba[4 * PX * PX];
    td_maptile_stats st;
    td_maptile_spec sp;
    td_sunlit *lit = NULL;
    (void)state;
    td_maptile_spec_default(&sp);
    td_shade_sun_dir(270.0, 30.0, sp.sun);
    sp.surface = TD_SURFACE_TRIANGLE;
    sp.method = TD_METHOD_INCREMENTAL;
    assert_int_equal(td_sunlit_build(&v, sp.sun, 0, &lit, NULL), TD_OK);
    lattice(xy, 215.0, 40.0, 15.0); /* x from 215 to 440 m along y = 40 .. -185 */
    assert_int_equal(td_maptile_render(&v, NULL, lit, &sp, xy, PX, 15.0, rgba, NULL, &st, NULL), TD_OK);
    for (int c = 0; c < PX; c++) {
        double x = xy[2 * c];
        int shadowed = rgba[4 * c] == lround(255.0 * 0.25);
        if (x > 212.0 && x < 373.2 - 3.0)
            assert_true(shadowed);
        else if (x > 373.2 + 3.0)
            assert_false(shadowed);
    }
    assert_true(st.shadow_rays > 0);
    td_sunlit_free(lit);
    td_grid_free(g);
}

static void test_levels_and_refusals(void **state)
{
    td_grid *g = grid(200, 200, 10.0, tilted);
    td_lod *lod = NULL;
    td_accel_opts ao;
    td_maptile_spec sp;
    double xy[2 * PX * PX];
    uint8_t rgba[4 * PX * PX];
    td_maptile_stats st;
    td_mapstyle m;
    (void)state;
    td_accel_opts_default(&ao);
    ao.planes = 0;
    assert_int_equal(td_lod_build(g, TD_LOD_MAX, &ao, &lod, NULL), TD_OK);
    assert_int_equal(td_maptile_level(g, lod, 5.0, 1.0), 0);
    assert_int_equal(td_maptile_level(g, lod, 19.9, 1.0), 0);
    assert_int_equal(td_maptile_level(g, lod, 20.0, 1.0), 1);
    assert_int_equal(td_maptile_level(g, lod, 45.0, 1.0), 2);
    assert_int_equal(td_maptile_level(g, lod, 45.0, 0.0), 0); /* lod off */
    assert_int_equal(td_maptile_level(g, NULL, 1e6, 1.0), 0);
    assert_int_equal(td_maptile_level(g, lod, 1e9, 1.0), lod->levels);
    td_view v = {g, NULL};
    lattice(xy, 100.0, 1900.0, 45.0);
    td_maptile_spec_default(&sp);
    assert_int_equal(td_maptile_render(&v, lod, NULL, &sp, xy, PX, 45.0, rgba, NULL, &st, NULL), TD_OK);
    assert_int_equal(st.level, 2);
    sp.ambient = 2.0;
    assert_int_equal(td_maptile_render(&v, lod, NULL, &sp, xy, PX, 45.0, rgba, NULL, &st, NULL), TD_EINVAL);
    assert_int_equal(td_mapstyle_parse("terrarium", &m), TD_OK);
    assert_int_equal(m, TD_MAPSTYLE_TERRARIUM);
    assert_int_equal(td_mapstyle_parse("hillshade", &m), TD_EINVAL);
    assert_string_equal(td_mapstyle_name(TD_MAPSTYLE_TERRAIN_RGB), "terrain-rgb");
    td_lod_free(lod);
    td_grid_free(g);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_tilted_plane),
        cmocka_unit_test(test_no_data),
        cmocka_unit_test(test_encodings),
        cmocka_unit_test(test_wall_shadow),
        cmocka_unit_test(test_levels_and_refusals),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
