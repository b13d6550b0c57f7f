/* static.c: the map page's files and its vendored Leaflet (see static.h). Files are read
 * whole per request (the page is a few small files; the client caches the vendor ones
 * for a day): rejected, a cache in memory, which would serve stale files while the page
 * is being developed. */
#include "static.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>

#define TD_STATIC_MAX_BYTES (64 << 20)

/* X(extension, Content-Type) */
#define TD_MIME_LIST(X)                                                        \
    X("html", "text/html; charset=utf-8")                                      \
    X("htm", "text/html; charset=utf-8")                                       \
    X("js", "text/javascript; charset=utf-8")                                  \
    X("mjs", "text/javascript; charset=utf-8")                                 \
    X("css", "text/css; charset=utf-8")                                        \
    X("json", "application/json")                                              \
    X("map", "application/json")                                               \
    X("txt", "text/plain; charset=utf-8")                                      \
    X("md", "text/markdown; charset=utf-8")                                    \
    X("png", "image/png")                                                      \
    X("jpg", "image/jpeg")                                                     \
    X("jpeg", "image/jpeg")                                                    \
    X("gif", "image/gif")                                                      \
    X("svg", "image/svg+xml")                                                  \
    X("ico", "image/x-icon")                                                   \
    X("webp", "image/webp")                                                    \
    X("woff", "font/woff")                                                     \
    X("woff2", "font/woff2")                                                   \
    X("wasm", "application/wasm")

static void resolve_dir(const char *path, char *out)
{
    if (!path || !*path || !realpath(path, out))
        out[0] = '\0';
}

void td_static_resolve(const char *web_dir, char web[PATH_MAX], char leaflet[PATH_MAX])
{
    char vendor[PATH_MAX + 64];
    resolve_dir(web_dir, web);
    snprintf(vendor, sizeof vendor, "%s/node_modules/leaflet/dist", web_dir ? web_dir : "");
    resolve_dir(web_dir && *web_dir ? vendor : NULL, leaflet);
}

int td_static_is_page(const char *path)
{
    return !strcmp(path, "/") || !strcmp(path, "/index.html") || !strcmp(path, "/map.html") || !strcmp(path, "/style.css") ||
           !strncmp(path, "/js/", 4) || !strcmp(path, "/favicon.ico");
}

const char *td_static_mime(const char *path)
{
    static const struct {
        const char *ext, *type;
    } types[] = {
#define TD_X_MIME(ext, type) {ext, type},
        TD_MIME_LIST(TD_X_MIME)
#undef TD_X_MIME
    };
    const char *dot = strrchr(path, '.'), *slash = strrchr(path, '/');
    const char *type = "application/octet-stream";
    if (dot && (!slash || dot > slash))
        for (size_t i = 0; i < sizeof types / sizeof types[0]; i++)
            if (!strcasecmp(dot + 1, types[i].ext))
                type = types[i].type;
    return type;
}

/* 1 when no segment of rel is empty (but a trailing one), starts with '.', or holds a
 * backslash. */
static int segments_ok(const char *rel)
{
    int ok = 1;
    const char *seg = rel;
    while (*seg && ok) {
        const char *next = strchr(seg, '/');
        size_t n = next ? (size_t)(next - seg) : strlen(seg);
        ok = !((n == 0 && next) || seg[0] == '.' || memchr(seg, '\\', n));
        seg += n + (next ? 1 : 0);
    }
    return ok;
}

/* The real path of root/rel (a folder: its index.html) into real, and its stat, when it
 * is a regular file inside root of at most TD_STATIC_MAX_BYTES; else 0. */
static int locate(const char *root, const char *rel, char real[PATH_MAX], struct stat *st)
{
    char path[PATH_MAX];
    size_t rl = strlen(root);
    int ok = (size_t)snprintf(path, sizeof path, "%s/%s", root, *rel ? rel : "index.html") < sizeof path &&
             realpath(path, real) && !strncmp(real, root, rl) && real[rl] == '/' && !stat(real, st);
    if (ok && S_ISDIR(st->st_mode)) {
        ok = (size_t)snprintf(path, sizeof path, "%s/index.html", real) < sizeof path && !stat(path, st) &&
             S_ISREG(st->st_mode);
        if (ok)
            snprintf(real, PATH_MAX, "%s", path);
    }
    return ok && S_ISREG(st->st_mode) && st->st_size <= TD_STATIC_MAX_BYTES;
}

td_status td_static_serve(const char *root, const char *rel, int vendor, td_http_resp *r, td_err *err)
{
    td_status rc = TD_OK;
    char real[PATH_MAX];
    struct stat st;
    FILE *f = NULL;
    char *buf = NULL;

    if (!root[0]) {
        rc = td_err_set(err, TD_ENOTFOUND, "the web page is not installed (no web/ directory)");
        goto out;
    }
    if (!segments_ok(rel) || !locate(root, rel, real, &st)) {
        rc = td_err_set(err, TD_ENOTFOUND, "no such file");
        goto out;
    }
    buf = malloc((size_t)st.st_size + 1);
    f = fopen(real, "rb");
    if (!buf || !f || fread(buf, 1, (size_t)st.st_size, f) != (size_t)st.st_size) {
        rc = td_err_set(err, TD_EIO, "cannot read the file");
        goto out;
    }
    r->status = 200;
    td_http_resp_take(r, buf, (size_t)st.st_size, td_static_mime(real));
    buf = NULL;
    td_http_resp_header(r, "Cache-Control", vendor ? "public, max-age=86400" : "no-cache");
    td_http_resp_header(r, "X-Content-Type-Options", "nosniff");
out:
    if (f)
        fclose(f);
    free(buf);
    return rc;
}
