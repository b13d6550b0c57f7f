/* metrics.c: counters as relaxed C11 atomics and their Prometheus text rendering (see
 * metrics.h). Layout: requests[route][status index] (status indices from http.h's
 * table; an unlisted status counts under "other"), and per method one count per
 * histogram bucket (non-cumulative; summed when printed), a count and a sum kept in
 * nanoseconds so it stays an integer atomic. Rejected: a client library (none in
 * Debian for C) and per-request locks. */
#include "metrics.h"

#include <stdarg.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "http.h"

static const double td_metrics_le[] = {
#define TD_X_LE(v) v,
    TD_METRICS_BUCKETS(TD_X_LE)
#undef TD_X_LE
};
#define TD_NBUCKETS ((int)(sizeof td_metrics_le / sizeof td_metrics_le[0]))

typedef struct td_metrics_hist {
    atomic_uint_least64_t bucket[TD_NBUCKETS + 1]; /* last: above every bound */
    atomic_uint_least64_t count, sum_ns;
} td_metrics_hist;

struct td_metrics {
    const char *const *route_names;
    int nroutes;
    atomic_uint_least64_t *requests; /* (nroutes + 1) x (TD_HTTP_STATUS_COUNT + 1) */
    td_metrics_hist render[TD_METHOD_COUNT];
    atomic_uint_least64_t rays, steps;
    atomic_uint_least64_t pagein_faults, pagein_ns; /* td_metrics_pagein */
};

td_metrics *td_metrics_create(const char *const *route_names, int nroutes)
{
    td_metrics *m = calloc(1, sizeof *m);
    size_t n = (size_t)(nroutes + 1) * (TD_HTTP_STATUS_COUNT + 1);
    if (!m)
        goto out;
    m->route_names = route_names;
    m->nroutes = nroutes;
    m->requests = calloc(n, sizeof *m->requests);
    if (!m->requests) {
        free(m);
        m = NULL;
        goto out;
    }
    for (size_t i = 0; i < n; i++)
        atomic_init(&m->requests[i], 0);
out:
    return m;
}

void td_metrics_free(td_metrics *m)
{
    if (m) {
        free(m->requests);
        free(m);
    }
}

void td_metrics_request(td_metrics *m, int route, int status)
{
    int r = route >= 0 && route < m->nroutes ? route : m->nroutes;
    int s = td_http_status_index(status);
    if (s < 0)
        s = TD_HTTP_STATUS_COUNT;
    atomic_fetch_add_explicit(&m->requests[(size_t)r * (TD_HTTP_STATUS_COUNT + 1) + (size_t)s], 1,
                              memory_order_relaxed);
}

void td_metrics_render(td_metrics *m, td_method method, double seconds, uint64_t rays,
                       uint64_t steps)
{
    td_metrics_hist *h;
    int b = 0;
    if ((unsigned)method >= TD_METHOD_COUNT)
        method = TD_METHOD_AUTO;
    h = &m->render[method];
    while (b < TD_NBUCKETS && seconds > td_metrics_le[b])
        b++;
    atomic_fetch_add_explicit(&h->bucket[b], 1, memory_order_relaxed);
    atomic_fetch_add_explicit(&h->count, 1, memory_order_relaxed);
    atomic_fetch_add_explicit(&h->sum_ns, (uint64_t)(seconds > 0 ? seconds * 1e9 : 0),
                              memory_order_relaxed);
    atomic_fetch_add_explicit(&m->rays, rays, memory_order_relaxed);
    atomic_fetch_add_explicit(&m->steps, steps, memory_order_relaxed);
}

typedef struct td_buf {
    char *p;
    size_t len, cap;
    int oom;
} td_buf;

static void put(td_buf *b, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void put(td_buf *b, const char *fmt, ...)
{
    va_list ap;
    int w;
    if (b->oom)
        return;
    for (;;) {
        va_start(ap, fmt);
        w = vsnprintf(b->p + b->len, b->cap - b->len, fmt, ap);
        va_end(ap);
        if (w < 0) {
            b->oom = 1;
            return;
        }
        if ((size_t)w < b->cap - b->len) {
            b->len += (size_t)w;
            return;
        }
        {
            size_t cap = b->cap * 2 + (size_t)w;
            char *np = realloc(b->p, cap);
            if (!np) {
                b->oom = 1;
                return;
            }
            b->p = np;
            b->cap = cap;
        }
    }
}

#define LD(x) ((unsigned long long)atomic_load_explicit(&(x), memory_order_relaxed))

/* terrad_requests_total by route and status, the statuses that occurred only. */
static void put_requests(td_buf *b, td_metrics *m)
{
    put(b, "# HELP terrad_requests_total HTTP requests answered, by route and status.\n"
            "# TYPE terrad_requests_total counter\n");
    for (int r = 0; r <= m->nroutes; r++)
        for (int s = 0; s <= TD_HTTP_STATUS_COUNT; s++) {
            unsigned long long v = LD(m->requests[(size_t)r * (TD_HTTP_STATUS_COUNT + 1) + (size_t)s]);
            char code[16];
            if (!v)
                continue;
            if (s < TD_HTTP_STATUS_COUNT)
                snprintf(code, sizeof code, "%d", td_http_status_code(s));
            else
                snprintf(code, sizeof code, "other");
            put(b, "terrad_requests_total{route=\"%s\",status=\"%s\"} %llu\n",
                r < m->nroutes ? m->route_names[r] : "other", code, v);
        }
}

/* terrad_render_seconds, a histogram per tracing method. */
static void put_render_seconds(td_buf *b, td_metrics *m)
{
    put(b, "# HELP terrad_render_seconds Wall time of renders, by tracing method.\n"
            "# TYPE terrad_render_seconds histogram\n");
    for (int k = 0; k < TD_METHOD_COUNT; k++) {
        td_metrics_hist *h = &m->render[k];
        unsigned long long cum = 0;
        const char *name = td_method_name((td_method)k);
        for (int i = 0; i < TD_NBUCKETS; i++) {
            cum += LD(h->bucket[i]);
            put(b, "terrad_render_seconds_bucket{method=\"%s\",le=\"%g\"} %llu\n", name,
                td_metrics_le[i], cum);
        }
        cum += LD(h->bucket[TD_NBUCKETS]);
        put(b, "terrad_render_seconds_bucket{method=\"%s\",le=\"+Inf\"} %llu\n", name, cum);
        put(b, "terrad_render_seconds_sum{method=\"%s\"} %.9f\n", name, (double)LD(h->sum_ns) * 1e-9);
        put(b, "terrad_render_seconds_count{method=\"%s\"} %llu\n", name, LD(h->count));
    }
}

void td_metrics_pagein(td_metrics *m, uint64_t faults, double seconds)
{
    atomic_fetch_add_explicit(&m->pagein_faults, faults, memory_order_relaxed);
    atomic_fetch_add_explicit(&m->pagein_ns, (uint64_t)(seconds > 0 ? seconds * 1e9 : 0), memory_order_relaxed);
}

/* The counters of the tracer and the gauges of the queue, the store and the jobs. */
static void put_totals(td_buf *b, td_metrics *m, const td_metrics_ext *e)
{
    put(b, "# HELP terrad_rays_total Rays traced by renders.\n# TYPE terrad_rays_total counter\n"
            "terrad_rays_total %llu\n", LD(m->rays));
    put(b, "# HELP terrad_steps_total Tracer steps taken by renders.\n# TYPE terrad_steps_total counter\n"
            "terrad_steps_total %llu\n", LD(m->steps));
    put(b, "# HELP terrad_render_queue_depth Renders queued or running.\n"
            "# TYPE terrad_render_queue_depth gauge\nterrad_render_queue_depth %d\n", e->queue_depth);
    put(b, "# HELP terrad_render_queue_capacity Renders that may be queued or running at once.\n"
            "# TYPE terrad_render_queue_capacity gauge\nterrad_render_queue_capacity %d\n",
        e->queue_capacity);
    put(b, "# HELP terrad_datasets Datasets served.\n# TYPE terrad_datasets gauge\n"
            "terrad_datasets %d\n", e->datasets);
    put(b, "# HELP terrad_resident_tiles Tiles with acceleration resident.\n"
            "# TYPE terrad_resident_tiles gauge\nterrad_resident_tiles %llu\n",
        (unsigned long long)e->resident_tiles);
    put(b, "# HELP terrad_tiles Tiles of all datasets.\n# TYPE terrad_tiles gauge\n"
            "terrad_tiles %llu\n", (unsigned long long)e->total_tiles);
    put(b, "# HELP terrad_resident_bytes Bytes of heights and acceleration resident.\n"
            "# TYPE terrad_resident_bytes gauge\nterrad_resident_bytes %llu\n",
        (unsigned long long)e->resident_bytes);
    put(b, "# HELP terrad_heights_mapped_bytes Heights, levels and tile structures of prepared datasets, memory-mapped.\n"
            "# TYPE terrad_heights_mapped_bytes gauge\nterrad_heights_mapped_bytes %llu\n"
            "# HELP terrad_heights_resident_bytes Of them, resident in this process (also in "
            "terrad_resident_bytes).\n"
            "# TYPE terrad_heights_resident_bytes gauge\nterrad_heights_resident_bytes %llu\n"
            "# HELP terrad_heights_trims_total Times the mapped heights were dropped back to the budget.\n"
            "# TYPE terrad_heights_trims_total counter\nterrad_heights_trims_total %llu\n",
        (unsigned long long)e->heights_mapped, (unsigned long long)e->heights_resident,
        (unsigned long long)e->heights_trims);
    put(b, "# HELP terrad_major_page_faults_total Pages read from disk on touch (mapped heights not "
            "in memory): each one a ray's wait.\n"
            "# TYPE terrad_major_page_faults_total counter\nterrad_major_page_faults_total %llu\n",
        (unsigned long long)e->major_faults);
    put(b, "# HELP terrad_render_major_faults_total Major page faults of renders, picks and map tiles "
            "(their worker thread's).\n"
            "# TYPE terrad_render_major_faults_total counter\nterrad_render_major_faults_total %llu\n"
            "# HELP terrad_render_pagein_seconds_total Time their worker was blocked (not on a CPU nor "
            "waiting for one): reading the pages it faulted on.\n"
            "# TYPE terrad_render_pagein_seconds_total counter\nterrad_render_pagein_seconds_total %.6f\n",
        LD(m->pagein_faults), (double)LD(m->pagein_ns) * 1e-9);
    put(b, "# HELP terrad_memory_budget_bytes The memory budget (--memory-mb).\n"
            "# TYPE terrad_memory_budget_bytes gauge\nterrad_memory_budget_bytes %llu\n",
        (unsigned long long)e->budget_bytes);
    put(b, "# HELP terrad_tiles_built_total Tile acceleration builds.\n"
            "# TYPE terrad_tiles_built_total counter\nterrad_tiles_built_total %llu\n",
        (unsigned long long)e->tiles_built);
    put(b, "# HELP terrad_tiles_evicted_total Tiles evicted (LRU or admin).\n"
            "# TYPE terrad_tiles_evicted_total counter\nterrad_tiles_evicted_total %llu\n",
        (unsigned long long)e->tiles_evicted);
    put(b, "# HELP terrad_cache_loads_total Tile acceleration read from the disk cache, by result.\n"
            "# TYPE terrad_cache_loads_total counter\n"
            "terrad_cache_loads_total{result=\"hit\"} %llu\n"
            "terrad_cache_loads_total{result=\"miss\"} %llu\n",
        (unsigned long long)e->cache_hits, (unsigned long long)e->cache_misses);
    put(b, "# HELP terrad_sun_bounds_total Sun bounds of shadow rays (renders and map tiles), by whether "
            "the dataset kept one for the same heights and sun.\n"
            "# TYPE terrad_sun_bounds_total counter\n"
            "terrad_sun_bounds_total{result=\"kept\"} %llu\n"
            "terrad_sun_bounds_total{result=\"built\"} %llu\n"
            "# HELP terrad_sun_bounds_bytes Bytes of the sun bounds the datasets keep (in terrad_resident_bytes).\n"
            "# TYPE terrad_sun_bounds_bytes gauge\nterrad_sun_bounds_bytes %llu\n",
        (unsigned long long)e->sun_kept, (unsigned long long)e->sun_built, (unsigned long long)e->sun_bytes);
    put(b, "# HELP terrad_build_jobs Admin preload jobs, by state.\n"
            "# TYPE terrad_build_jobs gauge\n"
            "terrad_build_jobs{state=\"queued\"} %llu\nterrad_build_jobs{state=\"running\"} %llu\n"
            "terrad_build_jobs{state=\"done\"} %llu\nterrad_build_jobs{state=\"failed\"} %llu\n",
        (unsigned long long)e->jobs_queued, (unsigned long long)e->jobs_running,
        (unsigned long long)e->jobs_done, (unsigned long long)e->jobs_failed);
}

/* The per-dataset series, each family's HELP and TYPE once. */
static void put_datasets(td_buf *b, const td_metrics_ext *e)
{
#define TD_DS_SERIES(X)                                                                     \
    X("terrad_dataset_resident_tiles", "gauge", "Tiles of the dataset with acceleration resident.", \
      resident_tiles)                                                                       \
    X("terrad_dataset_resident_bytes", "gauge", "Bytes of the dataset's heights and acceleration.", \
      resident_bytes)                                                                       \
    X("terrad_dataset_requests_total", "counter",                                           \
      "Requests that traced the dataset (renders, tiles, picks, viewsheds).", requests)
#define TD_X_PUT(name, type, help, field)                                                   \
    if (e->ndatasets)                                                                       \
        put(b, "# HELP " name " " help "\n# TYPE " name " " type "\n");                     \
    for (size_t i = 0; i < e->ndatasets; i++)                                               \
        put(b, name "{dataset=\"%s\"} %llu\n", e->ds[i].id, (unsigned long long)e->ds[i].field);
    TD_DS_SERIES(TD_X_PUT)
#undef TD_X_PUT
#undef TD_DS_SERIES
}

char *td_metrics_format(const td_metrics *mc, const td_metrics_ext *e, size_t *len)
{
    td_metrics *m = (td_metrics *)mc; /* atomic loads need a non-const object in C11 */
    td_buf b = {malloc(8192), 0, 8192, 0};
    if (!b.p)
        return NULL;
    put_requests(&b, m);
    put_render_seconds(&b, m);
    put_totals(&b, m, e);
    put_datasets(&b, e);
    if (b.oom) {
        free(b.p);
        b.p = NULL;
        b.len = 0;
    }
    *len = b.len;
    return b.p;
}
