/* test_static.c: the web page's files (server/static.c): MIME types by extension, which
 * URL paths are the page's, and serving a folder: a file with its type and cache
 * headers, a folder's index.html, and refusals of `..`, hidden files, empty segments,
 * backslashes, links out of the folder and a missing folder. */
#include <limits.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cmocka.h>

#include "static.h"

static char root[PATH_MAX];

static void put(const char *rel, const char *text)
{
    char p[PATH_MAX + 64];
    FILE *f;
    snprintf(p, sizeof p, "%s/%s", root, rel);
    f = fopen(p, "wb");
    assert_non_null(f);
    fputs(text, f);
    fclose(f);
}

static int setup(void **state)
{
    char tmpl[] = "/tmp/td-static-XXXXXX", p[PATH_MAX + 64];
    (void)state;
    assert_non_null(mkdtemp(tmpl));
    assert_non_null(realpath(tmpl, root));
    snprintf(p, sizeof p, "%s/js", root);
    assert_int_equal(mkdir(p, 0700), 0);
    snprintf(p, sizeof p, "%s/docs", root);
    assert_int_equal(mkdir(p, 0700), 0);
    put("index.html", "<p>map</p>");
    put("js/app.js", "let a = 1;");
    put("docs/index.html", "docs");
    put(".secret", "no");
    snprintf(p, sizeof p, "%s/out", root);
    assert_int_equal(symlink("/etc/passwd", p), 0);
    return 0;
}

static int teardown(void **state)
{
    char cmd[PATH_MAX + 16];
    (void)state;
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", root);
    return system(cmd) == 0 ? 0 : -1;
}

static const char *header(const td_http_resp *r, const char *name)
{
    for (int i = 0; i < r->nheaders; i++)
        if (!strcmp(r->hname[i], name))
            return r->hvalue[i];
    return NULL;
}

static void test_mime(void **state)
{
    (void)state;
    assert_string_equal(td_static_mime("/a/b/app.js"), "text/javascript; charset=utf-8");
    assert_string_equal(td_static_mime("x.PNG"), "image/png");
    assert_string_equal(td_static_mime("style.css"), "text/css; charset=utf-8");
    assert_string_equal(td_static_mime("README"), "application/octet-stream");
    assert_string_equal(td_static_mime("v1.2/README"), "application/octet-stream"); /* dot in a folder */
    assert_string_equal(td_static_mime("a.tar.gz"), "application/octet-stream");
}

static void test_page_paths(void **state)
{
    (void)state;
    assert_true(td_static_is_page("/"));
    assert_true(td_static_is_page("/index.html"));
    assert_true(td_static_is_page("/js/app.js"));
    assert_true(td_static_is_page("/favicon.ico"));
    assert_false(td_static_is_page("/package.json"));
    assert_false(td_static_is_page("/test/browser.test.mjs"));
    assert_false(td_static_is_page("/node_modules/leaflet/dist/leaflet.js"));
}

static void test_serve(void **state)
{
    td_http_resp r;
    td_err e = {0};
    (void)state;

    memset(&r, 0, sizeof r);
    assert_int_equal(td_static_serve(root, "js/app.js", 0, &r, &e), TD_OK);
    assert_int_equal(r.status, 200);
    assert_int_equal(r.len, strlen("let a = 1;"));
    assert_memory_equal(r.body, "let a = 1;", r.len);
    assert_string_equal(r.content_type, "text/javascript; charset=utf-8");
    assert_string_equal(header(&r, "Cache-Control"), "no-cache");
    assert_string_equal(header(&r, "X-Content-Type-Options"), "nosniff");
    free(r.body);

    memset(&r, 0, sizeof r);
    assert_int_equal(td_static_serve(root, "", 1, &r, &e), TD_OK); /* the folder's index */
    assert_memory_equal(r.body, "<p>map</p>", r.len);
    assert_string_equal(header(&r, "Cache-Control"), "public, max-age=86400");
    free(r.body);

    memset(&r, 0, sizeof r);
    assert_int_equal(td_static_serve(root, "docs", 0, &r, &e), TD_OK);
    assert_memory_equal(r.body, "docs", r.len);
    assert_string_equal(r.content_type, "text/html; charset=utf-8");
    free(r.body);
}

static void test_refusals(void **state)
{
    static const char *const bad[] = {"../etc/passwd", "js/../index.html", ".secret", "js//app.js",
                                      "js\\app.js", "out", "missing.html", "js/./app.js"};
    td_http_resp r;
    td_err e = {0};
    (void)state;

    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        memset(&r, 0, sizeof r);
        assert_int_equal(td_static_serve(root, bad[i], 0, &r, &e), TD_ENOTFOUND);
        assert_null(r.body);
        assert_string_equal(e.msg, "no such file");
    }
    assert_int_equal(td_static_serve("", "index.html", 0, &r, &e), TD_ENOTFOUND);
    assert_non_null(strstr(e.msg, "not installed"));
}

static void test_resolve(void **state)
{
    char web[PATH_MAX], leaflet[PATH_MAX];
    (void)state;
    td_static_resolve(root, web, leaflet);
    assert_string_equal(web, root);
    assert_string_equal(leaflet, ""); /* no node_modules here */
    td_static_resolve("/nonexistent/web", web, leaflet);
    assert_string_equal(web, "");
    assert_string_equal(leaflet, "");
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_mime),
        cmocka_unit_test(test_page_paths),
        cmocka_unit_test(test_serve),
        cmocka_unit_test(test_refusals),
        cmocka_unit_test(test_resolve),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
