/* http.c: libmicrohttpd glue (see http.h for the threads and the life of a request).
 *
 * Daemon: MHD_USE_INTERNAL_POLLING_THREAD with a thread pool (MHD_OPTION_THREAD_POOL_SIZE)
 * and poll(); MHD_ALLOW_SUSPEND_RESUME for deferred work; MHD_USE_ITC so that
 * MHD_quiesce_daemon can stop the listeners of a pool. Not epoll (MHD_USE_AUTO's choice on
 * Linux, used until 2026-12-02): libmicrohttpd 0.9.75's MHD_quiesce_daemon removes the
 * listening socket from each pool thread's epoll set while that thread may be removing it
 * itself, and panics (abort) when it finds it gone: "Failed to remove listen FD from epoll
 * set" (daemon.c:5531), seen once in CI as a SIGABRT on SIGTERM, the requests in flight
 * lost. With poll() it wakes each thread through its ITC instead, and the thread stops
 * polling the socket. A pool thread polls its own connections, a few dozen at most here.
 * Limits: connection timeout (libmicrohttpd's default is none), per-IP connections, and
 * the body cap, checked against Content-Length before any byte is read and again while
 * a chunked body streams in.
 *
 * Lingering close: a body over the cap is refused (413), but not before it has been read.
 * Answering at once makes libmicrohttpd stop reading and close the socket with the rest of
 * the body unread, and the kernel then resets the connection, so a client still sending
 * (most do: they read only after sending) sees a broken pipe or a reset instead of the
 * 413. So the rest of the body is read and discarded (nothing is kept) and the 413 goes
 * out when it ends, as nginx's lingering close lets its client read the answer. Bounded:
 * after TD_HTTP_LINGER_BYTES discarded or TD_HTTP_LINGER_S seconds the answer is queued
 * anyway (libmicrohttpd then closes; a silent client meets the connection timeout). A
 * client that sent `Expect: 100-continue` has sent no body yet: it gets the 413 at once.
 * Other refusals of a body (415, 401) are the handler's, after the body (within the cap)
 * was read, so they need no lingering.
 *
 * Deferred work: td_http_defer reserves one of (workers + queue) slots under the queue
 * lock or refuses. The connection is suspended after the handler returns and only then
 * pushed to the queue, so a worker can never resume a connection that is not yet
 * suspended. Rejected: running renders on the MHD threads (a pool sized to the cores
 * would stop answering /healthz while every thread renders) and one thread per
 * connection (unbounded concurrency).
 *
 * Deadlines: a worker notes when the work it took must stop (work_timeout_s later) and
 * clears its cancel flag; a watchdog thread wakes every 50 ms, and raises the flag of
 * every worker past its deadline, under the queue lock (so a worker cannot take new
 * work between the test and the store). The work polls the flag (td_render does per
 * block) and gives up with TD_ECANCELED. One flag per worker, not per request: only
 * running work can be late, and a worker runs one request at a time.
 *
 * Measured with curl on loopback (31 requests, medians): /healthz 0.29 ms; a 320 x 240
 * render 17 ms, of which 0.7 ms fall outside the Server-Timing stages (connection
 * set-up, HTTP, resuming the connection, taking the snapshot). */
#include "http.h"
#include "clock.h"
#include "mhdapi.h"

#include <arpa/inet.h>
#include <math.h>
#include <netdb.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include "log.h"

/* Lingering close of a refused body: at most this many bytes, for at most this long. */
#define TD_HTTP_LINGER_BYTES ((size_t)16 << 20)
#define TD_HTTP_LINGER_S 5.0

static const int td_http_codes[] = {
#define TD_X_CODE(code, reason) code,
    TD_HTTP_STATUS_LIST(TD_X_CODE)
#undef TD_X_CODE
};

int td_http_status_index(int status)
{
    int idx = -1;
    for (int i = 0; i < TD_HTTP_STATUS_COUNT && idx < 0; i++)
        if (td_http_codes[i] == status)
            idx = i;
    return idx;
}

int td_http_status_code(int index)
{
    return index >= 0 && index < TD_HTTP_STATUS_COUNT ? td_http_codes[index] : 0;
}

typedef enum td_http_state {
    TD_REQ_RECEIVING = 0, /* body arriving */
    TD_REQ_DEFERRED,      /* handler asked for a worker; suspended or about to be */
    TD_REQ_READY,         /* worker filled resp; waiting to be queued */
    TD_REQ_ANSWERED       /* response queued */
} td_http_state;

/* A worker thread and the deadline of the work it runs: busy and deadline under
 * td_http.mu; cancel is polled by the work without the lock. */
typedef struct td_http_worker {
    td_http *h;
    pthread_t thread;
    int busy;
    double deadline; /* td_clock_s() past which cancel is raised */
    atomic_int cancel;
} td_http_worker;

struct td_http_req {
    td_http *h;
    td_http_worker *worker; /* while its work fn runs */
    struct MHD_Connection *conn;
    char method[16];
    char *path;
    char *body;
    size_t len, cap;
    size_t body_max; /* td_http_opts.body_cap's answer */
    int too_big;
    size_t discarded;  /* body bytes dropped since too_big (lingering close) */
    double t_refused;  /* when too_big was set */
    int route;
    td_http_state state;
    double t0, t_enq, t_start;
    td_http_work_fn fn;
    void *fn_cls;
    td_http_resp resp;
    int status;
    size_t bytes;
    td_http_req *next; /* queue link */
};

struct td_http {
    struct MHD_Daemon *d;
    td_http_opts o;
    int port;
    atomic_int active; /* requests between first access callback and completion */
    pthread_mutex_t mu;
    pthread_cond_t cv;
    td_http_req *head, *tail;
    int reserved;      /* deferred requests queued or running */
    int capacity;      /* workers + queue */
    int stopping;      /* no new deferred work */
    int cancel;        /* past the deadline: queued work answers 503 */
    int quit;          /* workers and the watchdog exit */
    int nworkers;
    td_http_worker *workers;
    pthread_cond_t watch_cv; /* wakes the watchdog to quit */
    int watching;            /* the watchdog thread runs */
    pthread_t watch;
};

/* --- responses ------------------------------------------------------------------- */

void td_http_resp_header(td_http_resp *r, const char *name, const char *fmt, ...)
{
    va_list ap;
    if (r->nheaders >= TD_HTTP_MAX_HEADERS)
        return;
    snprintf(r->hname[r->nheaders], sizeof r->hname[0], "%s", name);
    va_start(ap, fmt);
    vsnprintf(r->hvalue[r->nheaders], sizeof r->hvalue[0], fmt, ap);
    va_end(ap);
    r->nheaders++;
}

void td_http_resp_take(td_http_resp *r, void *data, size_t len, const char *type)
{
    free(r->body);
    r->body = data;
    r->len = data ? len : 0;
    r->content_type = type;
}

int td_http_resp_copy(td_http_resp *r, const void *data, size_t len, const char *type)
{
    int rc = 0;
    char *copy = malloc(len ? len : 1);
    if (!copy) {
        rc = -1;
        goto out;
    }
    if (len)
        memcpy(copy, data, len);
    td_http_resp_take(r, copy, len, type);
out:
    return rc;
}

static enum MHD_Result send_resp(td_http_req *q)
{
    td_http_resp *r = &q->resp;
    struct MHD_Response *mr = NULL;
    enum MHD_Result ret = MHD_NO;

    if (r->len) {
        mr = MHD_create_response_from_buffer_with_free_callback(r->len, r->body, free);
        if (mr)
            r->body = NULL; /* libmicrohttpd owns it now */
    } else {
        mr = MHD_create_response_from_buffer(0, NULL, MHD_RESPMEM_PERSISTENT);
    }
    if (!mr)
        goto out;
    if (r->content_type)
        MHD_add_response_header(mr, MHD_HTTP_HEADER_CONTENT_TYPE, r->content_type);
    for (int i = 0; i < r->nheaders; i++)
        MHD_add_response_header(mr, r->hname[i], r->hvalue[i]);
    q->status = r->status;
    q->bytes = r->len;
    q->state = TD_REQ_ANSWERED;
    ret = MHD_queue_response(q->conn, (unsigned)r->status, mr);
    MHD_destroy_response(mr);
out:
    return ret;
}

/* --- requests -------------------------------------------------------------------- */

const char *td_http_req_method(const td_http_req *q) { return q->method; }
const char *td_http_req_path(const td_http_req *q) { return q->path; }
int td_http_req_too_big(const td_http_req *q) { return q->too_big; }
double td_http_req_age(const td_http_req *q) { return td_clock_s() - q->t0; }
void td_http_req_set_route(td_http_req *q, int route) { q->route = route; }

const atomic_int *td_http_req_cancel(const td_http_req *q)
{
    return q->worker ? &q->worker->cancel : NULL;
}

double td_http_req_queue_wait(const td_http_req *q)
{
    return q->t_start > q->t_enq && q->t_enq > 0 ? q->t_start - q->t_enq : 0.0;
}

const char *td_http_req_header(const td_http_req *q, const char *name)
{
    return MHD_lookup_connection_value(q->conn, MHD_HEADER_KIND, name);
}

const char *td_http_req_query(const td_http_req *q, const char *key)
{
    return MHD_lookup_connection_value(q->conn, MHD_GET_ARGUMENT_KIND, key);
}

typedef struct td_http_iter {
    int (*fn)(void *cls, const char *key, const char *value);
    void *cls;
} td_http_iter;

static enum MHD_Result query_iter(void *cls, enum MHD_ValueKind kind, const char *key,
                                  const char *value)
{
    td_http_iter *it = cls;
    (void)kind;
    return it->fn(it->cls, key, value ? value : "") ? MHD_NO : MHD_YES;
}

void td_http_req_query_each(const td_http_req *q,
                            int (*fn)(void *cls, const char *key, const char *value), void *cls)
{
    td_http_iter it = {fn, cls};
    MHD_get_connection_values(q->conn, MHD_GET_ARGUMENT_KIND, query_iter, &it);
}

const char *td_http_req_body(const td_http_req *q, size_t *len)
{
    *len = q->len;
    return q->body ? q->body : "";
}

int td_http_defer(td_http_req *q, td_http_work_fn fn, void *cls)
{
    int rc = -1;
    td_http *h = q->h;
    pthread_mutex_lock(&h->mu);
    if (!h->stopping && h->reserved < h->capacity) {
        h->reserved++;
        q->fn = fn;
        q->fn_cls = cls;
        q->state = TD_REQ_DEFERRED;
        rc = 0;
    }
    pthread_mutex_unlock(&h->mu);
    return rc;
}

int td_http_queue_depth(const td_http *h)
{
    int n;
    pthread_mutex_lock((pthread_mutex_t *)&h->mu);
    n = h->reserved;
    pthread_mutex_unlock((pthread_mutex_t *)&h->mu);
    return n;
}

static void *worker_main(void *arg)
{
    td_http_worker *wk = arg;
    td_http *h = wk->h;
    for (;;) {
        td_http_req *q = NULL;
        int cancelled;
        pthread_mutex_lock(&h->mu);
        while (!h->head && !h->quit)
            pthread_cond_wait(&h->cv, &h->mu);
        q = h->head;
        if (q) {
            h->head = q->next;
            if (!h->head)
                h->tail = NULL;
            wk->busy = 1;
            wk->deadline = h->o.work_timeout_s > 0 ? td_clock_s() + h->o.work_timeout_s : INFINITY;
            atomic_store(&wk->cancel, 0);
        }
        cancelled = h->cancel;
        pthread_mutex_unlock(&h->mu);
        if (!q)
            break;
        q->t_start = td_clock_s();
        q->worker = wk;
        q->fn(q->fn_cls, q, &q->resp, cancelled);
        q->worker = NULL;
        q->state = TD_REQ_READY;
        pthread_mutex_lock(&h->mu);
        wk->busy = 0;
        h->reserved--;
        pthread_cond_broadcast(&h->cv);
        pthread_mutex_unlock(&h->mu);
        MHD_resume_connection(q->conn);
    }
    return NULL;
}

/* Raises the cancel flag of every worker past its deadline, every 50 ms, until quit. */
static void *watch_main(void *arg)
{
    td_http *h = arg;
    pthread_mutex_lock(&h->mu);
    while (!h->quit) {
        struct timespec ts;
        double now = td_clock_s();
        for (int i = 0; i < h->nworkers; i++)
            if (h->workers[i].busy && now > h->workers[i].deadline)
                atomic_store(&h->workers[i].cancel, 1);
        clock_gettime(CLOCK_REALTIME, &ts);
        ts.tv_nsec += 50 * 1000 * 1000;
        if (ts.tv_nsec >= 1000000000L) {
            ts.tv_sec++;
            ts.tv_nsec -= 1000000000L;
        }
        pthread_cond_timedwait(&h->watch_cv, &h->mu, &ts);
    }
    pthread_mutex_unlock(&h->mu);
    return NULL;
}

/* Marks the request's body as over the cap: from now on it is discarded (lingering). */
static void refuse_body(td_http_req *q)
{
    if (!q->too_big) {
        q->too_big = 1;
        q->t_refused = td_clock_s();
    }
}

/* Whether a refused body has been read for long enough: the 413 goes out now. */
static int linger_over(const td_http_req *q)
{
    return q->discarded > TD_HTTP_LINGER_BYTES || td_clock_s() - q->t_refused > TD_HTTP_LINGER_S;
}

static int body_append(td_http_req *q, const char *data, size_t n)
{
    int rc = 0;
    size_t need = 0;
    if (q->too_big || !td_add_size(q->len, n, &need) || need > q->body_max) {
        refuse_body(q);
        q->discarded = q->discarded + n < q->discarded ? SIZE_MAX : q->discarded + n;
        free(q->body);
        q->body = NULL;
        q->len = q->cap = 0;
        goto out;
    }
    if (need + 1 > q->cap) {
        size_t cap = q->cap ? q->cap : 1024;
        char *nb;
        while (cap < need + 1)
            cap *= 2;
        nb = realloc(q->body, cap);
        if (!nb) {
            rc = -1;
            goto out;
        }
        q->body = nb;
        q->cap = cap;
    }
    memcpy(q->body + q->len, data, n);
    q->len = need;
    q->body[q->len] = '\0';
out:
    return rc;
}

static enum MHD_Result run_handler(td_http *h, td_http_req *q)
{
    enum MHD_Result ret = MHD_YES;
    q->resp.status = 500;
    h->o.handler(h->o.cls, q, &q->resp);
    if (q->state == TD_REQ_DEFERRED) {
        /* Suspend first, then hand over: the worker resumes a suspended connection. */
        MHD_suspend_connection(q->conn);
        pthread_mutex_lock(&h->mu);
        q->t_enq = td_clock_s();
        q->next = NULL;
        if (h->tail)
            h->tail->next = q;
        else
            h->head = q;
        h->tail = q;
        pthread_cond_signal(&h->cv);
        pthread_mutex_unlock(&h->mu);
    } else {
        ret = send_resp(q);
    }
    return ret;
}

static enum MHD_Result access_cb(void *cls, struct MHD_Connection *conn, const char *url,
                                 const char *method, const char *version,
                                 const char *upload_data, size_t *upload_data_size, void **con_cls)
{
    td_http *h = cls;
    td_http_req *q = *con_cls;
    enum MHD_Result ret = MHD_YES;
    (void)version;

    if (!q) {
        const char *cl;
        q = calloc(1, sizeof *q);
        if (!q || !(q->path = strdup(url ? url : "/"))) {
            if (q)
                free(q);
            ret = MHD_NO;
            goto out;
        }
        q->h = h;
        q->conn = conn;
        q->route = -1;
        q->t0 = td_clock_s();
        snprintf(q->method, sizeof q->method, "%s", method);
        q->body_max = h->o.body_cap ? h->o.body_cap(h->o.cls, q) : h->o.max_body;
        *con_cls = q;
        atomic_fetch_add(&h->active, 1);
        cl = MHD_lookup_connection_value(conn, MHD_HEADER_KIND, MHD_HTTP_HEADER_CONTENT_LENGTH);
        if (cl) {
            char *end = NULL;
            unsigned long long n = strtoull(cl, &end, 10);
            if (end != cl && n > q->body_max) {
                /* Refused; answered at once only to a client waiting for 100 Continue,
                   else after the body is read and discarded (lingering close, above) */
                const char *expect = MHD_lookup_connection_value(conn, MHD_HEADER_KIND,
                                                                 MHD_HTTP_HEADER_EXPECT);
                refuse_body(q);
                if (expect && !strcasecmp(expect, "100-continue"))
                    ret = run_handler(h, q);
            }
        }
        goto out;
    }
    if (q->state == TD_REQ_READY) {
        ret = send_resp(q);
        goto out;
    }
    if (q->state != TD_REQ_RECEIVING)
        goto out;
    if (*upload_data_size) {
        if (body_append(q, upload_data, *upload_data_size))
            ret = MHD_NO;
        *upload_data_size = 0;
        if (ret == MHD_YES && q->too_big && linger_over(q))
            ret = run_handler(h, q); /* lingered enough: answer, libmicrohttpd closes */
        goto out;
    }
    ret = run_handler(h, q);
out:
    return ret;
}

static void completed_cb(void *cls, struct MHD_Connection *conn, void **con_cls,
                         enum MHD_RequestTerminationCode toe)
{
    td_http *h = cls;
    td_http_req *q = *con_cls;
    char qpath[600];
    double secs;
    const char *route = "-";
    (void)conn;

    if (!q)
        return;
    secs = td_clock_s() - q->t0;
    if (toe != MHD_REQUEST_TERMINATED_COMPLETED_OK && q->state != TD_REQ_ANSWERED)
        q->status = 0;
    if (q->route >= 0 && q->route < h->o.nroutes && h->o.route_names)
        route = h->o.route_names[q->route];
    td_log(TD_LOG_INFO, "access", "method=%s path=%s route=%s status=%d bytes=%zu latency_ms=%.3f%s",
           q->method, td_log_quote(qpath, sizeof qpath, q->path), route, q->status, q->bytes,
           secs * 1e3, toe == MHD_REQUEST_TERMINATED_COMPLETED_OK ? "" : " aborted=1");
    if (h->o.done)
        h->o.done(h->o.cls, q->route, q->status, q->bytes, secs);
    free(q->resp.body);
    free(q->body);
    free(q->path);
    free(q);
    *con_cls = NULL;
    atomic_fetch_sub(&h->active, 1);
}

static void mhd_logger(void *cls, const char *fmt, va_list ap)
{
    char msg[400], q[500];
    size_t n;
    (void)cls;
    vsnprintf(msg, sizeof msg, fmt, ap);
    n = strlen(msg);
    while (n && (msg[n - 1] == '\n' || msg[n - 1] == '\r'))
        msg[--n] = '\0';
    td_log(TD_LOG_WARN, "mhd", "msg=%s", td_log_quote(q, sizeof q, msg));
}

static void stop_workers(td_http *h)
{
    pthread_mutex_lock(&h->mu);
    h->quit = 1;
    pthread_cond_broadcast(&h->cv);
    pthread_cond_signal(&h->watch_cv);
    pthread_mutex_unlock(&h->mu);
    if (h->watching)
        pthread_join(h->watch, NULL);
    h->watching = 0;
    for (int i = 0; i < h->nworkers; i++)
        pthread_join(h->workers[i].thread, NULL);
    h->nworkers = 0;
}

static void http_free(td_http *h)
{
    if (!h)
        return;
    stop_workers(h);
    free(h->workers);
    pthread_cond_destroy(&h->watch_cv);
    pthread_cond_destroy(&h->cv);
    pthread_mutex_destroy(&h->mu);
    free(h);
}

td_status td_http_start(const td_http_opts *o, td_http **out, td_err *err)
{
    td_status rc = TD_OK;
    td_http *h = NULL;
    struct addrinfo hints, *ai = NULL;
    char port[16];
    unsigned flags = MHD_USE_INTERNAL_POLLING_THREAD | MHD_USE_POLL | MHD_ALLOW_SUSPEND_RESUME |
                     MHD_USE_ITC | MHD_USE_ERROR_LOG;
    const union MHD_DaemonInfo *di;
    int gai;

    *out = NULL;
    rc = td_mhd_open(err); /* libmicrohttpd, loaded on first use (mhdapi.h) */
    if (rc)
        goto out;
    h = calloc(1, sizeof *h);
    if (!h) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for the HTTP server");
        goto out;
    }
    h->o = *o;
    pthread_mutex_init(&h->mu, NULL);
    pthread_cond_init(&h->cv, NULL);
    pthread_cond_init(&h->watch_cv, NULL);
    h->capacity = o->workers + o->queue;
    h->workers = calloc((size_t)o->workers, sizeof *h->workers);
    if (!h->workers) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for %d workers", o->workers);
        goto out;
    }
    for (int i = 0; i < o->workers; i++) {
        h->workers[i].h = h;
        atomic_init(&h->workers[i].cancel, 0);
        if (pthread_create(&h->workers[i].thread, NULL, worker_main, &h->workers[i])) {
            rc = td_err_set(err, TD_ENOMEM, "cannot start worker thread %d", i);
            goto out;
        }
        h->nworkers++;
    }
    if (pthread_create(&h->watch, NULL, watch_main, h)) {
        rc = td_err_set(err, TD_ENOMEM, "cannot start the work deadline watchdog");
        goto out;
    }
    h->watching = 1;
    memset(&hints, 0, sizeof hints);
    hints.ai_family = AF_UNSPEC;
    hints.ai_socktype = SOCK_STREAM;
    hints.ai_flags = AI_PASSIVE | AI_NUMERICSERV;
    snprintf(port, sizeof port, "%d", o->port);
    gai = getaddrinfo(o->host, port, &hints, &ai);
    if (gai || !ai) {
        rc = td_err_set(err, TD_EINVAL, "--listen: cannot resolve '%s': %s", o->host,
                        gai_strerror(gai));
        goto out;
    }
    if (ai->ai_family == AF_INET6)
        flags |= MHD_USE_IPv6;
    h->d = MHD_start_daemon(flags, (uint16_t)o->port, NULL, NULL, access_cb, h,
                            MHD_OPTION_EXTERNAL_LOGGER, mhd_logger, h,
                            MHD_OPTION_SOCK_ADDR, ai->ai_addr,
                            MHD_OPTION_THREAD_POOL_SIZE, (unsigned)(o->threads > 1 ? o->threads : 0),
                            MHD_OPTION_CONNECTION_TIMEOUT, o->conn_timeout_s,
                            MHD_OPTION_PER_IP_CONNECTION_LIMIT, o->per_ip,
                            MHD_OPTION_NOTIFY_COMPLETED, completed_cb, h,
                            MHD_OPTION_END);
    if (!h->d) {
        rc = td_err_set(err, TD_EIO, "cannot listen on %s:%d (address in use or not local?)",
                        o->host, o->port);
        goto out;
    }
    di = MHD_get_daemon_info(h->d, MHD_DAEMON_INFO_BIND_PORT);
    h->port = di ? (int)di->port : o->port;
out:
    if (ai)
        freeaddrinfo(ai);
    if (rc) {
        http_free(h);
        h = NULL;
    }
    *out = h;
    return rc;
}

int td_http_port(const td_http *h) { return h->port; }

int td_http_stop(td_http *h, double deadline_s)
{
    double end = td_clock_s() + deadline_s;
    int left = 0;
    MHD_socket lfd;
    struct timespec nap = {0, 10 * 1000 * 1000};

    lfd = MHD_quiesce_daemon(h->d);
    pthread_mutex_lock(&h->mu);
    h->stopping = 1;
    pthread_mutex_unlock(&h->mu);
    while (atomic_load(&h->active) > 0 && td_clock_s() < end)
        nanosleep(&nap, NULL);
    left = atomic_load(&h->active);
    pthread_mutex_lock(&h->mu);
    for (int i = 0; left && i < h->nworkers; i++)
        if (h->workers[i].busy) /* running work stops at its next poll */
            atomic_store(&h->workers[i].cancel, 1);
    h->cancel = 1; /* whatever is still queued answers 503 */
    while (h->reserved > 0)
        pthread_cond_wait(&h->cv, &h->mu);
    pthread_mutex_unlock(&h->mu);
    /* Let the resumed connections send their answers (bounded). */
    end = td_clock_s() + 1.0;
    while (atomic_load(&h->active) > 0 && td_clock_s() < end)
        nanosleep(&nap, NULL);
    MHD_stop_daemon(h->d);
    if (lfd != MHD_INVALID_SOCKET)
        close(lfd);
    http_free(h);
    return left;
}
