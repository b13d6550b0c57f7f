/* prefault.h: mapping a large fresh buffer's pages in one call before it is filled.
 *
 * A buffer of megabytes written whole right after its allocation (a DEM's heights, a
 * viewshed's counts) takes one page fault a 4 KiB page, each a few microseconds on the
 * virtual machines terrad runs on: trinidad's 11.5 MB of heights were 2,800 faults, a
 * fifth of its load. madvise(MADV_POPULATE_WRITE) (Linux 5.14) maps them all in one
 * system call, without the trap per page. Measured on trinidad's load (CPU, median of 15,
 * shared machine): 9.9 -> 8.2 ms. Only advice: on an older kernel the call fails and the
 * pages fault in as before, so callers need not know whether it worked.
 *
 * Not huge pages: MADV_HUGEPAGE made the same load 5.6 ms at the median, but with the
 * kernel's default "madvise" defrag a fault there may compact memory first: 3 of 15 loads
 * took 24-27 ms, a worse mean than no advice at all.
 *
 * Called by the DEM loaders (demutil.c) and for the viewshed's counts (server/viewshed.c,
 * server/cli_viewshed.c). */
#ifndef TD_PREFAULT_H
#define TD_PREFAULT_H

#include <stddef.h>

/* Below this many bytes nothing is asked (a few faults cost less than the call). */
#define TD_PREFAULT_MIN ((size_t)1 << 20)

/* Maps the whole pages of p[0 .. n) writable now (p from malloc, its contents not needed:
 * fresh pages read as zero, pages already mapped are left as they are). Nothing when
 * n < TD_PREFAULT_MIN. */
void td_prefault(void *p, size_t n);

#endif
