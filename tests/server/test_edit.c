/* test_edit.c: PUT /v1/admin/datasets/{id}/heights over real HTTP (libcurl): bearer
 * token, 400 naming the parameter (and nothing changed then), 413 over --max-edit-kb,
 * the dataset's version in the answer, in GET /v1/datasets/{id} and in render ETags;
 * GET of a region reading back what PUT wrote;
 * the render after an edit equal byte for byte to `terrad render --edit` of the same
 * scene, at once and once the rebuild job is done; an edit racing a preload; renders
 * during a stream of edits, each the picture of exactly one version; and a restart,
 * which forgets the edits (they live in memory only, as README says).
 *
 * terrad is started by the harness (tests/server/harness.c) on a free loopback port
 * with the built-in demo data; `terrad render` runs as a child process. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>

#include <cmocka.h>
#include <curl/curl.h>
#include <jansson.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "check.h"
#include "harness.h"

#define TOKEN "edit-token-0123456789"
static const char *const AUTH_BIN[] = {"Authorization: Bearer " TOKEN,
                                       "Content-Type: application/octet-stream", NULL};
static const char *const AUTH_JSON[] = {"Authorization: Bearer " TOKEN, "Content-Type: application/json", NULL};

static th_server S;
static char tmp[128]; /* a directory of this run's files */

/* The scene, as the CLI's JSON file and as GET /v1/render's query. */
#define SCENE_JSON                                                                               \
    "{\"dataset\":\"%s\",\"camera\":{\"position\":{\"x\":%d,\"y\":%d,\"z\":%d},\"pitch\":-20},"  \
    "\"image\":{\"width\":96,\"height\":72}}"
#define SCENE_QUERY                                                                              \
    "/v1/render?dataset=%s&camera.position.x=%d&camera.position.y=%d&camera.position.z=%d"       \
    "&camera.pitch=-20&image.width=96&image.height=72"

typedef struct view {
    const char *dataset;
    int x, y, z;
} view;

static const view VOLCANO = {"volcano", 300, -400, 400};
static const view TRINIDAD = {"trinidad", 17000, -6000, 7000};

static int start(th_server *s)
{
    const char *args[] = {"--demo-dir", TERRAD_DATA_DIR, "--preload", "none", "--render-workers", "2",
                          "--max-edit-kb", "300", NULL};
    const char *env[] = {"TERRAD_ADMIN_TOKEN=" TOKEN, NULL};
    return th_start(s, TERRAD_BIN, args, env);
}

static int setup(void **state)
{
    char cmd[400];
    (void)state;
    snprintf(tmp, sizeof tmp, "%s/terrad-edit-%ld", P_tmpdir, (long)getpid());
    snprintf(cmd, sizeof cmd, "rm -rf %s && mkdir -p %s", tmp, tmp);
    if (system(cmd))
        return -1;
    return start(&S);
}

static int teardown(void **state)
{
    char cmd[400];
    (void)state;
    assert_int_equal(th_stop(&S), 0);
    th_forget(&S);
    snprintf(cmd, sizeof cmd, "rm -rf %s", tmp);
    assert_int_equal(system(cmd), 0);
    return 0;
}

/* A request that must be refused with this status, code and field. */
static void expect_refusal(const char *method, const char *path, const char *const *h, const char *body,
                           size_t len, long status, const char *code, const char *field)
{
    th_resp r;
    assert_int_equal(th_request(&S, method, path, h, body, len, &r), 0);
    assert_error(&r, status, code, field);
    th_resp_free(&r);
}

/* A body of n samples, all z (little-endian float32). */
static char *samples(size_t n, float z)
{
    char *b = malloc(n * 4);
    uint32_t u;
    memcpy(&u, &z, 4);
    for (size_t k = 0; k < n; k++)
        for (int i = 0; i < 4; i++)
            b[4 * k + (size_t)i] = (char)(u >> (8 * i));
    return b;
}

/* An edit of dataset id, region (x, y, w, h), all samples z: the status; *version when 200. */
typedef struct edit {
    int x, y, w, h;
    float z;
} edit;

static long put_edit(const th_server *s, const char *id, const edit *e, long *version, long *job)
{
    char path[256];
    char *b = samples((size_t)e->w * (size_t)e->h, e->z);
    th_resp r;
    long st;
    snprintf(path, sizeof path, "/v1/admin/datasets/%s/heights?x=%d&y=%d&w=%d&h=%d", id, e->x, e->y, e->w, e->h);
    assert_int_equal(th_request(s, "PUT", path, AUTH_BIN, b, (size_t)e->w * (size_t)e->h * 4, &r), 0);
    st = r.status;
    if (st == 200) {
        json_t *j = body_json(&r), *reg = json_object_get(j, "region");
        *version = (long)json_integer_value(json_object_get(j, "version"));
        assert_int_equal(json_integer_value(json_object_get(reg, "w")), e->w);
        assert_string_equal(json_string_value(json_object_get(j, "dataset")), id);
        if (job)
            *job = json_is_integer(json_object_get(j, "job")) ? (long)json_integer_value(json_object_get(j, "job")) : 0;
        json_decref(j);
    }
    th_resp_free(&r);
    free(b);
    return st;
}

static long dataset_version(const th_server *s, const char *id)
{
    char path[128];
    th_resp r;
    json_t *j;
    long v;
    snprintf(path, sizeof path, "/v1/datasets/%s", id);
    assert_int_equal(th_request(s, "GET", path, NULL, NULL, 0, &r), 0);
    assert_int_equal(r.status, 200);
    j = body_json(&r);
    v = (long)json_integer_value(json_object_get(j, "version"));
    json_decref(j);
    th_resp_free(&r);
    return v;
}

static void wait_job(const th_server *s, long id)
{
    char path[64];
    snprintf(path, sizeof path, "/v1/admin/jobs/%ld", id);
    for (int i = 0; i < 3000; i++) {
        th_resp r;
        json_t *j;
        const char *st;
        int done;
        assert_int_equal(th_request(s, "GET", path, AUTH_JSON, NULL, 0, &r), 0);
        assert_int_equal(r.status, 200);
        j = body_json(&r);
        st = json_string_value(json_object_get(j, "state"));
        assert_string_not_equal(st, "failed");
        done = !strcmp(st, "done");
        json_decref(j);
        th_resp_free(&r);
        if (done)
            return;
        usleep(20000);
    }
    fail_msg("job %ld did not finish", id);
}

/* `terrad render` of view v after the edits e[0..n) (each written as a body file):
 * the PNG's bytes. */
static char *cli_render(const view *v, const edit *e, int n, size_t *len)
{
    char scene[200], png[200], cmd[8192];
    size_t used;
    FILE *f;
    char *data;
    long sz;
    snprintf(scene, sizeof scene, "%s/scene.json", tmp);
    f = fopen(scene, "w");
    assert_non_null(f);
    fprintf(f, SCENE_JSON, v->dataset, v->x, v->y, v->z);
    fclose(f);
    snprintf(png, sizeof png, "%s/cli.png", tmp);
    used = (size_t)snprintf(cmd, sizeof cmd, "%s render %s -o %s --threads 2", TERRAD_BIN, scene, png);
    for (int i = 0; i < n; i++) {
        char body[200], *b = samples((size_t)e[i].w * (size_t)e[i].h, e[i].z);
        snprintf(body, sizeof body, "%s/edit%d.f32", tmp, i);
        f = fopen(body, "wb");
        assert_non_null(f);
        assert_int_equal(fwrite(b, 4, (size_t)e[i].w * (size_t)e[i].h, f), (size_t)e[i].w * (size_t)e[i].h);
        fclose(f);
        free(b);
        used += (size_t)snprintf(cmd + used, sizeof cmd - used, " --edit %d,%d,%d,%d,%s", e[i].x, e[i].y,
                                 e[i].w, e[i].h, body);
    }
    assert_true(used < sizeof cmd);
    assert_int_equal(system(cmd), 0);
    f = fopen(png, "rb");
    assert_non_null(f);
    fseek(f, 0, SEEK_END);
    sz = ftell(f);
    fseek(f, 0, SEEK_SET);
    data = malloc((size_t)sz);
    assert_int_equal(fread(data, 1, (size_t)sz, f), (size_t)sz);
    fclose(f);
    *len = (size_t)sz;
    return data;
}

/* GET /v1/render of view v: the response (PNG body, ETag). */
static void srv_render(const th_server *s, const view *v, const char *const *h, th_resp *r)
{
    char path[400];
    snprintf(path, sizeof path, SCENE_QUERY, v->dataset, v->x, v->y, v->z);
    assert_int_equal(th_request(s, "GET", path, h, NULL, 0, r), 0);
}

static void assert_same_png(const th_resp *r, const char *png, size_t len)
{
    if (r->status != 200)
        fail_msg("render: %ld %.*s", r->status, (int)r->len, r->body);
    assert_int_equal(r->len, len);
    assert_memory_equal(r->body, png, len);
}

/* The datasets as their files hold them: version 1, volcano's picture `png`. */
static void assert_as_loaded(const char *png, size_t len)
{
    th_resp r;
    assert_int_equal(dataset_version(&S, "volcano"), 1);
    assert_int_equal(dataset_version(&S, "trinidad"), 1);
    srv_render(&S, &VOLCANO, NULL, &r);
    assert_same_png(&r, png, len);
    th_resp_free(&r);
}

/* --- tests ----------------------------------------------------------------------------- */

/* Auth and every refusal (nothing changes: version 1, the same picture). */
static void test_refusals(void **state)
{
    static const char *const no_auth[] = {"Content-Type: application/octet-stream", NULL};
    static const char *const wrong[] = {"Authorization: Bearer edit-token-0123456788",
                                        "Content-Type: application/octet-stream", NULL};
    static const struct {
        const char *query;
        size_t samples;
        const char *field;
    } bad[] = {
        {"y=0&w=1&h=1", 1, "x"},         {"x=0&y=zero&w=1&h=1", 1, "y"},
        {"x=-1&y=0&w=1&h=1", 1, "x"},    {"x=61&y=0&w=1&h=1", 1, "x"}, /* 61 columns: 0 .. 60 */
        {"x=0&y=87&w=1&h=1", 1, "y"},    {"x=60&y=0&w=2&h=1", 2, "w"},
        {"x=0&y=80&w=1&h=8", 8, "h"},    {"x=0&y=0&w=0&h=1", 0, "w"},
        {"x=0&y=0&w=2&h=2", 3, "body"},  {"x=0&y=0&w=2&h=2", 5, "body"},
    };
    const char *one = "/v1/admin/datasets/volcano/heights?x=0&y=0&w=1&h=1";
    char path[300], *b = samples(64, 150.0f), *png;
    th_resp r;
    size_t len;
    (void)state;
    png = cli_render(&VOLCANO, NULL, 0, &len);
    expect_refusal("PUT", one, no_auth, b, 4, 401, "unauthorized", NULL);
    expect_refusal("PUT", one, wrong, b, 4, 401, "unauthorized", NULL);
    expect_refusal("PUT", "/v1/admin/datasets/atlantis/heights?x=0&y=0&w=1&h=1", AUTH_BIN, b, 4, 404,
                   "unknown_dataset", "dataset");
    expect_refusal("PUT", one, AUTH_JSON, b, 4, 415, "unsupported_media_type", NULL);
    expect_refusal("POST", one, AUTH_BIN, b, 4, 405, "method_not_allowed", NULL);
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        snprintf(path, sizeof path, "/v1/admin/datasets/volcano/heights?%s", bad[i].query);
        expect_refusal("PUT", path, AUTH_BIN, b, bad[i].samples * 4, 400, "bad_request", bad[i].field);
    }
    /* +inf in the last sample: the body named, and which sample */
    b[4 * 3 + 0] = 0, b[4 * 3 + 1] = 0, b[4 * 3 + 2] = (char)0x80, b[4 * 3 + 3] = 0x7f;
    assert_int_equal(th_request(&S, "PUT", "/v1/admin/datasets/volcano/heights?x=0&y=0&w=2&h=2", AUTH_BIN, b, 16, &r), 0);
    assert_error(&r, 400, "bad_request", "body");
    assert_non_null(strstr(r.body, "sample 3"));
    th_resp_free(&r);
    free(b);
    /* over --max-body-kb (64) without the token: 413 before anything is read; with it the
     * body is taken (and found the wrong size for the region) */
    b = samples(160 * 160, 150.0f);
    expect_refusal("PUT", "/v1/admin/datasets/trinidad/heights?x=0&y=0&w=10&h=10", no_auth, b, 160 * 160 * 4,
                   413, "body_too_large", NULL);
    expect_refusal("PUT", "/v1/admin/datasets/trinidad/heights?x=0&y=0&w=10&h=10", AUTH_BIN, b, 160 * 160 * 4,
                   400, "bad_request", "body");
    free(b);
    /* over --max-edit-kb 300: 413, before the body is read */
    b = samples(600 * 200, 150.0f);
    assert_int_equal(th_request(&S, "PUT", "/v1/admin/datasets/trinidad/heights?x=0&y=0&w=600&h=200", AUTH_BIN, b,
                                600 * 200 * 4, &r), 0);
    assert_error(&r, 413, "body_too_large", NULL);
    assert_non_null(strstr(r.body, "--max-edit-kb"));
    th_resp_free(&r);
    free(b);
    assert_as_loaded(png, len);
    free(png);
}

/* An edit: the version everywhere, a new ETag, and the picture of `terrad render
 * --edit` at once, after the rebuild job, and after a second edit on top. */
static void test_edit_matches_cli(void **state)
{
    static const edit e[2] = {{20, 40, 20, 10, 250.0f}, {25, 30, 8, 30, 60.0f}};
    th_resp r0, r;
    char etag0[128], etag1[128], inm[160], *png1, *png2;
    const char *const if_none[] = {inm, NULL};
    size_t len1, len2;
    long version = 0, job = 0;
    (void)state;
    /* acceleration resident first, so the edit has something to rebuild */
    {
        th_resp p;
        json_t *j;
        assert_int_equal(th_request(&S, "POST", "/v1/admin/preload", AUTH_JSON, "{\"dataset\":\"volcano\"}", 21, &p), 0);
        assert_int_equal(p.status, 202);
        j = body_json(&p);
        wait_job(&S, (long)json_integer_value(json_object_get(j, "id")));
        json_decref(j);
        th_resp_free(&p);
    }
    png1 = cli_render(&VOLCANO, e, 1, &len1);
    png2 = cli_render(&VOLCANO, e, 2, &len2);
    srv_render(&S, &VOLCANO, NULL, &r0);
    assert_int_equal(r0.status, 200);
    assert_true(th_header(&r0, "ETag", etag0, sizeof etag0));
    assert_true(r0.len != len1 || memcmp(r0.body, png1, len1)); /* the edit shows */

    assert_int_equal(put_edit(&S, "volcano", &e[0], &version, &job), 200);
    assert_int_equal(version, 2);
    assert_true(job > 0); /* the touched tile held acceleration */
    assert_int_equal(dataset_version(&S, "volcano"), 2);
    snprintf(inm, sizeof inm, "If-None-Match: %s", etag0);
    srv_render(&S, &VOLCANO, if_none, &r); /* the old tag no longer matches */
    assert_same_png(&r, png1, len1);
    assert_true(th_header(&r, "ETag", etag1, sizeof etag1));
    assert_string_not_equal(etag0, etag1);
    assert_non_null(strstr(etag1, "-v2."));
    th_resp_free(&r);
    wait_job(&S, job);
    srv_render(&S, &VOLCANO, NULL, &r);
    assert_same_png(&r, png1, len1);
    th_resp_free(&r);
    /* GET reads the region back: the body that wrote it, and the version */
    {
        char v[32], *want = samples(20 * 10, 250.0f);
        assert_int_equal(th_request(&S, "GET", "/v1/admin/datasets/volcano/heights?x=20&y=40&w=20&h=10",
                                    AUTH_JSON, NULL, 0, &r), 0);
        assert_int_equal(r.status, 200);
        assert_int_equal(r.len, 20 * 10 * 4);
        assert_memory_equal(r.body, want, r.len);
        assert_true(th_header(&r, "X-Terrad-Version", v, sizeof v));
        assert_string_equal(v, "2");
        th_resp_free(&r);
        assert_int_equal(th_request(&S, "GET", "/v1/admin/datasets/volcano/heights?x=19&y=40&w=1&h=1",
                                    AUTH_JSON, NULL, 0, &r), 0);
        assert_int_equal(r.len, 4);
        assert_memory_not_equal(r.body, want, 4); /* outside the edit */
        th_resp_free(&r);
        assert_int_equal(th_request(&S, "GET", "/v1/admin/datasets/volcano/heights?x=20&y=40&w=50&h=10",
                                    AUTH_JSON, NULL, 0, &r), 0);
        assert_error(&r, 400, "bad_request", "w");
        th_resp_free(&r);
        assert_int_equal(th_request(&S, "GET", "/v1/admin/datasets/volcano/heights?x=20&y=40&w=5&h=10",
                                    NULL, NULL, 0, &r), 0);
        assert_error(&r, 401, "unauthorized", NULL);
        th_resp_free(&r);
        free(want);
    }

    assert_int_equal(put_edit(&S, "volcano", &e[1], &version, NULL), 200);
    assert_int_equal(version, 3);
    srv_render(&S, &VOLCANO, NULL, &r);
    assert_same_png(&r, png2, len2);
    th_resp_free(&r);
    th_resp_free(&r0);
    free(png1);
    free(png2);
}

/* An edit racing a preload of the same tiles: both jobs finish, the picture is the
 * edited one, and a later preload makes every tile resident again. */
static void test_edit_races_preload(void **state)
{
    static const edit e = {100, 150, 256, 256, 3000.0f};
    th_resp p, r;
    json_t *j;
    long version = 0, job = 0, pre;
    size_t len;
    char *png;
    (void)state;
    png = cli_render(&TRINIDAD, &e, 1, &len);
    assert_int_equal(th_request(&S, "POST", "/v1/admin/preload", AUTH_JSON, "{\"dataset\":\"trinidad\"}", 22, &p), 0);
    assert_int_equal(p.status, 202);
    j = body_json(&p);
    pre = (long)json_integer_value(json_object_get(j, "id"));
    json_decref(j);
    th_resp_free(&p);
    assert_int_equal(put_edit(&S, "trinidad", &e, &version, &job), 200);
    assert_int_equal(version, 2);
    srv_render(&S, &TRINIDAD, NULL, &r); /* during the preload, perhaps */
    assert_same_png(&r, png, len);
    th_resp_free(&r);
    wait_job(&S, pre);
    if (job)
        wait_job(&S, job);
    srv_render(&S, &TRINIDAD, NULL, &r);
    assert_same_png(&r, png, len);
    th_resp_free(&r);
    assert_int_equal(th_request(&S, "POST", "/v1/admin/preload", AUTH_JSON, "{\"dataset\":\"trinidad\"}", 22, &p), 0);
    j = body_json(&p);
    wait_job(&S, (long)json_integer_value(json_object_get(j, "id")));
    json_decref(j);
    th_resp_free(&p);
    assert_int_equal(th_request(&S, "GET", "/v1/datasets/trinidad", NULL, NULL, 0, &p), 0);
    j = body_json(&p);
    assert_int_equal(json_integer_value(json_object_get(json_object_get(j, "residency"), "tiles")),
                     json_integer_value(json_object_get(json_object_get(j, "tiles"), "total")));
    json_decref(j);
    th_resp_free(&p);
    srv_render(&S, &TRINIDAD, NULL, &r);
    assert_same_png(&r, png, len);
    th_resp_free(&r);
    free(png);
}

/* Renders during a stream of edits: each is the picture of the version its ETag names. */
typedef struct stream {
    const char *png[3]; /* by version % 3 ... see below */
    size_t len[3];
    long base;          /* the dataset's version before the stream */
    atomic_int stop, renders, wrong;
} stream;

static void *renderer(void *arg)
{
    stream *st = arg;
    while (!atomic_load(&st->stop) || atomic_load(&st->renders) < 4) {
        th_resp r;
        char etag[128];
        const char *v;
        long ver, k;
        srv_render(&S, &VOLCANO, NULL, &r);
        if (r.status != 200 || !th_header(&r, "ETag", etag, sizeof etag) || !(v = strstr(etag, "-v"))) {
            atomic_fetch_add(&st->wrong, 1);
        } else {
            /* base: picture 0; then edits alternate up (1), down (2), up, down ... */
            ver = strtol(v + 2, NULL, 10);
            k = ver == st->base ? 0 : (ver - st->base) % 2 ? 1 : 2;
            if (ver < st->base || r.len != st->len[k] || memcmp(r.body, st->png[k], r.len))
                atomic_fetch_add(&st->wrong, 1);
        }
        th_resp_free(&r);
        atomic_fetch_add(&st->renders, 1);
    }
    return NULL;
}

static void test_renders_during_edits(void **state)
{
    static const edit up = {10, 10, 40, 60, 260.0f}, down = {10, 10, 40, 60, 80.0f};
    stream *st = calloc(1, sizeof *st);
    edit hist[2];
    pthread_t th[2];
    long version = 0;
    char *p[3];
    (void)state;
    st->base = dataset_version(&S, "volcano");
    /* the pictures: as now (the previous test's two edits), then with up, then with down */
    {
        static const edit before[2] = {{20, 40, 20, 10, 250.0f}, {25, 30, 8, 30, 60.0f}};
        edit all[3] = {before[0], before[1], up};
        p[0] = cli_render(&VOLCANO, before, 2, &st->len[0]);
        p[1] = cli_render(&VOLCANO, all, 3, &st->len[1]);
        all[2] = down;
        p[2] = cli_render(&VOLCANO, all, 3, &st->len[2]);
    }
    for (int i = 0; i < 3; i++)
        st->png[i] = p[i];
    assert_true(st->len[1] != st->len[2] || memcmp(p[1], p[2], st->len[1]));
    for (int i = 0; i < 2; i++)
        assert_int_equal(pthread_create(&th[i], NULL, renderer, st), 0);
    for (int i = 0; i < 12; i++) {
        hist[0] = i % 2 ? down : up;
        assert_int_equal(put_edit(&S, "volcano", &hist[0], &version, NULL), 200);
        assert_int_equal(version, st->base + 1 + i);
        usleep(20000);
    }
    atomic_store(&st->stop, 1);
    for (int i = 0; i < 2; i++)
        pthread_join(th[i], NULL);
    assert_int_equal(atomic_load(&st->wrong), 0);
    assert_true(atomic_load(&st->renders) >= 4);
    for (int i = 0; i < 3; i++)
        free(p[i]);
    free(st);
}

/* `terrad render --edit` refuses what the endpoint refuses, naming the parameter or the
 * file, and renders nothing. */
static void test_cli_edit_refusals(void **state)
{
    static const struct {
        const char *edit, *says;
    } bad[] = {
        {"0,0,62,1,%s/e.f32", "w: 62 columns"},     /* volcano has 61 */
        {"0,-1,1,1,%s/e.f32", "y: '-1'"},
        {"0,0,1,1", "X,Y,W,H,FILE"},
        {"0,0,2,1,%s/e.f32", "body: 4 bytes"},        /* the file holds one sample */
        {"0,0,1,1,%s/none.f32", "none.f32"},
    };
    char scene[200], out[200], arg[300], cmd[1200], text[2000];
    FILE *f;
    (void)state;
    snprintf(scene, sizeof scene, "%s/scene.json", tmp);
    f = fopen(scene, "w");
    assert_non_null(f);
    fprintf(f, SCENE_JSON, VOLCANO.dataset, VOLCANO.x, VOLCANO.y, VOLCANO.z);
    fclose(f);
    snprintf(arg, sizeof arg, "%s/e.f32", tmp);
    f = fopen(arg, "wb");
    assert_non_null(f);
    assert_int_equal(fwrite("\0\0\x48\x43", 1, 4, f), 4); /* 200.0f */
    fclose(f);
    snprintf(out, sizeof out, "%s/refused.png", tmp);
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        size_t n;
        FILE *p;
        snprintf(arg, sizeof arg, bad[i].edit, tmp);
        snprintf(cmd, sizeof cmd, "rm -f %s; %s render %s -o %s --edit %s 2>&1", out, TERRAD_BIN, scene, out, arg);
        p = popen(cmd, "r");
        assert_non_null(p);
        n = fread(text, 1, sizeof text - 1, p);
        text[n] = '\0';
        assert_true(pclose(p) != 0);
        if (!strstr(text, bad[i].says))
            fail_msg("--edit %s: '%s' not in: %s", arg, bad[i].says, text);
        assert_int_not_equal(access(out, F_OK), 0);
    }
}

/* A restart forgets the edits: version 1 and the file's picture again. */
static void test_restart_forgets(void **state)
{
    size_t len;
    char *png = cli_render(&VOLCANO, NULL, 0, &len);
    (void)state;
    assert_true(dataset_version(&S, "volcano") > 1);
    assert_int_equal(th_stop(&S), 0);
    th_forget(&S);
    assert_int_equal(start(&S), 0);
    assert_as_loaded(png, len);
    free(png);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_refusals),
        cmocka_unit_test(test_edit_matches_cli),
        cmocka_unit_test(test_edit_races_preload),
        cmocka_unit_test(test_renders_during_edits),
        cmocka_unit_test(test_restart_forgets),
        cmocka_unit_test(test_cli_edit_refusals),
    };
    int rc;
    curl_global_init(CURL_GLOBAL_ALL);
    rc = cmocka_run_group_tests_name("heights edits", tests, setup, teardown);
    curl_global_cleanup();
    return rc;
}
