/* jobs.h: admin preload jobs. POST /v1/admin/preload submits one; a single builder
 * thread runs them in order (so the tile store's budget holds within one tile) and the
 * job record reports progress: state, phase, tiles done of total, elapsed seconds and an
 * estimate of the seconds left. The last TD_JOBS_KEEP jobs stay queryable. */
#ifndef TD_JOBS_H
#define TD_JOBS_H

#include <stddef.h>

#include "tilestore.h"

#define TD_JOBS_KEEP 256
#define TD_JOBS_QUEUE_MAX 64

#define TD_JOB_STATE_LIST(X)                                                   \
    X(TD_JOB_QUEUED, "queued")                                                 \
    X(TD_JOB_RUNNING, "running")                                               \
    X(TD_JOB_DONE, "done")                                                     \
    X(TD_JOB_FAILED, "failed")

typedef enum td_job_state {
#define TD_X_ENUM(e, name) e,
    TD_JOB_STATE_LIST(TD_X_ENUM)
#undef TD_X_ENUM
    TD_JOB_STATE_COUNT
} td_job_state;

const char *td_job_state_name(td_job_state s);

typedef struct td_job_info {
    unsigned id;
    char dataset[TD_STORE_ID_MAX + 1];
    td_job_state state;
    char phase[16];
    size_t done, total; /* tiles of the current phase */
    size_t requested;   /* tiles named by the request */
    size_t built;       /* tiles published (when done) */
    int maxmip, planes, pin, rebuild;
    double elapsed_s;   /* since it started (0 while queued) */
    double estimate_s;  /* seconds left, from the pace so far; -1 unknown */
    char error[512];
    int error_status;   /* td_status of a failure */
} td_job_info;

typedef struct td_jobs td_jobs;

td_status td_jobs_start(td_store *s, td_jobs **out, td_err *err);
/* Cancels queued jobs and the running one (before its next tile), joins, frees. */
void td_jobs_stop(td_jobs *j);

/* Queues a preload (the tile list is copied). TD_ETOOBIG when TD_JOBS_QUEUE_MAX jobs
 * are already waiting. */
td_status td_jobs_submit(td_jobs *j, const td_preload_spec *spec, unsigned *id, td_err *err);
/* Fills *out and returns 1 if the job is known, else 0. */
int td_jobs_get(td_jobs *j, unsigned id, td_job_info *out);
/* Jobs per state. */
void td_jobs_counts(td_jobs *j, size_t counts[TD_JOB_STATE_COUNT]);
/* Blocks until no job is queued or running (tests, start-up preload). */
void td_jobs_wait_idle(td_jobs *j);

#endif
