/* test_pagein_http.c: the page-in deadline (terrad serve --pagein-timeout, server/pagein.h).
 * A render whose worker waits for pages longer than the deadline is answered 503 with the
 * code pagein_timeout, a Retry-After header and its wait in Server-Timing; the same wait
 * without a deadline is answered 200. The wait is the server's fault injection
 * (TERRAD_FAULT_PAGEIN_STALL_MS: every render's worker first sleeps, as on a slow read),
 * which the watchdog measures from the worker thread's schedstat as it measures a real
 * page-in: a real one on this machine's disk and a 200 x 150 grid lasts well under a
 * watchdog tick, too short to test against a deadline without a flaky timing. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include <cmocka.h>
#include <jansson.h>

#include "harness.h"

#define SCENE                                                                                    \
    "{\"dataset\":\"good\",\"camera\":{\"position\":{\"x\":7000,\"y\":-2000,\"z\":2600},"        \
    "\"heading\":0,\"pitch\":-10,\"fov\":60},\"image\":{\"width\":80,\"height\":50}}"

static char root[256], data[300];
static th_server bounded, unbounded;

static int setup(void **state)
{
    const char *a1[] = {"--demo-dir", "", "--data", data, "--preload", "none", "--pagein-timeout", "0.05", NULL};
    const char *a0[] = {"--demo-dir", "", "--data", data, "--preload", "none", "--pagein-timeout", "0", NULL};
    const char *env[] = {"TERRAD_FAULT_PAGEIN_STALL_MS=400", NULL};
    (void)state;
    snprintf(root, sizeof root, "/tmp/td-pagein-http-XXXXXX");
    if (!mkdtemp(root))
        return -1;
    snprintf(data, sizeof data, "%s/data", root);
    if (th_sh("mkdir -p '%s' && '%s' prepare '%s/trinidad-crop.f32' '%s/good' --tile-size 64 --quiet >/dev/null", data,
           TERRAD_BIN, TERRAD_TEST_DATA, data))
        return -1;
    if (th_start(&bounded, TERRAD_BIN, a1, env) || th_start(&unbounded, TERRAD_BIN, a0, env))
        return -1;
    return 0;
}

static int teardown(void **state)
{
    (void)state;
    th_stop(&bounded);
    th_stop(&unbounded);
    th_sh("rm -rf '%s'", root);
    return 0;
}

/* Waits (at most 30 s) until the prepared dataset is checked and served. */
static void wait_served(const th_server *s)
{
    struct timespec nap = {0, 50 * 1000 * 1000};
    for (int k = 0; k < 600; k++) {
        th_resp r;
        int ok;
        assert_int_equal(th_request(s, "GET", "/v1/datasets/good", NULL, NULL, 0, &r), 0);
        ok = r.status == 200 && strstr(r.body, "\"state\":\"ok\"") != NULL;
        th_resp_free(&r);
        if (ok)
            return;
        nanosleep(&nap, NULL);
    }
    fail_msg("dataset 'good' not checked in 30 s");
}

static void render(const th_server *s, th_resp *r)
{
    const char *h[] = {"Content-Type: application/json", NULL};
    assert_int_equal(th_request(s, "POST", "/v1/render", h, SCENE, strlen(SCENE), r), 0);
}

static void test_over_deadline_503(void **state)
{
    th_resp r;
    char v[512];
    json_t *j;
    (void)state;
    wait_served(&bounded);
    render(&bounded, &r);
    assert_int_equal(r.status, 503);
    j = json_loadb(r.body, r.len, 0, NULL);
    assert_non_null(j);
    assert_string_equal(json_string_value(json_object_get(json_object_get(j, "error"), "code")), "pagein_timeout");
    json_decref(j);
    assert_int_equal(th_header(&r, "Retry-After", v, sizeof v), 1);
    assert_string_equal(v, "1");
    /* the wait (at least the stall's 0.4 s: the render was cut at its first block after
       the deadline, and the stall came before it) is in Server-Timing */
    assert_int_equal(th_header(&r, "Server-Timing", v, sizeof v), 1);
    {
        const char *p = strstr(v, "pagein;dur=");
        if (!p || !strstr(v, "over --pagein-timeout"))
            fail_msg("Server-Timing: %s", v);
        assert_true(strtod(p + strlen("pagein;dur="), NULL) >= 350.0);
    }
    th_resp_free(&r);
}

static void test_no_deadline_200(void **state)
{
    th_resp r;
    char v[512];
    (void)state;
    wait_served(&unbounded);
    render(&unbounded, &r);
    assert_int_equal(r.status, 200);
    assert_int_equal(th_header(&r, "Server-Timing", v, sizeof v), 1);
    if (strstr(v, "over --pagein-timeout"))
        fail_msg("Server-Timing: %s", v);
    th_resp_free(&r);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_over_deadline_503),
        cmocka_unit_test(test_no_deadline_200),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
