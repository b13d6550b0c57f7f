/* routes.h: the HTTP API of `terrad serve` (DESIGN.md, docs/api.md): dispatch by path
 * and method, JSON errors, authentication of admin routes, and the handlers that call
 * the tile store, the job queue, the renderer and the web page's files (static.h).
 *
 * Route labels are one X-macro table (enum, label for metrics and the access log); the
 * paths, methods and handlers are a table in routes.c. */
#ifndef TD_ROUTES_H
#define TD_ROUTES_H

#include <limits.h>
#include <jansson.h>
#include <stdatomic.h>

#include "config.h"
#include "http.h"
#include "jobs.h"
#include "metrics.h"
#include "tilestore.h"

#define TD_ROUTE_LIST(X)                                                       \
    X(TD_ROUTE_RENDER, "render")                                               \
    X(TD_ROUTE_TILES, "tiles")                                                 \
    X(TD_ROUTE_PICK, "pick")                                                   \
    X(TD_ROUTE_DATASETS, "datasets")                                           \
    X(TD_ROUTE_DATASET, "dataset")                                             \
    X(TD_ROUTE_PRELOAD, "admin_preload")                                       \
    X(TD_ROUTE_JOB, "admin_job")                                               \
    X(TD_ROUTE_EVICT, "admin_evict")                                           \
    X(TD_ROUTE_HEIGHTS, "admin_heights")                                       \
    X(TD_ROUTE_HEALTHZ, "healthz")                                             \
    X(TD_ROUTE_READYZ, "readyz")                                               \
    X(TD_ROUTE_METRICS, "metrics")                                             \
    X(TD_ROUTE_WEB, "web")                                                     \
    X(TD_ROUTE_VIEWSHED, "viewshed")                                           \
    X(TD_ROUTE_LOS, "los")                                                     \
    X(TD_ROUTE_MAPS, "maps")                                                   \
    X(TD_ROUTE_TILEJSON, "tilejson")                                           \
    X(TD_ROUTE_HORIZON, "horizon")                                             \
    X(TD_ROUTE_PEAKS, "peaks")                                                 \
    X(TD_ROUTE_UNKNOWN, "unknown")

typedef enum td_route {
#define TD_X_ENUM(e, name) e,
    TD_ROUTE_LIST(TD_X_ENUM)
#undef TD_X_ENUM
    TD_ROUTE_COUNT
} td_route;

extern const char *const td_route_names[TD_ROUTE_COUNT];

/* Everything a handler needs; owned by cli_serve.c. */
typedef struct td_app {
    const td_config *cfg;
    td_store *store;
    td_jobs *jobs;
    td_metrics *metrics;
    td_http *http;     /* set once the server runs (queue depth for /metrics) */
    atomic_int ready;  /* /readyz: 1 once serving, 0 again when stopping */
    atomic_int loaded; /* 1 once the datasets are loaded: before, only /healthz and
                          /readyz answer (503), and nothing reads the store */
    char web_dir[PATH_MAX];     /* realpath, or "" when absent */
    char leaflet_dir[PATH_MAX]; /* realpath of web/node_modules/leaflet/dist, or "" */
    struct td_maps *maps;       /* map tiles' per-dataset CRS cache (maps.h) */
    struct td_pagein_watch *pagein; /* the page-in deadline's watchdog (pagein.h), or NULL */
} td_app;

/* td_http_handler and td_http_done_fn for td_http_start (cls: the td_app). */
void td_routes_handle(void *cls, td_http_req *q, td_http_resp *resp);
void td_routes_done(void *cls, int route, int status, size_t bytes, double seconds);

/* For handlers in other files (viewshed.c, pano.c): a JSON error with one of routes.c's
 * codes ("bad_request", "unknown_dataset", "internal", "busy", "stopping",
 * "render_timeout"; an unknown code is "internal") and a JSON body (taken, NULL: 500). */
void td_routes_error(td_http_resp *r, const char *code, const char *field, const char *msg);
void td_routes_json(td_http_resp *r, int status, json_t *j);

/* What every deferred JSON job of another file starts with (its first member). */
typedef struct td_json_job {
    td_app *app;
    td_snapshot *snap; /* the dataset, held until the worker releases it */
    double parse_ms;
} td_json_job;

/* Reads a POST body's JSON object into job (its first member a td_json_job; app is set):
 * dataset is its "dataset", a string of 1 to TD_SCENE_DATASET_MAX - 1 bytes. TD_OK, or the
 * error in e (with the field at fault). */
typedef td_status (*td_json_parse_fn)(json_t *root, const char *dataset, td_json_job *job, td_err *e);

/* A POST with a JSON body as deferred work (viewshed.c, pano.c): 415 unless the body is
 * JSON, 400 unless it is a JSON object with a "dataset" string, then parse on the HTTP
 * thread (400 with its field; all timed into job->parse_ms), the
 * snapshot of the dataset it names (404 unknown_dataset, 503 loading, or 500), then fn(job)
 * queued on the HTTP layer's worker queue (503 busy or stopping, with Retry-After, when
 * it is full). job is calloc'd by the caller (NULL: 500) and owned here: the worker owns
 * it and its snapshot once queued, else it is freed here. */
void td_routes_json_job(td_app *app, td_http_req *q, td_http_resp *r, td_json_job *job,
                        td_json_parse_fn parse, td_http_work_fn fn);
/* A core failure of deferred work as the answer: the deadline or shutdown (TD_ECANCELED:
 * 503 render_timeout or stopping; `what` names the work, e.g. "the viewshed"), ours
 * (TD_ENOMEM, TD_EIO: 500), else the input at fault (400 with core's field). */
void td_routes_work_error(td_app *app, td_http_resp *r, td_status rc, const td_err *e, const char *what);

/* td_http_opts.body_cap: --max-edit-kb for a PUT of heights with the right bearer token,
 * --max-body-kb for every other request (so only an admin can send large bodies). */
size_t td_routes_body_cap(void *cls, const td_http_req *q);

/* A decimal integer in [0, max] (digits only): 1 and *out, or 0. */
int td_routes_parse_uint(const char *s, long max, long *out);

/* Constant-time comparison of a presented token with the configured one. */
int td_routes_token_equal(const char *given, const char *want);

#endif
