/* jobs.c: the admin preload queue and its single builder thread (see jobs.h).
 *
 * Records live in a ring of TD_JOBS_KEEP slots indexed by id % TD_JOBS_KEEP; a queued
 * or running job is never overwritten (submit refuses when its slot is still busy,
 * which TD_JOBS_QUEUE_MAX makes impossible in practice). All fields are under one
 * mutex; the progress callback takes it for a few stores per tile. */
#include "jobs.h"
#include "clock.h"

#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "log.h"

static const char *const td_job_state_names[] = {
#define TD_X_NAME(e, name) name,
    TD_JOB_STATE_LIST(TD_X_NAME)
#undef TD_X_NAME
};

const char *td_job_state_name(td_job_state s)
{
    return (unsigned)s < TD_JOB_STATE_COUNT ? td_job_state_names[s] : "unknown";
}

typedef struct td_job {
    td_job_info info;
    td_preload_spec spec;
    size_t *tiles;
    double t_start;
    int used;
} td_job;

struct td_jobs {
    td_store *store;
    pthread_mutex_t mu;
    pthread_cond_t cv;
    pthread_t thread;
    int started;
    int quit;
    unsigned next_id;
    td_job ring[TD_JOBS_KEEP];
    size_t queued;
    int running;
};

static td_job *oldest_queued_locked(td_jobs *j)
{
    td_job *best = NULL;
    for (int i = 0; i < TD_JOBS_KEEP; i++) {
        td_job *jb = &j->ring[i];
        if (jb->used && jb->info.state == TD_JOB_QUEUED && (!best || jb->info.id < best->info.id))
            best = jb;
    }
    return best;
}

typedef struct td_job_run {
    td_jobs *jobs;
    td_job *job;
} td_job_run;

static int run_progress(void *cls, const char *phase, size_t done, size_t total)
{
    td_job_run *r = cls;
    td_job_info *in = &r->job->info;
    int quit;
    pthread_mutex_lock(&r->jobs->mu);
    snprintf(in->phase, sizeof in->phase, "%s", phase);
    in->done = done;
    in->total = total;
    quit = r->jobs->quit;
    pthread_mutex_unlock(&r->jobs->mu);
    return quit;
}

static void *builder_main(void *arg)
{
    td_jobs *j = arg;
    pthread_mutex_lock(&j->mu);
    for (;;) {
        td_job *jb;
        td_preload_spec spec;
        td_job_run run;
        td_err e = {0};
        td_status rc;
        size_t built = 0;
        while (!j->quit && !(jb = oldest_queued_locked(j)))
            pthread_cond_wait(&j->cv, &j->mu);
        if (j->quit)
            break;
        jb->info.state = TD_JOB_RUNNING;
        jb->t_start = td_clock_s();
        j->queued--;
        j->running = 1;
        spec = jb->spec;
        pthread_mutex_unlock(&j->mu);

        td_log(TD_LOG_INFO, "job_started", "job=%u dataset=%s tiles=%zu", jb->info.id,
               jb->info.dataset, jb->info.requested);
        run.jobs = j;
        run.job = jb;
        rc = td_store_preload(j->store, &spec, run_progress, &run, &built, &e);

        pthread_mutex_lock(&j->mu);
        jb->info.elapsed_s = td_clock_s() - jb->t_start;
        jb->info.built = built;
        jb->info.estimate_s = 0;
        if (rc == TD_OK) {
            jb->info.state = TD_JOB_DONE;
            snprintf(jb->info.phase, sizeof jb->info.phase, "done");
            jb->info.done = jb->info.total = jb->info.requested; /* all resident now */
        } else {
            jb->info.state = TD_JOB_FAILED;
            jb->info.error_status = (int)rc;
            snprintf(jb->info.phase, sizeof jb->info.phase, "failed");
            snprintf(jb->info.error, sizeof jb->info.error, "%s", e.msg);
        }
        j->running = 0;
        free(jb->tiles);
        jb->tiles = NULL;
        jb->spec.tiles = NULL;
        pthread_cond_broadcast(&j->cv);
        {
            char q[600];
            td_log(rc ? TD_LOG_WARN : TD_LOG_INFO, "job_finished",
                   "job=%u dataset=%s state=%s built=%zu seconds=%.3f error=%s", jb->info.id,
                   jb->info.dataset, td_job_state_name(jb->info.state), built, jb->info.elapsed_s,
                   td_log_quote(q, sizeof q, jb->info.error));
        }
    }
    pthread_mutex_unlock(&j->mu);
    return NULL;
}

td_status td_jobs_start(td_store *s, td_jobs **out, td_err *err)
{
    td_status rc = TD_OK;
    td_jobs *j = calloc(1, sizeof *j);
    *out = NULL;
    if (!j) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for the job table");
        goto out;
    }
    j->store = s;
    j->next_id = 1;
    pthread_mutex_init(&j->mu, NULL);
    pthread_cond_init(&j->cv, NULL);
    if (pthread_create(&j->thread, NULL, builder_main, j)) {
        rc = td_err_set(err, TD_ENOMEM, "cannot start the builder thread");
        pthread_mutex_destroy(&j->mu);
        pthread_cond_destroy(&j->cv);
        free(j);
        goto out;
    }
    j->started = 1;
    *out = j;
out:
    return rc;
}

void td_jobs_stop(td_jobs *j)
{
    if (!j)
        return;
    pthread_mutex_lock(&j->mu);
    j->quit = 1;
    pthread_cond_broadcast(&j->cv);
    pthread_mutex_unlock(&j->mu);
    if (j->started)
        pthread_join(j->thread, NULL);
    for (int i = 0; i < TD_JOBS_KEEP; i++)
        free(j->ring[i].tiles);
    pthread_cond_destroy(&j->cv);
    pthread_mutex_destroy(&j->mu);
    free(j);
}

td_status td_jobs_submit(td_jobs *j, const td_preload_spec *spec, unsigned *id, td_err *err)
{
    td_status rc = TD_OK;
    size_t *tiles = NULL;
    td_job *jb;
    td_dataset_info di;

    if (spec->tiles && spec->ntiles) {
        tiles = malloc(spec->ntiles * sizeof *tiles);
        if (!tiles) {
            rc = td_err_set(err, TD_ENOMEM, "out of memory for %zu tiles", spec->ntiles);
            goto out;
        }
        memcpy(tiles, spec->tiles, spec->ntiles * sizeof *tiles);
    }
    td_store_info(j->store, spec->dataset, &di);
    pthread_mutex_lock(&j->mu);
    jb = &j->ring[j->next_id % TD_JOBS_KEEP];
    if (j->quit || j->queued >= TD_JOBS_QUEUE_MAX ||
        (jb->used && (jb->info.state == TD_JOB_QUEUED || jb->info.state == TD_JOB_RUNNING))) {
        pthread_mutex_unlock(&j->mu);
        rc = td_err_set(err, TD_ETOOBIG, "%d preload jobs are already waiting", TD_JOBS_QUEUE_MAX);
        goto out;
    }
    free(jb->tiles);
    memset(jb, 0, sizeof *jb);
    jb->used = 1;
    jb->spec = *spec;
    jb->spec.tiles = tiles;
    jb->tiles = tiles;
    tiles = NULL;
    jb->info.id = j->next_id++;
    snprintf(jb->info.dataset, sizeof jb->info.dataset, "%s", di.id);
    jb->info.state = TD_JOB_QUEUED;
    snprintf(jb->info.phase, sizeof jb->info.phase, "queued");
    jb->info.requested = spec->tiles ? spec->ntiles : di.ntiles;
    jb->info.total = jb->info.requested;
    jb->info.maxmip = spec->maxmip;
    jb->info.planes = spec->planes;
    jb->info.pin = spec->pin;
    jb->info.rebuild = spec->rebuild;
    jb->info.estimate_s = -1;
    *id = jb->info.id;
    j->queued++;
    pthread_cond_broadcast(&j->cv);
    pthread_mutex_unlock(&j->mu);
out:
    free(tiles);
    return rc;
}

int td_jobs_get(td_jobs *j, unsigned id, td_job_info *out)
{
    int found = 0;
    pthread_mutex_lock(&j->mu);
    {
        td_job *jb = &j->ring[id % TD_JOBS_KEEP];
        if (jb->used && jb->info.id == id) {
            *out = jb->info;
            if (jb->info.state == TD_JOB_RUNNING) {
                out->elapsed_s = td_clock_s() - jb->t_start;
                out->estimate_s = out->done > 0 && out->total >= out->done
                                      ? out->elapsed_s / (double)out->done *
                                            (double)(out->total - out->done)
                                      : -1;
            }
            found = 1;
        }
    }
    pthread_mutex_unlock(&j->mu);
    return found;
}

void td_jobs_counts(td_jobs *j, size_t counts[TD_JOB_STATE_COUNT])
{
    memset(counts, 0, sizeof(size_t) * TD_JOB_STATE_COUNT);
    pthread_mutex_lock(&j->mu);
    for (int i = 0; i < TD_JOBS_KEEP; i++)
        if (j->ring[i].used)
            counts[j->ring[i].info.state]++;
    pthread_mutex_unlock(&j->mu);
}

void td_jobs_wait_idle(td_jobs *j)
{
    pthread_mutex_lock(&j->mu);
    while (!j->quit && (j->queued || j->running))
        pthread_cond_wait(&j->cv, &j->mu);
    pthread_mutex_unlock(&j->mu);
}
