/* pagein.h: what a request waited for pages of mapped heights (issue 16): the major page
 * faults of the thread that ran it and the time it spent blocked, neither on a CPU nor
 * waiting for one (a ray that touches a page of a prepared dataset that is not in memory
 * waits there for the kernel to read it). The render worker (routes.c) measures around
 * each render, pick and map tile, and reports both in Server-Timing ("pagein") and
 * /metrics. A render runs on one worker thread (td_render_opts.threads = 1), so the
 * thread's counters are the request's. */
#ifndef TD_PAGEIN_H
#define TD_PAGEIN_H

#include <stdint.h>

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

#endif
