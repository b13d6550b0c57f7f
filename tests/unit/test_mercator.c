/* test_mercator.c: core/mercator.c. The tile math against the OpenStreetMap scheme's
 * numbers; the pixel positions of a tile against the inverse spherical Mercator written
 * out here (through td_merc_to_lonlat back from the dataset frame), for a lon/lat and a
 * UTM dataset, both where the lattice is interpolated (within TD_MERC_LATTICE_TOL pixels)
 * and where it must fall back to transforming every pixel (a world tile over UTM: PROJ
 * fails far outside the zone); the meridian convergence of UTM against the textbook
 * formula; refusals for grids without a usable CRS. */
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
#include "mercator.h"

/* A fixture's grid and, when p is not NULL, its transformations. */
static td_grid *fixture(const char *name, td_merc_proj **p)
{
    char path[512];
    td_grid *g = NULL;
    td_err e = {0};
    snprintf(path, sizeof path, "%s/%s", TERRAD_TEST_DATA, name);
    if (td_dem_load(path, NULL, &g, &e) || (p && td_merc_proj_create(path, g, p, &e)))
        fail_msg("%s: %s", path, e.msg);
    return g;
}

static void test_tile_math(void **state)
{
    double b[4];
    int32_t r[4];
    (void)state;
    td_merc_tile_bounds(0, 0, 0, b);
    assert_true(b[0] == -TD_MERC_HALF && b[2] == TD_MERC_HALF && b[1] == -TD_MERC_HALF && b[3] == TD_MERC_HALF);
    td_merc_tile_bounds(1, 1, 0, b); /* north-east quarter */
    assert_true(b[0] == 0.0 && b[1] == 0.0 && b[2] == TD_MERC_HALF && b[3] == TD_MERC_HALF);
    /* OSM's 156543.03 m per pixel at zoom 0 */
    assert_true(fabs(td_merc_pixel_m(0, 256) - 156543.03392804097) < 1e-6);
    assert_true(fabs(td_merc_pixel_m(3, 512) - 156543.03392804097 / 16) < 1e-6);
    /* 3 arc-seconds (73.6 m east) at 37.6 N: zoom 11's pixels are 60.5 m, zoom 10's 121 m */
    assert_int_equal(td_merc_zoom_for(73.6, 37.6), 11);
    assert_int_equal(td_merc_zoom_for(60.0, 37.6), 12);
    assert_int_equal(td_merc_zoom_for(1e9, 0.0), 0);
    assert_int_equal(td_merc_zoom_for(1e-6, 0.0), TD_MERC_MAX_ZOOM);
    assert_int_equal(td_merc_zoom_for(-1.0, 0.0), 0);
    /* a box from inside tile 13/1719/3171 to 5 km east of it (tiles are 4892 m wide) */
    td_merc_tile_bounds(13, 1719, 3171, b);
    {
        double m[4] = {b[0] + 1, b[1] + 1, b[2] + 5000, b[3] - 1};
        td_merc_tile_range(m, 13, r);
        assert_int_equal(r[0], 1719);
        assert_int_equal(r[1], 3171);
        assert_int_equal(r[2], 1721);
        assert_int_equal(r[3], 3171);
    }
    {
        double world[4] = {-1e9, -1e9, 1e9, 1e9};
        td_merc_tile_range(world, 2, r);
        assert_true(r[0] == 0 && r[1] == 0 && r[2] == 3 && r[3] == 3);
    }
}

/* Every 7th pixel's position, back to lon/lat, against the pixel centre's lon/lat. */
static double check_positions(td_merc_proj *p, int z, int x, int y, int px, int *exact)
{
    double *xy = malloc((size_t)2 * px * px * sizeof *xy), foot = 0, worst = 0;
    double side = 2.0 * TD_MERC_HALF / ldexp(1.0, z), ps = side / px;
    td_err e = {0};
    assert_non_null(xy);
    assert_int_equal(td_merc_positions(p, z, x, y, px, xy, exact, &foot, &e), TD_OK);
    assert_true(foot > 0.0);
    for (int k = 0; k < px * px; k += 7) {
        int r = k / px, c = k % px;
        double X = -TD_MERC_HALF + x * side + (c + 0.5) * ps, Y = TD_MERC_HALF - y * side - (r + 0.5) * ps;
        double lon = X / 6378137.0 * 180.0 / M_PI, lat = atan(sinh(Y / 6378137.0)) * 180.0 / M_PI, ll[2];
        if (isnan(xy[2 * k]))
            continue;
        assert_int_equal(td_merc_to_lonlat(p, xy[2 * k], xy[2 * k + 1], ll, &e), TD_OK);
        /* in pixels: a degree of longitude is side * 2^z / 360 Mercator metres */
        worst = fmax(worst, fabs(ll[0] - lon) * 111319.49 / ps);
        worst = fmax(worst, fabs(ll[1] - lat) * 111319.49 / cos(lat * M_PI / 180.0) / ps);
    }
    free(xy);
    return worst;
}

static void test_positions(void **state)
{
    td_merc_proj *pl = NULL, *pu = NULL;
    td_grid *ll = fixture("trinidad-crop.f32", &pl), *utm = fixture("trinidad-utm13.tif", &pu);
    int exact = -1;
    double w;
    (void)state;
    w = check_positions(pl, 13, 1719, 3171, 256, &exact);
    printf("lon/lat, 13/1719/3171: lattice %s, largest error %.2e pixels\n", exact ? "refused" : "used", w);
    assert_int_equal(exact, 0);
    assert_true(w < TD_MERC_LATTICE_TOL);
    w = check_positions(pu, 13, 1719, 3171, 512, &exact);
    printf("UTM, 13/1719/3171@2x: lattice %s, largest error %.2e pixels\n", exact ? "refused" : "used", w);
    assert_int_equal(exact, 0);
    assert_true(w < TD_MERC_LATTICE_TOL);
    /* the whole world over UTM 13N: far from the zone, every pixel through PROJ */
    w = check_positions(pu, 0, 0, 0, 256, &exact);
    printf("UTM, 0/0/0: lattice %s, largest error %.2e pixels\n", exact ? "refused" : "used", w);
    assert_int_equal(exact, 1);
    assert_true(w < 1e-3);
    /* UTM 13N's grid convergence at the centre: atan(tan(lon - lon0) sin(lat)), negative
       west of the central meridian (105 W): true north lies west of grid north */
    {
        double llb[4], m[4], c[2], gamma;
        td_merc_proj_bounds(pu, llb, m, c);
        gamma = atan(tan((c[0] + 105.0) * M_PI / 180.0) * sin(c[1] * M_PI / 180.0)) * 180.0 / M_PI;
        printf("UTM convergence %.4f (formula %.4f) degrees\n", td_merc_proj_grid_north(pu), -gamma);
        assert_true(fabs(td_merc_proj_grid_north(pu) + gamma) < 0.01);
        assert_true(td_merc_proj_grid_north(pl) == 0.0);
        /* bounds: the lon/lat grid's own extent */
        td_merc_proj_bounds(pl, llb, m, c);
        assert_true(fabs(llb[0] - ll->geo.x0) < 1e-9 && fabs(llb[1] - ll->geo.y0) < 1e-9);
        assert_true(fabs(llb[2] - (ll->geo.x0 + (ll->w - 1) * ll->geo.dx)) < 1e-9);
        assert_true(m[0] < m[2] && m[1] < m[3]);
    }
    /* a clone answers the same */
    {
        td_merc_proj *cl = NULL;
        td_err e = {0};
        assert_int_equal(td_merc_proj_clone(pu, &cl, &e), TD_OK);
        w = check_positions(cl, 13, 1719, 3171, 256, &exact);
        assert_true(w < TD_MERC_LATTICE_TOL);
        td_merc_proj_free(cl);
    }
    td_merc_proj_free(pl);
    td_merc_proj_free(pu);
    td_grid_free(ll);
    td_grid_free(utm);
}

static void test_refusals(void **state)
{
    td_grid *g = fixture("volcano.asc", NULL); /* projected by its extent, no .prj */
    td_merc_proj *p = NULL;
    td_err e = {0};
    double xy[2 * 256 * 256], foot;
    int exact;
    (void)state;
    assert_int_equal(td_merc_proj_create(NULL, g, &p, &e), TD_EUNSUPPORTED);
    assert_null(p);
    assert_non_null(strstr(e.msg, "CRS"));
    g->geo.kind = TD_GEO_NONE;
    assert_int_equal(td_merc_proj_create(NULL, g, &p, &e), TD_EUNSUPPORTED);
    assert_non_null(strstr(e.msg, "georeference"));
    /* a projected grid whose sidecar names a CRS PROJ knows: accepted; a URL: not read */
    g->geo.kind = TD_GEO_PROJECTED;
    g->geo.x0 = 500000.0;
    g->geo.y0 = 4160000.0;
    g->geo.dx = g->geo.dy = 10.0;
    snprintf(g->geo.crs, sizeof g->geo.crs, "EPSG:32613");
    assert_int_equal(td_merc_proj_create(NULL, g, &p, &e), TD_OK);
    assert_string_equal(td_merc_proj_name(p), "WGS 84 / UTM zone 13N");
    assert_int_equal(td_merc_positions(p, 25, 0, 0, 256, xy, &exact, &foot, &e), TD_EINVAL);
    assert_int_equal(td_merc_positions(p, 2, 4, 0, 256, xy, &exact, &foot, &e), TD_EINVAL);
    assert_int_equal(td_merc_positions(p, 2, 0, 0, 100, xy, &exact, &foot, &e), TD_EINVAL);
    td_merc_proj_free(p);
    p = NULL;
    snprintf(g->geo.crs, sizeof g->geo.crs, "http://example.invalid/crs.wkt");
    assert_int_equal(td_merc_proj_create(NULL, g, &p, &e), TD_EUNSUPPORTED);
    /* a geographic CRS for a projected georeference: refused as unknown */
    snprintf(g->geo.crs, sizeof g->geo.crs, "EPSG:4326");
    assert_int_equal(td_merc_proj_create(NULL, g, &p, &e), TD_EUNSUPPORTED);
    td_grid_free(g);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_tile_math),
        cmocka_unit_test(test_positions),
        cmocka_unit_test(test_refusals),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
