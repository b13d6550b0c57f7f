/* test_viewshed_http.c: POST /v1/viewshed and POST /v1/los over real HTTP (libcurl),
 * against the built-in demo data: the PNG is the dataset's grid, pixel for pixel what
 * td_viewshed computes in process on the same file (so the service runs the same code),
 * its counts are the JSON format's, cumulative observers count, lon/lat observers on the
 * georeferenced trinidad, the line of sight against td_los, and every refusal a 4xx
 * naming its field. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <cmocka.h>
#include <curl/curl.h>
#include <jansson.h>

#include "accel.h"
#include "dem.h"
#include "harness.h"
#include "image.h"
#include "viewshed.h"

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

static void post(const char *path, const char *body, th_resp *r)
{
    assert_int_equal(th_request(&S, "POST", path, JSON_CT, body, strlen(body), r), 0);
}

static json_t *body_json(const th_resp *r)
{
    json_t *j = json_loadb(r->body, r->len, 0, NULL);
    if (!j)
        fail_msg("not JSON: %.*s", (int)r->len, r->body);
    return j;
}

static void expect_error(const char *path, const char *body, long status, const char *field)
{
    th_resp r;
    json_t *j, *e;
    post(path, body, &r);
    if (r.status != status)
        fail_msg("%s %s: status %ld, expected %ld: %.*s", path, body, r.status, status, (int)r.len, r.body);
    j = body_json(&r);
    e = json_object_get(j, "error");
    assert_non_null(e);
    if (field)
        assert_string_equal(json_string_value(json_object_get(e, "field")), field);
    json_decref(j);
    th_resp_free(&r);
}

/* The demo's volcano, loaded here as terrad loads it, and its viewshed in process. */
static uint8_t *local_viewshed(const td_vs_point *p, int n, double h, double maxd, int32_t *w,
                               int32_t *hh)
{
    td_dem_opts o;
    td_grid *g = NULL;
    td_view v;
    td_viewshed_opts vo;
    td_viewshed_stats st;
    uint8_t *out;
    td_dem_opts_default(&o);
    assert_int_equal(td_dem_load(TERRAD_DATA_DIR "/volcano/volcano.asc", &o, &g, NULL), TD_OK);
    v.grid = g;
    v.accel = NULL;
    td_viewshed_opts_default(&vo);
    vo.obs = p;
    vo.nobs = n;
    vo.height = h;
    vo.max_distance = maxd;
    vo.method = TD_METHOD_INCREMENTAL; /* the answer does not depend on the method */
    out = malloc((size_t)g->w * g->h);
    assert_non_null(out);
    assert_int_equal(td_viewshed(&v, &vo, out, &st, NULL), TD_OK);
    if (n == 1)
        td_viewshed_gray(out, (size_t)g->w * g->h, out);
    *w = g->w;
    *hh = g->h;
    td_grid_free(g);
    return out;
}

/* The PNG's gray values (its first channel, decoded to RGB). */
static uint8_t *png_gray(const th_resp *r, int32_t w, int32_t h)
{
    td_image8 *img = NULL;
    uint8_t *px = malloc((size_t)w * h);
    assert_non_null(px);
    assert_int_equal(td_image_decode((const uint8_t *)r->body, r->len, 3, 1u << 24, &img, NULL), TD_OK);
    assert_int_equal(img->width, w);
    assert_int_equal(img->height, h);
    for (size_t k = 0; k < (size_t)w * h; k++)
        px[k] = img->px[3 * k];
    td_image_free(img);
    return px;
}

static void test_viewshed_png_and_json(void **state)
{
    th_resp r;
    td_vs_point p = {300, 430};
    int32_t w, h;
    uint8_t *want = local_viewshed(&p, 1, 2.0, 250.0, &w, &h), *got;
    uint64_t n255 = 0, n128 = 0;
    json_t *j;
    char v[64];
    (void)state;
    post("/v1/viewshed", "{\"dataset\":\"volcano\",\"observer\":{\"x\":300,\"y\":430},\"height\":2,"
                         "\"max_distance\":250}", &r);
    assert_int_equal(r.status, 200);
    assert_true(th_header(&r, "Content-Type", v, sizeof v) && !strcmp(v, "image/png"));
    assert_true(th_header(&r, "Server-Timing", v, sizeof v));
    got = png_gray(&r, w, h);
    for (size_t k = 0; k < (size_t)w * h; k++) {
        assert_int_equal(got[k], want[k]);
        n255 += got[k] == 255;
        n128 += got[k] == 128;
    }
    assert_true(n255 > 0 && n128 > 0 && n255 + n128 < (uint64_t)w * h); /* seen, hidden, outside */
    th_resp_free(&r);
    post("/v1/viewshed", "{\"dataset\":\"volcano\",\"observer\":{\"x\":300,\"y\":430},\"height\":2,"
                         "\"max_distance\":250,\"format\":\"json\"}", &r);
    assert_int_equal(r.status, 200);
    j = body_json(&r);
    assert_int_equal(json_integer_value(json_object_get(j, "visible")), (json_int_t)n255);
    assert_int_equal(json_integer_value(json_object_get(j, "outside")), (json_int_t)n128);
    assert_int_equal(json_integer_value(json_object_get(j, "samples")), (json_int_t)w * h);
    assert_true(fabs(json_real_value(json_object_get(j, "visible_area_m2")) - 100.0 * (double)n255) < 1e-6);
    assert_non_null(json_object_get(json_object_get(j, "timings_ms"), "trace"));
    json_decref(j);
    th_resp_free(&r);
    free(want);
    free(got);
}

static void test_viewshed_cumulative(void **state)
{
    th_resp r;
    td_vs_point p[3] = {{300, 430}, {310, 440}, {500, 800}};
    int32_t w, h;
    uint8_t *want = local_viewshed(p, 3, 5.0, INFINITY, &w, &h), *got;
    json_t *j, *seen;
    uint64_t count[4] = {0};
    (void)state;
    post("/v1/viewshed", "{\"dataset\":\"volcano\",\"observers\":[{\"x\":300,\"y\":430},{\"x\":310,\"y\":440},"
                         "{\"x\":500,\"y\":800}],\"height\":5}", &r);
    assert_int_equal(r.status, 200);
    got = png_gray(&r, w, h);
    for (size_t k = 0; k < (size_t)w * h; k++) {
        assert_int_equal(got[k], want[k]);
        assert_true(got[k] <= 3);
        count[got[k]]++;
    }
    th_resp_free(&r);
    post("/v1/viewshed", "{\"dataset\":\"volcano\",\"observers\":[{\"x\":300,\"y\":430},{\"x\":310,\"y\":440},"
                         "{\"x\":500,\"y\":800}],\"height\":5,\"format\":\"json\",\"method\":\"parametric\"}", &r);
    assert_int_equal(r.status, 200);
    j = body_json(&r);
    seen = json_object_get(j, "seen_by");
    assert_int_equal(json_array_size(seen), 4);
    for (int k = 0; k < 4; k++)
        assert_int_equal(json_integer_value(json_array_get(seen, (size_t)k)), (json_int_t)count[k]);
    assert_true(count[2] + count[3] > 0);
    json_decref(j);
    th_resp_free(&r);
    free(want);
    free(got);
}

/* trinidad is lon/lat: an observer by lon/lat near Blanca Peak, with curvature. */
static void test_viewshed_lonlat_curvature(void **state)
{
    th_resp r;
    json_t *j;
    (void)state;
    post("/v1/viewshed", "{\"dataset\":\"trinidad\",\"observer\":{\"lon\":-105.4856,\"lat\":37.5775},"
                         "\"height\":2,\"curvature\":{\"k\":0.13},\"surface\":\"triangle\",\"format\":\"json\"}", &r);
    assert_int_equal(r.status, 200);
    j = body_json(&r);
    assert_true(json_is_true(json_object_get(j, "curvature")));
    assert_int_equal(json_integer_value(json_object_get(j, "samples")), 600 * 500);
    assert_true(json_integer_value(json_object_get(j, "visible")) > 1000); /* from the summit */
    json_decref(j);
    th_resp_free(&r);
}

static void test_viewshed_refusals(void **state)
{
    char many[8192];
    size_t n;
    th_resp r;
    (void)state;
    expect_error("/v1/viewshed", "{\"dataset\":\"volcano\",\"observer\":{\"x\":-1,\"y\":10},\"height\":2}", 400, "observer");
    expect_error("/v1/viewshed", "{\"dataset\":\"volcano\",\"observers\":[{\"x\":1,\"y\":1},{\"x\":1e6,\"y\":1}],\"height\":2}",
                 400, "observers[1]");
    expect_error("/v1/viewshed", "{\"dataset\":\"volcano\",\"observer\":{\"x\":1,\"y\":1},\"height\":-2}", 400, "height");
    expect_error("/v1/viewshed", "{\"dataset\":\"volcano\",\"observer\":{\"x\":1,\"y\":1}}", 400, "height");
    expect_error("/v1/viewshed", "{\"dataset\":\"volcano\",\"observer\":{\"x\":1,\"y\":1},\"height\":2,\"target_height\":-1}",
                 400, "target_height");
    expect_error("/v1/viewshed", "{\"dataset\":\"volcano\",\"observer\":{\"x\":1,\"y\":1},\"height\":2,\"max_distance\":0}",
                 400, "max_distance");
    expect_error("/v1/viewshed", "{\"dataset\":\"volcano\",\"observer\":{\"x\":1,\"y\":1},\"height\":2,\"max_distance\":-5}",
                 400, "max_distance");
    expect_error("/v1/viewshed", "{\"dataset\":\"volcano\",\"observer\":{\"x\":1,\"y\":1},\"height\":2,\"format\":\"gif\"}",
                 400, "format");
    expect_error("/v1/viewshed", "{\"dataset\":\"volcano\",\"observer\":{\"x\":1,\"y\":1},\"height\":2,\"bogus\":1}", 400, "bogus");
    expect_error("/v1/viewshed", "{\"dataset\":\"volcano\",\"observer\":{\"x\":1,\"y\":1,\"z\":3},\"height\":2}", 400,
                 "observer.z");
    expect_error("/v1/viewshed", "{\"dataset\":\"volcano\",\"observer\":{\"lon\":1,\"lat\":1},\"height\":2}", 400, "observer");
    expect_error("/v1/viewshed", "{\"dataset\":\"volcano\",\"observer\":{\"x\":1,\"y\":1,\"lon\":1},\"height\":2}", 400,
                 "observer");
    expect_error("/v1/viewshed", "{\"dataset\":\"volcano\",\"observer\":{\"x\":1,\"y\":1},\"height\":2,\"curvature\":{\"k\":3}}",
                 400, "curvature.k");
    expect_error("/v1/viewshed", "{\"dataset\":\"volcano\",\"observer\":{\"x\":1,\"y\":1},\"height\":2,\"surface\":\"smooth\"}",
                 400, "surface");
    expect_error("/v1/viewshed", "{\"dataset\":\"nowhere\",\"observer\":{\"x\":1,\"y\":1},\"height\":2}", 404, "dataset");
    expect_error("/v1/viewshed", "[1,2]", 400, NULL);
    n = (size_t)snprintf(many, sizeof many, "{\"dataset\":\"volcano\",\"height\":2,\"observers\":[");
    for (int k = 0; k < 65; k++)
        n += (size_t)snprintf(many + n, sizeof many - n, "%s{\"x\":%d,\"y\":10}", k ? "," : "", 10 + k);
    snprintf(many + n, sizeof many - n, "]}");
    expect_error("/v1/viewshed", many, 400, "observers");
    assert_int_equal(th_request(&S, "POST", "/v1/viewshed", NULL, "{}", 2, &r), 0);
    assert_int_equal(r.status, 415);
    th_resp_free(&r);
    assert_int_equal(th_request(&S, "GET", "/v1/viewshed", NULL, NULL, 0, &r), 0);
    assert_int_equal(r.status, 405);
    th_resp_free(&r);
}

/* Line of sight: the same answer as td_los in process, a profile, refusals. */
static void test_los(void **state)
{
    td_dem_opts o;
    td_grid *g = NULL;
    td_view v;
    td_los_opts lo;
    td_los_result *want = malloc(sizeof *want);
    th_resp r;
    json_t *j, *b;
    (void)state;
    assert_non_null(want);
    td_dem_opts_default(&o);
    assert_int_equal(td_dem_load(TERRAD_DATA_DIR "/volcano/volcano.asc", &o, &g, NULL), TD_OK);
    v.grid = g;
    v.accel = NULL;
    td_los_opts_default(&lo);
    lo.a = (td_vs_point){50, 50};
    lo.b = (td_vs_point){550, 800};
    lo.height_a = 1.5;
    lo.height_b = 1.5;
    assert_int_equal(td_los(&v, &lo, want, NULL), TD_OK);
    post("/v1/los", "{\"dataset\":\"volcano\",\"from\":{\"x\":50,\"y\":50,\"height\":1.5},"
                    "\"to\":{\"x\":550,\"y\":800,\"height\":1.5}}", &r);
    assert_int_equal(r.status, 200);
    j = body_json(&r);
    assert_int_equal(json_is_true(json_object_get(j, "visible")), want->visible);
    assert_false(want->visible); /* across the crater's rim */
    b = json_object_get(j, "blocked_at");
    assert_true(fabs(json_real_value(json_object_get(b, "distance")) - want->block_s) < 1e-6);
    assert_true(fabs(json_real_value(json_object_get(json_object_get(b, "point"), "z")) - want->block[2]) < 1e-6);
    assert_int_equal(json_array_size(json_object_get(j, "profile")), (size_t)want->nprofile);
    json_decref(j);
    th_resp_free(&r);
    post("/v1/los", "{\"dataset\":\"volcano\",\"from\":{\"x\":50,\"y\":50,\"height\":1.5},"
                    "\"to\":{\"x\":60,\"y\":50,\"height\":1.5}}", &r);
    assert_int_equal(r.status, 200);
    j = body_json(&r);
    assert_true(json_is_null(json_object_get(j, "blocked_at")) == json_is_true(json_object_get(j, "visible")));
    json_decref(j);
    th_resp_free(&r);
    expect_error("/v1/los", "{\"dataset\":\"volcano\",\"from\":{\"x\":50,\"y\":50},\"to\":{\"x\":5000,\"y\":50}}", 400, "to");
    expect_error("/v1/los", "{\"dataset\":\"volcano\",\"from\":{\"x\":50,\"y\":50,\"height\":-1},\"to\":{\"x\":60,\"y\":50}}",
                 400, "from.height");
    expect_error("/v1/los", "{\"dataset\":\"volcano\",\"from\":{\"x\":50,\"y\":50}}", 400, "to");
    free(want);
    td_grid_free(g);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_viewshed_png_and_json),
        cmocka_unit_test(test_viewshed_cumulative),
        cmocka_unit_test(test_viewshed_lonlat_curvature),
        cmocka_unit_test(test_viewshed_refusals),
        cmocka_unit_test(test_los),
    };
    int rc;
    curl_global_init(CURL_GLOBAL_ALL);
    rc = cmocka_run_group_tests_name("viewshed and line of sight over HTTP", tests, setup, teardown);
    curl_global_cleanup();
    return rc;
}
