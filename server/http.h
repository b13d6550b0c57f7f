/* http.h: the HTTP layer of `terrad serve` over libmicrohttpd.
 *
 * One handler sees every request once its whole body has arrived (or once the body is
 * known to exceed the cap: td_http_req_too_big). It fills a td_http_resp whose body
 * buffer is handed to libmicrohttpd with a free callback (no copy). Slow work (renders)
 * does not run on the HTTP threads: the handler calls td_http_defer, which reserves a
 * slot in a bounded queue of worker threads or refuses (the caller answers 503); a
 * deferred connection is suspended and resumed when a worker has filled the response,
 * so health checks and metrics stay answered while every worker renders. Each worker
 * has a cancel flag that deferred work polls (td_http_req_cancel): a watchdog thread
 * raises it once the work has run for work_timeout_s, and td_http_stop raises every
 * flag when its deadline passes.
 *
 *   MHD threads (pool, poll)           worker threads (render_workers)
 *   access cb -> handler --defer-->  [bounded queue] -> work fn -> resume connection
 *            <---------------- response queued on the next access cb ------------
 *                                      watchdog: raises a worker's flag at its deadline
 *
 * Per-request state lives from the first access callback to the completion callback,
 * which logs the access line, reports to the metrics hook and frees it. */
#ifndef TD_HTTP_H
#define TD_HTTP_H

#include <stdatomic.h>
#include <stddef.h>
#include <stdint.h>

#include "status.h"

/* X(code, reason): the statuses terrad answers with (metrics index them). */
#define TD_HTTP_STATUS_LIST(X)                                                 \
    X(200, "OK")                                                               \
    X(202, "Accepted")                                                         \
    X(204, "No Content")                                                       \
    X(304, "Not Modified")                                                     \
    X(400, "Bad Request")                                                      \
    X(401, "Unauthorized")                                                     \
    X(403, "Forbidden")                                                        \
    X(404, "Not Found")                                                        \
    X(405, "Method Not Allowed")                                               \
    X(409, "Conflict")                                                         \
    X(413, "Content Too Large")                                                \
    X(415, "Unsupported Media Type")                                           \
    X(500, "Internal Server Error")                                            \
    X(503, "Service Unavailable")

enum {
#define TD_X_COUNT(code, reason) TD_HTTP_IDX_##code,
    TD_HTTP_STATUS_LIST(TD_X_COUNT)
#undef TD_X_COUNT
    TD_HTTP_STATUS_COUNT
};

/* Index of a status in the table, or -1. */
int td_http_status_index(int status);
int td_http_status_code(int index);

#define TD_HTTP_MAX_HEADERS 16

typedef struct td_http_resp {
    int status;
    char *body;               /* malloc'ed, owned; handed to libmicrohttpd */
    size_t len;
    const char *content_type; /* static string or NULL */
    int nheaders;
    char hname[TD_HTTP_MAX_HEADERS][40];
    char hvalue[TD_HTTP_MAX_HEADERS][512];
} td_http_resp;

/* Adds a header (dropped, silently, beyond TD_HTTP_MAX_HEADERS). */
void td_http_resp_header(td_http_resp *r, const char *name, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
/* Replaces the body with a copy of (data, len); returns 0, or -1 out of memory. */
int td_http_resp_copy(td_http_resp *r, const void *data, size_t len, const char *type);
/* Takes ownership of a malloc'ed body. */
void td_http_resp_take(td_http_resp *r, void *data, size_t len, const char *type);

typedef struct td_http_req td_http_req;
typedef struct td_http td_http;

const char *td_http_req_method(const td_http_req *q);
const char *td_http_req_path(const td_http_req *q);
const char *td_http_req_header(const td_http_req *q, const char *name); /* case-insensitive */
const char *td_http_req_query(const td_http_req *q, const char *key);
/* Calls fn for every query argument in order; stops when fn returns non-zero. */
void td_http_req_query_each(const td_http_req *q,
                            int (*fn)(void *cls, const char *key, const char *value), void *cls);
const char *td_http_req_body(const td_http_req *q, size_t *len);
int td_http_req_too_big(const td_http_req *q);
double td_http_req_age(const td_http_req *q); /* seconds since the request began */
/* Seconds a deferred request waited in the queue before a worker took it. */
double td_http_req_queue_wait(const td_http_req *q);
/* Route label kept for the access log and metrics (a static string id). */
void td_http_req_set_route(td_http_req *q, int route);
/* In a work fn (td_http_defer): the flag that long work polls (td_render_opts.cancel),
 * raised once the work has run for td_http_opts.work_timeout_s or when td_http_stop's
 * deadline passes. NULL outside a work fn. */
const atomic_int *td_http_req_cancel(const td_http_req *q);

/* Worker callback: fills resp. `cancelled` is set when the server is stopping past its
 * deadline: answer quickly (503) without doing the work. */
typedef void (*td_http_work_fn)(void *cls, td_http_req *q, td_http_resp *resp, int cancelled);

/* From a handler: run fn on a worker and answer with what it fills in. Returns 0 when
 * queued (the handler's resp is then ignored), -1 when the queue is full. `cls` is
 * owned by the caller's fn (free it there). */
int td_http_defer(td_http_req *q, td_http_work_fn fn, void *cls);

typedef void (*td_http_handler)(void *cls, td_http_req *q, td_http_resp *resp);
/* Called once per finished request (status 0 if the client went away first). */
typedef void (*td_http_done_fn)(void *cls, int route, int status, size_t bytes, double seconds);

typedef struct td_http_opts {
    const char *host; /* numeric or resolvable */
    int port;         /* 0: any free port (see td_http_port) */
    int threads;      /* HTTP thread pool size, >= 1 */
    int workers;      /* deferred-work threads, >= 1 */
    int queue;        /* deferred requests waiting beyond the running ones, >= 0 */
    size_t max_body;  /* bytes */
    /* The body cap of one request, asked once its headers are in (NULL: max_body for
     * all): a route may take larger bodies from whom it trusts (heights edits, token). */
    size_t (*body_cap)(void *cls, const td_http_req *q);
    unsigned conn_timeout_s;
    unsigned per_ip;
    td_http_handler handler;
    td_http_done_fn done;
    void *cls;
    double work_timeout_s;          /* deferred work's deadline once a worker takes it */
    const char *const *route_names; /* for the access log; indexed by route id */
    int nroutes;
} td_http_opts;

td_status td_http_start(const td_http_opts *o, td_http **out, td_err *err);
int td_http_port(const td_http *h);
/* Deferred requests queued or running now. */
int td_http_queue_depth(const td_http *h);
/* Stops accepting, lets requests in flight finish for up to `deadline_s` seconds
 * (then raises the running work's cancel flags and tells queued work it is cancelled),
 * stops the threads, frees. Returns the number of requests still unfinished at the
 * deadline. */
int td_http_stop(td_http *h, double deadline_s);

#endif
