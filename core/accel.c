/* accel.c: builds max-mipmaps and parameter planes for every tile of a grid, in
 * parallel: worker threads take tiles from a shared atomic counter (tiles are
 * independent, so no other synchronisation). Reports wall time and resident bytes. */
#include "accel.h"
#include "clock.h"

#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "bigalloc.h"
#include "maxmip.h"
#include "planes.h"

void td_accel_opts_default(td_accel_opts *o)
{
    o->maxmip = 1;
    o->planes = 1;
    o->planes_k = TD_PLANES_K_DEFAULT;
    o->minima = 1;
    o->threads = 0;
    o->transient = 0;
}

void td_accel_opts_for(td_method m, td_accel_opts *o)
{
    td_accel_opts_default(o);
    o->maxmip = m == TD_METHOD_HIERARCHICAL || m == TD_METHOD_AUTO;
    o->planes = m == TD_METHOD_PARAMETRIC;
}

int td_cpu_count(void)
{
    long n = sysconf(_SC_NPROCESSORS_ONLN);
    return n < 1 ? 1 : (int)n;
}

typedef struct build_job {
    const td_grid *g;
    td_accel *a;
    const size_t *at; /* max-mipmaps: tile i's codes at code + at[2 i], its minima at
                         mins + at[2 i + 1] */
    uint16_t *code;
    float *mins;
    int what; /* 0 maxmip, 1 planes */
    int k;
    int minima; /* td_accel_opts.minima */
    atomic_size_t next;
    atomic_int failed;
    td_err err; /* first failure */
    pthread_mutex_t err_lock;
} build_job;

/* Builds tiles until none is left. A max-mipmap's scratch is the worker's, kept from tile
 * to tile on huge pages (td_bigalloc_scratch): picos's six tiles faulted in 80 fresh
 * 4 KiB pages for it, 0.85 ms of a 1.9 ms build. */
static void *build_worker(void *arg)
{
    build_job *job = arg;
    float *scratch = NULL;
    size_t cap = 0;
    for (;;) {
        size_t i = atomic_fetch_add(&job->next, 1);
        td_err err;
        td_status rc;
        if (i >= job->a->ntiles || atomic_load(&job->failed))
            break;
        if (job->what == 0) {
            td_maxmip *m = &job->a->mm[i];
            size_t need = td_maxmip_scratch_floats(job->g, i, job->minima);
            if (need > cap) {
                free(scratch);
                scratch = td_bigalloc_scratch(need * sizeof *scratch);
                cap = scratch ? need : 0;
            }
            rc = td_maxmip_build_into(job->g, i, job->minima, m, job->code + job->at[2 * i],
                                      job->mins + job->at[2 * i + 1], scratch, &err);
            job->a->tiles[i].maxmip = rc == TD_OK ? m : NULL;
        } else {
            td_planes *p = NULL;
            rc = td_planes_build(job->g, i, job->k, &p, &err);
            job->a->tiles[i].planes = p;
        }
        if (rc != TD_OK) {
            pthread_mutex_lock(&job->err_lock);
            if (!atomic_load(&job->failed))
                job->err = err;
            atomic_store(&job->failed, (int)rc);
            pthread_mutex_unlock(&job->err_lock);
        }
    }
    free(scratch);
    return NULL;
}

static td_status run_build(const td_grid *g, td_accel *a, int what, const td_accel_opts *o, int threads,
                           const size_t *at, double *seconds, td_err *err)
{
    td_status rc = TD_OK;
    build_job job = {.g = g, .a = a, .what = what, .k = o->planes_k, .minima = o->minima, .at = at};
    pthread_t tid[256];
    int started = 0;
    double t0 = td_clock_s();

    if (at) {
        job.code = a->store;
        job.mins = (float *)(void *)((char *)a->store + at[2 * a->ntiles]);
    }
    atomic_init(&job.next, 0);
    atomic_init(&job.failed, 0);
    pthread_mutex_init(&job.err_lock, NULL);
    if (threads > 256)
        threads = 256;
    for (int i = 1; i < threads; i++) {
        if (pthread_create(&tid[started], NULL, build_worker, &job) == 0)
            started++;
    }
    build_worker(&job); /* the calling thread works too */
    for (int i = 0; i < started; i++)
        pthread_join(tid[i], NULL);
    pthread_mutex_destroy(&job.err_lock);
    *seconds = td_clock_s() - t0;
    if (atomic_load(&job.failed)) {
        rc = (td_status)atomic_load(&job.failed);
        if (err)
            *err = job.err;
    }
    return rc;
}

/* The max-mipmaps' records and their one buffer: *at (malloc'ed, 2 ntiles + 1 entries) gets
 * where each tile's codes and minima start (in codes and in floats from the first of each)
 * and, last, the byte offset of the first minimum in the buffer. */
static td_status maxmip_store(const td_grid *g, td_accel *a, int minima, int transient, size_t **at, td_err *err)
{
    td_status rc = TD_OK;
    size_t codes = 0, mins = 0, bytes = 0, *o = malloc((2 * a->ntiles + 1) * sizeof *o);
    for (size_t i = 0; o && i < a->ntiles; i++) {
        size_t c, m;
        td_maxmip_sizes(g, i, minima, &c, &m);
        o[2 * i] = codes;
        o[2 * i + 1] = mins;
        codes += c;
        mins += m;
    }
    if (o) /* the minima after the codes, on a float's boundary */
        o[2 * a->ntiles] = (codes * sizeof(uint16_t) + sizeof(float) - 1) & ~(sizeof(float) - 1);
    a->mm = calloc(a->ntiles ? a->ntiles : 1, sizeof *a->mm);
    if (o && !td_add_size(o[2 * a->ntiles], mins * sizeof(float), &bytes)) /* cannot overflow: */
        bytes = 0;                                                         /* they fit the grid */
    a->store = o && bytes ? (transient ? td_bigalloc_scratch(bytes) : td_bigalloc(bytes)) : NULL;
    if (!o || !a->mm || !a->store)
        rc = td_err_set(err, TD_ENOMEM, "out of memory for the max-mipmaps (%zu bytes)", bytes);
    *at = o;
    return rc;
}

td_status td_accel_build(const td_grid *g, const td_accel_opts *o, td_accel **out,
                         td_accel_stats *st, td_err *err)
{
    td_status rc = TD_OK;
    td_accel_stats stats;
    td_accel *a = NULL;
    size_t *at = NULL;
    int threads = o->threads > 0 ? o->threads : td_cpu_count();

    memset(&stats, 0, sizeof stats);
    *out = NULL;
    a = calloc(1, sizeof *a);
    if (!a) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for acceleration records");
        goto out;
    }
    a->ntiles = (size_t)g->tiles_x * (size_t)g->tiles_y;
    a->tiles = calloc(a->ntiles, sizeof *a->tiles);
    if (!a->tiles) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for acceleration records");
        goto out;
    }
    stats.tiles = (int64_t)a->ntiles;
    if (o->maxmip) {
        rc = maxmip_store(g, a, o->minima, o->transient, &at, err);
        if (rc == TD_OK)
            rc = run_build(g, a, 0, o, threads, at, &stats.maxmip_seconds, err);
        if (rc != TD_OK)
            goto out;
        for (size_t i = 0; i < a->ntiles; i++)
            stats.maxmip_bytes += a->tiles[i].maxmip->bytes;
    }
    if (o->planes) {
        rc = run_build(g, a, 1, o, threads, NULL, &stats.planes_seconds, err);
        if (rc != TD_OK)
            goto out;
        for (size_t i = 0; i < a->ntiles; i++)
            stats.planes_bytes += a->tiles[i].planes->bytes;
    }
out:
    free(at);
    if (rc != TD_OK) {
        td_accel_free(a);
        a = NULL;
    }
    if (st)
        *st = stats;
    *out = a;
    return rc;
}

void td_accel_free(td_accel *a)
{
    if (a) {
        for (size_t i = 0; a->tiles && i < a->ntiles; i++)
            td_planes_free((td_planes *)a->tiles[i].planes); /* the max-mipmaps are a->mm's */
        free(a->mm);
        free(a->store);
        free(a->tiles);
        free(a);
    }
}
