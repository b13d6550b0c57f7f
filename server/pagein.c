/* pagein.c: a thread's major faults and blocked time around a request, and the watchdog
 * that bounds it (see pagein.h). Called by the render worker in routes.c; the watchdog is
 * started by `terrad serve` (cli_serve.c). Blocked time comes from the scheduler's own
 * accounting (/proc/thread-self/schedstat: nanoseconds on a CPU, nanoseconds runnable
 * but waiting for one), so a render slowed by other threads on a busy 2-core machine is
 * not counted as waiting for the disk. Rejected: delay accounting's blkio ticks
 * (/proc/.../stat field 42), off by default (kernel.task_delayacct = 0 here). */
#define _GNU_SOURCE
#include "pagein.h"

#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <time.h>
#include <unistd.h>

#include "clock.h"

/* A thread's schedstat: tid 0 for the calling thread. */
static int sched_of(pid_t tid, uint64_t *run_ns, uint64_t *rq_ns)
{
    unsigned long long a = 0, b = 0;
    char path[64];
    FILE *f;
    if (tid)
        snprintf(path, sizeof path, "/proc/self/task/%ld/schedstat", (long)tid);
    else
        snprintf(path, sizeof path, "/proc/thread-self/schedstat");
    f = fopen(path, "r");
    int ok = f && fscanf(f, "%llu %llu", &a, &b) == 2;
    if (f)
        fclose(f);
    *run_ns = a;
    *rq_ns = b;
    return ok;
}

static int sched_read(uint64_t *run_ns, uint64_t *rq_ns) { return sched_of(0, run_ns, rq_ns); }

static double cpu_s(void)
{
    struct timespec ts;
    return clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts) == 0 ? (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9 : 0.0;
}

void td_pagein_begin(td_pagein *p)
{
    struct rusage ru;
    p->majflt = getrusage(RUSAGE_THREAD, &ru) == 0 ? ru.ru_majflt : 0;
    p->sched = sched_read(&p->run_ns, &p->rq_ns);
    if (!p->sched)
        p->run_ns = (uint64_t)(cpu_s() * 1e9);
    p->wall = td_clock_s();
}

void td_pagein_end(const td_pagein *p, uint64_t *faults, double *blocked_ms)
{
    struct rusage ru;
    uint64_t run = 0, rq = 0;
    double wall = td_clock_s() - p->wall, busy;
    long now = getrusage(RUSAGE_THREAD, &ru) == 0 ? ru.ru_majflt : p->majflt;
    *faults = now > p->majflt ? (uint64_t)(now - p->majflt) : 0;
    if (p->sched && sched_read(&run, &rq))
        busy = ((double)(run - p->run_ns) + (double)(rq - p->rq_ns)) * 1e-9;
    else
        busy = cpu_s() - (double)p->run_ns * 1e-9;
    *blocked_ms = wall > busy ? (wall - busy) * 1e3 : 0.0;
}

/* --- the page-in deadline ---------------------------------------------------------- */

struct td_pagein_watch {
    double deadline_s;
    long stall_ms;
    pthread_t th;
    pthread_mutex_t mu;
    pthread_cond_t cv;
    td_pagein_guard *guards; /* under mu */
    int stop;                /* under mu */
};

/* Seconds g's thread has been blocked since its render began (0 when unreadable: a
 * render is never cut short on a guess). */
static double guard_blocked(const td_pagein_guard *g)
{
    uint64_t run, rq;
    double wall = td_clock_s() - g->start.wall, busy;
    if (!g->start.sched || !sched_of(g->tid, &run, &rq))
        return 0.0;
    busy = ((double)(run - g->start.run_ns) + (double)(rq - g->start.rq_ns)) * 1e-9;
    return wall > busy ? wall - busy : 0.0;
}

static void *watch_run(void *arg)
{
    td_pagein_watch *w = arg;
    pthread_mutex_lock(&w->mu);
    while (!w->stop) {
        struct timespec ts;
        for (td_pagein_guard *g = w->guards; g; g = g->next) {
            if (atomic_load(&g->cancel))
                continue;
            if (g->outer && atomic_load(g->outer)) {
                atomic_store(&g->cancel, 1);
            } else if (guard_blocked(g) > w->deadline_s) {
                atomic_store(&g->expired, 1);
                atomic_store(&g->cancel, 1);
            }
        }
        if (!w->guards) {
            pthread_cond_wait(&w->cv, &w->mu);
            continue;
        }
        clock_gettime(CLOCK_REALTIME, &ts);
        ts.tv_nsec += TD_PAGEIN_TICK_MS * 1000L * 1000L;
        ts.tv_sec += ts.tv_nsec / 1000000000L;
        ts.tv_nsec %= 1000000000L;
        pthread_cond_timedwait(&w->cv, &w->mu, &ts);
    }
    pthread_mutex_unlock(&w->mu);
    return NULL;
}

td_status td_pagein_watch_start(double seconds, long stall_ms, td_pagein_watch **out, td_err *err)
{
    td_status rc = TD_OK;
    td_pagein_watch *w = NULL;
    *out = NULL;
    if (!(seconds > 0))
        goto out;
    w = calloc(1, sizeof *w);
    if (!w) {
        rc = td_err_set(err, TD_ENOMEM, "out of memory for the page-in watchdog");
        goto out;
    }
    w->deadline_s = seconds;
    w->stall_ms = stall_ms > 0 ? stall_ms : 0;
    pthread_mutex_init(&w->mu, NULL);
    pthread_cond_init(&w->cv, NULL);
    if (pthread_create(&w->th, NULL, watch_run, w)) {
        pthread_mutex_destroy(&w->mu);
        pthread_cond_destroy(&w->cv);
        free(w);
        w = NULL;
        rc = td_err_set(err, TD_ENOMEM, "cannot start the page-in watchdog");
    }
    *out = w;
out:
    return rc;
}

void td_pagein_watch_stop(td_pagein_watch *w)
{
    if (!w)
        return;
    pthread_mutex_lock(&w->mu);
    w->stop = 1;
    pthread_cond_broadcast(&w->cv);
    pthread_mutex_unlock(&w->mu);
    pthread_join(w->th, NULL);
    pthread_mutex_destroy(&w->mu);
    pthread_cond_destroy(&w->cv);
    free(w);
}

void td_pagein_guard_begin(td_pagein_watch *w, td_pagein_guard *g, const atomic_int *outer)
{
    atomic_init(&g->cancel, 0);
    atomic_init(&g->expired, 0);
    g->outer = outer;
    g->tid = (pid_t)syscall(SYS_gettid);
    g->next = NULL;
    td_pagein_begin(&g->start);
    if (!w)
        return;
    pthread_mutex_lock(&w->mu);
    g->next = w->guards;
    w->guards = g;
    pthread_cond_broadcast(&w->cv);
    pthread_mutex_unlock(&w->mu);
    if (w->stall_ms) { /* the fault injection: blocked as a slow read would block it */
        struct timespec nap = {w->stall_ms / 1000, (w->stall_ms % 1000) * 1000000L};
        nanosleep(&nap, NULL);
    }
}

const atomic_int *td_pagein_flag(const td_pagein_watch *w, const td_pagein_guard *g)
{
    return w ? &g->cancel : g->outer;
}

int td_pagein_guard_end(td_pagein_watch *w, td_pagein_guard *g)
{
    if (w) {
        pthread_mutex_lock(&w->mu);
        for (td_pagein_guard **p = &w->guards; *p; p = &(*p)->next)
            if (*p == g) {
                *p = g->next;
                break;
            }
        pthread_mutex_unlock(&w->mu);
    }
    return td_pagein_expired(g);
}

int td_pagein_expired(const td_pagein_guard *g) { return atomic_load(&((td_pagein_guard *)g)->expired); }

double td_pagein_deadline(const td_pagein_watch *w) { return w ? w->deadline_s : 0.0; }
