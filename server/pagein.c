/* pagein.c: a thread's major faults and blocked time around a request (see pagein.h).
 * Called by the render worker in routes.c. Blocked time comes from the scheduler's own
 * accounting (/proc/thread-self/schedstat: nanoseconds on a CPU, nanoseconds runnable
 * but waiting for one), so a render slowed by other threads on a busy 2-core machine is
 * not counted as waiting for the disk. Rejected: delay accounting's blkio ticks
 * (/proc/.../stat field 42), off by default (kernel.task_delayacct = 0 here). */
#define _GNU_SOURCE
#include "pagein.h"

#include <stdio.h>
#include <sys/resource.h>
#include <time.h>

#include "clock.h"

static int sched_read(uint64_t *run_ns, uint64_t *rq_ns)
{
    unsigned long long a = 0, b = 0;
    FILE *f = fopen("/proc/thread-self/schedstat", "r");
    int ok = f && fscanf(f, "%llu %llu", &a, &b) == 2;
    if (f)
        fclose(f);
    *run_ns = a;
    *rq_ns = b;
    return ok;
}

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
