/* cli_serve.c: `terrad serve`: reads the settings, makes the tile store, starts the preload
 * builder and the HTTP server (whose workers render, each with --render-timeout as its
 * deadline), then loads the demo and --data datasets into the store, and waits for
 * SIGTERM/SIGINT.
 * The listener comes first so that a load (seconds for a large DEM) never leaves the
 * server mute: /healthz answers from the first moment, while /readyz and every other route
 * answer 503 (Retry-After: 1) until the datasets are loaded (app->loaded, set once after
 * the last one; handlers read the store only after it, so the store is still filled by
 * one thread before anyone reads it). Then the `ready` log line. With
 * TERRAD_TEST_LOAD_GATE=FILE in the environment the load waits while FILE exists (the
 * tests' way to hold a load, tests/server/test_robust.c).
 * On a signal it stops accepting, lets requests in flight finish for --shutdown-timeout
 * seconds (then cancels renders still running), and exits 0.
 *
 * Signals are blocked before any thread starts and taken with sigwait() on the main
 * thread, so no handler runs in the middle of a render or a malloc. */
#include "cli.h"

#include <limits.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "accel.h"
#include "config.h"
#include "http.h"
#include "jobs.h"
#include "log.h"
#include "metrics.h"
#include "pagein.h"
#include "routes.h"
#include "maps.h"
#include "static.h"
#include "tilestore.h"

static int log2_of(long v)
{
    int k = 0;
    while ((1L << k) < v)
        k++;
    return k;
}

/* The empty tile store. 0, or -1 with the error logged. */
static int open_store(const td_config *cfg, td_app *app)
{
    int rc = 0;
    td_store_opts so;
    td_err e = {0};
    char q[600];

    memset(&so, 0, sizeof so);
    so.budget_bytes = (uint64_t)cfg->memory_mb << 20;
    so.tile_log2 = log2_of(cfg->tile_size);
    so.planes_k = (int)cfg->planes_k;
    so.cache_dir = cfg->cache_dir;
    if (td_store_create(&so, &app->store, &e)) {
        td_log(TD_LOG_ERROR, "start_failed", "msg=%s", td_log_quote(q, sizeof q, e.msg));
        rc = -1;
    } else {
        td_store_set_lod_iso(app->store, (int)cfg->isometric_lod);
    }
    return rc;
}

/* TERRAD_TEST_LOAD_GATE: waits while that file exists (see the top of the file). */
static void load_gate(void)
{
    const char *gate = getenv("TERRAD_TEST_LOAD_GATE");
    struct timespec nap = {0, 20 * 1000 * 1000};
    while (gate && *gate && access(gate, F_OK) == 0)
        nanosleep(&nap, NULL);
}

/* The demo and --data datasets into the store (a missing demo folder is a warning, a bad
 * --data folder an error). 0, or -1 with the error logged. */
static int load_datasets(const td_config *cfg, td_app *app)
{
    int rc = -1, loaded = 0;
    td_err e = {0};
    char q[600];

    load_gate();
    if (cfg->demo_dir[0]) {
        int n = 0;
        if (td_store_add_dir(app->store, cfg->demo_dir, "demo", &n, &e))
            td_log(TD_LOG_WARN, "demo_missing", "msg=%s", td_log_quote(q, sizeof q, e.msg));
        loaded += n;
    }
    if (cfg->data_dir[0]) {
        int n = 0;
        if (td_store_add_dir(app->store, cfg->data_dir, "data", &n, &e)) {
            td_log(TD_LOG_ERROR, "start_failed", "msg=%s", td_log_quote(q, sizeof q, e.msg));
            goto out;
        }
        loaded += n;
    }
    if (loaded == 0)
        td_log(TD_LOG_WARN, "no_datasets",
               "msg=\"no dataset could be loaded; serving anyway (give --data DIR)\"");
    else
        td_log(TD_LOG_INFO, "datasets_ready", "count=%d", loaded);
    rc = 0;
out:
    return rc;
}

/* The HTTP server over the routes (not ready until the datasets are loaded). 0, or -1 with
 * the error logged. */
static int start_http(const td_config *cfg, td_app *app)
{
    td_http_opts ho;
    td_err e = {0};
    char q[600];
    int rc = -1;

    memset(&ho, 0, sizeof ho);
    ho.host = cfg->host;
    ho.port = cfg->port;
    ho.threads = (int)cfg->threads;
    ho.workers = (int)cfg->render_workers;
    ho.queue = (int)cfg->queue;
    ho.max_body = (size_t)cfg->max_body_kb << 10;
    ho.body_cap = td_routes_body_cap;
    ho.conn_timeout_s = (unsigned)cfg->conn_timeout_s;
    ho.per_ip = (unsigned)cfg->per_ip;
    ho.handler = td_routes_handle;
    ho.done = td_routes_done;
    ho.work_timeout_s = cfg->render_timeout_s;
    ho.cls = app;
    ho.route_names = td_route_names;
    ho.nroutes = TD_ROUTE_COUNT;
    if (td_http_start(&ho, &app->http, &e)) {
        td_log(TD_LOG_ERROR, "start_failed", "msg=%s", td_log_quote(q, sizeof q, e.msg));
        goto out;
    }
    td_log(TD_LOG_INFO, "listening", "url=http://%s%s%s:%d/ port=%d threads=%ld workers=%ld queue=%ld",
           strchr(cfg->host, ':') ? "[" : "", cfg->host, strchr(cfg->host, ':') ? "]" : "",
           td_http_port(app->http), td_http_port(app->http), cfg->threads, cfg->render_workers, cfg->queue);
    rc = 0;
out:
    return rc;
}

/* --preload all: one job per dataset, both structures. */
static void preload_all(td_app *app)
{
    td_err e = {0};
    char q[600];
    for (size_t i = 0; i < td_store_count(app->store); i++) {
        td_preload_spec sp;
        unsigned id;
        memset(&sp, 0, sizeof sp);
        sp.dataset = i;
        sp.maxmip = sp.planes = 1;
        if (td_jobs_submit(app->jobs, &sp, &id, &e))
            td_log(TD_LOG_WARN, "preload_skipped", "msg=%s", td_log_quote(q, sizeof q, e.msg));
    }
}

/* Waits for SIGTERM or SIGINT, then stops the HTTP server within --shutdown-timeout. */
static void wait_and_stop(const td_config *cfg, td_app *app, sigset_t *set)
{
    int sig = 0, left;
    while (sigwait(set, &sig) != 0)
        ;
    td_log(TD_LOG_INFO, "stopping", "signal=%s deadline_s=%g", sig == SIGTERM ? "SIGTERM" : "SIGINT",
           cfg->shutdown_s);
    atomic_store(&app->ready, 0);
    left = td_http_stop(app->http, cfg->shutdown_s);
    app->http = NULL;
    td_log(left ? TD_LOG_WARN : TD_LOG_INFO, "stopped", "unfinished_at_deadline=%d", left);
}

int td_cli_serve(int argc, char **argv)
{
    int rc = 1, help = 0, cores = td_cpu_count();
    td_config cfg;
    td_err e = {0};
    td_app app;
    sigset_t set;
    char q[600];

    memset(&app, 0, sizeof app);
    sigemptyset(&set);
    sigaddset(&set, SIGTERM);
    sigaddset(&set, SIGINT);
    pthread_sigmask(SIG_BLOCK, &set, NULL);
    signal(SIGPIPE, SIG_IGN);

    if (td_config_load(&cfg, argc, argv, &help, &e)) {
        fprintf(stderr, "terrad serve: %s\n", e.msg);
        rc = 2;
        goto out;
    }
    if (help) {
        td_config_usage(stdout);
        rc = 0;
        goto out;
    }
    {
        td_log_level lvl = TD_LOG_INFO;
        td_log_level_parse(cfg.log_level, &lvl);
        td_log_set_level(lvl);
    }
    if (cfg.threads == 0)
        cfg.threads = cores;
    if (cfg.render_workers == 0)
        cfg.render_workers = cores;
    td_config_log(&cfg);
    app.cfg = &cfg;
    if (open_store(&cfg, &app))
        goto out;
    td_static_resolve(cfg.web_dir, app.web_dir, app.leaflet_dir);
    app.metrics = td_metrics_create(td_route_names, TD_ROUTE_COUNT);
    app.maps = td_maps_create();
    /* the page-in deadline's watchdog; TERRAD_FAULT_PAGEIN_STALL_MS: its tests' fault injection */
    if (!app.metrics || !app.maps || td_jobs_start(app.store, &app.jobs, &e) ||
        td_pagein_watch_start(cfg.pagein_timeout_s,
                              getenv("TERRAD_FAULT_PAGEIN_STALL_MS") ? atol(getenv("TERRAD_FAULT_PAGEIN_STALL_MS")) : 0,
                              &app.pagein, &e)) {
        td_log(TD_LOG_ERROR, "start_failed", "msg=%s", td_log_quote(q, sizeof q, e.msg[0] ? e.msg : "out of memory"));
        goto out;
    }
    if (start_http(&cfg, &app) || load_datasets(&cfg, &app))
        goto out;
    if (td_store_background_start(app.store, &e)) { /* checks prepared datasets' chunks */
        td_log(TD_LOG_ERROR, "start_failed", "msg=%s", td_log_quote(q, sizeof q, e.msg));
        goto out;
    }
    atomic_store(&app.loaded, 1);
    atomic_store(&app.ready, 1);
    td_log(TD_LOG_INFO, "ready", "datasets=%zu", td_store_count(app.store));
    if (!strcmp(cfg.preload, "all"))
        preload_all(&app);
    wait_and_stop(&cfg, &app, &set);
    rc = 0;
out:
    if (app.http)
        td_http_stop(app.http, 0);
    td_jobs_stop(app.jobs);
    td_pagein_watch_stop(app.pagein);
    td_store_free(app.store);
    td_maps_free(app.maps);
    td_metrics_free(app.metrics);
    td_config_free(&cfg);
    return rc;
}
