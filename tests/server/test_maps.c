/* test_maps.c: GET /v1/maps/... (server/maps.c) over real HTTP, values decoded and judged.
 *
 * terrad serves a copy of tests/data's trinidad crop (raw + sidecar, lon/lat), the SRTM
 * tile N37W105 (lon/lat), the same terrain warped to UTM zone 13N (trinidad-utm13.tif)
 * and volcano (projected without a CRS: no map). The test places each tile pixel itself:
 * its centre in EPSG:3857 -> lon/lat by the inverse spherical Mercator written out here
 * (independent of terrad's PROJ path) -> the dataset frame by the georeference, and reads
 * the grid in process (td_dem_load, td_grid_bilinear). Checked:
 *   - terrain-rgb and terrarium decode to the bilinear surface there within half their
 *     step (0.05 m, 1/512 m) plus 0.01 m; no-data pixels encode 0 m with alpha 0, exactly
 *     where the position is off the grid;
 *   - shaded without shadows is round(255 * (a + (1 - a) * max(0, n.sun))) with n the
 *     bilinear patch's normal (within 1 level); with a low sun, shadows only darken, and a
 *     shadowed pixel is the ambient level;
 *   - tiles wholly outside answer 404, partial ones are transparent outside;
 *   - ETag, 304, Cache-Control; CORS (*, a list, never on admin routes, preflight);
 *   - TileJSON 3.0.0 (bounds, maxzoom, encoding, template with the query, the sun of
 *     ?time= from core/solar at the dataset's centre);
 *   - the lon/lat and the UTM pyramids line up: over a shared tile, their heights agree
 *     best with no shift (among +-2 pixels), and closely;
 *   - every refusal a 4xx naming its field. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include <cmocka.h>
#include <jansson.h>

#include "dem.h"
#include "harness.h"
#include "image.h"
#include "solar.h"

#define R_EARTH 6378137.0
#define HALF (M_PI * R_EARTH)

static th_server S;
static char dir[256];

static void copy_file(const char *name)
{
    char cmd[1024];
    snprintf(cmd, sizeof cmd, "cp '%s/%s' '%s/'", TERRAD_TEST_DATA, name, dir);
    if (system(cmd) != 0)
        fail_msg("cannot copy %s", name);
}

static int setup(void **state)
{
    const char *args[] = {"--demo-dir", "", "--data", dir, "--render-workers", "2", "--preload", "all", NULL};
    static const char *const files[] = {"trinidad-crop.f32", "trinidad-crop.json", "N37W105.hgt",
                                        "trinidad-utm13.tif", "volcano.asc"};
    (void)state;
    snprintf(dir, sizeof dir, "/tmp/terrad-maps-XXXXXX");
    if (!mkdtemp(dir))
        return -1;
    for (size_t i = 0; i < sizeof files / sizeof files[0]; i++)
        copy_file(files[i]);
    return th_start(&S, TERRAD_BIN, args, NULL);
}

static int teardown(void **state)
{
    int rc = th_stop(&S);
    char cmd[300];
    (void)state;
    if (rc == 0)
        th_forget(&S);
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
    if (system(cmd) != 0)
        rc = -1;
    return rc;
}

static void get(const th_server *s, const char *path, const char *const *hdr, th_resp *r)
{
    assert_int_equal(th_request(s, "GET", path, hdr, NULL, 0, r), 0);
}

/* A 200 PNG tile, decoded to RGBA. */
static td_image8 *tile(const char *path)
{
    th_resp r;
    td_image8 *img = NULL;
    td_err e = {0};
    get(&S, path, NULL, &r);
    if (r.status != 200)
        fail_msg("%s: status %ld: %.*s", path, r.status, (int)r.len, r.body);
    if (td_image_decode((const uint8_t *)r.body, r.len, 4, 1 << 20, &img, &e))
        fail_msg("%s: %s", path, e.msg);
    th_resp_free(&r);
    return img;
}

static td_grid *load(const char *name)
{
    char path[512];
    td_grid *g = NULL;
    td_err e = {0};
    snprintf(path, sizeof path, "%s/%s", TERRAD_TEST_DATA, name);
    if (td_dem_load(path, NULL, &g, &e))
        fail_msg("%s: %s", path, e.msg);
    return g;
}

/* Tile z/x/y's pixel (c, r) of px -> lon/lat (spherical Mercator, inverted here). */
static void pixel_lonlat(int z, int x, int y, int px, int c, int r, double *lon, double *lat)
{
    double side = 2.0 * HALF / ldexp(1.0, z), ps = side / px;
    double X = -HALF + x * side + (c + 0.5) * ps, Y = HALF - y * side - (r + 0.5) * ps;
    *lon = X / R_EARTH * 180.0 / M_PI;
    *lat = atan(sinh(Y / R_EARTH)) * 180.0 / M_PI;
}

/* The tile holding lon/lat at zoom z. */
static void tile_of(double lon, double lat, int z, int *x, int *y)
{
    double n = ldexp(1.0, z), la = lat * M_PI / 180.0;
    *x = (int)floor((lon + 180.0) / 360.0 * n);
    *y = (int)floor((1.0 - asinh(tan(la)) / M_PI) / 2.0 * n);
}

/* A lon/lat grid's frame position of lon/lat; 1 when on the grid. */
static int frame_of(const td_grid *g, double lon, double lat, double *fx, double *fy)
{
    *fx = (lon - g->geo.x0) / g->geo.dx * g->sx;
    *fy = (lat - g->geo.y0) / g->geo.dy * g->sy;
    return *fx >= 0 && *fy >= 0 && *fx <= (g->w - 1) * g->sx && *fy <= (g->h - 1) * g->sy;
}

static double decode(const uint8_t *p, int terrarium)
{
    double v = p[0] * 65536.0 + p[1] * 256.0 + p[2];
    return terrarium ? v / 256.0 - 32768.0 : -10000.0 + v * 0.1;
}

/* terrain-rgb and terrarium against the bilinear surface, on a tile inside and one on
 * the grid's edge. */
static void test_encodings(void **state)
{
    td_grid *g = load("trinidad-crop.f32");
    int z = 13, tx, ty;
    (void)state;
    for (int edge = 0; edge < 2; edge++) {
        if (edge)
            tile_of(g->geo.x0, g->geo.y0, z, &tx, &ty); /* the south-west corner */
        else
            tile_of(g->geo.x0 + 0.5 * (g->w - 1) * g->geo.dx, g->geo.y0 + 0.5 * (g->h - 1) * g->geo.dy, z, &tx, &ty);
        for (int terrarium = 0; terrarium < 2; terrarium++) {
            char path[200];
            td_image8 *img;
            long inside = 0, outside = 0;
            double worst = 0, tol = (terrarium ? 1.0 / 512.0 : 0.05) + 0.01;
            snprintf(path, sizeof path, "/v1/maps/trinidad-crop/%s/%d/%d/%d.png", terrarium ? "terrarium" : "terrain-rgb",
                     z, tx, ty);
            img = tile(path);
            assert_int_equal(img->width, 256);
            for (int r = 0; r < 256; r++)
                for (int c = 0; c < 256; c++) {
                    const uint8_t *p = &img->px[4 * (r * 256 + c)];
                    double lon, lat, fx, fy, h;
                    pixel_lonlat(z, tx, ty, 256, c, r, &lon, &lat);
                    if (frame_of(g, lon, lat, &fx, &fy) && td_grid_bilinear(g, fx, fy, &h, NULL)) {
                        assert_int_equal(p[3], 255);
                        worst = fmax(worst, fabs(decode(p, terrarium) - h));
                        inside++;
                    } else {
                        /* no data: 0 m, transparent */
                        assert_int_equal(p[3], 0);
                        assert_true(decode(p, terrarium) == 0.0);
                        outside++;
                    }
                }
            printf("%s: %ld pixels inside (largest error %.4f m, allowed %.4f), %ld outside\n", path, inside, worst,
                   tol, outside);
            assert_true(worst <= tol);
            assert_true(inside > 1000);
            if (edge)
                assert_true(outside > 1000);
            td_image_free(img);
        }
    }
    td_grid_free(g);
}

/* Shaded pixels: Lambert from the bilinear patch's normal; shadows only darken. */
static void test_shaded(void **state)
{
    td_grid *g = load("trinidad-crop.f32");
    int z = 13, tx, ty;
    char path[300];
    td_image8 *flat, *lit, *shadow;
    double sun[3], a = 0.25;
    long checked = 0, shadowed = 0, worst = 0;
    (void)state;
    tile_of(g->geo.x0 + 0.5 * (g->w - 1) * g->geo.dx, g->geo.y0 + 0.5 * (g->h - 1) * g->geo.dy, z, &tx, &ty);
    snprintf(path, sizeof path, "/v1/maps/trinidad-crop/shaded/%d/%d/%d.png?azimuth=315&elevation=45&shadows=false", z,
             tx, ty);
    flat = tile(path);
    td_solar_direction(315.0, 45.0, sun);
    for (int r = 0; r < 256; r++)
        for (int c = 0; c < 256; c++) {
            const uint8_t *p = &flat->px[4 * (r * 256 + c)];
            double lon, lat, fx, fy, h, n[3];
            pixel_lonlat(z, tx, ty, 256, c, r, &lon, &lat);
            if (frame_of(g, lon, lat, &fx, &fy) && td_grid_bilinear(g, fx, fy, &h, n)) {
                double ns = n[0] * sun[0] + n[1] * sun[1] + n[2] * sun[2];
                long want = lround(255.0 * (a + (1 - a) * fmax(0.0, ns)));
                long d = labs((long)p[0] - want);
                worst = d > worst ? d : worst;
                assert_int_equal(p[3], 255);
                checked++;
            }
        }
    printf("shaded: %ld pixels, largest difference %ld levels\n", checked, worst);
    assert_true(checked > 1000 && worst <= 1);
    /* a low sun from the west: shadows on and off */
    snprintf(path, sizeof path, "/v1/maps/trinidad-crop/shaded/%d/%d/%d.png?azimuth=270&elevation=4&shadows=false", z,
             tx, ty);
    lit = tile(path);
    snprintf(path, sizeof path, "/v1/maps/trinidad-crop/shaded/%d/%d/%d.png?azimuth=270&elevation=4", z, tx, ty);
    shadow = tile(path);
    for (int k = 0; k < 256 * 256; k++) {
        assert_true(shadow->px[4 * k] <= lit->px[4 * k]);
        if (shadow->px[4 * k] < lit->px[4 * k]) {
            assert_int_equal(shadow->px[4 * k], lround(255.0 * a));
            shadowed++;
        }
    }
    printf("shadows, sun 4 degrees up in the west: %ld pixels shadowed\n", shadowed);
    assert_true(shadowed > 100);
    td_image_free(flat);
    td_image_free(lit);
    td_image_free(shadow);
    td_grid_free(g);
}

static void expect_status(const th_server *s, const char *path, const char *const *hdr, long status,
                          const char *field)
{
    th_resp r;
    get(s, path, hdr, &r);
    if (r.status != status)
        fail_msg("%s: status %ld, expected %ld: %.*s", path, r.status, status, (int)r.len, r.body);
    if (field) {
        json_t *j = json_loadb(r.body, r.len, 0, NULL), *f;
        assert_non_null(j);
        f = json_object_get(json_object_get(j, "error"), "field");
        if (!json_is_string(f) || strcmp(json_string_value(f), field))
            fail_msg("%s: field %s, expected %s", path, json_is_string(f) ? json_string_value(f) : "null", field);
        json_decref(j);
    }
    th_resp_free(&r);
}

static void test_errors(void **state)
{
    (void)state;
    expect_status(&S, "/v1/maps/trinidad-crop/hillshade/13/1718/3173.png", NULL, 404, "style");
    expect_status(&S, "/v1/maps/nowhere/shaded/13/1718/3173.png", NULL, 404, "dataset");
    expect_status(&S, "/v1/maps/volcano/shaded/13/1718/3173.png", NULL, 404, "dataset");
    expect_status(&S, "/v1/maps/trinidad-crop/shaded/25/0/0.png", NULL, 400, "z");
    expect_status(&S, "/v1/maps/trinidad-crop/shaded/2/4/0.png", NULL, 404, NULL);
    expect_status(&S, "/v1/maps/trinidad-crop/shaded/2/0/0@3x.png", NULL, 404, NULL);
    expect_status(&S, "/v1/maps/trinidad-crop/shaded/2/0/0.jpg", NULL, 404, NULL);
    expect_status(&S, "/v1/maps/trinidad-crop/shaded/13/1718/3173.png?azimuth=400", NULL, 400, "azimuth");
    expect_status(&S, "/v1/maps/trinidad-crop/shaded/13/1718/3173.png?elevation=x", NULL, 400, "elevation");
    expect_status(&S, "/v1/maps/trinidad-crop/shaded/13/1718/3173.png?time=2026-13-01", NULL, 400, "time");
    expect_status(&S, "/v1/maps/trinidad-crop/shaded/13/1718/3173.png?time=2026-06-21T18:00Z&azimuth=3", NULL, 400,
                  "time");
    expect_status(&S, "/v1/maps/trinidad-crop/shaded/13/1718/3173.png?shadows=maybe", NULL, 400, "shadows");
    expect_status(&S, "/v1/maps/trinidad-crop/shaded/13/1718/3173.png?surface=smooth", NULL, 400, "surface");
    expect_status(&S, "/v1/maps/trinidad-crop/shaded/13/1718/3173.png?method=fast", NULL, 400, "method");
    expect_status(&S, "/v1/maps/trinidad-crop/shaded/13/1718/3173.png?colour=red", NULL, 400, "colour");
    expect_status(&S, "/v1/maps/trinidad-crop/terrain-rgb/13/1718/3173.png?azimuth=3", NULL, 400, "azimuth");
    expect_status(&S, "/v1/maps/trinidad-crop/shaded/13/1718/3173.png?lod=-1", NULL, 400, "lod");
    expect_status(&S, "/v1/maps/trinidad-crop/shaded.jsn", NULL, 404, NULL);
    expect_status(&S, "/v1/maps/trinidad-crop", NULL, 404, NULL);
    /* wholly outside the dataset: 404 */
    expect_status(&S, "/v1/maps/trinidad-crop/shaded/13/0/0.png", NULL, 404, NULL);
    expect_status(&S, "/v1/maps/trinidad-crop/terrain-rgb/13/4000/4000.png", NULL, 404, NULL);
}

/* ETag and 304, Cache-Control, @2x, CORS. */
static void test_cache_cors(void **state)
{
    th_resp r;
    char etag[128], hdr[200], v[256];
    const char *path = "/v1/maps/trinidad-crop/shaded/13/1718/3173@2x.png?time=2026-06-21T18:00Z";
    const char *origin[] = {"Origin: http://maps.example:9000", NULL};
    const char *pre[] = {"Origin: http://maps.example:9000", "Access-Control-Request-Method: GET", NULL};
    const char *args[] = {"--demo-dir", "", "--data", dir, "--render-workers", "1", "--cors-origins",
                          "http://a.example, http://maps.example:9000", NULL};
    const char *other[] = {"Origin: http://evil.example", NULL};
    th_server s2;
    int w, h;
    (void)state;
    get(&S, path, origin, &r);
    assert_int_equal(r.status, 200);
    assert_true(th_png_size(&r, &w, &h) && w == 512 && h == 512);
    assert_true(th_header(&r, "ETag", etag, sizeof etag));
    assert_true(strstr(etag, "-v1.") != NULL);
    assert_true(th_header(&r, "Cache-Control", v, sizeof v) && strstr(v, "max-age=86400"));
    assert_true(th_header(&r, "Access-Control-Allow-Origin", v, sizeof v) && !strcmp(v, "*"));
    assert_true(th_header(&r, "Access-Control-Expose-Headers", v, sizeof v) && strstr(v, "ETag") && strstr(v, "X-Terrad-Sun-Bound"));
    th_resp_free(&r);
    snprintf(hdr, sizeof hdr, "If-None-Match: %s", etag);
    {
        const char *inm[] = {hdr, NULL};
        get(&S, path, inm, &r);
        assert_int_equal(r.status, 304);
        th_resp_free(&r);
    }
    /* another sun: another tag */
    get(&S, "/v1/maps/trinidad-crop/shaded/13/1718/3173@2x.png?time=2026-06-21T23:00Z", NULL, &r);
    assert_int_equal(r.status, 200);
    assert_true(th_header(&r, "ETag", v, sizeof v) && strcmp(v, etag));
    th_resp_free(&r);
    /* preflight, TileJSON, render: CORS; admin: never */
    assert_int_equal(th_request(&S, "OPTIONS", "/v1/render", pre, NULL, 0, &r), 0);
    assert_int_equal(r.status, 204);
    assert_true(th_header(&r, "Access-Control-Allow-Methods", v, sizeof v) && strstr(v, "POST"));
    assert_true(th_header(&r, "Access-Control-Allow-Headers", v, sizeof v) && strstr(v, "Content-Type"));
    th_resp_free(&r);
    get(&S, "/v1/maps/trinidad-crop/terrain-rgb.json", origin, &r);
    assert_true(th_header(&r, "Access-Control-Allow-Origin", v, sizeof v));
    th_resp_free(&r);
    get(&S, "/v1/admin/jobs/1", origin, &r);
    assert_false(th_header(&r, "Access-Control-Allow-Origin", v, sizeof v));
    th_resp_free(&r);
    assert_int_equal(th_request(&S, "OPTIONS", "/v1/admin/preload", pre, NULL, 0, &r), 0);
    assert_int_not_equal(r.status, 204);
    assert_false(th_header(&r, "Access-Control-Allow-Origin", v, sizeof v));
    th_resp_free(&r);
    /* a list of origins: the listed one echoed (with Vary), another none */
    assert_int_equal(th_start(&s2, TERRAD_BIN, args, NULL), 0);
    get(&s2, "/v1/maps/trinidad-crop/terrain-rgb.json", origin, &r);
    assert_true(th_header(&r, "Access-Control-Allow-Origin", v, sizeof v) && !strcmp(v, "http://maps.example:9000"));
    assert_true(th_header(&r, "Vary", v, sizeof v) && !strcmp(v, "Origin"));
    th_resp_free(&r);
    get(&s2, "/v1/maps/trinidad-crop/terrain-rgb.json", other, &r);
    assert_int_equal(r.status, 200);
    assert_false(th_header(&r, "Access-Control-Allow-Origin", v, sizeof v));
    th_resp_free(&r);
    assert_int_equal(th_stop(&s2), 0);
    th_forget(&s2);
}

static void test_tilejson(void **state)
{
    th_resp r;
    json_t *j, *b;
    td_grid *g = load("trinidad-crop.f32");
    td_sun sun;
    td_err e = {0};
    double t, lon0 = g->geo.x0, lat0 = g->geo.y0;
    double lon1 = lon0 + (g->w - 1) * g->geo.dx, lat1 = lat0 + (g->h - 1) * g->geo.dy;
    (void)state;
    get(&S, "/v1/maps/trinidad-crop/terrarium.json", NULL, &r);
    assert_int_equal(r.status, 200);
    j = json_loadb(r.body, r.len, 0, NULL);
    assert_non_null(j);
    assert_string_equal(json_string_value(json_object_get(j, "tilejson")), "3.0.0");
    assert_string_equal(json_string_value(json_object_get(j, "encoding")), "terrarium");
    assert_int_equal(json_integer_value(json_object_get(j, "minzoom")), 0);
    /* 3 arc-seconds, 73.6 m east: zoom 11's pixels are 60.5 m at 37.6 N, zoom 10's 121 m */
    assert_int_equal(json_integer_value(json_object_get(j, "maxzoom")), 11);
    b = json_object_get(j, "bounds");
    assert_true(fabs(json_real_value(json_array_get(b, 0)) - lon0) < 1e-6);
    assert_true(fabs(json_real_value(json_array_get(b, 1)) - lat0) < 1e-6);
    assert_true(fabs(json_real_value(json_array_get(b, 2)) - lon1) < 1e-6);
    assert_true(fabs(json_real_value(json_array_get(b, 3)) - lat1) < 1e-6);
    assert_non_null(strstr(json_string_value(json_array_get(json_object_get(j, "tiles"), 0)),
                           "/v1/maps/trinidad-crop/terrarium/{z}/{x}/{y}.png"));
    json_decref(j);
    th_resp_free(&r);
    /* shaded at a time: the template keeps it; the sun is NOAA's at the centre */
    get(&S, "/v1/maps/trinidad-crop/shaded.json?time=2026-06-21T23:00Z&shadows=true", NULL, &r);
    assert_int_equal(r.status, 200);
    j = json_loadb(r.body, r.len, 0, NULL);
    assert_non_null(j);
    assert_null(json_object_get(j, "encoding"));
    assert_non_null(strstr(json_string_value(json_array_get(json_object_get(j, "tiles"), 0)),
                           "shaded/{z}/{x}/{y}.png?time=2026-06-21T23:00Z&shadows=true"));
    assert_int_equal(td_solar_parse_time("2026-06-21T23:00Z", "time", &t, &e), TD_OK);
    assert_int_equal(td_solar_position(0.5 * (lat0 + lat1), 0.5 * (lon0 + lon1), t, &sun, &e), TD_OK);
    b = json_object_get(j, "sun");
    assert_true(fabs(json_real_value(json_object_get(b, "azimuth")) - sun.azimuth_deg) < 1e-6);
    assert_true(fabs(json_real_value(json_object_get(b, "elevation")) - sun.elevation_deg) < 1e-6);
    printf("sun over trinidad-crop at 2026-06-21T23:00Z: azimuth %.3f, elevation %.3f\n", sun.azimuth_deg,
           sun.elevation_deg);
    json_decref(j);
    th_resp_free(&r);
    td_grid_free(g);
}

/* The lon/lat pyramid (N37W105) and the UTM one (trinidad-utm13, warped from it) over the
 * same zoom-14 tile: the heights agree best unshifted, and closely. */
static void test_pyramids_line_up(void **state)
{
    int z = 14, tx, ty, best_dx = 9, best_dy = 9;
    char p1[200], p2[200];
    td_image8 *a, *b;
    double best = INFINITY, at0 = 0;
    (void)state;
    tile_of(-104.42, 37.605, z, &tx, &ty);
    snprintf(p1, sizeof p1, "/v1/maps/N37W105/terrain-rgb/%d/%d/%d.png", z, tx, ty);
    snprintf(p2, sizeof p2, "/v1/maps/trinidad-utm13/terrain-rgb/%d/%d/%d.png", z, tx, ty);
    a = tile(p1);
    b = tile(p2);
    for (int dy = -2; dy <= 2; dy++)
        for (int dx = -2; dx <= 2; dx++) {
            double sum = 0;
            long n = 0;
            for (int r = 2; r < 254; r++)
                for (int c = 2; c < 254; c++) {
                    const uint8_t *pa = &a->px[4 * (r * 256 + c)], *pb = &b->px[4 * ((r + dy) * 256 + c + dx)];
                    if (pa[3] && pb[3]) {
                        sum += fabs(decode(pa, 0) - decode(pb, 0));
                        n++;
                    }
                }
            assert_true(n > 50000);
            if (sum / n < best) {
                best = sum / n;
                best_dx = dx;
                best_dy = dy;
            }
            if (!dx && !dy)
                at0 = sum / n;
        }
    printf("lon/lat against UTM, zoom %d: mean |difference| %.3f m unshifted; best shift (%d, %d)\n", z, at0, best_dx,
           best_dy);
    assert_int_equal(best_dx, 0);
    assert_int_equal(best_dy, 0);
    assert_true(at0 < 2.0);
    td_image_free(a);
    td_image_free(b);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_encodings),
        cmocka_unit_test(test_shaded),
        cmocka_unit_test(test_errors),
        cmocka_unit_test(test_cache_cors),
        cmocka_unit_test(test_tilejson),
        cmocka_unit_test(test_pyramids_line_up),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
