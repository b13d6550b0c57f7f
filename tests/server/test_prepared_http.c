/* test_prepared_http.c: prepared datasets served by a live terrad (`terrad prepare`, then
 * `terrad serve --data`). A prepared dataset answers the same picture, byte for byte, as its
 * source file served beside it (every method and surface, shadows and smooth normals: the
 * render path reads heights.blk, with blocks of 32 (the default) and of 8 cells), with levels of detail too; it is listed with its check state and its mapped heights are
 * in /metrics; edits are refused; a corrupted chunk, a truncated heights file and an
 * unfinished prepare are never served, and the log names the file and the reason. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include <cmocka.h>
#include <jansson.h>

#include "harness.h"

#define TOKEN "prep-token-0123456789"
#define SCENE                                                                                    \
    "{\"dataset\":\"%s\",\"camera\":{\"position\":{\"x\":7000,\"y\":-2000,\"z\":2600},"          \
    "\"heading\":0,\"pitch\":-10,\"fov\":60},\"image\":{\"width\":160,\"height\":100},"           \
    "\"quality\":{\"method\":\"%s\",\"surface\":\"%s\",\"lod\":%s,\"smooth_normals\":true},"                    \
    "\"effects\":{\"sun\":{\"azimuth\":300,\"elevation\":20},\"shadows\":true,\"sky\":true}}"

static char root[256], data[300];
static th_server srv;

/* Flips one byte of dir/name at `at`. */
static void flip(const char *dir, const char *name, long at)
{
    char p[600];
    FILE *f;
    int c;
    snprintf(p, sizeof p, "%s/%s/%s", data, dir, name);
    f = fopen(p, "r+b");
    assert_non_null(f);
    fseek(f, at, SEEK_SET);
    c = fgetc(f);
    fseek(f, at, SEEK_SET);
    fputc(c ^ 0x40, f);
    fclose(f);
}

static int setup(void **state)
{
    const char *src = TERRAD_TEST_DATA "/trinidad-crop";
    const char *args[] = {"--demo-dir", "", "--data", data, "--preload", "none", NULL};
    const char *env[] = {"TERRAD_ADMIN_TOKEN=" TOKEN, NULL};
    (void)state;
    snprintf(root, sizeof root, "/tmp/td-prep-http-XXXXXX");
    if (!mkdtemp(root))
        return -1;
    snprintf(data, sizeof data, "%s/data", root);
    if (th_sh("mkdir -p '%s' && cp '%s.f32' '%s/crop.f32' && cp '%s.json' '%s/crop.json'", data, src, data, src,
           data))
        return -1;
    /* good, bad (a chunk corrupted), short (truncated), half (an unfinished prepare) */
    if (th_sh("for d in good bad short badlod badblk badacc cold; do '%s' prepare '%s/crop.f32' '%s/'\"$d\" --chunk-rows 16 "
           "--tile-size 64 --quiet >/dev/null || exit 1; done", TERRAD_BIN, data, data))
        return -1;
    if (th_sh("'%s' prepare '%s/crop.f32' '%s/good8' --chunk-rows 16 --tile-size 64 --block-size 8 --quiet >/dev/null",
           TERRAD_BIN, data, data))
        return -1;
    if (th_sh("'%s' prepare '%s/crop.f32' '%s/half' --chunk-rows 16 --stop-after 2 --quiet >/dev/null 2>&1; "
           "test -f '%s/half/prepare.state'", TERRAD_BIN, data, data, data))
        return -1;
    flip("bad", "heights.f32", (long)(120 * 200 + 3) * 4 + 1); /* south row 120: file row 29, chunk 1 */
    flip("badlod", "lod1.f32", (long)(40 * 101 + 3) * 4 + 1); /* level 1 (101 x 76): file row 35, chunk 2 */
    flip("badblk", "heights.blk", 30492 + 5000); /* band 1: 7 blocks of 33 x 33 samples a band */
    flip("badacc", "accel.bin", 40); /* the first tile's structures (tile row 0 of the full grid) */
    if (th_sh("truncate -s 119000 '%s/short/heights.f32'", data))
        return -1;
    return th_start(&srv, TERRAD_BIN, args, env);
}

static int teardown(void **state)
{
    (void)state;
    th_stop(&srv);
    th_sh("rm -rf '%s'", root);
    return 0;
}

static json_t *get_json(const char *path, long want)
{
    th_resp r;
    json_t *j;
    assert_int_equal(th_request(&srv, "GET", path, NULL, NULL, 0, &r), 0);
    assert_int_equal(r.status, want);
    j = json_loadb(r.body, r.len, 0, NULL);
    assert_non_null(j);
    th_resp_free(&r);
    return j;
}

/* Waits (at most 30 s) until the dataset's chunks are checked; returns its state. */
static const char *wait_checked(const char *id, char *state, size_t n)
{
    char path[128];
    struct timespec nap = {0, 50 * 1000 * 1000};
    snprintf(path, sizeof path, "/v1/datasets/%s", id);
    for (int k = 0; k < 600; k++) {
        json_t *j = get_json(path, 200);
        const char *st = json_string_value(json_object_get(json_object_get(j, "prepared"), "state"));
        snprintf(state, n, "%s", st ? st : "(none)");
        json_decref(j);
        if (strcmp(state, "checking"))
            break;
        nanosleep(&nap, NULL);
    }
    return state;
}

/* lod: "false", or the pixels a coarse cell may span (quality.lod) */
static void render_lod(const char *id, const char *method, const char *surface, const char *lod, th_resp *r)
{
    char body[512];
    const char *h[] = {"Content-Type: application/json", NULL};
    snprintf(body, sizeof body, SCENE, id, method, surface, lod);
    assert_int_equal(th_request(&srv, "POST", "/v1/render", h, body, strlen(body), r), 0);
}

static void render(const char *id, const char *method, const char *surface, th_resp *r)
{
    render_lod(id, method, surface, "false", r);
}

static unsigned long long steps_of(th_resp *r)
{
    char v[64];
    assert_int_equal(th_header(r, "X-Terrad-Steps", v, sizeof v), 1);
    return strtoull(v, NULL, 10);
}

/* Every method on every surface: the prepared dataset's picture is its source's, byte for
 * byte; with lod (not "false") also not lod off's picture (the levels were used). The
 * prepared datasets step with their mapped structures (prepaccel.h): parametric takes
 * fewer steps (X-Terrad-Steps) than on the source, which has none (--preload none) but
 * its levels' max-mipmaps. */
static void same_pictures(const char *lod)
{
    static const char *const methods[] = {"incremental", "hierarchical", "parametric", "silhouette", "auto"};
    static const char *const surfaces[] = {"plane", "linear", "triangle", "bilinear"};
    char st[32];
    assert_string_equal(wait_checked("good", st, sizeof st), "ok");
    assert_string_equal(wait_checked("good8", st, sizeof st), "ok");
    for (int m = 0; m < 5; m++)
        for (int s = 0; s < 4; s++) {
            th_resp a, b, c, d;
            render_lod("crop", methods[m], surfaces[s], lod, &a);
            render_lod("good", methods[m], surfaces[s], lod, &b);
            render_lod("good8", methods[m], surfaces[s], lod, &d);
            assert_int_equal(a.status, 200);
            assert_int_equal(b.status, 200);
            assert_int_equal(d.status, 200);
            assert_int_equal(a.len, b.len);
            assert_memory_equal(a.body, b.body, a.len);
            assert_int_equal(a.len, d.len);
            assert_memory_equal(a.body, d.body, a.len);
            if (m == 2 && !(steps_of(&b) < steps_of(&a)))
                fail_msg("parametric on %s: %llu steps prepared, %llu from the source", surfaces[s], steps_of(&b),
                         steps_of(&a));
            th_resp_free(&d);
            if (strcmp(lod, "false")) {
                render("good", methods[m], surfaces[s], &c);
                assert_true(b.len != c.len || memcmp(b.body, c.body, b.len) != 0);
                th_resp_free(&c);
            }
            th_resp_free(&a);
            th_resp_free(&b);
        }
}

static void test_same_picture(void **state)
{
    (void)state;
    same_pictures("false");
}

/* Levels of detail (quality.lod, 8 pixels a coarse cell so that most far pixels of this
 * small grid end on coarse levels): the prepared dataset's mapped levels, traced with no
 * acceleration, give the picture the in-memory levels (with theirs) give. */
static void test_same_picture_lod(void **state)
{
    (void)state;
    same_pictures("8");
}

static void test_listed_and_metrics(void **state)
{
    json_t *j;
    th_resp r;
    char st[32];
    (void)state;
    assert_string_equal(wait_checked("good", st, sizeof st), "ok");
    j = get_json("/v1/datasets/good", 200);
    assert_int_equal(json_integer_value(json_object_get(json_object_get(j, "size"), "width")), 200);
    /* 10 chunks of heights, 15 of the 8 levels, 5 bands of heights.blk (test_prepared.c
       counts them), 12 tile rows of structures (tiles of 64 cells: 3 + 2 + 1 x 7) */
    assert_int_equal(json_integer_value(json_object_get(json_object_get(j, "prepared"), "chunks")), 42);
    assert_int_equal(json_integer_value(json_object_get(json_object_get(j, "prepared"), "checked")), 42);
    assert_int_equal(json_integer_value(json_object_get(json_object_get(j, "prepared"), "levels")), 8);
    json_decref(j);
    j = get_json("/v1/datasets/crop", 200);
    assert_true(json_is_null(json_object_get(j, "prepared")));
    json_decref(j);
    assert_int_equal(th_request(&srv, "GET", "/metrics", NULL, NULL, 0, &r), 0);
    assert_int_equal(r.status, 200);
    /* good, bad, badlod, badblk, badacc and cold are mapped (short and half are not served
       at all): 6 x ((200 x 150 + the levels' 10420 samples) x 4 + heights.blk's 5 bands of 7 blocks
       of 33 x 33 floats), and good8: its heights.blk has 19 bands of 25 blocks of 9 x 9;
       and each one's accel.bin: 67000 bytes of the 23 tiles' structures */
    assert_non_null(strstr(r.body, "\nterrad_heights_mapped_bytes 2669420\n"));
    assert_non_null(strstr(r.body, "\nterrad_heights_resident_bytes "));
    th_resp_free(&r);
}

static void test_bad_never_served(void **state)
{
    th_resp r;
    char st[32];
    (void)state;
    assert_string_equal(wait_checked("bad", st, sizeof st), "refused");
    render("bad", "auto", "bilinear", &r);
    assert_int_equal(r.status, 404);
    assert_non_null(strstr(r.body, "heights.f32: chunk 1 (file rows 16..31)"));
    th_resp_free(&r);
    assert_true(th_log_has(&srv, "event=dataset_refused id=bad "));
    /* a corrupted chunk of a level: refused the same way */
    assert_string_equal(wait_checked("badlod", st, sizeof st), "refused");
    render_lod("badlod", "auto", "bilinear", "8", &r);
    assert_int_equal(r.status, 404);
    assert_non_null(strstr(r.body, "lod1.f32: chunk 2 (file rows 32..47)"));
    th_resp_free(&r);
    /* and of heights.blk */
    assert_string_equal(wait_checked("badblk", st, sizeof st), "refused");
    render("badblk", "auto", "bilinear", &r);
    assert_int_equal(r.status, 404);
    assert_non_null(strstr(r.body, "heights.blk: band 1 (south rows 32..64)"));
    th_resp_free(&r);
    /* and of the tiles' structures */
    assert_string_equal(wait_checked("badacc", st, sizeof st), "refused");
    render("badacc", "auto", "bilinear", &r);
    assert_int_equal(r.status, 404);
    if (!strstr(r.body, "accel.bin: layer 0 tile 0 (tile row 0)"))
        fail_msg("%s", r.body);
    th_resp_free(&r);
    assert_true(th_log_has(&srv, "event=dataset_refused id=badacc "));
    /* truncated: not even listed; the log names the file and the reason */
    render("short", "auto", "bilinear", &r);
    assert_int_equal(r.status, 404);
    th_resp_free(&r);
    assert_true(th_log_has(&srv, "short/heights.f32: 119000 bytes"));
    assert_true(th_log_has(&srv, "truncated"));
    render("half", "auto", "bilinear", &r);
    assert_int_equal(r.status, 404);
    th_resp_free(&r);
    assert_true(th_log_has(&srv, "an unfinished prepare"));
}

/* "cold" is rendered here first, with its files dropped from the page cache: the render
 * waits for pages, and says so in Server-Timing (pagein: blocked time and major faults of
 * its worker thread) and /metrics. */
static void test_pagein_reported(void **state)
{
    th_resp r;
    char st[32], timing[512], *m;
    (void)state;
    assert_string_equal(wait_checked("cold", st, sizeof st), "ok");
    /* fadvise DONTNEED on every file of the folder (clean: the prepare synced them) */
    assert_int_equal(th_sh("python3 -c \"import os,sys\n"
                        "for f in os.listdir(sys.argv[1]):\n"
                        "  fd=os.open(os.path.join(sys.argv[1],f),os.O_RDONLY); "
                        "os.posix_fadvise(fd,0,0,os.POSIX_FADV_DONTNEED); os.close(fd)\" '%s/cold'", data),
                     0);
    render_lod("cold", "auto", "bilinear", "8", &r);
    assert_int_equal(r.status, 200);
    assert_int_equal(th_header(&r, "Server-Timing", timing, sizeof timing), 1);
    if (!strstr(timing, ", pagein;dur=") || !strstr(timing, " major faults\""))
        fail_msg("Server-Timing: %s", timing);
    th_resp_free(&r);
    assert_int_equal(th_request(&srv, "GET", "/metrics", NULL, NULL, 0, &r), 0);
    m = strstr(r.body, "\nterrad_render_major_faults_total ");
    assert_non_null(m);
    assert_true(strtoull(m + strlen("\nterrad_render_major_faults_total "), NULL, 10) >= 1);
    assert_non_null(strstr(r.body, "\nterrad_render_pagein_seconds_total "));
    th_resp_free(&r);
}

static void test_edit_refused(void **state)
{
    th_resp r;
    float z[4] = {1, 2, 3, 4};
    const char *h[] = {"Authorization: Bearer " TOKEN, "Content-Type: application/octet-stream", NULL};
    (void)state;
    assert_int_equal(th_request(&srv, "PUT", "/v1/admin/datasets/good/heights?x=0&y=0&w=2&h=2", h,
                                (const char *)z, sizeof z, &r),
                     0);
    assert_true(r.status >= 400 && r.status < 500);
    assert_non_null(strstr(r.body, "prepared"));
    th_resp_free(&r);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_same_picture),
        cmocka_unit_test(test_same_picture_lod),
        cmocka_unit_test(test_listed_and_metrics),
        cmocka_unit_test(test_bad_never_served),
        cmocka_unit_test(test_pagein_reported),
        cmocka_unit_test(test_edit_refused),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
