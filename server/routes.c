/* routes.c: the HTTP API (see routes.h and docs/api.md).
 *
 * Dispatch: the path is matched against the rows of td_routes (at the end of the file:
 * a path and its shape, admin or not, the methods, the handler), first match wins; a
 * known path with the wrong method gets 405 and an Allow header; admin routes check the
 * bearer token (constant time) before anything else, and are 404 `admin_disabled` when
 * no token is configured. A new endpoint is a label in routes.h, a row and a handler.
 * POST bodies must be application/json (415) and fit the cap (413). Errors are JSON
 * {"error": {"code", "field", "message"}}; bad input is always a 4xx, never a 500.
 *
 * Renders, picks and map tiles run on the HTTP layer's bounded worker queue
 * (td_http_defer): the handler parses and validates on the HTTP thread (so a bad
 * request never takes a queue slot) and takes the tile-store snapshot (the dataset
 * resolved once, for the ETag, the drape and the render), a full queue answers 503 with
 * Retry-After, and the worker renders, encodes and fills the response with
 * Server-Timing (parse, queue, every render stage that ran, encode). The HTTP layer
 * raises a render's cancel flag at its deadline (--render-timeout) and at shutdown.
 * Elsewhere: the web page's files (static.c), the pick answer (answer.c, shared with
 * `terrad render`), scene parsing (request.c). */
#include "routes.h"
#include "answer.h"
#include "clock.h"

#include <ctype.h>
#include <dirent.h>
#include <errno.h>
#include <jansson.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <stddef.h>
#include <sys/stat.h>
#include <sys/resource.h>

#include "dem.h"
#include "hash.h"
#include "log.h"
#include "render.h"
#include "request.h"
#include "static.h"
#include "cors.h"
#include "maps.h"
#include "viewshed_api.h"
#include "pano.h"
#include "pagein.h"
#include "prepared.h"
#include "solar.h"

const char *const td_route_names[TD_ROUTE_COUNT] = {
#define TD_X_NAME(e, name) name,
    TD_ROUTE_LIST(TD_X_NAME)
#undef TD_X_NAME
};

/* X(enum, status, code): the error codes of the JSON error body. */
#define TD_APIERR_LIST(X)                                                      \
    X(TD_AE_BAD_REQUEST, 400, "bad_request")                                   \
    X(TD_AE_UNAUTHORIZED, 401, "unauthorized")                                 \
    X(TD_AE_NOT_FOUND, 404, "not_found")                                       \
    X(TD_AE_UNKNOWN_DATASET, 404, "unknown_dataset")                           \
    X(TD_AE_UNKNOWN_JOB, 404, "unknown_job")                                   \
    X(TD_AE_ADMIN_DISABLED, 404, "admin_disabled")                             \
    X(TD_AE_METHOD, 405, "method_not_allowed")                                 \
    X(TD_AE_TOO_LARGE, 413, "body_too_large")                                  \
    X(TD_AE_MEDIA_TYPE, 415, "unsupported_media_type")                         \
    X(TD_AE_INTERNAL, 500, "internal")                                         \
    X(TD_AE_BUSY, 503, "busy")                                                 \
    X(TD_AE_STOPPING, 503, "stopping")                                         \
    X(TD_AE_LOADING, 503, "loading")                                           \
    X(TD_AE_TIMEOUT, 503, "render_timeout")                                    \
    X(TD_AE_PAGEIN, 503, "pagein_timeout")

typedef enum td_apierr {
#define TD_X_ENUM(e, st, code) e,
    TD_APIERR_LIST(TD_X_ENUM)
#undef TD_X_ENUM
    TD_AE_COUNT
} td_apierr;

static const struct {
    int status;
    const char *code;
} td_apierrs[] = {
#define TD_X_ERR(e, st, code) {st, code},
    TD_APIERR_LIST(TD_X_ERR)
#undef TD_X_ERR
};

/* --- response helpers ---------------------------------------------------------------- */

static void send_json(td_http_resp *r, int status, json_t *j)
{
    char *text = j ? json_dumps(j, JSON_COMPACT | JSON_REAL_PRECISION(10)) : NULL;
    json_decref(j);
    r->status = status;
    if (text) {
        size_t n = strlen(text);
        text[n] = '\0';
        td_http_resp_take(r, text, n, "application/json");
    } else {
        /* Out of memory while building JSON: a fixed body, still JSON. */
        static const char oom[] = "{\"error\":{\"code\":\"internal\",\"field\":null,"
                                  "\"message\":\"out of memory\"}}";
        r->status = 500;
        td_http_resp_copy(r, oom, sizeof oom - 1, "application/json");
    }
}

static void api_error(td_http_resp *r, td_apierr e, const char *field, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
/* Replaces bytes that are not valid UTF-8 (or are control characters) with '?', so that
 * text echoed from a request (a key, a value) can always go into a JSON string. */
static void utf8_clean(char *s)
{
    unsigned char *p = (unsigned char *)s;
    while (*p) {
        int n = *p < 0x80 ? 1 : (*p & 0xe0) == 0xc0 ? 2 : (*p & 0xf0) == 0xe0 ? 3
                : (*p & 0xf8) == 0xf0 ? 4 : 0;
        int ok = n > 0 && !(n == 2 && *p < 0xc2);
        for (int k = 1; ok && k < n; k++)
            ok = (p[k] & 0xc0) == 0x80;
        if (!ok || (n == 1 && *p < 0x20)) {
            *p++ = '?';
        } else {
            p += n;
        }
    }
}

static void api_error(td_http_resp *r, td_apierr e, const char *field, const char *fmt, ...)
{
    char msg[600], fld[160];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    utf8_clean(msg);
    if (field) {
        snprintf(fld, sizeof fld, "%s", field);
        utf8_clean(fld);
    }
    send_json(r, td_apierrs[e].status,
              json_pack("{s:{s:s,s:s?,s:s}}", "error", "code", td_apierrs[e].code, "field",
                        field ? fld : NULL, "message", msg));
}

static void method_not_allowed(td_http_resp *r, const char *allow, const char *method)
{
    td_http_resp_header(r, "Allow", "%s", allow);
    api_error(r, TD_AE_METHOD, NULL, "method %s is not allowed here (allowed: %s)", method, allow);
}

int td_routes_token_equal(const char *given, const char *want)
{
    size_t gl = strlen(given), wl = strlen(want);
    unsigned char diff = (unsigned char)(gl != wl);
    /* Walk the configured token's length whatever was given: time depends on it only. */
    for (size_t i = 0; i < wl; i++)
        diff |= (unsigned char)(want[i] ^ (i < gl ? given[i] : 0));
    return diff == 0;
}

size_t td_routes_body_cap(void *cls, const td_http_req *q)
{
    const td_app *app = cls;
    const char *path = td_http_req_path(q), *auth = td_http_req_header(q, "Authorization");
    const char *pre = "/v1/admin/datasets/", *suf = "/heights";
    size_t pl = strlen(path), sl = strlen(suf);
    int edit = !strcmp(td_http_req_method(q), "PUT") && !strncmp(path, pre, strlen(pre)) &&
               pl > strlen(pre) + sl && !strcmp(path + pl - sl, suf) && app->cfg->admin_token && auth &&
               !strncasecmp(auth, "Bearer ", 7) && td_routes_token_equal(auth + 7, app->cfg->admin_token);
    return (size_t)(edit ? app->cfg->max_edit_kb : app->cfg->max_body_kb) << 10;
}

/* 0 when the request may use admin routes; else the response is filled. */
static int admin_check(td_app *app, td_http_req *q, td_http_resp *r)
{
    int rc = -1;
    const char *auth = td_http_req_header(q, "Authorization");
    if (!app->cfg->admin_token) {
        api_error(r, TD_AE_ADMIN_DISABLED, NULL,
                  "admin routes are off: set TERRAD_ADMIN_TOKEN or --admin-token-file");
        goto out;
    }
    if (!auth || strncasecmp(auth, "Bearer ", 7)) {
        td_http_resp_header(r, "WWW-Authenticate", "Bearer realm=\"terrad admin\"");
        api_error(r, TD_AE_UNAUTHORIZED, NULL, "missing bearer token (Authorization: Bearer ...)");
        goto out;
    }
    if (!td_routes_token_equal(auth + 7, app->cfg->admin_token)) {
        td_http_resp_header(r, "WWW-Authenticate", "Bearer realm=\"terrad admin\", error=\"invalid_token\"");
        api_error(r, TD_AE_UNAUTHORIZED, NULL, "wrong bearer token");
        goto out;
    }
    rc = 0;
out:
    return rc;
}

/* 0 when the body is JSON; else the response (415) is filled. */
static int json_body_check(td_http_req *q, td_http_resp *r)
{
    const char *ct = td_http_req_header(q, "Content-Type");
    size_t n = strlen("application/json");
    int rc = ct && !strncasecmp(ct, "application/json", n) &&
                     (ct[n] == '\0' || ct[n] == ';' || ct[n] == ' ')
                 ? 0
                 : -1;
    if (rc)
        api_error(r, TD_AE_MEDIA_TYPE, NULL, "the body must be application/json (got %s)",
                  ct ? ct : "no Content-Type");
    return rc;
}

/* --- datasets ---------------------------------------------------------------------- */

/* Drapes a render may name for this dataset: PNG files beside its file that are not
 * themselves DEMs (at most 16, sorted). */
static json_t *drapes_json(const td_dataset_info *di)
{
    json_t *arr = json_array();
    struct dirent **names = NULL;
    int n = di->dir[0] ? scandir(di->dir, &names, NULL, alphasort) : 0;
    for (int i = 0; i < n; i++) {
        const char *nm = names[i]->d_name;
        size_t len = strlen(nm);
        char path[PATH_MAX], id[TD_SCENE_PATH_MAX];
        if (len > 4 && !strcasecmp(nm + len - 4, ".png") && nm[0] != '.' && json_array_size(arr) < 16 &&
            (size_t)snprintf(path, sizeof path, "%s/%s", di->dir, nm) < sizeof path &&
            !td_dem_recognised(path) && len - 4 < sizeof id) {
            memcpy(id, nm, len - 4);
            id[len - 4] = '\0';
            if (td_store_id_valid(id))
                json_array_append_new(arr, json_string(id));
        }
        free(names[i]);
    }
    free(names);
    return arr;
}

static json_t *dataset_json(td_app *app, size_t idx)
{
    td_dataset_info di;
    const td_grid *g;
    json_t *geo = json_null();
    td_store_info(app->store, idx, &di);
    g = di.grid;
    if (g->geo.kind != TD_GEO_NONE) {
        const td_georef *r = &g->geo;
        geo = json_pack("{s:s,s:[f,f],s:[f,f],s:[f,f,f,f],s:s}", "kind",
                        r->kind == TD_GEO_LONLAT ? "lonlat" : "projected", "origin", r->x0, r->y0,
                        "step", r->dx, r->dy, "bounds", r->x0, r->y0,
                        r->x0 + r->dx * (g->w - 1), r->y0 + r->dy * (g->h - 1), "crs", r->crs);
    }
    return json_pack(
        "{s:s,s:s,s:s,s:I,s:{s:i,s:i},s:[f,f],s:{s:[f,f],s:[f,f],s:[f,f]},s:I,s:o,"
        "s:{s:i,s:i,s:i,s:I},s:{s:I,s:I,s:I,s:I,s:I,s:I},s:o,s:o}",
        "id", di.id, "file", di.file, "origin", di.origin, "version", (json_int_t)di.version,
        "size", "width", (int)g->w, "height", (int)g->h,
        "spacing", g->sx, g->sy,
        "extent", "x", 0.0, g->sx * (g->w - 1), "y", 0.0, g->sy * (g->h - 1),
        "z", isfinite(g->zmin) ? (double)g->zmin : 0.0, isfinite(g->zmax) ? (double)g->zmax : 0.0,
        "voids", (json_int_t)g->voids,
        "georeference", geo,
        "tiles", "size", (int)td_grid_tile_size(g), "x", (int)g->tiles_x, "y", (int)g->tiles_y,
        "total", (json_int_t)di.ntiles,
        "residency", "tiles", (json_int_t)di.resident_tiles, "maxmip", (json_int_t)di.maxmip_tiles,
        "planes", (json_int_t)di.planes_tiles, "pinned", (json_int_t)di.pinned_tiles,
        "grid_bytes", (json_int_t)di.grid_bytes, "accel_bytes", (json_int_t)di.accel_bytes,
        "drapes", drapes_json(&di),
        "prepared", !di.prepared ? json_null()
                    : json_pack("{s:s,s:i,s:i,s:i,s:I}", "state",
                                di.refused ? "refused" : di.chunks_checked < di.chunks ? "checking" : "ok",
                                "chunks", (int)di.chunks, "checked", (int)di.chunks_checked, "levels", di.levels,
                                "heights_resident_bytes", (json_int_t)di.heights_resident));
}

static void h_datasets(td_app *app, td_http_req *q, td_http_resp *r, char **seg)
{
    json_t *arr = json_array();
    (void)q;
    (void)seg;
    for (size_t i = 0; arr && i < td_store_count(app->store); i++)
        json_array_append_new(arr, dataset_json(app, i));
    send_json(r, 200, arr);
}

/* GET /v1/datasets/{id} */
static void h_dataset(td_app *app, td_http_req *q, td_http_resp *r, char **seg)
{
    const char *id = seg[0];
    long idx = td_store_find(app->store, id);
    (void)q;
    if (idx < 0)
        api_error(r, TD_AE_UNKNOWN_DATASET, "dataset", "unknown dataset '%s'", id);
    else
        send_json(r, 200, dataset_json(app, (size_t)idx));
}

/* --- health, metrics ------------------------------------------------------------------- */

static void h_healthz(td_app *app, td_http_req *q, td_http_resp *r, char **seg)
{
    (void)app;
    (void)q;
    (void)seg;
    send_json(r, 200, json_pack("{s:s}", "status", "ok"));
}

static void h_metrics(td_app *app, td_http_req *q, td_http_resp *r, char **seg)
{
    td_metrics_ext e;
    td_metrics_dataset *ds;
    td_store_stats st;
    size_t jc[TD_JOB_STATE_COUNT], len = 0;
    char *text;
    (void)q;
    (void)seg;
    memset(&e, 0, sizeof e);
    td_store_stats_get(app->store, &st);
    td_jobs_counts(app->jobs, jc);
    e.queue_depth = app->http ? td_http_queue_depth(app->http) : 0;
    e.queue_capacity = (int)(app->cfg->render_workers + app->cfg->queue);
    e.datasets = (int)st.datasets;
    e.resident_tiles = st.resident_tiles;
    e.total_tiles = st.total_tiles;
    e.resident_bytes = st.resident_bytes;
    e.budget_bytes = st.budget_bytes;
    e.tiles_built = st.tiles_built;
    e.tiles_evicted = st.tiles_evicted;
    e.cache_hits = st.cache_hits;
    e.cache_misses = st.cache_misses;
    e.sun_kept = st.sun_kept;
    e.sun_built = st.sun_built;
    e.sun_bytes = st.sun_bytes;
    e.heights_mapped = st.heights_mapped;
    e.heights_resident = st.heights_mapped_resident;
    e.heights_trims = st.heights_trims;
    {
        struct rusage ru;
        e.major_faults = getrusage(RUSAGE_SELF, &ru) == 0 ? (uint64_t)ru.ru_majflt : 0;
    }
    e.jobs_queued = jc[TD_JOB_QUEUED];
    e.jobs_running = jc[TD_JOB_RUNNING];
    e.jobs_done = jc[TD_JOB_DONE];
    e.jobs_failed = jc[TD_JOB_FAILED];
    e.ndatasets = td_store_count(app->store);
    e.ds = ds = calloc(e.ndatasets ? e.ndatasets : 1, sizeof *ds);
    for (size_t i = 0; ds && i < e.ndatasets; i++) {
        td_dataset_info di;
        td_store_info(app->store, i, &di);
        ds[i] = (td_metrics_dataset){di.id, di.resident_tiles,
                                     di.grid_bytes + di.accel_bytes + di.drape_bytes + di.sun_bytes, di.snapshots};
    }
    text = ds ? td_metrics_format(app->metrics, &e, &len) : NULL;
    free(ds);
    if (text) {
        r->status = 200;
        td_http_resp_take(r, text, len, "text/plain; version=0.0.4; charset=utf-8");
    } else {
        api_error(r, TD_AE_INTERNAL, NULL, "out of memory");
    }
}

static void h_readyz(td_app *app, td_http_req *q, td_http_resp *r, char **seg)
{
    (void)q;
    (void)seg;
    if (atomic_load(&app->ready)) {
        send_json(r, 200, json_pack("{s:s,s:I}", "status", "ready", "datasets",
                                    (json_int_t)td_store_count(app->store)));
    } else {
        td_http_resp_header(r, "Retry-After", "1");
        if (!atomic_load(&app->loaded))
            api_error(r, TD_AE_LOADING, NULL, "not ready: the datasets are loading");
        else
            api_error(r, TD_AE_STOPPING, NULL, "not ready (stopping)");
    }
}

/* --- admin --------------------------------------------------------------------------- */

static const char *const preload_keys[] = {"dataset", "tiles", "bbox", "bbox_lonlat", "build",
                                           "pin", "rebuild", NULL};

static int key_allowed(const char *k, const char *const *allowed)
{
    for (size_t i = 0; allowed[i]; i++)
        if (!strcmp(k, allowed[i]))
            return 1;
    return 0;
}

static int read_box(json_t *v, double box[4])
{
    int ok = json_is_array(v) && json_array_size(v) == 4;
    for (size_t i = 0; ok && i < 4; i++) {
        ok = json_is_number(json_array_get(v, i));
        if (ok)
            box[i] = json_number_value(json_array_get(v, i));
    }
    return ok;
}

static void job_json_send(td_http_resp *r, int status, const td_job_info *ji)
{
    json_t *build = json_array();
    json_t *err = json_null();
    if (ji->maxmip)
        json_array_append_new(build, json_string("maxmip"));
    if (ji->planes)
        json_array_append_new(build, json_string("planes"));
    if (ji->state == TD_JOB_FAILED)
        err = json_pack("{s:s,s:s}", "code", td_status_json((td_status)ji->error_status), "message",
                        ji->error);
    send_json(r, status,
              json_pack("{s:I,s:s,s:s,s:s,s:{s:I,s:I,s:I,s:I},s:o,s:b,s:b,s:f,s:o,s:o}",
                        "id", (json_int_t)ji->id, "dataset", ji->dataset, "state",
                        td_job_state_name(ji->state), "phase", ji->phase, "tiles", "done",
                        (json_int_t)ji->done, "total", (json_int_t)ji->total, "requested",
                        (json_int_t)ji->requested, "built", (json_int_t)ji->built, "build", build,
                        "pin", ji->pin, "rebuild", ji->rebuild, "elapsed_s", ji->elapsed_s,
                        "estimate_s", ji->estimate_s >= 0 ? json_real(ji->estimate_s) : json_null(),
                        "error", err));
}

/* `?dataset=ID` on a POST is a routing key for a proxy in front of replicas
 * (docker/nginx.conf hashes on it, as it does on the id in GET paths); the body says what
 * is traced, so where both name a dataset they must agree. Called by each handler with the
 * id it parsed (no second parse of the body). 0, or -1 with a 400 sent. */
static int dataset_hint_check(td_http_req *q, td_http_resp *r, const char *id)
{
    const char *hint = td_http_req_query(q, "dataset");
    int rc = 0;
    if (hint && id && strcmp(td_http_req_method(q), "GET") && strcmp(id, hint)) {
        rc = -1;
        api_error(r, TD_AE_BAD_REQUEST, "dataset",
                  "dataset: the body's '%.64s' differs from the query's '%.64s' (the key a proxy "
                  "routes on)", id, hint);
    }
    return rc;
}

/* POST /v1/admin/preload, stage 1: the body is a JSON object of known keys naming a
 * dataset of the store. 0 and *root (the caller's to free), or -1 with r answered. */
static int preload_body(td_app *app, td_http_req *q, td_http_resp *r, json_t **root,
                        td_preload_spec *spec)
{
    json_error_t je;
    json_t *v;
    const char *key;
    size_t len;
    const char *body = td_http_req_body(q, &len);
    long idx;
    int rc = -1;

    *root = json_loadb(body, len, JSON_REJECT_DUPLICATES, &je);
    if (!*root || !json_is_object(*root)) {
        api_error(r, TD_AE_BAD_REQUEST, "", "the body is not a JSON object%s%s", *root ? "" : ": ",
                  *root ? "" : je.text);
        goto out;
    }
    json_object_foreach(*root, key, v)
    {
        if (!key_allowed(key, preload_keys)) {
            api_error(r, TD_AE_BAD_REQUEST, key, "unknown key '%s'", key);
            goto out;
        }
    }
    v = json_object_get(*root, "dataset");
    if (!json_is_string(v)) {
        api_error(r, TD_AE_BAD_REQUEST, "dataset", "dataset: a string id is required");
        goto out;
    }
    if (dataset_hint_check(q, r, json_string_value(v)))
        goto out;
    idx = td_store_find(app->store, json_string_value(v));
    if (idx < 0) {
        api_error(r, TD_AE_UNKNOWN_DATASET, "dataset", "unknown dataset '%s'", json_string_value(v));
        goto out;
    }
    spec->dataset = (size_t)idx;
    rc = 0;
out:
    return rc;
}

/* Stage 2: what to build ("build", both by default) and the pin and rebuild flags. */
static int preload_flags(json_t *root, td_http_resp *r, td_preload_spec *spec)
{
    json_t *v;
    int rc = -1;
    char field[64];

    spec->maxmip = spec->planes = 1;
    if ((v = json_object_get(root, "build"))) {
        size_t i;
        json_t *b;
        if (!json_is_array(v) || !json_array_size(v)) {
            api_error(r, TD_AE_BAD_REQUEST, "build", "build: a non-empty list of \"maxmip\", \"planes\"");
            goto out;
        }
        spec->maxmip = spec->planes = 0;
        json_array_foreach(v, i, b)
        {
            const char *s = json_string_value(b);
            snprintf(field, sizeof field, "build[%zu]", i);
            if (s && !strcmp(s, "maxmip"))
                spec->maxmip = 1;
            else if (s && !strcmp(s, "planes"))
                spec->planes = 1;
            else {
                api_error(r, TD_AE_BAD_REQUEST, field, "%s: expected \"maxmip\" or \"planes\"", field);
                goto out;
            }
        }
    }
    if ((v = json_object_get(root, "pin")) && !json_is_boolean(v)) {
        api_error(r, TD_AE_BAD_REQUEST, "pin", "pin: expected true or false");
        goto out;
    }
    spec->pin = json_is_true(v);
    if ((v = json_object_get(root, "rebuild")) && !json_is_boolean(v)) {
        api_error(r, TD_AE_BAD_REQUEST, "rebuild", "rebuild: expected true or false");
        goto out;
    }
    spec->rebuild = json_is_true(v);
    rc = 0;
out:
    return rc;
}

/* Stage 3a: "tiles": "all" (*tiles stays NULL) or a list of [tx, ty] of the dataset. */
static int preload_tile_list(td_app *app, json_t *v, td_http_resp *r, size_t dataset, size_t **tiles,
                             size_t *ntiles)
{
    td_dataset_info di;
    int rc = -1;
    char field[64];

    td_store_info(app->store, dataset, &di);
    if (json_is_string(v) && !strcmp(json_string_value(v), "all")) {
        rc = 0; /* all: the tiles stay NULL */
    } else if (json_is_array(v) && json_array_size(v) > 0 && json_array_size(v) <= di.ntiles * 4) {
        size_t i;
        json_t *t;
        *ntiles = json_array_size(v);
        *tiles = malloc(*ntiles * sizeof **tiles);
        if (!*tiles) {
            api_error(r, TD_AE_INTERNAL, NULL, "out of memory");
            goto out;
        }
        json_array_foreach(v, i, t)
        {
            json_t *tx = json_array_get(t, 0), *ty = json_array_get(t, 1);
            snprintf(field, sizeof field, "tiles[%zu]", i);
            if (!json_is_array(t) || json_array_size(t) != 2 || !json_is_integer(tx) ||
                !json_is_integer(ty)) {
                api_error(r, TD_AE_BAD_REQUEST, field, "%s: expected [tx, ty] (integers)", field);
                goto out;
            }
            if (json_integer_value(tx) < 0 || json_integer_value(tx) >= di.grid->tiles_x ||
                json_integer_value(ty) < 0 || json_integer_value(ty) >= di.grid->tiles_y) {
                api_error(r, TD_AE_BAD_REQUEST, field,
                          "%s: tile [%lld, %lld] is outside the %d x %d tiles of '%s'", field,
                          (long long)json_integer_value(tx), (long long)json_integer_value(ty),
                          (int)di.grid->tiles_x, (int)di.grid->tiles_y, di.id);
                goto out;
            }
            (*tiles)[i] = (size_t)json_integer_value(ty) * (size_t)di.grid->tiles_x +
                          (size_t)json_integer_value(tx);
        }
        rc = 0;
    } else {
        api_error(r, TD_AE_BAD_REQUEST, "tiles",
                  "tiles: \"all\" or a non-empty list of [tx, ty] (at most 4x the tile count)");
    }
out:
    return rc;
}

/* Stage 3b: "bbox" (dataset frame, metres) or "bbox_lonlat": the tiles it meets. */
static int preload_box(td_app *app, json_t *v, int lonlat, td_http_resp *r, size_t dataset,
                       size_t **tiles, size_t *ntiles)
{
    const char *f = lonlat ? "bbox_lonlat" : "bbox";
    double box[4];
    td_dataset_info di;
    td_err e = {0};
    int rc = -1;

    td_store_info(app->store, dataset, &di);
    if (!read_box(v, box)) {
        api_error(r, TD_AE_BAD_REQUEST, f, "%s: expected [xmin, ymin, xmax, ymax] (numbers)", f);
        goto out;
    }
    if (lonlat) {
        const td_georef *g = &di.grid->geo;
        if (g->kind != TD_GEO_LONLAT) {
            api_error(r, TD_AE_BAD_REQUEST, f, "%s: dataset '%s' is not in lon/lat", f, di.id);
            goto out;
        }
        box[0] = (box[0] - g->x0) / g->dx * di.grid->sx;
        box[2] = (box[2] - g->x0) / g->dx * di.grid->sx;
        box[1] = (box[1] - g->y0) / g->dy * di.grid->sy;
        box[3] = (box[3] - g->y0) / g->dy * di.grid->sy;
    }
    if (td_store_tiles_in_box(app->store, dataset, box, tiles, ntiles, &e)) {
        api_error(r, TD_AE_BAD_REQUEST, f, "%s: %s", f, e.msg);
        goto out;
    }
    if (!*ntiles) {
        api_error(r, TD_AE_BAD_REQUEST, f, "%s: the box meets no tile of '%s'", f, di.id);
        goto out;
    }
    rc = 0;
out:
    return rc;
}

/* Stage 3: at most one of tiles, bbox, bbox_lonlat; none means every tile. */
static int preload_tiles(td_app *app, json_t *root, td_http_resp *r, size_t dataset, size_t **tiles,
                         size_t *ntiles)
{
    json_t *v;
    int rc = 0;
    int nsel = !!json_object_get(root, "tiles") + !!json_object_get(root, "bbox") +
               !!json_object_get(root, "bbox_lonlat");
    if (nsel > 1) {
        api_error(r, TD_AE_BAD_REQUEST, "tiles", "give one of tiles, bbox, bbox_lonlat");
        rc = -1;
    } else if ((v = json_object_get(root, "tiles"))) {
        rc = preload_tile_list(app, v, r, dataset, tiles, ntiles);
    } else if ((v = json_object_get(root, "bbox")) || (v = json_object_get(root, "bbox_lonlat"))) {
        rc = preload_box(app, v, !!json_object_get(root, "bbox_lonlat"), r, dataset, tiles, ntiles);
    }
    return rc;
}

/* POST /v1/admin/preload: the body, stage by stage (each answers its own 4xx), then a job
 * (202 with its state and Location), or 503 when the job queue is full. */
static void h_preload(td_app *app, td_http_req *q, td_http_resp *r, char **seg)
{
    json_t *root = NULL;
    size_t *tiles = NULL, ntiles = 0;
    td_preload_spec spec;
    unsigned id = 0;
    td_err e = {0};
    td_job_info ji;

    (void)seg;
    memset(&spec, 0, sizeof spec);
    if (json_body_check(q, r) || preload_body(app, q, r, &root, &spec) || preload_flags(root, r, &spec) ||
        preload_tiles(app, root, r, spec.dataset, &tiles, &ntiles))
        goto out;
    spec.tiles = tiles;
    spec.ntiles = ntiles;
    if (td_jobs_submit(app->jobs, &spec, &id, &e)) {
        td_http_resp_header(r, "Retry-After", "5");
        api_error(r, TD_AE_BUSY, NULL, "%s", e.msg);
        goto out;
    }
    if (!td_jobs_get(app->jobs, id, &ji)) {
        api_error(r, TD_AE_INTERNAL, NULL, "job %u vanished", id);
        goto out;
    }
    td_http_resp_header(r, "Location", "/v1/admin/jobs/%u", id);
    job_json_send(r, 202, &ji);
out:
    free(tiles);
    json_decref(root);
}

/* GET /v1/admin/jobs/{id} */
static void h_job(td_app *app, td_http_req *q, td_http_resp *r, char **seg)
{
    const char *ids = seg[1];
    char *end = NULL;
    unsigned long id;
    td_job_info ji;
    (void)q;
    errno = 0;
    id = strtoul(ids, &end, 10);
    if (!*ids || !isdigit((unsigned char)ids[0]) || errno || *end || id > 0xffffffffUL ||
        !td_jobs_get(app->jobs, (unsigned)id, &ji))
        api_error(r, TD_AE_UNKNOWN_JOB, NULL, "unknown job '%s'", ids);
    else
        job_json_send(r, 200, &ji);
}

/* DELETE /v1/admin/datasets/{id}/tiles */
static void h_evict(td_app *app, td_http_req *q, td_http_resp *r, char **seg)
{
    const char *id = seg[1];
    long idx = td_store_find(app->store, id);
    size_t n = 0;
    (void)q;
    if (idx < 0) {
        api_error(r, TD_AE_UNKNOWN_DATASET, "dataset", "unknown dataset '%s'", id);
    } else {
        td_store_evict_dataset(app->store, (size_t)idx, &n);
        td_log(TD_LOG_INFO, "tiles_evicted", "dataset=%s tiles=%zu", id, n);
        send_json(r, 200, json_pack("{s:s,s:I}", "dataset", id, "evicted", (json_int_t)n));
    }
}

/* The region of the query (x, y, w, h) of dataset idx; 0, or -1 with a 400 naming the
 * parameter. At most --max-edit-kb of samples, reading or writing. */
static int heights_region(td_app *app, td_http_req *q, td_http_resp *r, size_t idx,
                          td_grid_region *reg)
{
    td_dataset_info di;
    td_err e = {0};
    int rc;
    td_store_info(app->store, idx, &di);
    rc = td_grid_edit_parse(di.grid, td_http_req_query(q, "x"), td_http_req_query(q, "y"),
                            td_http_req_query(q, "w"), td_http_req_query(q, "h"),
                            (int64_t)(app->cfg->max_edit_kb << 10) / 4, reg, &e) ? -1 : 0;
    if (rc)
        api_error(r, TD_AE_BAD_REQUEST, e.field, "%s", e.msg);
    return rc;
}

/* GET /v1/admin/datasets/{id}/heights?x=&y=&w=&h=: the region's heights now, as the body
 * a PUT takes (w*h little-endian float32, row 0 north, NaN void), with X-Terrad-Version:
 * a client reads, changes and writes back (the web page's disc edits). */
static void heights_get(td_app *app, td_http_req *q, td_http_resp *r, const char *id, size_t idx)
{
    td_grid_region reg;
    td_snapshot *snap = NULL;
    unsigned char *body = NULL;
    size_t len;
    td_err e = {0};

    if (heights_region(app, q, r, idx, &reg))
        goto out;
    len = (size_t)reg.w * (size_t)reg.h * 4; /* at most --max-edit-kb */
    body = malloc(len);
    if (!body || td_store_acquire(app->store, id, &snap, &e)) {
        api_error(r, TD_AE_INTERNAL, NULL, "%s", body ? e.msg : "out of memory");
        goto out;
    }
    td_grid_edit_read(td_snapshot_view(snap)->grid, &reg, body);
    td_http_resp_header(r, "X-Terrad-Version", "%llu", (unsigned long long)td_snapshot_version(snap, NULL));
    td_http_resp_header(r, "Cache-Control", "no-store");
    r->status = 200;
    td_http_resp_take(r, body, len, "application/octet-stream");
    body = NULL;
out:
    td_snapshot_release(snap);
    free(body);
}

/* PUT /v1/admin/datasets/{id}/heights?x=&y=&w=&h=: the region and the body are checked
 * first (400 naming the parameter or `body`; nothing changes then), then applied as the
 * dataset's next heights version at once (td_store_edit), and the touched tiles that
 * held acceleration are queued for rebuilding as a preload job. 200 with the version,
 * the touched tiles and the job (null when nothing was resident there, or when the
 * queue is full: those tiles are then traced without acceleration until a preload).
 * GET reads the region instead (heights_get). */
static void h_heights(td_app *app, td_http_req *q, td_http_resp *r, char **seg)
{
    const char *id = seg[1], *ct = td_http_req_header(q, "Content-Type"), *body;
    const size_t ctl = strlen("application/octet-stream");
    long idx = td_store_find(app->store, id);
    td_grid_region reg;
    td_edit_result res;
    size_t len = 0;
    float *z = NULL;
    unsigned job = 0;
    td_err e = {0};
    td_status rc;
    double t0 = td_clock_s();

    memset(&res, 0, sizeof res);
    if (idx < 0) {
        api_error(r, TD_AE_UNKNOWN_DATASET, "dataset", "unknown dataset '%s'", id);
        goto out;
    }
    if (strcmp(td_http_req_method(q), "PUT")) {
        heights_get(app, q, r, id, (size_t)idx);
        goto out;
    }
    if (!ct || strncasecmp(ct, "application/octet-stream", ctl) || (ct[ctl] && ct[ctl] != ';' && ct[ctl] != ' ')) {
        api_error(r, TD_AE_MEDIA_TYPE, NULL, "the body must be application/octet-stream: w*h "
                  "little-endian float32 (got %s)", ct ? ct : "no Content-Type");
        goto out;
    }
    if (heights_region(app, q, r, (size_t)idx, &reg))
        goto out;
    body = td_http_req_body(q, &len);
    rc = td_grid_edit_decode(&reg, body, body ? len : 0, &z, &e);
    if (!rc)
        rc = td_store_edit(app->store, (size_t)idx, &reg, z, &res, &e);
    if (rc) {
        api_error(r, e.field[0] ? TD_AE_BAD_REQUEST : TD_AE_INTERNAL, e.field[0] ? e.field : NULL, "%s", e.msg);
        goto out;
    }
    if (res.rebuild.ntiles && td_jobs_submit(app->jobs, &res.rebuild, &job, &e)) {
        td_log(TD_LOG_WARN, "heights_rebuild_refused", "dataset=%s tiles=%zu reason=\"queue full\"", id,
               res.rebuild.ntiles);
        job = 0;
    }
    td_log(TD_LOG_INFO, "heights_edited", "dataset=%s version=%llu x=%d y=%d w=%d h=%d tiles=%zu job=%u", id,
           (unsigned long long)res.version, (int)reg.x, (int)reg.y, (int)reg.w, (int)reg.h, res.touched, job);
    if (job)
        td_http_resp_header(r, "Location", "/v1/admin/jobs/%u", job);
    send_json(r, 200, json_pack("{s:s,s:I,s:{s:i,s:i,s:i,s:i},s:I,s:I,s:o,s:f}", "dataset", id, "version",
                                (json_int_t)res.version, "region", "x", (int)reg.x, "y", (int)reg.y, "w",
                                (int)reg.w, "h", (int)reg.h, "tiles", (json_int_t)res.touched, "rebuild",
                                (json_int_t)res.rebuild.ntiles,
                                "job", job ? json_integer((json_int_t)job) : json_null(),
                                "apply_ms", 1e3 * (td_clock_s() - t0)));
out:
    free(z);
    free((void *)res.rebuild.tiles);
}

/* --- static files (static.c) ----------------------------------------------------------- */

static void h_static(const char *root, const char *rel, int vendor, td_http_resp *r)
{
    td_err e = {0};
    td_status rc = td_static_serve(root, rel, vendor, r, &e);
    if (rc)
        api_error(r, rc == TD_ENOTFOUND ? TD_AE_NOT_FOUND : TD_AE_INTERNAL, NULL, "%s", e.msg);
}

/* GET /vendor/leaflet/... */
static void h_vendor(td_app *app, td_http_req *q, td_http_resp *r, char **seg)
{
    (void)seg;
    h_static(app->leaflet_dir, td_http_req_path(q) + strlen(TD_STATIC_VENDOR_PREFIX), 1, r);
}

/* GET / and the page's own files only: not its tests, build files or node_modules */
static void h_page(td_app *app, td_http_req *q, td_http_resp *r, char **seg)
{
    const char *path = td_http_req_path(q);
    (void)seg;
    if (!td_static_is_page(path))
        api_error(r, TD_AE_NOT_FOUND, NULL, "no such page (the web page is /, /style.css and /js/)");
    else
        h_static(app->web_dir, path + 1, 0, r);
}

/* --- renders, picks and map tiles -------------------------------------------------------- */

typedef enum td_rkind { TD_RK_RENDER, TD_RK_PICK, TD_RK_TILE } td_rkind;

typedef struct td_rjob {
    td_app *app;
    td_rkind kind;
    int get;           /* GET: ETag and Cache-Control */
    double parse_ms;
    char etag[80];
    td_snapshot *snap; /* the dataset, acquired by render_defer, released with the job */
    td_scene scene;    /* large (the pick list): the job is heap-allocated */
} td_rjob;

static void request_limits(const td_app *app, td_request_limits *lim)
{
    td_request_limits_default(lim);
    lim->max_pixels = (uint64_t)app->cfg->max_pixels;
    if (lim->max_samples > app->cfg->max_samples)
        lim->max_samples = (int)app->cfg->max_samples;
    lim->allow_paths = 0;
}

static void scene_etag(const td_scene *s, const td_snapshot *snap, char *out, size_t n)
{
    size_t bytes = offsetof(td_scene, pick) + (size_t)s->npick * sizeof s->pick[0];
    uint64_t h = td_fnv1a(TD_FNV1A_INIT, s, bytes), chain = 0, ver = td_snapshot_version(snap, &chain);
    const td_grid *g = td_snapshot_view(snap)->grid;
    /* The dataset too: same scene over different heights is a different picture. */
    h ^= (uint64_t)g->w * 2654435761u ^ (uint64_t)g->h ^ (uint64_t)(g->zmax * 1000.0);
    h *= TD_FNV1A_PRIME;
    snprintf(out, n, "\"%016llx-v%llu.%08llx\"", (unsigned long long)h, (unsigned long long)ver,
             (unsigned long long)(chain & 0xffffffffu));
}

static int etag_matches(td_http_req *q, const char *etag)
{
    const char *inm = td_http_req_header(q, "If-None-Match");
    return inm && (strstr(inm, etag) || !strcmp(inm, "*"));
}

/* The resolved method label: what the tracer can actually use with what is resident. */
/* The method asked for and, from the render's stats, the tracers that camera rays
 * actually ended in (what `auto` chose, or the walk where a tile had no acceleration
 * resident), e.g. "auto:hierarchical" or "hierarchical:hierarchical=97%,incremental=3%". */
static void method_label(td_method m, const td_render_stats *st, char *out, size_t n)
{
    uint64_t total = 0;
    int used = 0, only = -1;
    size_t k;
    for (int i = 0; i < TD_METHOD_COUNT; i++) {
        total += st->method_rays[i];
        if (st->method_rays[i]) {
            used++;
            only = i;
        }
    }
    k = (size_t)snprintf(out, n, "%s", td_method_name(m));
    if (used == 1 && only == (int)m) {
        /* the method asked for, everywhere */
    } else if (used == 1 && k < n) {
        snprintf(out + k, n - k, ":%s", td_method_name((td_method)only));
    } else if (used > 1) {
        for (int i = 0; i < TD_METHOD_COUNT && k < n; i++) {
            if (st->method_rays[i])
                k += (size_t)snprintf(out + k, n - k, "%s%s=%.0f%%", k == strlen(td_method_name(m)) ? ":" : ",",
                                      td_method_name((td_method)i),
                                      100.0 * (double)st->method_rays[i] / (double)total);
        }
    }
}

/* pagein: what the worker waited for pages of mapped heights (pagein.h); with no major
 * fault it is left out, unless the wait passed the page-in deadline. */
static void timing_header(td_http_resp *r, const td_rjob *j, double queue_ms,
                          const td_render_stats *st, uint64_t faults, double pagein_ms, int expired)
{
    char v[512];
    size_t n = 0;
    int w;
    w = snprintf(v, sizeof v, "parse;dur=%.3f, queue;dur=%.3f", j->parse_ms, queue_ms);
    n = w > 0 ? (size_t)w : 0;
    if (st) {
        w = snprintf(v + n, sizeof v - n, ", trace;dur=%.3f",
                     st->stage_ms[TD_STAGE_PRIMARY] + st->stage_ms[TD_STAGE_CURVATURE]);
        if (w > 0 && (size_t)w < sizeof v - n)
            n += (size_t)w;
        for (int k = 0; k < TD_STAGE_COUNT; k++) {
            if (!st->stage_ran[k] || k == TD_STAGE_PRIMARY || k == TD_STAGE_CURVATURE)
                continue;
            w = snprintf(v + n, sizeof v - n, ", %s;dur=%.3f", td_stage_name((td_stage)k),
                         st->stage_ms[k]);
            if (w > 0 && (size_t)w < sizeof v - n)
                n += (size_t)w;
        }
    }
    if (faults || expired)
        snprintf(v + n, sizeof v - n, ", pagein;dur=%.3f;desc=\"%llu major faults%s\"", pagein_ms,
                 (unsigned long long)faults, expired ? ", over --pagein-timeout" : "");
    td_http_resp_header(r, "Server-Timing", "%s", v);
}

/* A core error: input at fault (400, with the field core named in e->field) or not. */
static void render_error(const td_app *app, td_http_resp *r, td_status rc, const td_err *e)
{
    if (rc == TD_ECANCELED && !atomic_load(&((td_app *)app)->ready))
        api_error(r, TD_AE_STOPPING, NULL, "the server stopped before the render finished");
    else if (rc == TD_ECANCELED)
        api_error(r, TD_AE_TIMEOUT, NULL, "the render did not finish within --render-timeout");
    else if (rc == TD_ENOMEM || rc == TD_EIO)
        api_error(r, TD_AE_INTERNAL, NULL, "%s", e->msg);
    else
        api_error(r, TD_AE_BAD_REQUEST, e->field[0] ? e->field : NULL, "%s", e->msg);
}

/* A pick: 200 with the picks' JSON and their stats in *st; else r holds the error.
 * Returns 1 when answered with 200. */
static int work_pick(td_app *app, td_rjob *j, const td_view *v, td_http_resp *r, td_render_stats *st)
{
    td_pick *picks = calloc((size_t)(j->scene.npick ? j->scene.npick : 1), sizeof *picks);
    td_err e = {0};
    td_status rc;
    int ok = 0;
    if (!picks) {
        api_error(r, TD_AE_INTERNAL, NULL, "out of memory");
        goto out;
    }
    rc = td_render_pick(v, &j->scene, picks, st, &e);
    if (rc) {
        render_error(app, r, rc, &e);
        goto out;
    }
    send_json(r, 200, td_answer_picks(j->scene.dataset, v->grid, picks, j->scene.npick));
    ok = 1;
out:
    free(picks);
    return ok;
}

/* td_render_opts.sunlit: the sun bound the snapshot's dataset keeps for the sun */
static td_status snapshot_sunlit(void *ctx, const td_view *v, const double sun[3], const td_sunlit **out, int *kept,
                                 td_err *err)
{
    (void)v; /* the snapshot's own (td_snapshot_view) */
    return td_snapshot_sunlit(ctx, sun, out, kept, err);
}

/* A render (or a map tile): 200 with the encoded image and its format's headers, the
 * result in *res (the caller frees it); else r holds the error. 1 when answered 200. */
static int work_image(td_app *app, td_rjob *j, td_pagein_guard *pg, td_snapshot *snap, td_http_resp *r,
                      td_render_result *res)
{
    td_render_opts o;
    td_buf buf = {0};
    td_err e = {0};
    td_status rc;
    double depth_scale = 0;
    int ok = 0;

    td_render_opts_default(&o);
    o.threads = 1; /* one render per worker; the workers use the cores */
    o.cancel = td_pagein_flag(app->pagein, pg); /* raised at --render-timeout (http.c) or
                                                   --pagein-timeout (pagein.h) */
    o.lod = td_snapshot_lod(snap);
    o.sunlit = snapshot_sunlit; /* kept across renders of the same heights and sun */
    o.sunlit_ctx = snap;
    /* the drape, decoded once and kept with the dataset (a depth image has none) */
    rc = TD_OK;
    if (j->scene.effects.drape[0] && j->scene.image.format != TD_FORMAT_DEPTH16 &&
        j->scene.image.format != TD_FORMAT_DEPTH32F)
        rc = td_snapshot_drape(snap, j->scene.effects.drape, &o.drape, &e);
    if (rc == TD_OK)
        rc = td_render(td_snapshot_view(snap), &j->scene, &o, res, &e);
    if (rc == TD_OK)
        rc = td_render_encode(res, &j->scene, &buf, &depth_scale, &e);
    if (rc == TD_ECANCELED && td_pagein_expired(pg)) {
        const td_grid *g = td_snapshot_view(snap)->grid;
        if (j->scene.camera.pos_kind == TD_POS_XYZ || j->scene.camera.pos_kind == TD_POS_XY_AGL)
            td_prepared_willneed_near(g, j->scene.camera.x, j->scene.camera.y, 4 << g->tile_log2);
        td_http_resp_header(r, "Retry-After", "%d", (int)ceil(td_pagein_deadline(app->pagein)));
        api_error(r, TD_AE_PAGEIN, NULL, "the render waited for pages of the dataset's files longer than "
                  "--pagein-timeout (%.3g s); they are being read: retry", td_pagein_deadline(app->pagein));
        goto out;
    }
    if (rc) {
        render_error(app, r, rc, &e);
        goto out;
    }
    r->status = 200;
    td_http_resp_take(r, buf.data, buf.len,
                      j->scene.image.format == TD_FORMAT_DEPTH32F ? "application/octet-stream" : "image/png");
    buf.data = NULL;
    if (j->scene.image.format == TD_FORMAT_DEPTH16)
        td_http_resp_header(r, "X-Terrad-Depth-Scale", "%.9g", depth_scale);
    if (j->scene.image.format == TD_FORMAT_DEPTH32F)
        td_http_resp_header(r, "X-Terrad-Size", "%dx%d", (int)res->width, (int)res->height);
    ok = 1;
out:
    td_buf_free(&buf);
    return ok;
}

/* The headers of a 200 render or pick: what the tracer did (X-Terrad-*) and caching. */
static void work_headers(const td_rjob *j, const td_render_stats *st, td_http_resp *r)
{
    char label[160];
    method_label(j->scene.quality.method, st, label, sizeof label);
    td_http_resp_header(r, "X-Terrad-Method", "%s", label);
    td_http_resp_header(r, "X-Terrad-Surface", "%s", td_surface_name(j->scene.quality.surface));
    /* the sun the picture was shaded with (from effects.sun.time, or as given) */
    td_http_resp_header(r, "X-Terrad-Sun", "azimuth=%.17g; elevation=%.17g", j->scene.effects.sun_azimuth,
                        j->scene.effects.sun_elevation);
    td_http_resp_header(r, "X-Terrad-Rays", "%llu", (unsigned long long)(st->rays[TD_RAY_PRIMARY] +
                        st->rays[TD_RAY_SHADOW] + st->rays[TD_RAY_REFLECTION] + st->rays[TD_RAY_AO]));
    td_http_resp_header(r, "X-Terrad-Steps", "%llu", (unsigned long long)st->steps);
    if (st->sun_bound != TD_SUN_BOUND_NONE) /* built for this render, or kept from an earlier one */
        td_http_resp_header(r, "X-Terrad-Sun-Bound", "%s", td_sun_bound_name(st->sun_bound));
    /* how far the picture is from the exact one (render.h): metres, over the camera hits */
    if (st->height_err_hits)
        td_http_resp_header(r, "X-Terrad-Height-Error", "mean=%.3g; max=%.3g; hits=%llu", st->height_err_mean_m,
                            st->height_err_max_m, (unsigned long long)st->height_err_hits);
    if (j->get) {
        td_http_resp_header(r, "ETag", "%s", j->etag);
        td_http_resp_header(r, "Cache-Control", "public, max-age=%d", j->kind == TD_RK_TILE ? 86400 : 3600);
    } else {
        td_http_resp_header(r, "Cache-Control", "no-store");
    }
}

/* The worker's part of a render, pick or map tile (td_http_defer): on the job's store
 * snapshot, the work, its headers and metrics, Server-Timing whatever the outcome; frees
 * the job and releases the snapshot. */
static void render_work(void *cls, td_http_req *q, td_http_resp *r, int cancelled)
{
    td_rjob *j = cls;
    td_app *app = j->app;
    td_snapshot *snap = j->snap;
    td_render_result res;
    td_render_stats pst;
    const td_view *v;
    double queue_ms = td_http_req_queue_wait(q) * 1e3, t0 = td_clock_s(), pagein_ms;
    const td_render_stats *st = NULL;
    td_pagein_guard pg;
    uint64_t faults;
    int expired;

    td_pagein_guard_begin(app->pagein, &pg, td_http_req_cancel(q));
    memset(&res, 0, sizeof res);
    memset(&pst, 0, sizeof pst);
    if (cancelled) {
        td_http_resp_header(r, "Retry-After", "1");
        api_error(r, TD_AE_STOPPING, NULL, "the server is stopping");
        goto out;
    }
    v = td_snapshot_view(snap);
    if (j->kind == TD_RK_PICK) {
        if (!work_pick(app, j, v, r, &pst))
            goto out;
        st = &pst;
    } else {
        if (!work_image(app, j, &pg, snap, r, &res))
            goto out;
        st = &res.stats;
    }
    work_headers(j, st, r);
    {
        uint64_t rays = 0;
        for (int k = 0; k < TD_RAY_KIND_COUNT; k++)
            rays += st->rays[k];
        td_metrics_render(app->metrics, j->scene.quality.method, td_clock_s() - t0, rays, st->steps);
    }
out:
    expired = td_pagein_guard_end(app->pagein, &pg) && !st; /* and it cut the work short */
    td_pagein_end(&pg.start, &faults, &pagein_ms);
    td_metrics_pagein(app->metrics, faults, pagein_ms * 1e-3);
    timing_header(r, j, queue_ms, st, faults, pagein_ms, expired);
    td_render_result_free(&res);
    td_snapshot_release(snap);
    free(j);
}

/* Queues a job (which the worker frees), or answers at once: unknown dataset or drape,
 * 304 for a matching If-None-Match, 503 with Retry-After when the queue is full. */
static void render_defer(td_app *app, td_http_req *q, td_http_resp *r, td_rjob *j)
{
    td_err e = {0};
    td_status rc;
    int deferred = 0;

    if (dataset_hint_check(q, r, j->scene.dataset))
        goto out;
    rc = td_store_acquire(app->store, j->scene.dataset, &j->snap, &e);
    if (rc == TD_EAGAIN) /* a prepared dataset still being checked */
        td_http_resp_header(r, "Retry-After", "1");
    if (rc) {
        api_error(r, rc == TD_ENOTFOUND ? TD_AE_UNKNOWN_DATASET : rc == TD_EAGAIN ? TD_AE_LOADING : TD_AE_INTERNAL,
                  "dataset", "%s", e.msg);
        goto out;
    }
    if (j->scene.effects.drape[0]) {
        /* A drape is an id: a PNG beside the dataset's file, never a path. */
        char path[PATH_MAX];
        const char *dir = td_snapshot_dir(j->snap);
        struct stat st;
        if ((size_t)snprintf(path, sizeof path, "%s/%s.png", dir, j->scene.effects.drape) >=
                sizeof path || sizeof j->scene.effects.drape <= strlen(path) || stat(path, &st) ||
            !S_ISREG(st.st_mode)) {
            api_error(r, TD_AE_BAD_REQUEST, "effects.drape",
                      "effects.drape: dataset '%s' has no drape '%s'", j->scene.dataset, j->scene.effects.drape);
            goto out;
        }
        memcpy(j->scene.effects.drape, path, strlen(path) + 1); /* fits: checked above */
    }
    if (j->get && j->kind != TD_RK_TILE) {
        scene_etag(&j->scene, j->snap, j->etag, sizeof j->etag);
    } else if (j->get) { /* a map tile: its tag (h_tile) and the heights version */
        uint64_t chain = 0, ver = td_snapshot_version(j->snap, &chain);
        size_t l = strlen(j->etag);
        snprintf(j->etag + l - 1, sizeof j->etag - (l - 1), "-v%llu.%08llx\"", (unsigned long long)ver,
                 (unsigned long long)(chain & 0xffffffffu));
    }
    if (j->get && etag_matches(q, j->etag)) {
        r->status = 304;
        td_http_resp_header(r, "ETag", "%s", j->etag);
        td_http_resp_header(r, "Cache-Control", "public, max-age=%d", j->kind == TD_RK_TILE ? 86400 : 3600);
        goto out;
    }
    j->app = app;
    deferred = td_http_defer(q, render_work, j) == 0;
    if (!deferred) {
        td_http_resp_header(r, "Retry-After", "1");
        if (!atomic_load(&app->ready))
            api_error(r, TD_AE_STOPPING, NULL, "the server is stopping; retry on another replica");
        else
            api_error(r, TD_AE_BUSY, NULL, "the render queue is full (%ld running, %ld waiting); retry later",
                      app->cfg->render_workers, app->cfg->queue);
    }
out:
    if (!deferred) {
        td_snapshot_release(j->snap);
        free(j);
    }
}

typedef struct td_qargs {
    const char *keys[128], *values[128];
    size_t n;
    int overflow;
} td_qargs;

static int collect_arg(void *cls, const char *key, const char *value)
{
    td_qargs *a = cls;
    if (a->n >= 128) {
        a->overflow = 1;
        return 1;
    }
    a->keys[a->n] = key;
    a->values[a->n++] = value;
    return 0;
}

/* effects.sun.time: the sun at that instant over the dataset's centre (NOAA, core/solar.h),
 * in the dataset's frame. 0, or -1 with a 400 naming effects.sun.time (no georeference). An
 * unknown dataset is left to render_defer's 404. */
static int sun_at_time(td_app *app, td_scene *s, td_http_resp *r)
{
    td_dataset_info di;
    long idx = td_store_find(app->store, s->dataset);
    double centre[2], north = 0.0;
    char msg[320];
    td_err e = {0};
    int rc = 0;
    if (idx >= 0) {
        td_store_info(app->store, (size_t)idx, &di);
        if (td_maps_centre(app->maps, &di, centre, &north, msg, sizeof msg) ||
            td_solar_in_grid(centre[0], centre[1], north, s->effects.sun_time_s, &s->effects.sun_azimuth,
                             &s->effects.sun_elevation, &e)) {
            rc = -1;
            api_error(r, TD_AE_BAD_REQUEST, "effects.sun.time", "effects.sun.time: %s",
                      e.msg[0] ? e.msg : msg);
        }
    }
    return rc;
}

static void h_render(td_app *app, td_http_req *q, td_http_resp *r, int post, int pick)
{
    td_rjob *j = calloc(1, sizeof *j);
    td_request_limits lim;
    td_request_error re;
    td_status rc;
    double t0 = td_clock_s();

    memset(&re, 0, sizeof re);
    if (!j) {
        api_error(r, TD_AE_INTERNAL, NULL, "out of memory");
        goto out;
    }
    request_limits(app, &lim);
    if (post) {
        size_t len;
        const char *body;
        if (json_body_check(q, r))
            goto out;
        body = td_http_req_body(q, &len);
        /* /v1/pick implies image.format "pick" where the body leaves it out */
        rc = pick ? td_request_parse_pick(body, len, &lim, &j->scene, &re)
                  : td_request_parse_scene(body, len, &lim, &j->scene, &re);
    } else {
        td_qargs a;
        memset(&a, 0, sizeof a);
        td_http_req_query_each(q, collect_arg, &a);
        if (a.overflow) {
            api_error(r, TD_AE_BAD_REQUEST, NULL, "more than 128 query parameters");
            goto out;
        }
        rc = td_request_parse_query(a.keys, a.values, a.n, &lim, &j->scene, &re);
        j->get = 1;
    }
    if (rc) {
        api_error(r, TD_AE_BAD_REQUEST, re.field, "%s", re.message);
        goto out;
    }
    if (pick && j->scene.npick == 0) {
        api_error(r, TD_AE_BAD_REQUEST, "pick", "pick: give the pixels to pick, [[x, y], ...]");
        goto out;
    }
    j->kind = pick || j->scene.image.format == TD_FORMAT_PICK ? TD_RK_PICK : TD_RK_RENDER;
    if (j->scene.effects.sun_time && sun_at_time(app, &j->scene, r))
        goto out;
    j->parse_ms = (td_clock_s() - t0) * 1e3;
    render_defer(app, q, r, j); /* takes j */
    j = NULL;
out:
    free(j);
}

/* POST or GET /v1/render */
static void h_render_route(td_app *app, td_http_req *q, td_http_resp *r, char **seg)
{
    (void)seg;
    h_render(app, q, r, !strcmp(td_http_req_method(q), "POST"), 0);
}

/* POST /v1/pick */
static void h_pick(td_app *app, td_http_req *q, td_http_resp *r, char **seg)
{
    (void)seg;
    h_render(app, q, r, 1, 1);
}

int td_routes_parse_uint(const char *s, long max, long *out)
{
    char *end = NULL;
    long v;
    if (!isdigit((unsigned char)s[0]))
        return 0;
    errno = 0;
    v = strtol(s, &end, 10);
    if (errno || *end || v < 0 || v > max)
        return 0;
    *out = v;
    return 1;
}

/* GET /v1/tiles/{dataset}/{z}/{x}/{y}.png: a 256 x 256 top-down view for Leaflet's
 * CRS.Simple. z = 0 is the whole dataset in one tile: its north-west corner at the
 * dataset's north-west corner, side = max(width, height) in metres; each zoom halves it.
 * ?quality.lod_grid=isometric traces the level of detail on its isometric twin (lod.h;
 * a 400 naming it where the twins are not resident, as for /v1/render). */
static void h_tile(td_app *app, td_http_req *q, td_http_resp *r, char **seg)
{
    long z, x, y, idx;
    size_t yl = strlen(seg[3]);
    const char *lg = td_http_req_query(q, "quality.lod_grid");
    td_lod_grid grid = TD_LOD_GRID_SQUARE;
    td_rjob *j = NULL;
    td_dataset_info di;
    double wm, hm, side, t;

    if (yl < 5 || strcmp(seg[3] + yl - 4, ".png")) {
        api_error(r, TD_AE_NOT_FOUND, NULL, "tile paths end in {y}.png");
        goto out;
    }
    seg[3][yl - 4] = '\0';
    idx = td_store_find(app->store, seg[0]);
    if (idx < 0) {
        api_error(r, TD_AE_UNKNOWN_DATASET, "dataset", "unknown dataset '%s'", seg[0]);
        goto out;
    }
    if (!td_routes_parse_uint(seg[1], 24, &z)) {
        api_error(r, TD_AE_BAD_REQUEST, "z", "z: an integer zoom in [0, 24]");
        goto out;
    }
    if (!td_routes_parse_uint(seg[2], (1L << z) - 1, &x) || !td_routes_parse_uint(seg[3], (1L << z) - 1, &y)) {
        api_error(r, TD_AE_NOT_FOUND, NULL, "no tile %s/%s at zoom %ld (x and y in [0, %ld])", seg[2],
                  seg[3], z, (1L << z) - 1);
        goto out;
    }
    if (lg && td_lod_grid_parse(lg, &grid)) {
        api_error(r, TD_AE_BAD_REQUEST, "quality.lod_grid", "quality.lod_grid: '%.40s' is not square or isometric", lg);
        goto out;
    }
    td_store_info(app->store, (size_t)idx, &di);
    wm = di.grid->sx * (di.grid->w - 1);
    hm = di.grid->sy * (di.grid->h - 1);
    side = wm > hm ? wm : hm;
    t = side / (double)(1L << z);
    if (x * t >= wm || y * t >= hm) {
        api_error(r, TD_AE_NOT_FOUND, NULL, "tile %ld/%ld/%ld is outside dataset '%s'", z, x, y, di.id);
        goto out;
    }
    j = calloc(1, sizeof *j);
    if (!j) {
        api_error(r, TD_AE_INTERNAL, NULL, "out of memory");
        goto out;
    }
    td_scene_defaults(&j->scene);
    snprintf(j->scene.dataset, sizeof j->scene.dataset, "%s", di.id);
    j->scene.camera.projection = TD_PROJ_ORTHOGRAPHIC;
    j->scene.camera.extent[0] = (double)x * t;
    j->scene.camera.extent[2] = (double)(x + 1) * t;
    j->scene.camera.extent[3] = hm - (double)y * t;
    j->scene.camera.extent[1] = hm - (double)(y + 1) * t;
    j->scene.image.width = 256;
    j->scene.image.height = 256;
    j->scene.image.format = TD_FORMAT_PNG;
    /* a map tile whose pixels cover several cells is traced on the level of detail whose
     * cells fit a pixel: cheaper at low zooms, and no aliasing from skipped cells */
    j->scene.quality.lod = 1;
    j->scene.quality.lod_grid = (int)grid;
    j->kind = TD_RK_TILE;
    j->get = 1;
    {
        /* The tile's place and the dataset's shape and height range: a changed dataset
         * (same id after a restart) gets new tags. */
        double key[6] = {(double)di.grid->w, (double)di.grid->h, di.grid->sx, di.grid->sy,
                         (double)di.grid->zmin, (double)di.grid->zmax};
        uint64_t hsh = td_fnv1a(TD_FNV1A_INIT, key, sizeof key);
        snprintf(j->etag, sizeof j->etag, "\"t%012llx-%ld-%ld-%ld%s\"",
                 (unsigned long long)(hsh & 0xffffffffffffULL), z, x, y, grid ? "-iso" : "");
    }
    render_defer(app, q, r, j); /* takes j */
out:
    return;
}

/* --- dispatch ------------------------------------------------------------------------ */

/* Any other path under /v1: 404 naming it (any method). */
static void h_no_route(td_app *app, td_http_req *q, td_http_resp *r, char **seg)
{
    (void)app;
    (void)seg;
    api_error(r, TD_AE_NOT_FOUND, NULL, "no such route: %s", td_http_req_path(q));
}

/* Splits "a/b/c" after a prefix into at most max segments (copied into buf). */
static int split_path(const char *rest, char *buf, size_t cap, char **seg, int max)
{
    int n = 0;
    char *p;
    if (strlen(rest) >= cap)
        return -1;
    strcpy(buf, rest);
    p = buf;
    while (n < max) {
        char *slash = strchr(p, '/');
        seg[n++] = p;
        if (!slash)
            break;
        *slash = '\0';
        p = slash + 1;
    }
    return strchr(p, '/') && n == max ? -1 : n;
}

typedef void (*td_handler)(td_app *app, td_http_req *q, td_http_resp *r, char **seg);

/* One row a route, tried in order; the first that matches answers.
 *   rest NULL: the path is exactly `path`. rest "": any path that starts with `path`.
 *   Otherwise the path starts with `path` and what follows, split into at most `max`
 *   segments (split_path), has rest's shape: as many segments, `*` any, others equal.
 * Then: the route label is set; admin rows check the bearer token; a row with `allow`
 * refuses other methods (405 + Allow); the handler gets the segments, or a row without
 * one answers 404 with `missing` (a path under a known prefix but of no known shape). */
typedef struct td_route_row {
    td_route route;
    const char *path, *rest;
    int max, admin;
    const char *allow; /* as the Allow header says it; NULL: any method */
    td_handler fn;
    const char *missing;
} td_route_row;

static const td_route_row td_routes[] = {
    {TD_ROUTE_HEALTHZ, "/healthz", NULL, 0, 0, "GET, HEAD", h_healthz, NULL},
    {TD_ROUTE_READYZ, "/readyz", NULL, 0, 0, "GET, HEAD", h_readyz, NULL},
    {TD_ROUTE_METRICS, "/metrics", NULL, 0, 0, "GET, HEAD", h_metrics, NULL},
    {TD_ROUTE_RENDER, "/v1/render", NULL, 0, 0, "GET, HEAD, POST", h_render_route, NULL},
    {TD_ROUTE_PICK, "/v1/pick", NULL, 0, 0, "POST", h_pick, NULL},
    {TD_ROUTE_VIEWSHED, "/v1/viewshed", NULL, 0, 0, "POST", td_vs_route, NULL},
    {TD_ROUTE_LOS, "/v1/los", NULL, 0, 0, "POST", td_los_route, NULL},
    {TD_ROUTE_HORIZON, "/v1/horizon", NULL, 0, 0, "POST", td_horizon_route, NULL}, /* pano.c */
    {TD_ROUTE_PEAKS, "/v1/peaks", NULL, 0, 0, "POST", td_peaks_route, NULL},
    {TD_ROUTE_TILES, "/v1/tiles/", "*/*/*/*", 4, 0, "GET, HEAD", h_tile, NULL},
    {TD_ROUTE_TILES, "/v1/tiles/", "", 0, 0, NULL, NULL, "tile paths are /v1/tiles/{dataset}/{z}/{x}/{y}.png"},
    {TD_ROUTE_MAPS, "/v1/maps/", "*/*/*/*/*", 5, 0, "GET, HEAD", td_maps_tile_route, NULL},
    {TD_ROUTE_TILEJSON, "/v1/maps/", "*/*", 2, 0, "GET, HEAD", td_maps_tilejson_route, NULL},
    {TD_ROUTE_MAPS, "/v1/maps/", "", 0, 0, NULL, NULL,
     "map paths are /v1/maps/{dataset}/{style}/{z}/{x}/{y}.png and /v1/maps/{dataset}/{style}.json"},
    {TD_ROUTE_DATASETS, "/v1/datasets", NULL, 0, 0, "GET, HEAD", h_datasets, NULL},
    {TD_ROUTE_DATASETS, "/v1/datasets/", NULL, 0, 0, "GET, HEAD", h_datasets, NULL},
    {TD_ROUTE_DATASET, "/v1/datasets/", "*", 1, 0, "GET, HEAD", h_dataset, NULL},
    {TD_ROUTE_DATASET, "/v1/datasets/", "", 0, 0, NULL, NULL, "no such route"},
    {TD_ROUTE_PRELOAD, "/v1/admin/", "preload", 4, 1, "POST", h_preload, NULL},
    {TD_ROUTE_JOB, "/v1/admin/", "jobs/*", 4, 1, "GET, HEAD", h_job, NULL},
    {TD_ROUTE_JOB, "/v1/admin/jobs/", "", 0, 1, NULL, NULL, "no such admin route"},
    {TD_ROUTE_EVICT, "/v1/admin/", "datasets/*/tiles", 4, 1, "DELETE", h_evict, NULL},
    {TD_ROUTE_HEIGHTS, "/v1/admin/", "datasets/*/heights", 4, 1, "GET, HEAD, PUT", h_heights, NULL},
    {TD_ROUTE_EVICT, "/v1/admin/", "", 0, 1, NULL, NULL, "no such admin route"},
    {TD_ROUTE_WEB, TD_STATIC_VENDOR_PREFIX, "", 0, 0, "GET, HEAD", h_vendor, NULL},
    {TD_ROUTE_WEB, TD_MAPS_VENDOR_PREFIX, "", 0, 0, "GET, HEAD", td_maps_vendor_route, NULL},
    {TD_ROUTE_UNKNOWN, "/v1", NULL, 0, 0, NULL, h_no_route, NULL},
    {TD_ROUTE_UNKNOWN, "/v1/", "", 0, 0, NULL, h_no_route, NULL},
    {TD_ROUTE_WEB, "/", "", 0, 0, "GET, HEAD", h_page, NULL},
};

/* 1 when path matches row w (see td_route_row); the segments are in seg (buf holds them). */
static int row_matches(const td_route_row *w, const char *path, char *buf, size_t cap, char **seg)
{
    size_t pl = strlen(w->path);
    const char *shape = w->rest;
    int ok, n;
    if (!shape)
        return !strcmp(path, w->path);
    ok = !strncmp(path, w->path, pl);
    if (!ok || !*shape)
        return ok;
    n = split_path(path + pl, buf, cap, seg, w->max);
    ok = n > 0;
    for (int i = 0; ok && i < n; i++) {
        size_t l = strcspn(shape, "/");
        ok = (l == 1 && shape[0] == '*') || (strlen(seg[i]) == l && !strncmp(seg[i], shape, l));
        shape += l;
        if (*shape == '/')
            shape++;
        else if (i + 1 < n)
            ok = 0; /* more segments than the shape has */
    }
    return ok && !*shape; /* and not fewer */
}

/* 1 when method is one of the comma-separated names of allow. */
static int method_allowed(const char *allow, const char *method)
{
    size_t ml = strlen(method);
    int ok = 0;
    for (const char *p = allow; *p && !ok; p += strspn(p, ", ")) {
        size_t l = strcspn(p, ", ");
        ok = l == ml && !strncmp(p, method, l);
        p += l;
    }
    return ok;
}

static void dispatch(td_app *app, td_http_req *q, td_http_resp *r)
{
    const char *m = td_http_req_method(q), *path = td_http_req_path(q);
    char buf[512], *seg[8] = {NULL};
    const td_route_row *w = &td_routes[sizeof td_routes / sizeof td_routes[0] - 1]; /* "/": any */

    for (size_t i = 0; i + 1 < sizeof td_routes / sizeof td_routes[0]; i++)
        if (row_matches(&td_routes[i], path, buf, sizeof buf, seg)) {
            w = &td_routes[i];
            break;
        }
    td_http_req_set_route(q, w->route);
    if (!atomic_load(&app->loaded) && w->route != TD_ROUTE_HEALTHZ && w->route != TD_ROUTE_READYZ) {
        td_http_resp_header(r, "Retry-After", "1");
        api_error(r, TD_AE_LOADING, NULL, "the datasets are loading; retry shortly");
    } else if (w->admin && admin_check(app, q, r)) {
        /* answered: 404 admin_disabled or 401 */
    } else if (!w->admin && w->route != TD_ROUTE_WEB && td_cors_apply(app->cfg->cors_origins, q, r, w->allow)) {
        /* answered: a CORS preflight (cors.h); admin routes never get CORS */
    } else if (w->allow && !method_allowed(w->allow, m)) {
        method_not_allowed(r, w->allow, m);
    } else if (!w->fn) {
        api_error(r, TD_AE_NOT_FOUND, NULL, "%s", w->missing);
    } else {
        w->fn(app, q, r, seg);
    }
}

void td_routes_handle(void *cls, td_http_req *q, td_http_resp *r)
{
    td_app *app = cls;
    if (td_http_req_too_big(q)) {
        td_http_req_set_route(q, TD_ROUTE_UNKNOWN);
        int edit = td_routes_body_cap(app, q) != (size_t)app->cfg->max_body_kb << 10;
        api_error(r, TD_AE_TOO_LARGE, NULL, "the body is over the limit of %ld KiB (%s)",
                  edit ? app->cfg->max_edit_kb : app->cfg->max_body_kb,
                  edit ? "--max-edit-kb" : "--max-body-kb; heights edits with the admin token: --max-edit-kb");
        td_http_resp_header(r, "Connection", "close");
    } else {
        dispatch(app, q, r);
    }
}

void td_routes_done(void *cls, int route, int status, size_t bytes, double seconds)
{
    td_app *app = cls;
    (void)bytes;
    (void)seconds;
    td_metrics_request(app->metrics, route, status);
}

/* --- for handlers in other files (routes.h) ----------------------------------------- */

void td_routes_error(td_http_resp *r, const char *code, const char *field, const char *msg)
{
    td_apierr e = TD_AE_INTERNAL;
    for (int k = 0; k < TD_AE_COUNT; k++)
        if (!strcmp(td_apierrs[k].code, code))
            e = (td_apierr)k;
    api_error(r, e, field, "%s", msg);
}

void td_routes_json(td_http_resp *r, int status, json_t *j) { send_json(r, status, j); }

/* Takes the snapshot of dataset id into *snap and queues fn(job) (td_routes_json_job). 0 when
 * queued; else the answer is set, *snap is released and NULL, and job is still the
 * caller's. */
static int defer_dataset(td_app *app, td_http_req *q, td_http_resp *r, const char *id, td_snapshot **snap,
                         td_http_work_fn fn, void *job)
{
    td_err e = {0};
    td_status rc;
    int queued = 0, answered = dataset_hint_check(q, r, id) != 0;
    *snap = NULL;
    rc = answered ? TD_OK : td_store_acquire(app->store, id, snap, &e);
    if (rc == TD_EAGAIN) /* a prepared dataset still being checked */
        td_http_resp_header(r, "Retry-After", "1");
    if (answered) {
        /* 400: the routing key */
    } else if (rc) {
        *snap = NULL;
        td_routes_error(r, rc == TD_ENOTFOUND ? "unknown_dataset" : rc == TD_EAGAIN ? "loading" : "internal",
                        "dataset", e.msg);
    } else if (td_http_defer(q, fn, job) == 0) {
        queued = 1;
    } else {
        td_snapshot_release(*snap);
        *snap = NULL;
        td_http_resp_header(r, "Retry-After", "1");
        td_routes_error(r, atomic_load(&app->ready) ? "busy" : "stopping", NULL, "the work queue is full; retry later");
    }
    return queued ? 0 : -1;
}

void td_routes_json_job(td_app *app, td_http_req *q, td_http_resp *r, td_json_job *job,
                        td_json_parse_fn parse, td_http_work_fn fn)
{
    td_err e = {0};
    json_t *root = NULL, *ds = NULL;
    json_error_t je;
    double t0 = td_clock_s();
    if (!job) {
        td_routes_error(r, "internal", NULL, "out of memory");
    } else if (json_body_check(q, r) == 0) {
        size_t len;
        const char *body = td_http_req_body(q, &len);
        td_status rc;
        job->app = app;
        root = json_loadb(body, len, JSON_REJECT_DUPLICATES, &je);
        ds = json_is_object(root) ? json_object_get(root, "dataset") : NULL;
        if (!json_is_object(root))
            rc = td_err_set(&e, TD_EFORMAT, "the body must be a JSON object%s%s", root ? "" : ": ",
                            root ? "" : je.text);
        else if (!json_is_string(ds) || !json_string_length(ds) || json_string_length(ds) >= TD_SCENE_DATASET_MAX)
            rc = td_err_field(&e, TD_EINVAL, "dataset", "required: a dataset id");
        else
            rc = parse(root, json_string_value(ds), job, &e);
        if (rc) {
            td_routes_error(r, "bad_request", e.field[0] ? e.field : NULL, e.msg);
        } else {
            job->parse_ms = 1e3 * (td_clock_s() - t0);
            if (defer_dataset(app, q, r, json_string_value(ds), &job->snap, fn, job) == 0)
                job = NULL; /* the worker frees it */
        }
    }
    json_decref(root);
    free(job);
}

void td_routes_work_error(td_app *app, td_http_resp *r, td_status rc, const td_err *e, const char *what)
{
    if (rc == TD_ECANCELED)
        api_error(r, atomic_load(&app->ready) ? TD_AE_TIMEOUT : TD_AE_STOPPING, NULL,
                  "%s did not finish within --render-timeout", what);
    else if (rc == TD_ENOMEM || rc == TD_EIO)
        api_error(r, TD_AE_INTERNAL, NULL, "%s", e->msg);
    else
        api_error(r, TD_AE_BAD_REQUEST, e->field[0] ? e->field : NULL, "%s", e->msg);
}
