/* pagein.h: what a request waited for pages of mapped heights (issue 16), and the bound on
 * that wait. The major page faults of the thread that ran it and the time it spent
 * blocked, neither on a CPU nor waiting for one (a ray that touches a page of a prepared dataset that is not in memory
 * waits there for the kernel to read it). The render worker (routes.c) measures around
 * each render, pick and map tile, and reports both in Server-Timing ("pagein") and
 * /metrics. A render runs on one worker thread (td_render_opts.threads = 1), so the
 * thread's counters are the request's. */
#ifndef TD_PAGEIN_H
#define TD_PAGEIN_H

#include <stdatomic.h>
#include <stdint.h>
#include <sys/types.h>

#include "status.h"

typedef struct td_pagein {
    long majflt;          /* getrusage(RUSAGE_THREAD) at the start */
    double wall;          /* monotonic seconds at the start */
    uint64_t run_ns, rq_ns; /* /proc/thread-self/schedstat: on a CPU, runnable */
    int sched;            /* schedstat was readable */
} td_pagein;

void td_pagein_begin(td_pagein *p);
/* Major faults since td_pagein_begin on this thread, and the milliseconds it was blocked
 * (wall - on a CPU - runnable; without schedstat: wall - CPU time, which then counts a
 * busy machine's queueing too). */
void td_pagein_end(const td_pagein *p, uint64_t *faults, double *blocked_ms);

/* The page-in deadline (terrad serve --pagein-timeout): a ray that enters a tile whose
 * pages are not resident waits for the kernel to read them (a major fault: the thread
 * sleeps), and a render may wait so at most the deadline in all. A watchdog thread looks
 * every TD_PAGEIN_TICK_MS at each guarded render's worker thread (its schedstat, as
 * td_pagein_end counts it) and, once that thread has been blocked longer than the deadline
 * since the render began, raises the render's cancel flag (td_render_opts.cancel, polled
 * per block of pixels): the render ends with TD_ECANCELED and td_pagein_expired says why,
 * which routes.c answers with 503 pagein_timeout and Retry-After. The guard also forwards
 * the request's own cancel flag (--render-timeout, http.c). The wait is bounded by the
 * deadline plus one tick, one block's work and the fault in progress (a fault cannot be
 * interrupted); the pages asked for stay on their way into the page cache, so a retry
 * finds more of them resident. */
#define TD_PAGEIN_TICK_MS 5

typedef struct td_pagein_watch td_pagein_watch;

typedef struct td_pagein_guard {
    atomic_int cancel;       /* what the render polls when watched */
    atomic_int expired;      /* raised for the page-in deadline */
    const atomic_int *outer; /* the request's cancel flag (may be NULL) */
    pid_t tid;               /* the worker thread */
    td_pagein start;         /* its counters when the render began */
    struct td_pagein_guard *next;
} td_pagein_guard;

/* Starts the watchdog for a deadline of `seconds` (> 0); *out NULL (no watchdog, no
 * bound) for 0. stall_ms > 0 is a fault injection for tests (the server's environment
 * TERRAD_FAULT_PAGEIN_STALL_MS): every guarded render first sleeps that long, as if its
 * first page took that long to read. */
td_status td_pagein_watch_start(double seconds, long stall_ms, td_pagein_watch **out, td_err *err);
void td_pagein_watch_stop(td_pagein_watch *w);
/* On the worker thread, before the render: registers g (w may be NULL: nothing watched). */
void td_pagein_guard_begin(td_pagein_watch *w, td_pagein_guard *g, const atomic_int *outer);
/* The flag the render polls: g's own when watched, else the request's. */
const atomic_int *td_pagein_flag(const td_pagein_watch *w, const td_pagein_guard *g);
/* After the render: unregisters g; non-zero when its deadline passed. */
int td_pagein_guard_end(td_pagein_watch *w, td_pagein_guard *g);
int td_pagein_expired(const td_pagein_guard *g);
double td_pagein_deadline(const td_pagein_watch *w);

#endif
