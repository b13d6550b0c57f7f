/* test_pano_http.c: POST /v1/horizon and POST /v1/peaks over real HTTP (server/pano.c),
 * on the built-in demo data: the skyline of a rendered 360-degree panorama (POST
 * /v1/render, cylindrical, depth32f) matches /v1/horizon's to a pixel in every column;
 * the sun rises over trinidad's terrain later than the almanac says, its upper limb on
 * the skyline at that instant (NOAA position in process, core/solar); every summit
 * /v1/peaks lists is where a pick of its pixel lands, summits in the picture it leaves out
 * are fewer than the summits; the summits are cached; every refusal names its field. (That
 * a summit behind a nearer one is left out is test_peaks.c's, on cones whose answer is
 * known.) */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <cmocka.h>
#include <jansson.h>

#include "harness.h"
#include "solar.h"

#define DEG (M_PI / 180.0)

static th_server S;
static const char *const JSON_CT[] = {"Content-Type: application/json", NULL};

static int setup(void **state)
{
    const char *args[] = {"--demo-dir", TERRAD_DATA_DIR, "--render-workers", "2", NULL};
    (void)state;
    return th_start(&S, TERRAD_BIN, args, NULL);
}

static int teardown(void **state)
{
    int rc = th_stop(&S);
    (void)state;
    if (rc == 0)
        th_forget(&S);
    return rc;
}

static json_t *post_json(const char *path, const char *body, long status)
{
    th_resp r;
    json_t *j;
    assert_int_equal(th_request(&S, "POST", path, JSON_CT, body, strlen(body), &r), 0);
    if (r.status != status)
        fail_msg("%s %s: status %ld, expected %ld: %.*s", path, body, r.status, status, (int)r.len, r.body);
    j = json_loadb(r.body, r.len, 0, NULL);
    if (!j)
        fail_msg("not JSON: %.*s", (int)r.len, r.body);
    th_resp_free(&r);
    return j;
}

static double num(json_t *o, const char *key)
{
    json_t *v = json_object_get(o, key);
    if (!json_is_number(v))
        fail_msg("%s is not a number", key);
    return json_number_value(v);
}

static void expect_error(const char *path, const char *body, long status, const char *field)
{
    json_t *j = post_json(path, body, status), *e = json_object_get(j, "error");
    assert_non_null(e);
    if (field)
        assert_string_equal(json_string_value(json_object_get(e, "field")), field);
    json_decref(j);
}

/* The panorama's first terrain row per column against the skyline's row: every column
 * within a pixel; returns how many columns agree exactly. Both bend their rays with
 * curvature on, but the render only the rays long enough to move a pixel (render.c), the
 * skyline every ray, so there a skyline a fraction of a pixel above a row's centre may
 * show one row lower. */
static int render_vs_horizon(int curvature)
{
    enum { W = 720, H = 240 };
    char body[1024];
    th_resp r;
    int exact = 0;
    snprintf(body, sizeof body,
             "{\"dataset\": \"trinidad\", \"observer\": {\"x\": 21000, \"y\": 17500}, \"height\": 5, "
             "\"step_deg\": 0.5, \"curvature\": %s}",
             curvature ? "true" : "false");
    json_t *hz = post_json("/v1/horizon", body, 200);
    json_t *obs = json_object_get(hz, "observer"), *sky = json_object_get(hz, "skyline");
    assert_int_equal(json_array_size(sky), W);
    snprintf(body, sizeof body,
             "{\"dataset\": \"trinidad\", \"camera\": {\"projection\": \"cylindrical\", \"position\": "
             "{\"x\": %.17g, \"y\": %.17g, \"z\": %.17g}, \"heading\": 179.75, \"fov\": 360}, "
             "\"image\": {\"width\": %d, \"height\": %d, \"format\": \"depth32f\"}%s}",
             num(obs, "x"), num(obs, "y"), num(obs, "z"), W, H,
             curvature ? "" : ", \"effects\": {\"curvature\": false}");
    assert_int_equal(th_request(&S, "POST", "/v1/render", JSON_CT, body, strlen(body), &r), 0);
    assert_int_equal(r.status, 200);
    assert_int_equal(r.len, (size_t)W * H * 4);
    const float *depth = (const float *)r.body;
    double f = W / (2.0 * M_PI), tan_top = 0.5 * H / f; /* camera.h: fov_v from the aspect */
    for (int x = 0; x < W; x++) {
        json_t *pt = json_array_get(sky, (size_t)x);
        int row = 0;
        assert_float_equal(num(pt, "azimuth"), 0.5 * x, 1e-9);
        while (row < H && !isfinite(depth[row * W + x]))
            row++;
        int want = (int)ceil(f * (tan_top - tan(num(pt, "elevation") * DEG)) - 0.5);
        if (abs(row - want) > 1)
            fail_msg("column %d: terrain from row %d, skyline row %d", x, row, want);
        exact += row == want;
    }
    th_resp_free(&r);
    json_decref(hz);
    return exact;
}

static void test_render_matches_horizon(void **state)
{
    (void)state;
    /* curvature as the panorama's default: to a pixel everywhere, mostly exact */
    assert_true(render_vs_horizon(1) >= 720 * 3 / 4);
    /* straight rays in both: the same rays, the same rows */
    assert_int_equal(render_vs_horizon(0), 720);
}

/* Sunrise on the solstice from a valley floor: later than the almanac's, the upper limb
 * on the skyline then; the path's samples seen exactly inside the day's stretches. */
static void test_sun(void **state)
{
    td_sun p;
    td_err err = {0};
    double t;
    (void)state;
    json_t *hz = post_json("/v1/horizon",
                           "{\"dataset\": \"trinidad\", \"observer\": {\"lon\": -105.5, \"lat\": 37.52}, "
                           "\"sun\": {\"date\": \"2026-06-21\"}}",
                           200);
    json_t *obs = json_object_get(hz, "observer"), *sun = json_object_get(hz, "sun");
    json_t *rise = json_object_get(sun, "sunrise");
    double lon = num(obs, "lon"), lat = num(obs, "lat");
    assert_float_equal(lon, -105.5, 1e-6);
    double astro, terrain;
    assert_int_equal(td_solar_parse_time(json_string_value(json_object_get(rise, "astronomical")), "a", &astro, &err),
                     TD_OK);
    assert_int_equal(td_solar_parse_time(json_string_value(json_object_get(rise, "terrain")), "t", &terrain, &err),
                     TD_OK);
    assert_true(terrain > astro);
    assert_float_equal(num(rise, "delay_s"), (terrain - astro), 1.0);
    /* at the terrain's sunrise the upper limb is on the skyline (to a second's climb) */
    assert_int_equal(td_solar_position(lat, lon, terrain, &p, &err), TD_OK);
    json_t *sky = json_object_get(hz, "skyline");
    double step = num(hz, "step_deg"), f = p.azimuth_deg / step;
    size_t k0 = (size_t)floor(f), k1 = (k0 + 1) % json_array_size(sky);
    double e = (1 - (f - k0)) * num(json_array_get(sky, k0), "elevation") +
               (f - k0) * num(json_array_get(sky, k1), "elevation");
    assert_true(e > 0.5); /* a valley: the eastern skyline is well above the horizon */
    assert_float_equal(p.elevation_deg + p.refraction_deg + 0.2667, e, 0.01);
    /* the path */
    json_t *path = json_object_get(sun, "path");
    assert_int_equal(json_array_size(path), 289);
    for (size_t k = 0; k < json_array_size(path); k++) {
        json_t *s = json_array_get(path, k);
        assert_int_equal(td_solar_parse_time(json_string_value(json_object_get(s, "time")), "p", &t, &err), TD_OK);
        int in = 0;
        json_t *iv = json_object_get(sun, "intervals");
        for (size_t i = 0; i < json_array_size(iv); i++) {
            double a, b;
            td_solar_parse_time(json_string_value(json_array_get(json_array_get(iv, i), 0)), "a", &a, &err);
            td_solar_parse_time(json_string_value(json_array_get(json_array_get(iv, i), 1)), "b", &b, &err);
            in |= t >= a - 1 && t <= b + 1;
        }
        assert_int_equal(json_is_true(json_object_get(s, "seen")), in);
    }
    json_decref(hz);
}

/* Peaks of a panorama: each listed summit is where its pixel's pick lands; a summit in the
 * picture that is not listed is hidden (its pick lands well short of it). */
static void test_peaks(void **state)
{
    static const char *cam = "\"camera\": {\"projection\": \"cylindrical\", \"position\": {\"x\": 30000, "
                             "\"y\": 10000, \"agl\": 2}, \"fov\": 360, \"pitch\": 3}, \"image\": {\"width\": 1440, "
                             "\"height\": 300}";
    char body[1024], pick[65536];
    (void)state;
    snprintf(body, sizeof body, "{\"dataset\": \"trinidad\", %s, \"min_prominence\": 0, \"max_peaks\": 1000}", cam);
    json_t *pk = post_json("/v1/peaks", body, 200);
    json_t *all = post_json("/v1/peaks", body, 200);
    assert_true(json_is_true(json_object_get(all, "cached")));
    json_t *list = json_object_get(pk, "peaks");
    size_t n = json_array_size(list);
    assert_true(n > 5);
    assert_true(n < (size_t)num(pk, "summits")); /* some are hidden */
    /* listed: the pick of the pixel lands on the summit (within 1.5 cell diagonals) */
    size_t len = (size_t)snprintf(pick, sizeof pick, "{\"dataset\": \"trinidad\", %s, \"pick\": [", cam);
    size_t np = n < 200 ? n : 200;
    for (size_t k = 0; k < np; k++)
        len += (size_t)snprintf(pick + len, sizeof pick - len, "%s[%.17g, %.17g]", k ? ", " : "",
                                num(json_array_get(list, k), "px"), num(json_array_get(list, k), "py"));
    snprintf(pick + len, sizeof pick - len, "]}");
    json_t *pj = post_json("/v1/pick", pick, 200);
    json_t *picks = json_object_get(pj, "picks");
    assert_int_equal(json_array_size(picks), np);
    for (size_t k = 0; k < np; k++) {
        json_t *p = json_array_get(picks, k), *s = json_array_get(list, k), *pt = json_object_get(p, "point");
        if (json_is_true(json_object_get(p, "hit"))) {
            double d = hypot(num(pt, "x") - num(s, "x"), num(pt, "y") - num(s, "y"));
            double ds = num(s, "distance");
            /* the ray ends at the summit or passes it: never well short of it */
            double reach = hypot(num(pt, "x") - 30000, num(pt, "y") - 10000);
            assert_true(d < 1.5 * hypot(73.6, 92.5) || reach > ds);
        }
    }
    /* min_prominence filters: the default of 100 m lists fewer */
    snprintf(body, sizeof body, "{\"dataset\": \"trinidad\", %s}", cam);
    json_t *p100 = post_json("/v1/peaks", body, 200);
    assert_true(json_array_size(json_object_get(p100, "peaks")) < n);
    for (size_t k = 0; k < json_array_size(json_object_get(p100, "peaks")); k++)
        assert_true(num(json_array_get(json_object_get(p100, "peaks"), k), "prominence") >= 100.0);
    json_decref(p100);
    json_decref(pj);
    json_decref(all);
    json_decref(pk);
}

static void test_refusals(void **state)
{
    (void)state;
    expect_error("/v1/horizon", "{\"dataset\": \"trinidad\"}", 400, "observer");
    expect_error("/v1/horizon", "{\"dataset\": \"trinidad\", \"observer\": {\"x\": 1, \"y\": 2}, \"bogus\": 1}", 400,
                 "bogus");
    expect_error("/v1/horizon", "{\"dataset\": \"trinidad\", \"observer\": {\"x\": 1, \"y\": 2}, \"step_deg\": 0}",
                 400, "step_deg");
    expect_error("/v1/horizon", "{\"dataset\": \"trinidad\", \"observer\": {\"x\": -50, \"y\": 2}}", 400, "observer");
    expect_error("/v1/horizon",
                 "{\"dataset\": \"trinidad\", \"observer\": {\"x\": 10, \"y\": 20}, \"sun\": {\"date\": \"2026-13-01\"}}",
                 400, "sun.date");
    expect_error("/v1/horizon",
                 "{\"dataset\": \"volcano\", \"observer\": {\"x\": 100, \"y\": 200}, \"sun\": {\"date\": \"2026-06-01\"}}",
                 400, "sun");
    expect_error("/v1/horizon", "{\"dataset\": \"nope\", \"observer\": {\"x\": 1, \"y\": 2}}", 404, "dataset");
    expect_error("/v1/peaks",
                 "{\"dataset\": \"trinidad\", \"camera\": {\"position\": {\"x\": 1, \"y\": 2, \"z\": 5000}}, "
                 "\"min_prominence\": -1}",
                 400, "min_prominence");
    expect_error("/v1/peaks", "{\"dataset\": \"trinidad\", \"camera\": {\"position\": {\"x\": 1, \"y\": 2, \"z\": 5000}, "
                              "\"projection\": \"cylindrical\", \"fov\": 400}}",
                 400, "camera.fov");
    expect_error("/v1/render", "{\"dataset\": \"trinidad\", \"camera\": {\"position\": {\"x\": 1, \"y\": 2, \"z\": 5000}, "
                               "\"fov_v\": 30}}",
                 400, "camera.fov_v");
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_render_matches_horizon),
        cmocka_unit_test(test_sun),
        cmocka_unit_test(test_peaks),
        cmocka_unit_test(test_refusals),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
