/* metrics.h: Prometheus text exposition of terrad's counters (series prefixed terrad_).
 *
 * Counters that the HTTP and render paths bump live here as relaxed atomics (no lock on
 * a request path): requests by route and status, render seconds as a histogram per
 * method, rays and steps. Values owned by other modules (queue depth, resident tiles and
 * bytes, build jobs, cache hits) are read by the caller at scrape time and passed in a
 * td_metrics_ext, so this module depends on nobody. */
#ifndef TD_METRICS_H
#define TD_METRICS_H

#include <stddef.h>
#include <stdint.h>

#include "trace.h"

typedef struct td_metrics td_metrics;

/* Upper bounds (seconds) of the render histogram buckets; +Inf is implicit. */
#define TD_METRICS_BUCKETS(X) X(0.005) X(0.01) X(0.025) X(0.05) X(0.1) X(0.25) X(0.5) \
    X(1.0) X(2.5) X(5.0) X(10.0) X(30.0)

/* One dataset's series (labels dataset="id"): what a replica keeps hot and serves, so a
 * load balancer's routing by dataset can be seen per replica. */
typedef struct td_metrics_dataset {
    const char *id; /* td_store_id_valid: no character that needs escaping in a label */
    uint64_t resident_tiles, resident_bytes, requests;
} td_metrics_dataset;

typedef struct td_metrics_ext {
    int queue_depth, queue_capacity;
    int datasets;
    uint64_t resident_tiles, total_tiles, resident_bytes, budget_bytes;
    uint64_t tiles_built, tiles_evicted, cache_hits, cache_misses;
    uint64_t sun_kept, sun_built, sun_bytes; /* sun bounds (td_snapshot_sunlit) */
    uint64_t jobs_queued, jobs_running, jobs_done, jobs_failed;
    /* prepared datasets' mapped heights: mapped, resident in the process, trims */
    uint64_t heights_mapped, heights_resident, heights_trims;
    uint64_t major_faults; /* pages the process waited on the disk for (getrusage) */
    const td_metrics_dataset *ds; /* ndatasets of them (may be 0) */
    size_t ndatasets;
} td_metrics_ext;

/* route_names[nroutes] must outlive the metrics. NULL when out of memory. */
td_metrics *td_metrics_create(const char *const *route_names, int nroutes);
void td_metrics_free(td_metrics *m);

void td_metrics_request(td_metrics *m, int route, int status);
void td_metrics_render(td_metrics *m, td_method method, double seconds, uint64_t rays,
                       uint64_t steps);
/* A render's (pick's, map tile's) wait for pages of mapped heights (pagein.h). */
void td_metrics_pagein(td_metrics *m, uint64_t faults, double seconds);

/* Returns a malloc'ed text/plain; version=0.0.4 body and its length, or NULL. */
char *td_metrics_format(const td_metrics *m, const td_metrics_ext *ext, size_t *len);

#endif
