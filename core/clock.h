/* clock.h: the one monotonic clock every stage timing, timeout and benchmark reads.
 *
 * Seconds since an arbitrary fixed point, as a double (nanosecond resolution for about
 * a hundred days of uptime). Wall-clock dates (log lines, HTTP Date headers) are not
 * this clock's business. */
#ifndef TD_CLOCK_H
#define TD_CLOCK_H

/* CLOCK_MONOTONIC in seconds. */
double td_clock_s(void);

#endif
