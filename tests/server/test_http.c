/* test_http.c: integration tests of `terrad serve` over real HTTP (libcurl): every
 * endpoint, every error code (400, 401, 404, 405, 413, 415, 503), ETag / 304, admin
 * auth and preload jobs, renders running while tiles are preloaded and evicted, a full
 * render queue, the static web files, and a clean exit on SIGTERM.
 *
 * terrad is started by the harness on a free loopback port (--listen 127.0.0.1:0) with
 * the built-in demo data (data/: levi 400 x 400, trinidad 600 x 500, volcano 61 x 87)
 * and stopped by pid at the end; every server must exit 0. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>

#include <cmocka.h>
#include <curl/curl.h>
#include <jansson.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "check.h"
#include "harness.h"

#define TOKEN "test-token-0123456789"
static const char *const AUTH[] = {"Authorization: Bearer " TOKEN, "Content-Type: application/json", NULL};
static const char *const JSON_CT[] = {"Content-Type: application/json", NULL};

static th_server A; /* admin on, no preload, a test web dir */
static char webdir[256];

static const char *SCENE =
    "{\"dataset\":\"levi\",\"camera\":{\"position\":{\"x\":4000,\"y\":-2000,\"z\":1500},"
    "\"pitch\":-15},\"image\":{\"width\":64,\"height\":48}}";

static void write_file(const char *path, const char *text)
{
    FILE *f = fopen(path, "w");
    assert_non_null(f);
    fputs(text, f);
    fclose(f);
}

static int setup_a(void **state)
{
    const char *args[] = {"--demo-dir", TERRAD_DATA_DIR, "--preload", "none", "--web-dir", NULL,
                          "--render-workers", "2", "--queue", "16", NULL};
    const char *env[] = {"TERRAD_ADMIN_TOKEN=" TOKEN, NULL};
    char p[512];
    (void)state;
    snprintf(webdir, sizeof webdir, "%s/terrad-web-%ld", P_tmpdir, (long)getpid());
    mkdir(webdir, 0755);
    snprintf(p, sizeof p, "%s/site", webdir);
    mkdir(p, 0755);
    snprintf(p, sizeof p, "%s/site/index.html", webdir);
    write_file(p, "<!doctype html><title>terrad test</title>");
    snprintf(p, sizeof p, "%s/site/js", webdir);
    mkdir(p, 0755);
    snprintf(p, sizeof p, "%s/site/js/app.js", webdir);
    write_file(p, "console.log('terrad');");
    snprintf(p, sizeof p, "%s/site/package.json", webdir); /* not part of the page */
    write_file(p, "{}");
    snprintf(p, sizeof p, "%s/site/.hidden", webdir);
    write_file(p, "hidden");
    snprintf(p, sizeof p, "%s/secret.txt", webdir); /* outside the served root */
    write_file(p, "secret");
    snprintf(p, sizeof p, "%s/site", webdir);
    args[5] = p;
    return th_start(&A, TERRAD_BIN, args, env);
}

static int teardown_a(void **state)
{
    int rc = th_stop(&A);
    (void)state;
    assert_int_equal(rc, 0);
    assert_true(th_log_has(&A, "event=stopped"));
    th_forget(&A);
    {
        char cmd[300];
        snprintf(cmd, sizeof cmd, "rm -rf %s", webdir);
        assert_int_equal(system(cmd), 0);
    }
    return 0;
}

static void req(const th_server *s, const char *m, const char *path, const char *const *h,
                const char *body, th_resp *r)
{
    assert_int_equal(th_request(s, m, path, h, body, body ? strlen(body) : 0, r), 0);
}

/* Like req, for a server with a per-address connection limit: the server notices a
 * client's close on its own time, so a new connection right after the last one may be
 * closed unanswered while the old one still counts. A refused connection has no effect on
 * the server (it is closed before anything is read), so sending again is safe. */
static void req_limited(const th_server *s, const char *m, const char *path, const char *const *h,
                        const char *body, th_resp *r)
{
    int rc = -1;
    for (int i = 0; rc != 0 && i < 500; i++) {
        rc = th_request(s, m, path, h, body, body ? strlen(body) : 0, r);
        if (rc != 0) {
            th_resp_free(r);
            usleep(10000);
        }
    }
    assert_int_equal(rc, 0);
}

/* --- health, metrics, datasets ---------------------------------------------------------- */

static void test_health(void **state)
{
    th_resp r;
    json_t *j;
    (void)state;
    req(&A, "GET", "/healthz", NULL, NULL, &r);
    assert_int_equal(r.status, 200);
    j = body_json(&r);
    assert_string_equal(json_string_value(json_object_get(j, "status")), "ok");
    json_decref(j);
    th_resp_free(&r);
    req(&A, "GET", "/readyz", NULL, NULL, &r);
    assert_int_equal(r.status, 200);
    j = body_json(&r);
    assert_int_equal(json_integer_value(json_object_get(j, "datasets")), 3);
    json_decref(j);
    th_resp_free(&r);
    req(&A, "POST", "/healthz", JSON_CT, "{}", &r);
    assert_error(&r, 405, "method_not_allowed", NULL);
    th_resp_free(&r);
}

static void test_datasets(void **state)
{
    th_resp r;
    json_t *j, *levi = NULL, *tri = NULL;
    size_t i;
    json_t *d;
    (void)state;
    req(&A, "GET", "/v1/datasets", NULL, NULL, &r);
    assert_int_equal(r.status, 200);
    j = body_json(&r);
    assert_true(json_is_array(j));
    assert_int_equal(json_array_size(j), 3);
    json_array_foreach(j, i, d)
    {
        const char *id = json_string_value(json_object_get(d, "id"));
        if (!strcmp(id, "levi"))
            levi = d;
        if (!strcmp(id, "trinidad"))
            tri = d;
    }
    assert_non_null(levi);
    assert_non_null(tri);
    assert_int_equal(json_integer_value(json_object_get(json_object_get(levi, "size"), "width")), 400);
    assert_int_equal(json_integer_value(json_object_get(json_object_get(tri, "size"), "height")), 500);
    assert_float_equal(json_real_value(json_array_get(json_object_get(levi, "spacing"), 0)), 20.0, 1e-9);
    assert_float_equal(json_real_value(json_array_get(json_object_get(json_object_get(levi, "extent"), "x"), 1)),
                       7980.0, 1e-6);
    assert_true(json_is_null(json_object_get(levi, "georeference")));
    assert_int_equal(json_array_size(json_object_get(levi, "drapes")), 1);
    assert_string_equal(json_string_value(json_array_get(json_object_get(levi, "drapes"), 0)), "orthophoto");
    assert_int_equal(json_array_size(json_object_get(tri, "drapes")), 0);
    assert_string_equal(json_string_value(json_object_get(json_object_get(tri, "georeference"), "kind")),
                        "lonlat");
    assert_int_equal(json_integer_value(json_object_get(json_object_get(levi, "tiles"), "total")), 4);
    assert_non_null(json_object_get(json_object_get(levi, "residency"), "tiles"));
    json_decref(j);
    th_resp_free(&r);

    req(&A, "GET", "/v1/datasets/volcano", NULL, NULL, &r);
    assert_int_equal(r.status, 200);
    j = body_json(&r);
    assert_int_equal(json_integer_value(json_object_get(json_object_get(j, "size"), "width")), 61);
    assert_int_equal(json_integer_value(json_object_get(json_object_get(j, "size"), "height")), 87);
    json_decref(j);
    th_resp_free(&r);

    req(&A, "GET", "/v1/datasets/nope", NULL, NULL, &r);
    assert_error(&r, 404, "unknown_dataset", "dataset");
    th_resp_free(&r);
    req(&A, "DELETE", "/v1/datasets", NULL, NULL, &r);
    assert_error(&r, 405, "method_not_allowed", NULL);
    th_resp_free(&r);
    req(&A, "GET", "/v1/nothing-here", NULL, NULL, &r);
    assert_error(&r, 404, "not_found", NULL);
    th_resp_free(&r);
}

/* --- renders --------------------------------------------------------------------------- */

static void test_render_post(void **state)
{
    th_resp r;
    int w = 0, h = 0;
    char v[512];
    (void)state;
    req(&A, "POST", "/v1/render", JSON_CT, SCENE, &r);
    assert_int_equal(r.status, 200);
    assert_true(th_png_size(&r, &w, &h));
    assert_int_equal(w, 64);
    assert_int_equal(h, 48);
    assert_true(th_header(&r, "Content-Type", v, sizeof v));
    assert_string_equal(v, "image/png");
    assert_true(th_header(&r, "Server-Timing", v, sizeof v));
    assert_non_null(strstr(v, "parse;dur="));
    assert_non_null(strstr(v, "queue;dur="));
    assert_non_null(strstr(v, "trace;dur="));
    assert_non_null(strstr(v, "encode;dur="));
    assert_null(strstr(v, "shadows;dur=")); /* not asked for: not run */
    assert_true(th_header(&r, "X-Terrad-Surface", v, sizeof v));
    assert_string_equal(v, "bilinear");
    assert_true(th_header(&r, "X-Terrad-Method", v, sizeof v));
    assert_int_equal(strncmp(v, "auto", 4), 0);
    assert_true(th_header(&r, "X-Terrad-Rays", v, sizeof v));
    assert_int_equal(atoi(v), 64 * 48);
    {
        /* bilinear without level of detail: the picture is the exact one */
        double mean = -1.0, max = -1.0;
        unsigned long long hits = 0;
        assert_true(th_header(&r, "X-Terrad-Height-Error", v, sizeof v));
        assert_int_equal(sscanf(v, "mean=%lf; max=%lf; hits=%llu", &mean, &max, &hits), 3);
        assert_true(mean >= 0.0 && mean < 1e-6 && max < 1e-6 && hits > 0 && hits <= 64 * 48);
    }
    th_resp_free(&r);

    req(&A, "POST", "/v1/render", JSON_CT,
        "{\"dataset\":\"levi\",\"camera\":{\"position\":{\"x\":4000,\"y\":-2000,\"z\":1500},\"pitch\":-15},"
        "\"image\":{\"width\":32,\"height\":24},\"quality\":{\"method\":\"incremental\",\"surface\":\"triangle\"},"
        "\"effects\":{\"shadows\":true}}", &r);
    assert_int_equal(r.status, 200);
    assert_true(th_header(&r, "Server-Timing", v, sizeof v));
    assert_non_null(strstr(v, "shadows;dur="));
    assert_true(th_header(&r, "X-Terrad-Method", v, sizeof v));
    assert_string_equal(v, "incremental");
    assert_true(th_header(&r, "X-Terrad-Surface", v, sizeof v));
    assert_string_equal(v, "triangle");
    {
        /* triangles are off the exact (bilinear) surface inside the cells */
        double mean = -1.0, max = -1.0;
        assert_true(th_header(&r, "X-Terrad-Height-Error", v, sizeof v));
        assert_int_equal(sscanf(v, "mean=%lf; max=%lf", &mean, &max), 2);
        assert_true(mean > 1e-4 && max >= mean && max < 400.0);
    }
    th_resp_free(&r);

    /* level of detail: the dataset's coarse levels are resident from load */
    req(&A, "POST", "/v1/render", JSON_CT,
        "{\"dataset\":\"levi\",\"camera\":{\"position\":{\"x\":4000,\"y\":-2000,\"z\":1500},\"pitch\":-15},"
        "\"image\":{\"width\":32,\"height\":24},\"quality\":{\"lod\":4}}", &r);
    assert_int_equal(r.status, 200);
    assert_true(th_header(&r, "X-Terrad-Rays", v, sizeof v));
    assert_int_equal(atoi(v), 32 * 24);
    th_resp_free(&r);

    /* A drape named by id (a PNG beside the dataset), as /v1/datasets lists it. */
    req(&A, "POST", "/v1/render", JSON_CT,
        "{\"dataset\":\"levi\",\"camera\":{\"position\":{\"x\":4000,\"y\":-2000,\"z\":1500},\"pitch\":-15},"
        "\"image\":{\"width\":32,\"height\":24},\"effects\":{\"drape\":\"orthophoto\"}}", &r);
    assert_int_equal(r.status, 200);
    assert_true(th_png_size(&r, &w, &h));
    assert_int_equal(w, 32);
    th_resp_free(&r);
}

static void test_render_get_etag(void **state)
{
    th_resp r, r2;
    char etag[128], etag2[128], hdr[200], v[128];
    const char *path = "/v1/render?dataset=levi&camera.position.x=4000&camera.position.y=-2000"
                       "&camera.position.z=1500&camera.pitch=-15&image.width=40&image.height=30";
    const char *path2 = "/v1/render?dataset=levi&camera.position.x=4000&camera.position.y=-2000"
                        "&camera.position.z=1500&camera.pitch=-16&image.width=40&image.height=30";
    const char *inm[] = {hdr, NULL};
    int w, h;
    (void)state;
    req(&A, "GET", path, NULL, NULL, &r);
    assert_int_equal(r.status, 200);
    assert_true(th_png_size(&r, &w, &h));
    assert_int_equal(w, 40);
    assert_true(th_header(&r, "ETag", etag, sizeof etag));
    assert_true(th_header(&r, "Cache-Control", v, sizeof v));
    assert_non_null(strstr(v, "max-age="));
    snprintf(hdr, sizeof hdr, "If-None-Match: %s", etag);
    req(&A, "GET", path, inm, NULL, &r2);
    assert_int_equal(r2.status, 304);
    assert_int_equal(r2.len, 0);
    th_resp_free(&r2);
    /* The same scene with keys in another order is the same picture: same ETag. */
    req(&A, "GET", "/v1/render?image.height=30&image.width=40&camera.pitch=-15&camera.position.z=1500"
                   "&camera.position.y=-2000&camera.position.x=4000&dataset=levi", NULL, NULL, &r2);
    assert_int_equal(r2.status, 200);
    assert_true(th_header(&r2, "ETag", etag2, sizeof etag2));
    assert_string_equal(etag, etag2);
    th_resp_free(&r2);
    req(&A, "GET", path2, NULL, NULL, &r2);
    assert_int_equal(r2.status, 200);
    assert_true(th_header(&r2, "ETag", etag2, sizeof etag2));
    assert_string_not_equal(etag, etag2);
    th_resp_free(&r2);
    th_resp_free(&r);

    req(&A, "GET", "/v1/render?dataset=levi&camera.fov=abc&camera.position.x=1&camera.position.y=1&camera.position.z=1",
        NULL, NULL, &r);
    assert_error(&r, 400, "bad_request", "camera.fov");
    th_resp_free(&r);
}

static void test_render_errors(void **state)
{
    th_resp r;
    char v[128];
    char *big;
    const char *text_ct[] = {"Content-Type: text/plain", NULL};
    (void)state;
    req(&A, "POST", "/v1/render", JSON_CT,
        "{\"dataset\":\"levi\",\"camera\":{\"position\":{\"x\":1,\"y\":1,\"z\":900},\"fov\":500}}", &r);
    assert_error(&r, 400, "bad_request", "camera.fov");
    th_resp_free(&r);
    req(&A, "POST", "/v1/render", JSON_CT, "{\"dataset\":\"levi\",", &r);
    assert_error(&r, 400, "bad_request", NULL);
    th_resp_free(&r);
    req(&A, "POST", "/v1/render", JSON_CT,
        "{\"dataset\":\"levi\",\"camera\":{\"position\":{\"x\":1,\"y\":1,\"z\":900}},\"colour\":1}", &r);
    assert_error(&r, 400, "bad_request", "colour");
    th_resp_free(&r);
    req(&A, "POST", "/v1/render", JSON_CT,
        "{\"dataset\":\"levi\",\"camera\":{\"position\":{\"x\":1,\"y\":1,\"z\":900}},"
        "\"image\":{\"width\":100000,\"height\":100000}}", &r);
    assert_int_equal(r.status, 400);
    th_resp_free(&r);
    req(&A, "POST", "/v1/render", text_ct, SCENE, &r);
    assert_error(&r, 415, "unsupported_media_type", NULL);
    th_resp_free(&r);
    req(&A, "POST", "/v1/render", NULL, SCENE, &r); /* curl's default form type */
    assert_error(&r, 415, "unsupported_media_type", NULL);
    th_resp_free(&r);
    big = malloc(200000);
    assert_non_null(big);
    memset(big, ' ', 199999);
    big[0] = '{';
    big[199998] = '}';
    big[199999] = '\0';
    req(&A, "POST", "/v1/render", JSON_CT, big, &r);
    assert_error(&r, 413, "body_too_large", NULL);
    th_resp_free(&r);
    free(big);
    req(&A, "POST", "/v1/render", JSON_CT,
        "{\"dataset\":\"atlantis\",\"camera\":{\"position\":{\"x\":1,\"y\":1,\"z\":900}}}", &r);
    assert_error(&r, 404, "unknown_dataset", "dataset");
    th_resp_free(&r);
    req(&A, "PUT", "/v1/render", JSON_CT, SCENE, &r);
    assert_error(&r, 405, "method_not_allowed", NULL);
    assert_true(th_header(&r, "Allow", v, sizeof v));
    assert_non_null(strstr(v, "POST"));
    th_resp_free(&r);
    req(&A, "POST", "/v1/render", JSON_CT,
        "{\"dataset\":\"../etc/passwd\",\"camera\":{\"position\":{\"x\":1,\"y\":1,\"z\":900}}}", &r);
    assert_int_equal(r.status, 400);
    th_resp_free(&r);
    req(&A, "POST", "/v1/render", JSON_CT,
        "{\"dataset\":\"levi\",\"camera\":{\"position\":{\"x\":1,\"y\":1,\"z\":900}},"
        "\"effects\":{\"drape\":\"nothing-here\"}}", &r);
    assert_error(&r, 400, "bad_request", "effects.drape");
    th_resp_free(&r);
}

/* Mutated scenes: whatever the bytes, the answer is never a 5xx. */
static void test_render_never_500(void **state)
{
    const char *base = "{\"dataset\":\"volcano\",\"camera\":{\"position\":{\"x\":300,\"y\":-100,\"z\":400},"
                       "\"heading\":10,\"pitch\":-20,\"fov\":50},\"image\":{\"width\":16,\"height\":12},"
                       "\"quality\":{\"method\":\"parametric\",\"samples\":1},\"effects\":{\"haze\":{\"visibility_km\":5}}}";
    const char alphabet[] = "{}[]\",:0123456789-.eE truefalsn\\\x01\xff";
    size_t n = strlen(base);
    char *b = malloc(n + 1);
    uint64_t x = 88172645463325252ULL;
    int ok200 = 0;
    (void)state;
    assert_non_null(b);
    for (int it = 0; it < 150; it++) {
        th_resp r;
        memcpy(b, base, n + 1);
        for (int k = 0; k < 1 + it % 3; k++) {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            b[x % n] = alphabet[(x >> 32) % (sizeof alphabet - 1)];
        }
        req(&A, "POST", "/v1/render", JSON_CT, b, &r);
        if (r.status >= 500 || r.status < 200) {
            print_error("status %ld for mutation %d: %.*s\n", r.status, it, (int)r.len, r.body);
            fail();
        }
        ok200 += r.status == 200;
        th_resp_free(&r);
    }
    free(b);
    (void)ok200;
}

static void test_pick(void **state)
{
    th_resp r;
    json_t *j, *p0, *p1;
    (void)state;
    req(&A, "POST", "/v1/pick", JSON_CT,
        "{\"dataset\":\"levi\",\"camera\":{\"position\":{\"x\":4000,\"y\":-2000,\"z\":1500},\"pitch\":-15},"
        "\"pick\":[[320,400],[320,5]]}", &r);
    assert_int_equal(r.status, 200);
    j = body_json(&r);
    p0 = json_array_get(json_object_get(j, "picks"), 0);
    p1 = json_array_get(json_object_get(j, "picks"), 1);
    assert_true(json_is_true(json_object_get(p0, "hit")));
    {
        double z = json_real_value(json_object_get(json_object_get(p0, "point"), "z"));
        double y = json_real_value(json_object_get(json_object_get(p0, "point"), "y"));
        assert_true(z >= 180.0 && z <= 531.0);
        assert_true(y >= 0.0 && y <= 7980.0);
        assert_true(json_real_value(json_object_get(p0, "distance")) > 0);
        /* the default surface is the exact one */
        assert_true(json_is_real(json_object_get(p0, "height_error_m")));
        assert_true(json_real_value(json_object_get(p0, "height_error_m")) < 1e-6);
    }
    assert_true(json_is_false(json_object_get(p1, "hit"))); /* above the horizon: sky */
    json_decref(j);
    th_resp_free(&r);
    /* on the flat-topped plane surface the picked point is off the exact one, and the
       response says by how much, as renders do */
    req(&A, "POST", "/v1/pick", JSON_CT,
        "{\"dataset\":\"levi\",\"camera\":{\"position\":{\"x\":4000,\"y\":-2000,\"z\":1500},\"pitch\":-15},"
        "\"quality\":{\"surface\":\"plane\"},\"pick\":[[320,400],[300,380],[340,420]]}", &r);
    assert_int_equal(r.status, 200);
    {
        char v[256];
        double sum = 0.0;
        j = body_json(&r);
        for (int i = 0; i < 3; i++)
            sum += json_real_value(json_object_get(json_array_get(json_object_get(j, "picks"), (size_t)i),
                                                   "height_error_m"));
        assert_true(sum > 1e-3);
        json_decref(j);
        assert_true(th_header(&r, "X-Terrad-Height-Error", v, sizeof v));
        assert_non_null(strstr(v, "hits=3"));
    }
    th_resp_free(&r);
    req(&A, "POST", "/v1/pick", JSON_CT, SCENE, &r);
    assert_error(&r, 400, "bad_request", "pick");
    th_resp_free(&r);
    req(&A, "GET", "/v1/pick", NULL, NULL, &r);
    assert_error(&r, 405, "method_not_allowed", NULL);
    th_resp_free(&r);
}

static void test_tiles(void **state)
{
    th_resp r, r2;
    int w, h;
    char etag[128], hdr[200];
    const char *inm[] = {hdr, NULL};
    (void)state;
    req(&A, "GET", "/v1/tiles/levi/0/0/0.png", NULL, NULL, &r);
    assert_int_equal(r.status, 200);
    assert_true(th_png_size(&r, &w, &h));
    assert_int_equal(w, 256);
    assert_int_equal(h, 256);
    assert_true(th_header(&r, "ETag", etag, sizeof etag));
    snprintf(hdr, sizeof hdr, "If-None-Match: %s", etag);
    req(&A, "GET", "/v1/tiles/levi/0/0/0.png", inm, NULL, &r2);
    assert_int_equal(r2.status, 304);
    th_resp_free(&r2);
    th_resp_free(&r);
    req(&A, "GET", "/v1/tiles/trinidad/2/3/1.png", NULL, NULL, &r);
    assert_int_equal(r.status, 200);
    th_resp_free(&r);
    req(&A, "GET", "/v1/tiles/levi/1/2/0.png", NULL, NULL, &r);
    assert_error(&r, 404, "not_found", NULL);
    th_resp_free(&r);
    /* volcano is 600 m x 860 m: at zoom 2 (215 m tiles) column 3 starts at 645 m, past it. */
    req(&A, "GET", "/v1/tiles/volcano/2/3/0.png", NULL, NULL, &r);
    assert_error(&r, 404, "not_found", NULL);
    th_resp_free(&r);
    req(&A, "GET", "/v1/tiles/levi/z/0/0.png", NULL, NULL, &r);
    assert_error(&r, 400, "bad_request", "z");
    th_resp_free(&r);
    req(&A, "GET", "/v1/tiles/atlantis/0/0/0.png", NULL, NULL, &r);
    assert_error(&r, 404, "unknown_dataset", "dataset");
    th_resp_free(&r);
    req(&A, "POST", "/v1/tiles/levi/0/0/0.png", JSON_CT, "{}", &r);
    assert_error(&r, 405, "method_not_allowed", NULL);
    th_resp_free(&r);
}

/* Map tiles on the levels of detail's isometric twins (?quality.lod_grid=isometric): a 400
 * naming the field without --isometric-lod 1 or for an unknown lattice; with it, a tile
 * with its own ETag (not the square tile's) and a height error. */
static void test_tiles_isometric(void **state)
{
    th_server s;
    th_resp r, r2;
    int w, h;
    char e1[128], e2[128], herr[128];
    const char *args[] = {"--demo-dir", TERRAD_DATA_DIR, "--preload", "none", "--isometric-lod", "1", NULL};
    const char *refused[] = {"isometric", "hex"}; /* on A: no twins; no such lattice */
    (void)state;
    for (int k = 0; k < 2; k++) {
        char path[96];
        snprintf(path, sizeof path, "/v1/tiles/volcano/0/0/0.png?quality.lod_grid=%s", refused[k]);
        req(&A, "GET", path, NULL, NULL, &r);
        assert_error(&r, 400, "bad_request", "quality.lod_grid");
        th_resp_free(&r);
    }
    assert_int_equal(th_start(&s, TERRAD_BIN, args, NULL), 0);
    req(&s, "GET", "/v1/tiles/volcano/0/0/0.png?quality.lod_grid=isometric", NULL, NULL, &r);
    assert_int_equal(r.status, 200);
    assert_true(th_png_size(&r, &w, &h));
    assert_int_equal(w, 256);
    assert_int_equal(h, 256);
    assert_true(th_header(&r, "ETag", e1, sizeof e1));
    assert_true(th_header(&r, "X-Terrad-Height-Error", herr, sizeof herr));
    req(&s, "GET", "/v1/tiles/volcano/0/0/0.png?quality.lod_grid=square", NULL, NULL, &r2);
    assert_int_equal(r2.status, 200);
    assert_true(th_header(&r2, "ETag", e2, sizeof e2));
    assert_string_not_equal(e1, e2);
    th_resp_free(&r2);
    th_resp_free(&r);
    assert_int_equal(th_stop(&s), 0);
    th_forget(&s);
}

/* --- admin ------------------------------------------------------------------------------- */

static json_t *dataset_residency(const th_server *s, const char *id)
{
    th_resp r;
    char path[128];
    json_t *j, *res;
    snprintf(path, sizeof path, "/v1/datasets/%s", id);
    req(s, "GET", path, NULL, NULL, &r);
    assert_int_equal(r.status, 200);
    j = body_json(&r);
    res = json_incref(json_object_get(j, "residency"));
    json_decref(j);
    th_resp_free(&r);
    return res;
}

/* Submits a preload and waits for its job to finish; returns the final job JSON. */
static json_t *preload_wait(const th_server *s, const char *body)
{
    th_resp r;
    json_t *j;
    char loc[128];
    int id;
    req(s, "POST", "/v1/admin/preload", AUTH, body, &r);
    if (r.status != 202)
        fail_msg("preload: %ld %.*s", r.status, (int)r.len, r.body);
    assert_true(th_header(&r, "Location", loc, sizeof loc));
    j = body_json(&r);
    id = (int)json_integer_value(json_object_get(j, "id"));
    assert_true(id > 0);
    json_decref(j);
    th_resp_free(&r);
    for (int i = 0; i < 2000; i++) {
        const char *st;
        req(s, "GET", loc, AUTH, NULL, &r);
        assert_int_equal(r.status, 200);
        j = body_json(&r);
        th_resp_free(&r);
        assert_int_equal(json_integer_value(json_object_get(j, "id")), id);
        st = json_string_value(json_object_get(j, "state"));
        if (!strcmp(st, "done") || !strcmp(st, "failed"))
            return j;
        json_decref(j);
        usleep(20000);
    }
    fail_msg("job did not finish");
    return NULL;
}

static void test_admin_auth(void **state)
{
    th_resp r;
    char v[256];
    const char *wrong[] = {"Authorization: Bearer test-token-0123456788", "Content-Type: application/json", NULL};
    const char *shorter[] = {"Authorization: Bearer test", "Content-Type: application/json", NULL};
    const char *basic[] = {"Authorization: Basic dGVzdA==", "Content-Type: application/json", NULL};
    (void)state;
    req(&A, "POST", "/v1/admin/preload", JSON_CT, "{\"dataset\":\"volcano\"}", &r);
    assert_error(&r, 401, "unauthorized", NULL);
    assert_true(th_header(&r, "WWW-Authenticate", v, sizeof v));
    assert_int_equal(strncmp(v, "Bearer", 6), 0);
    th_resp_free(&r);
    req(&A, "POST", "/v1/admin/preload", wrong, "{\"dataset\":\"volcano\"}", &r);
    assert_error(&r, 401, "unauthorized", NULL);
    th_resp_free(&r);
    req(&A, "POST", "/v1/admin/preload", shorter, "{\"dataset\":\"volcano\"}", &r);
    assert_error(&r, 401, "unauthorized", NULL);
    th_resp_free(&r);
    req(&A, "POST", "/v1/admin/preload", basic, "{\"dataset\":\"volcano\"}", &r);
    assert_error(&r, 401, "unauthorized", NULL);
    th_resp_free(&r);
    req(&A, "GET", "/v1/admin/jobs/1", NULL, NULL, &r);
    assert_error(&r, 401, "unauthorized", NULL);
    th_resp_free(&r);
    req(&A, "DELETE", "/v1/admin/datasets/levi/tiles", wrong, NULL, &r);
    assert_error(&r, 401, "unauthorized", NULL);
    th_resp_free(&r);
}

static void test_admin_preload(void **state)
{
    th_resp r;
    json_t *j, *res;
    const char *const text_auth[] = {"Authorization: Bearer " TOKEN, "Content-Type: text/plain", NULL};
    (void)state;
    j = preload_wait(&A, "{\"dataset\":\"levi\",\"tiles\":\"all\",\"build\":[\"maxmip\",\"planes\"]}");
    assert_string_equal(json_string_value(json_object_get(j, "state")), "done");
    assert_int_equal(json_integer_value(json_object_get(json_object_get(j, "tiles"), "built")), 4);
    assert_int_equal(json_integer_value(json_object_get(json_object_get(j, "tiles"), "requested")), 4);
    assert_true(json_is_null(json_object_get(j, "error")));
    assert_true(json_real_value(json_object_get(j, "elapsed_s")) >= 0);
    json_decref(j);
    res = dataset_residency(&A, "levi");
    assert_int_equal(json_integer_value(json_object_get(res, "tiles")), 4);
    assert_int_equal(json_integer_value(json_object_get(res, "maxmip")), 4);
    assert_int_equal(json_integer_value(json_object_get(res, "planes")), 4);
    assert_true(json_integer_value(json_object_get(res, "accel_bytes")) > 0);
    json_decref(res);

    /* A render now says which tracers auto used: the max-mipmap, now resident (and the
     * walk where a ray crosses only a few cells of a tile). */
    req(&A, "POST", "/v1/render", JSON_CT, SCENE, &r);
    assert_int_equal(r.status, 200);
    {
        char v[160];
        assert_true(th_header(&r, "X-Terrad-Method", v, sizeof v));
        assert_int_equal(strncmp(v, "auto:", 5), 0);
        assert_non_null(strstr(v, "hierarchical"));
    }
    th_resp_free(&r);

    req(&A, "DELETE", "/v1/admin/datasets/levi/tiles", AUTH, NULL, &r);
    assert_int_equal(r.status, 200);
    j = body_json(&r);
    assert_int_equal(json_integer_value(json_object_get(j, "evicted")), 4);
    json_decref(j);
    th_resp_free(&r);
    res = dataset_residency(&A, "levi");
    assert_int_equal(json_integer_value(json_object_get(res, "tiles")), 0);
    assert_int_equal(json_integer_value(json_object_get(res, "accel_bytes")), 0);
    json_decref(res);

    /* One tile by box, pinned, maxmip only. */
    j = preload_wait(&A, "{\"dataset\":\"levi\",\"bbox\":[0,0,100,100],\"build\":[\"maxmip\"],\"pin\":true}");
    assert_string_equal(json_string_value(json_object_get(j, "state")), "done");
    assert_int_equal(json_integer_value(json_object_get(json_object_get(j, "tiles"), "requested")), 1);
    json_decref(j);
    res = dataset_residency(&A, "levi");
    assert_int_equal(json_integer_value(json_object_get(res, "tiles")), 1);
    assert_int_equal(json_integer_value(json_object_get(res, "maxmip")), 1);
    assert_int_equal(json_integer_value(json_object_get(res, "planes")), 0);
    assert_int_equal(json_integer_value(json_object_get(res, "pinned")), 1);
    json_decref(res);
    /* trinidad is lon/lat: a box in degrees around its south-west corner. */
    j = preload_wait(&A, "{\"dataset\":\"trinidad\",\"bbox_lonlat\":[-105.74,37.36,-105.70,37.38]}");
    json_decref(j);

    req(&A, "POST", "/v1/admin/preload", AUTH, "{\"dataset\":\"levi\",\"speed\":1}", &r);
    assert_error(&r, 400, "bad_request", "speed");
    th_resp_free(&r);
    req(&A, "POST", "/v1/admin/preload", AUTH, "{\"dataset\":\"levi\",\"tiles\":[[0,0],[9,9]]}", &r);
    assert_error(&r, 400, "bad_request", "tiles[1]");
    th_resp_free(&r);
    req(&A, "POST", "/v1/admin/preload", AUTH, "{\"dataset\":\"levi\",\"build\":[\"octree\"]}", &r);
    assert_error(&r, 400, "bad_request", "build[0]");
    th_resp_free(&r);
    req(&A, "POST", "/v1/admin/preload", AUTH, "{\"dataset\":\"levi\",\"pin\":\"yes\"}", &r);
    assert_error(&r, 400, "bad_request", "pin");
    th_resp_free(&r);
    req(&A, "POST", "/v1/admin/preload", AUTH, "{\"dataset\":\"levi\",\"bbox\":[0,0,1]}", &r);
    assert_error(&r, 400, "bad_request", "bbox");
    th_resp_free(&r);
    req(&A, "POST", "/v1/admin/preload", AUTH, "{\"dataset\":\"levi\",\"bbox_lonlat\":[0,0,1,1]}", &r);
    assert_error(&r, 400, "bad_request", "bbox_lonlat"); /* levi has no georeference */
    th_resp_free(&r);
    req(&A, "POST", "/v1/admin/preload", AUTH, "[1,2]", &r);
    assert_error(&r, 400, "bad_request", NULL);
    th_resp_free(&r);
    req(&A, "POST", "/v1/admin/preload", AUTH, "{\"dataset\":\"atlantis\"}", &r);
    assert_error(&r, 404, "unknown_dataset", "dataset");
    th_resp_free(&r);
    req(&A, "POST", "/v1/admin/preload", text_auth, "{\"dataset\":\"levi\"}", &r);
    assert_error(&r, 415, "unsupported_media_type", NULL);
    th_resp_free(&r);
    req(&A, "GET", "/v1/admin/preload", AUTH, NULL, &r);
    assert_error(&r, 405, "method_not_allowed", NULL);
    th_resp_free(&r);
    req(&A, "GET", "/v1/admin/jobs/999999", AUTH, NULL, &r);
    assert_error(&r, 404, "unknown_job", NULL);
    th_resp_free(&r);
    req(&A, "GET", "/v1/admin/jobs/abc", AUTH, NULL, &r);
    assert_error(&r, 404, "unknown_job", NULL);
    th_resp_free(&r);
    req(&A, "DELETE", "/v1/admin/datasets/atlantis/tiles", AUTH, NULL, &r);
    assert_error(&r, 404, "unknown_dataset", "dataset");
    th_resp_free(&r);
    req(&A, "POST", "/v1/admin/datasets/levi/tiles", AUTH, "{}", &r);
    assert_error(&r, 405, "method_not_allowed", NULL);
    th_resp_free(&r);
    req(&A, "DELETE", "/v1/admin/datasets/levi/tiles", AUTH, NULL, &r);
    assert_int_equal(r.status, 200);
    th_resp_free(&r);
}

/* --- renders while tiles are preloaded and evicted --------------------------------------- */

typedef struct render_loop {
    int n, ok, same, png;
    const char *scene;
    char *ref;
    size_t ref_len;
} render_loop;

static void *render_thread(void *arg)
{
    render_loop *L = arg;
    for (int i = 0; i < L->n; i++) {
        th_resp r;
        int w, h;
        if (th_request(&A, "POST", "/v1/render", JSON_CT, L->scene, strlen(L->scene), &r) == 0) {
            L->ok += r.status == 200;
            L->png += th_png_size(&r, &w, &h) && w == 48 && h == 32;
            L->same += L->ref && r.len == L->ref_len && !memcmp(r.body, L->ref, r.len);
        }
        th_resp_free(&r);
    }
    return NULL;
}

static void test_render_during_preload_and_evict(void **state)
{
    /* The incremental tracer never reads acceleration: its pictures must be identical
     * whatever is resident. The auto renders use whatever a snapshot holds. */
    const char *inc = "{\"dataset\":\"trinidad\",\"camera\":{\"position\":{\"x\":20000,\"y\":-3000,\"z\":5200},"
                      "\"pitch\":-12},\"image\":{\"width\":48,\"height\":32},"
                      "\"quality\":{\"method\":\"incremental\"}}";
    const char *aut = "{\"dataset\":\"trinidad\",\"camera\":{\"position\":{\"x\":20000,\"y\":-3000,\"z\":5200},"
                      "\"pitch\":-12},\"image\":{\"width\":48,\"height\":32},"
                      "\"quality\":{\"method\":\"auto\"}}";
    render_loop a = {12, 0, 0, 0, inc, NULL, 0}, b = {12, 0, 0, 0, aut, NULL, 0};
    pthread_t ta, tb;
    th_resp ref;
    int rounds = 0;
    (void)state;
    req(&A, "POST", "/v1/render", JSON_CT, inc, &ref);
    assert_int_equal(ref.status, 200);
    a.ref = ref.body;
    a.ref_len = ref.len;
    assert_int_equal(pthread_create(&ta, NULL, render_thread, &a), 0);
    assert_int_equal(pthread_create(&tb, NULL, render_thread, &b), 0);
    for (rounds = 0; rounds < 4; rounds++) {
        th_resp r;
        json_t *j = preload_wait(&A, "{\"dataset\":\"trinidad\",\"rebuild\":true}");
        assert_string_equal(json_string_value(json_object_get(j, "state")), "done");
        assert_int_equal(json_integer_value(json_object_get(json_object_get(j, "tiles"), "built")), 6);
        json_decref(j);
        req(&A, "DELETE", "/v1/admin/datasets/trinidad/tiles", AUTH, NULL, &r);
        assert_int_equal(r.status, 200);
        th_resp_free(&r);
    }
    pthread_join(ta, NULL);
    pthread_join(tb, NULL);
    th_resp_free(&ref);
    assert_int_equal(a.ok, a.n);
    assert_int_equal(a.png, a.n);
    assert_int_equal(a.same, a.n);
    assert_int_equal(b.ok, b.n);
    assert_int_equal(b.png, b.n);
}

/* A sun bound is built by the first render with a sun, built again finer by the second
 * (a kept bound's blocks, sunlit.c) and kept with the dataset for the next ones
 * (X-Terrad-Sun-Bound, /metrics): the same picture every time. */
static void test_render_sun_bound_kept(void **state)
{
    th_resp r[4];
    char v[128];
    const char *scene = "{\"dataset\":\"trinidad\",\"camera\":{\"position\":{\"x\":22000,\"y\":2000,"
                        "\"z\":4300},\"pitch\":-8},\"image\":{\"width\":64,\"height\":48},"
                        "\"effects\":{\"shadows\":true,\"sun\":{\"azimuth\":123.25,\"elevation\":17.5}}}";
    (void)state;
    for (int k = 0; k < 3; k++) {
        req(&A, "POST", "/v1/render", JSON_CT, scene, &r[k]);
        assert_int_equal(r[k].status, 200);
        assert_true(th_header(&r[k], "X-Terrad-Sun-Bound", v, sizeof v));
        assert_string_equal(v, k < 2 ? "built" : "kept");
        assert_int_equal(r[0].len, r[k].len);
        assert_memory_equal(r[0].body, r[k].body, r[0].len);
    }
    /* no shadows: no bound */
    req(&A, "POST", "/v1/render", JSON_CT,
        "{\"dataset\":\"trinidad\",\"camera\":{\"position\":{\"x\":22000,\"y\":2000,\"z\":4300},\"pitch\":-8},"
        "\"image\":{\"width\":64,\"height\":48}}", &r[3]);
    assert_int_equal(r[3].status, 200);
    assert_false(th_header(&r[3], "X-Terrad-Sun-Bound", v, sizeof v));
    for (int k = 0; k < 4; k++)
        th_resp_free(&r[k]);
    req(&A, "GET", "/metrics", NULL, NULL, &r[0]);
    assert_int_equal(r[0].status, 200);
    {
        const char *p = strstr(r[0].body, "terrad_sun_bounds_total{result=\"kept\"} ");
        const char *q = strstr(r[0].body, "\nterrad_sun_bounds_bytes ");
        assert_non_null(p);
        assert_non_null(q);
        assert_true(atoll(p + strlen("terrad_sun_bounds_total{result=\"kept\"} ")) >= 1);
        assert_true(atoll(q + strlen("\nterrad_sun_bounds_bytes ")) > 0);
    }
    th_resp_free(&r[0]);
}

/* --- metrics (after the requests above) ---------------------------------------------------- */

static void test_metrics(void **state)
{
    th_resp r;
    char v[128];
    (void)state;
    req(&A, "GET", "/metrics", NULL, NULL, &r);
    assert_int_equal(r.status, 200);
    assert_true(th_header(&r, "Content-Type", v, sizeof v));
    assert_int_equal(strncmp(v, "text/plain", 10), 0);
    assert_non_null(strstr(r.body, "terrad_requests_total{route=\"healthz\",status=\"200\"} "));
    assert_non_null(strstr(r.body, "terrad_requests_total{route=\"render\",status=\"400\"} "));
    assert_non_null(strstr(r.body, "terrad_requests_total{route=\"admin_preload\",status=\"401\"} "));
    assert_non_null(strstr(r.body, "# TYPE terrad_render_seconds histogram"));
    assert_non_null(strstr(r.body, "terrad_render_seconds_bucket{method=\"incremental\",le=\"+Inf\"} "));
    assert_non_null(strstr(r.body, "terrad_rays_total "));
    assert_null(strstr(r.body, "terrad_rays_total 0\n"));
    assert_non_null(strstr(r.body, "terrad_resident_tiles "));
    assert_non_null(strstr(r.body, "terrad_build_jobs{state=\"done\"} "));
    assert_non_null(strstr(r.body, "terrad_datasets 3\n"));
    assert_non_null(strstr(r.body, "terrad_render_queue_capacity 18\n"));
    /* per dataset: what this replica serves and keeps (a proxy routes by dataset) */
    assert_non_null(strstr(r.body, "# TYPE terrad_dataset_requests_total counter\n"));
    assert_non_null(strstr(r.body, "terrad_dataset_resident_tiles{dataset=\"levi\"} "));
    assert_non_null(strstr(r.body, "terrad_dataset_resident_bytes{dataset=\"volcano\"} "));
    assert_null(strstr(r.body, "terrad_dataset_requests_total{dataset=\"levi\"} 0\n"));
    th_resp_free(&r);
}

/* effects.sun.time: the sun of that instant over the dataset's centre, said in X-Terrad-Sun,
 * and the picture the same as with that azimuth and elevation given. */
static void test_render_sun_time(void **state)
{
    th_resp r, r2;
    char v[128], body[512];
    double az = 0, el = 0;
    const char *scene = "{\"dataset\":\"trinidad\",\"camera\":{\"position\":{\"x\":22000,\"y\":2000,"
                        "\"z\":4300},\"pitch\":-8},\"image\":{\"width\":64,\"height\":48},"
                        "\"effects\":{\"shadows\":true,\"sun\":{%s}}}";
    (void)state;
    /* 21 June, 18:00 UTC: about 11:00 local solar time in Colorado, sun high in the south-east */
    snprintf(body, sizeof body, scene, "\"time\":\"2026-06-21T18:00:00Z\"");
    req(&A, "POST", "/v1/render", JSON_CT, body, &r);
    assert_int_equal(r.status, 200);
    assert_true(th_header(&r, "X-Terrad-Sun", v, sizeof v));
    assert_int_equal(sscanf(v, "azimuth=%lf; elevation=%lf", &az, &el), 2);
    assert_true(az > 100.0 && az < 160.0);
    assert_true(el > 55.0 && el < 75.0);
    snprintf(body, sizeof body, scene, "\"azimuth\":%.17g,\"elevation\":%.17g");
    {
        char b2[512];
        snprintf(b2, sizeof b2, body, az, el);
        req(&A, "POST", "/v1/render", JSON_CT, b2, &r2);
    }
    assert_int_equal(r2.status, 200);
    assert_int_equal(r.len, r2.len);
    assert_memory_equal(r.body, r2.body, r.len);
    th_resp_free(&r);
    th_resp_free(&r2);
    /* 08:00 UTC is 01:00 there: the sun is down */
    snprintf(body, sizeof body, scene, "\"time\":\"2026-06-21T08:00:00Z\"");
    req(&A, "POST", "/v1/render", JSON_CT, body, &r);
    assert_int_equal(r.status, 200);
    assert_true(th_header(&r, "X-Terrad-Sun", v, sizeof v));
    assert_int_equal(sscanf(v, "azimuth=%lf; elevation=%lf", &az, &el), 2);
    assert_true(el < 0.0);
    th_resp_free(&r);
    /* refusals name the field */
    snprintf(body, sizeof body, scene, "\"time\":\"2026-02-30T12:00Z\"");
    req(&A, "POST", "/v1/render", JSON_CT, body, &r);
    assert_error(&r, 400, "bad_request", "effects.sun.time");
    th_resp_free(&r);
    snprintf(body, sizeof body, scene, "\"time\":\"2026-06-21T18:00Z\",\"azimuth\":90");
    req(&A, "POST", "/v1/render", JSON_CT, body, &r);
    assert_error(&r, 400, "bad_request", "effects.sun.time");
    th_resp_free(&r);
    req(&A, "POST", "/v1/render", JSON_CT,
        "{\"dataset\":\"volcano\",\"camera\":{\"position\":{\"x\":300,\"y\":-400,\"z\":450}},"
        "\"image\":{\"width\":16,\"height\":16},\"effects\":{\"sun\":{\"time\":\"2026-06-21\"}}}", &r);
    assert_error(&r, 400, "bad_request", "effects.sun.time"); /* no georeference */
    th_resp_free(&r);
}

/* `?dataset=` on a POST is the key a proxy routes on: it must agree with the body's. */
static void test_dataset_routing_key(void **state)
{
    th_resp r;
    (void)state;
    req(&A, "POST", "/v1/render?dataset=volcano", JSON_CT, SCENE, &r);
    assert_error(&r, 400, "bad_request", "dataset");
    assert_non_null(strstr(r.body, "'levi' differs from the query's 'volcano'"));
    th_resp_free(&r);
    req(&A, "POST", "/v1/render?dataset=levi", JSON_CT, SCENE, &r);
    assert_int_equal(r.status, 200);
    th_resp_free(&r);
    /* the same rule where the body is another endpoint's (the shared deferral) */
    req(&A, "POST", "/v1/los?dataset=volcano", JSON_CT,
        "{\"dataset\":\"levi\",\"from\":{\"x\":4000,\"y\":4000,\"height\":2},"
        "\"to\":{\"x\":5000,\"y\":5000,\"height\":2}}", &r);
    assert_error(&r, 400, "bad_request", "dataset");
    th_resp_free(&r);
}

/* --- static web -------------------------------------------------------------------------- */

static void test_web(void **state)
{
    th_resp r;
    char v[128];
    (void)state;
    req(&A, "GET", "/", NULL, NULL, &r);
    assert_int_equal(r.status, 200);
    assert_non_null(strstr(r.body, "terrad test"));
    assert_true(th_header(&r, "Content-Type", v, sizeof v));
    assert_string_equal(v, "text/html; charset=utf-8");
    th_resp_free(&r);
    req(&A, "GET", "/js/app.js", NULL, NULL, &r);
    assert_int_equal(r.status, 200);
    assert_true(th_header(&r, "Content-Type", v, sizeof v));
    assert_string_equal(v, "text/javascript; charset=utf-8");
    th_resp_free(&r);
    /* only the page's own files: not package.json, tests or node_modules */
    req(&A, "GET", "/package.json", NULL, NULL, &r);
    assert_error(&r, 404, "not_found", NULL);
    th_resp_free(&r);
    req(&A, "GET", "/../secret.txt", NULL, NULL, &r);
    assert_int_equal(r.status, 404);
    assert_null(strstr(r.body, "secret"));
    th_resp_free(&r);
    req(&A, "GET", "/%2e%2e/secret.txt", NULL, NULL, &r);
    assert_int_equal(r.status, 404);
    th_resp_free(&r);
    req(&A, "GET", "/.hidden", NULL, NULL, &r);
    assert_int_equal(r.status, 404);
    th_resp_free(&r);
    req(&A, "GET", "/nope.html", NULL, NULL, &r);
    assert_error(&r, 404, "not_found", NULL);
    th_resp_free(&r);
    req(&A, "GET", "/vendor/leaflet/../../../secret.txt", NULL, NULL, &r);
    assert_int_equal(r.status, 404);
    th_resp_free(&r);
    req(&A, "POST", "/", JSON_CT, "{}", &r);
    assert_error(&r, 405, "method_not_allowed", NULL);
    th_resp_free(&r);
}

/* --- other servers ----------------------------------------------------------------------- */

static void test_admin_disabled(void **state)
{
    th_server s;
    th_resp r;
    const char *args[] = {"--demo-dir", TERRAD_DATA_DIR, "--preload", "none", NULL};
    const char *env[] = {"TERRAD_ADMIN_TOKEN=", NULL};
    (void)state;
    assert_int_equal(th_start(&s, TERRAD_BIN, args, env), 0);
    req(&s, "POST", "/v1/admin/preload", AUTH, "{\"dataset\":\"levi\"}", &r);
    assert_error(&r, 404, "admin_disabled", NULL);
    th_resp_free(&r);
    req(&s, "GET", "/v1/admin/jobs/1", AUTH, NULL, &r);
    assert_error(&r, 404, "admin_disabled", NULL);
    th_resp_free(&r);
    assert_true(th_log_has(&s, "admin_token=unset"));
    assert_int_equal(th_stop(&s), 0);
    th_forget(&s);
}

/* A rolled camera whose image leaves a block of one pixel at its corner (65 x 17: blocks
 * of 16), on a server that preloads its datasets (the camera devices run on their
 * resident max-mipmaps): before 2026-11-30 the band sort divided by the block's zero
 * width and wrote 8 GB below its counts (fuzz_render; test_render's
 * test_rolled_corner_block). A daemon started by hand died of it; this one's write
 * happened to land in mapped memory (the address sanitizer's build of this test sees
 * it). Answered, and the next request too. */
static void test_render_rolled_corner(void **state)
{
    th_server s;
    th_resp r;
    const char *args[] = {"--demo-dir", TERRAD_DATA_DIR, "--render-workers", "2", NULL};
    (void)state;
    assert_int_equal(th_start(&s, TERRAD_BIN, args, NULL), 0);
    for (int k = 0, w = 0, h = 0; k < 2; k++) {
        req(&s, "POST", "/v1/render", JSON_CT,
            "{\"dataset\":\"levi\",\"camera\":{\"position\":{\"x\":4000,\"y\":-2000,\"z\":1500},\"pitch\":-15,"
            "\"roll\":35},\"image\":{\"width\":65,\"height\":17}}", &r);
        assert_int_equal(r.status, 200);
        assert_true(th_png_size(&r, &w, &h));
        assert_int_equal(w, 65);
        assert_int_equal(h, 17);
        th_resp_free(&r);
    }
    assert_int_equal(th_stop(&s), 0);
    th_forget(&s);
}

static void test_budget_refusal(void **state)
{
    /* Heights and levels of detail: levi 0.98 MB, trinidad 1.90 MB, volcano 0.04 MB. In
     * 2 MiB trinidad's do not fit beside the others: skipped at load. In 3 MiB all three
     * fit, with 0.43 MB to spare: volcano's acceleration (0.01 MB) and levi's (0.26 MB,
     * pinned) fit, trinidad's (up to 0.43 MB) cannot be added beside them. */
    th_server s;
    th_resp r;
    json_t *j, *res;
    const char *args2[] = {"--demo-dir", TERRAD_DATA_DIR, "--preload", "none", "--memory-mb", "2", NULL};
    const char *args[] = {"--demo-dir", TERRAD_DATA_DIR, "--preload", "none", "--memory-mb", "3", NULL};
    const char *env[] = {"TERRAD_ADMIN_TOKEN=" TOKEN, NULL};
    (void)state;
    assert_int_equal(th_start(&s, TERRAD_BIN, args2, env), 0);
    assert_true(th_log_has(&s, "event=dataset_skipped id=trinidad"));
    req(&s, "GET", "/v1/datasets", NULL, NULL, &r);
    j = body_json(&r);
    assert_int_equal(json_array_size(j), 2);
    json_decref(j);
    th_resp_free(&r);
    assert_int_equal(th_stop(&s), 0);
    th_forget(&s);

    assert_int_equal(th_start(&s, TERRAD_BIN, args, env), 0);
    req(&s, "GET", "/v1/datasets", NULL, NULL, &r);
    j = body_json(&r);
    assert_int_equal(json_array_size(j), 3);
    json_decref(j);
    th_resp_free(&r);
    j = preload_wait(&s, "{\"dataset\":\"volcano\"}");
    assert_string_equal(json_string_value(json_object_get(j, "state")), "done");
    json_decref(j);
    j = preload_wait(&s, "{\"dataset\":\"levi\",\"pin\":true}");
    assert_string_equal(json_string_value(json_object_get(j, "state")), "done");
    json_decref(j);
    j = preload_wait(&s, "{\"dataset\":\"trinidad\"}");
    assert_string_equal(json_string_value(json_object_get(j, "state")), "failed");
    assert_string_equal(json_string_value(json_object_get(json_object_get(j, "error"), "code")), "too_big");
    assert_non_null(strstr(json_string_value(json_object_get(json_object_get(j, "error"), "message")),
                           "budget"));
    json_decref(j);
    res = dataset_residency(&s, "trinidad");
    assert_int_equal(json_integer_value(json_object_get(res, "tiles")), 0);
    json_decref(res);
    res = dataset_residency(&s, "volcano"); /* untouched by the failed preload */
    assert_int_equal(json_integer_value(json_object_get(res, "tiles")), 1);
    json_decref(res);
    assert_int_equal(th_stop(&s), 0);
    th_forget(&s);
}

typedef struct acc {
    char buf[4096];
    size_t len;
} acc;

static size_t acc_cb(char *data, size_t size, size_t nmemb, void *cls)
{
    acc *a = cls;
    size_t n = size * nmemb, room = sizeof a->buf - 1 - a->len;
    memcpy(a->buf + a->len, data, n < room ? n : room);
    a->len += n < room ? n : room;
    a->buf[a->len] = '\0';
    return n;
}

static void test_queue_full(void **state)
{
    /* One worker, no queue: of requests sent together, those that find the worker busy
     * are refused at once with 503 + Retry-After instead of waiting. */
    th_server s;
    const char *args[] = {"--demo-dir", TERRAD_DATA_DIR, "--preload", "none", "--render-workers", "1",
                          "--queue", "0", NULL};
    const char *heavy = "{\"dataset\":\"trinidad\",\"camera\":{\"position\":{\"x\":20000,\"y\":-3000,\"z\":5200},"
                        "\"pitch\":-12},\"image\":{\"width\":640,\"height\":480},"
                        "\"quality\":{\"method\":\"incremental\",\"samples\":2},\"effects\":{\"shadows\":true}}";
    enum { N = 6 };
    CURLM *m;
    CURL *c[N];
    static acc hdr[N], body[N];
    struct curl_slist *hl = NULL;
    char url[128];
    int running = 0, n200 = 0, n503 = 0;
    (void)state;
    assert_int_equal(th_start(&s, TERRAD_BIN, args, NULL), 0);
    snprintf(url, sizeof url, "http://127.0.0.1:%d/v1/render", s.port);
    hl = curl_slist_append(hl, "Content-Type: application/json");
    m = curl_multi_init();
    for (int i = 0; i < N; i++) {
        hdr[i].len = body[i].len = 0;
        c[i] = curl_easy_init();
        curl_easy_setopt(c[i], CURLOPT_URL, url);
        curl_easy_setopt(c[i], CURLOPT_POSTFIELDS, heavy);
        curl_easy_setopt(c[i], CURLOPT_HTTPHEADER, hl);
        curl_easy_setopt(c[i], CURLOPT_WRITEFUNCTION, acc_cb);
        curl_easy_setopt(c[i], CURLOPT_WRITEDATA, &body[i]);
        curl_easy_setopt(c[i], CURLOPT_HEADERFUNCTION, acc_cb);
        curl_easy_setopt(c[i], CURLOPT_HEADERDATA, &hdr[i]);
        curl_multi_add_handle(m, c[i]);
    }
    do {
        curl_multi_perform(m, &running);
        curl_multi_wait(m, NULL, 0, 100, NULL);
    } while (running);
    for (int i = 0; i < N; i++) {
        long st = 0;
        curl_easy_getinfo(c[i], CURLINFO_RESPONSE_CODE, &st);
        n200 += st == 200;
        if (st == 503) {
            n503++;
            assert_non_null(strstr(hdr[i].buf, "Retry-After: 1\r\n"));
            assert_non_null(strstr(body[i].buf, "\"code\":\"busy\""));
        }
        curl_multi_remove_handle(m, c[i]);
        curl_easy_cleanup(c[i]);
    }
    curl_multi_cleanup(m);
    curl_slist_free_all(hl);
    assert_true(n200 >= 1);
    assert_true(n503 >= 1);
    assert_int_equal(n200 + n503, N);
    assert_int_equal(th_stop(&s), 0);
    th_forget(&s);
}

static const char *HEAVY =
    "{\"dataset\":\"trinidad\",\"camera\":{\"position\":{\"x\":20000,\"y\":-3000,\"z\":5200},"
    "\"pitch\":-12},\"image\":{\"width\":960,\"height\":720},"
    "\"quality\":{\"method\":\"incremental\",\"samples\":2},\"effects\":{\"shadows\":true}}";

typedef struct bg_render {
    const th_server *s;
    long status;
    int w, h;
} bg_render;

static void *bg_render_main(void *arg)
{
    bg_render *b = arg;
    th_resp r;
    if (th_request(b->s, "POST", "/v1/render", JSON_CT, HEAVY, strlen(HEAVY), &r) == 0) {
        b->status = r.status;
        th_png_size(&r, &b->w, &b->h);
    }
    th_resp_free(&r);
    return NULL;
}

static void test_sigterm_finishes_inflight(void **state)
{
    /* A render running when SIGTERM arrives is finished and answered; then exit 0. */
    th_server s;
    const char *args[] = {"--demo-dir", TERRAD_DATA_DIR, "--preload", "none", "--render-workers", "1",
                          "--shutdown-timeout", "60", NULL};
    bg_render b = {&s, 0, 0, 0};
    pthread_t t;
    int seen = 0;
    (void)state;
    assert_int_equal(th_start(&s, TERRAD_BIN, args, NULL), 0);
    assert_int_equal(pthread_create(&t, NULL, bg_render_main, &b), 0);
    for (int i = 0; i < 1000 && !seen; i++) {
        th_resp r;
        req(&s, "GET", "/metrics", NULL, NULL, &r);
        seen = strstr(r.body, "terrad_render_queue_depth 1\n") != NULL;
        th_resp_free(&r);
        if (!seen)
            usleep(5000);
    }
    assert_true(seen);
    assert_int_equal(th_stop(&s), 0);
    pthread_join(t, NULL);
    assert_int_equal(b.status, 200);
    assert_int_equal(b.w, 960);
    assert_int_equal(b.h, 720);
    assert_true(th_log_has(&s, "event=stopped unfinished_at_deadline=0"));
    th_forget(&s);
}

static void test_render_timeout(void **state)
{
    /* A render past --render-timeout is cancelled: 503 render_timeout, not a hung worker. */
    th_server s;
    th_resp r;
    const char *args[] = {"--demo-dir", TERRAD_DATA_DIR, "--preload", "none", "--render-timeout", "0.01", NULL};
    (void)state;
    assert_int_equal(th_start(&s, TERRAD_BIN, args, NULL), 0);
    req(&s, "POST", "/v1/render", JSON_CT, HEAVY, &r);
    assert_error(&r, 503, "render_timeout", NULL);
    th_resp_free(&r);
    /* The worker is free again, and the 503 is counted (the count lands when the
     * response is complete, which may be just after the client read it: poll). */
    for (int i = 0, ok = 0; !ok; i++) {
        req(&s, "GET", "/metrics", NULL, NULL, &r);
        ok = strstr(r.body, "terrad_render_queue_depth 0\n") &&
             strstr(r.body, "terrad_requests_total{route=\"render\",status=\"503\"} 1\n");
        th_resp_free(&r);
        assert_true(ok || i < 200);
        if (!ok)
            usleep(5000);
    }
    assert_int_equal(th_stop(&s), 0);
    th_forget(&s);
}

static void test_token_file_and_limits(void **state)
{
    /* The token from --admin-token-file (trailing newline trimmed) wins over the
     * variable; at most 2 connections per address; HEAD answers headers only. */
    th_server s;
    th_resp r;
    char tok[256];
    const char *args[] = {"--demo-dir", TERRAD_DATA_DIR, "--preload", "none", "--admin-token-file", tok,
                          "--per-ip-connections", "2", NULL};
    const char *env[] = {"TERRAD_ADMIN_TOKEN=" TOKEN, NULL};
    const char *file_auth[] = {"Authorization: Bearer from-the-file", "Content-Type: application/json", NULL};
    int fds[3];
    struct sockaddr_in a;
    (void)state;
    snprintf(tok, sizeof tok, "%s/terrad-token-%ld", P_tmpdir, (long)getpid());
    write_file(tok, "from-the-file\n");
    assert_int_equal(th_start(&s, TERRAD_BIN, args, env), 0);
    memset(&a, 0, sizeof a);
    a.sin_family = AF_INET;
    a.sin_port = htons((uint16_t)s.port);
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    {
        /* Two connections, each proven accepted by an answer (kept alive), then a third,
         * which the server closes unanswered. The server notices earlier clients' closes
         * (th_start's readiness probe) on its own time, so the first two are retried until
         * both are answered. */
        char buf[512];
        const char *get = "GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n";
        ssize_t n;
        int open2 = 0;
        for (int attempt = 0; !open2; attempt++) {
            open2 = 1;
            for (int i = 0; i < 2; i++) {
                fds[i] = socket(AF_INET, SOCK_STREAM, 0);
                assert_true(fds[i] >= 0);
                assert_int_equal(connect(fds[i], (struct sockaddr *)&a, sizeof a), 0);
                n = write(fds[i], get, strlen(get));
                n = open2 ? read(fds[i], buf, sizeof buf - 1) : 0;
                if (n > 12) {
                    buf[n] = '\0';
                    assert_non_null(strstr(buf, "HTTP/1.1 200"));
                } else {
                    open2 = 0;
                }
            }
            if (!open2) {
                close(fds[0]);
                close(fds[1]);
                assert_true(attempt < 200);
                usleep(20000);
            }
        }
        fds[2] = socket(AF_INET, SOCK_STREAM, 0);
        assert_true(fds[2] >= 0);
        assert_int_equal(connect(fds[2], (struct sockaddr *)&a, sizeof a), 0);
        n = write(fds[2], get, strlen(get));
        n = read(fds[2], buf, sizeof buf - 1);
        assert_true(n <= 0);
    }
    for (int i = 0; i < 3; i++)
        close(fds[i]);
    /* The server notices the closes on its own time: poll until a slot is free. */
    for (int i = 0, ok = 0; !ok; i++) {
        ok = th_request(&s, "GET", "/healthz", NULL, NULL, 0, &r) == 0 && r.status == 200;
        th_resp_free(&r);
        assert_true(ok || i < 500);
        if (!ok)
            usleep(10000);
    }
    req_limited(&s, "POST", "/v1/admin/preload", AUTH, "{\"dataset\":\"volcano\"}", &r);
    assert_error(&r, 401, "unauthorized", NULL);
    th_resp_free(&r);
    req_limited(&s, "POST", "/v1/admin/preload", file_auth, "{\"dataset\":\"volcano\"}", &r);
    assert_int_equal(r.status, 202);
    th_resp_free(&r);

    req_limited(&s, "HEAD", "/v1/datasets", NULL, NULL, &r);
    assert_int_equal(r.status, 200);
    assert_int_equal(r.len, 0);
    th_resp_free(&r);

    assert_int_equal(th_stop(&s), 0);
    th_forget(&s);
    unlink(tok);
}

static void test_data_dir_and_empty(void **state)
{
    /* --data DIR makes datasets of its files (id = name without extension); with no
     * dataset at all terrad still starts, says so, and serves an empty list. */
    th_server s;
    th_resp r;
    json_t *j;
    char dir[256], p[512], cmd[600];
    const char *args[] = {"--demo-dir", "", "--data", dir, "--preload", "none", NULL};
    const char *empty[] = {"--demo-dir", "", "--preload", "none", NULL};
    FILE *in, *out;
    char buf[4096];
    size_t n;
    (void)state;
    snprintf(dir, sizeof dir, "%s/terrad-data-%ld", P_tmpdir, (long)getpid());
    mkdir(dir, 0755);
    snprintf(p, sizeof p, "%s/mt-eden.asc", dir);
    in = fopen(TERRAD_DATA_DIR "/volcano/volcano.asc", "rb");
    out = fopen(p, "wb");
    assert_non_null(in);
    assert_non_null(out);
    while ((n = fread(buf, 1, sizeof buf, in)) > 0)
        fwrite(buf, 1, n, out);
    fclose(in);
    fclose(out);

    assert_int_equal(th_start(&s, TERRAD_BIN, args, NULL), 0);
    req(&s, "GET", "/v1/datasets", NULL, NULL, &r);
    j = body_json(&r);
    assert_int_equal(json_array_size(j), 1);
    assert_string_equal(json_string_value(json_object_get(json_array_get(j, 0), "id")), "mt-eden");
    assert_string_equal(json_string_value(json_object_get(json_array_get(j, 0), "origin")), "data");
    json_decref(j);
    th_resp_free(&r);
    assert_int_equal(th_stop(&s), 0);
    th_forget(&s);

    assert_int_equal(th_start(&s, TERRAD_BIN, empty, NULL), 0);
    assert_true(th_log_has(&s, "event=no_datasets"));
    req(&s, "GET", "/v1/datasets", NULL, NULL, &r);
    assert_int_equal(r.status, 200);
    j = body_json(&r);
    assert_int_equal(json_array_size(j), 0);
    json_decref(j);
    th_resp_free(&r);
    req(&s, "GET", "/healthz", NULL, NULL, &r);
    assert_int_equal(r.status, 200);
    th_resp_free(&r);
    assert_int_equal(th_stop(&s), 0);
    th_forget(&s);
    snprintf(cmd, sizeof cmd, "rm -rf %s", dir);
    assert_int_equal(system(cmd), 0);
}

int main(void)
{
    const struct CMUnitTest with_a[] = {
        cmocka_unit_test(test_health),
        cmocka_unit_test(test_datasets),
        cmocka_unit_test(test_render_post),
        cmocka_unit_test(test_render_get_etag),
        cmocka_unit_test(test_render_errors),
        cmocka_unit_test(test_render_never_500),
        cmocka_unit_test(test_pick),
        cmocka_unit_test(test_tiles),
        cmocka_unit_test(test_tiles_isometric),
        cmocka_unit_test(test_admin_auth),
        cmocka_unit_test(test_admin_preload),
        cmocka_unit_test(test_render_during_preload_and_evict),
        cmocka_unit_test(test_web),
        cmocka_unit_test(test_render_sun_bound_kept),
        cmocka_unit_test(test_metrics),
        cmocka_unit_test(test_dataset_routing_key),
        cmocka_unit_test(test_render_sun_time),
    };
    const struct CMUnitTest others[] = {
        cmocka_unit_test(test_admin_disabled),
        cmocka_unit_test(test_render_rolled_corner),
        cmocka_unit_test(test_budget_refusal),
        cmocka_unit_test(test_queue_full),
        cmocka_unit_test(test_sigterm_finishes_inflight),
        cmocka_unit_test(test_render_timeout),
        cmocka_unit_test(test_token_file_and_limits),
        cmocka_unit_test(test_data_dir_and_empty),
    };
    int rc;
    curl_global_init(CURL_GLOBAL_ALL);
    rc = cmocka_run_group_tests_name("server with admin", with_a, setup_a, teardown_a);
    rc += cmocka_run_group_tests_name("other servers", others, NULL, NULL);
    curl_global_cleanup();
    return rc;
}
