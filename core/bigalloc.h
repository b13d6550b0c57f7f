/* bigalloc.h: large buffers on transparent huge pages.
 *
 * The first touch of a fresh 4 KiB page costs a trap, and on the virtual machines terrad
 * runs on (shadow page tables: the guest's fault and then the host's) about 10 us:
 * trinidad's 11.5 MB of heights, written once by the loader, were 28 ms of a 29 ms load,
 * and a viewshed's counts or a render's sun bound pay the same on every request. Asking
 * for one populate call first (MADV_POPULATE_WRITE) saved little there (30.4 -> 29.5 ms
 * for 11.5 MB), since the host still maps each page on its first use. A 2 MiB huge page
 * is one fault for 512 pages and one TLB entry: the same 11.5 MB copied into a
 * 2 MiB-aligned buffer advised MADV_HUGEPAGE took 1.4-1.8 ms (12 runs, 2026-12-01, AMD
 * EPYC guest, 23 GB free); populated first it took 14 ms, so these buffers are not.
 *
 * The costs: with the kernel's default defrag ("madvise"), a fault in an advised range
 * compacts memory when no free 2 MiB block is left; and a huge page is resident whole
 * once touched, so a buffer's last, partial one is advised (the buffer rounded up to it)
 * only when that adds at most a quarter to the buffer (11.5 MB of heights take 12) or when
 * it is the buffer's only one (from TD_BIGALLOC_MIN to 2 MiB: at most 1 MiB more), else
 * it stays 4 KiB pages (a 2.1 MB sun bound kept by the server costs no more than its size).
 * Those 4 KiB pages are mapped in one call (MADV_POPULATE_WRITE), since every user writes
 * its buffer whole right after: picos's 1.4 MB of heights loaded 1.5 ms faster so, and
 * on one huge page (2026-12-02) 3.5-4.0 -> 0.55-0.77 ms again (td_dem_load in a loop, the
 * first call aside; `terrad viewshed`'s `cpu_ms.load` 4.4-4.9 -> 1.1-1.3 ms). Where
 * the kernel has no transparent huge pages (or is older than 5.14) the advice fails and
 * the buffer is an aligned malloc like any other.
 *
 * Used for the buffers of megabytes a grid or an image sizes: the heights (grid.c), a
 * viewshed's counts and visibility (viewshed.c, server/viewshed.c, server/cli_viewshed.c),
 * a render's sun bound (sunlit.c) and its result planes (render.c). */
#ifndef TD_BIGALLOC_H
#define TD_BIGALLOC_H

#include <stddef.h>

/* Buffers below this many bytes are plain malloc */
#define TD_BIGALLOC_MIN ((size_t)1 << 20)
/* The huge page size the buffers are aligned to and rounded up to */
#define TD_BIGALLOC_PAGE ((size_t)2 << 20)

/* n bytes, uninitialised, or NULL when out of memory; free() releases them. From
 * TD_BIGALLOC_MIN bytes on, 2 MiB-aligned, its whole huge pages advised MADV_HUGEPAGE (the
 * last, partial one as above) and the 4 KiB pages after them mapped: for a buffer the
 * caller writes whole next. */
void *td_bigalloc(size_t n);

/* td_bigalloc of n zero bytes (count * size, NULL on overflow) */
void *td_bigcalloc(size_t count, size_t size);

/* From this many bytes on, td_bigalloc_scratch rounds a buffer up to whole huge pages */
#define TD_BIGALLOC_SCRATCH_MIN ((size_t)64 << 10)

/* n bytes, uninitialised, or NULL, for scratch that lives for one request or one build
 * and is freed with free(). In a one-shot process (td_bigalloc_oneshot), from
 * TD_BIGALLOC_SCRATCH_MIN on, td_bigalloc of n rounded up to whole huge pages, every page
 * of it a huge one; else malloc. A huge page's first touch took 114-140 us here
 * (2026-12-02, the guest above: zeroing 2 MiB), eleven or so 4 KiB pages' (10.5-10.7 us
 * each), so from about 48 KiB touched it is the cheaper; the rest of the page is memory
 * only while the buffer lives. A viewshed's sweep lists and its visibility, a max-mipmap
 * build's cell maxima: picos (714 x 482) faulted in about 360 fresh 4 KiB pages for them,
 * 3.8 ms of a 17 ms `terrad viewshed`. A server's heap is warm after its first requests
 * (td_bigalloc_policy), and there a huge page a request faulted anew each time: 0.5-1.0 ms
 * more CPU a viewshed of picos and of the demo's trinidad. */
void *td_bigalloc_scratch(size_t n);

/* on: the process runs one command and exits (`terrad viewshed`), so its heap is cold and
 * td_bigalloc_scratch takes huge pages. Off by default; set before any thread allocates. */
void td_bigalloc_oneshot(int on);

/* The process's malloc policy, for the programs that serve or measure requests (terrad's
 * main, terrad-bench, maps-bench: what is measured is what is served). Every request
 * allocates and frees buffers of up to a few MB (a 512 x 512 render's 1 MiB of pixels,
 * the sun bound, the samples of each worker, a PNG's filtered rows), and glibc's defaults
 * give a freed buffer of more than 128 KiB (at first; the threshold then follows the
 * largest freed) back to the kernel, so the next request maps it again and pays the first
 * touch above: a 512 x 512 render of trinidad with shadows took 16.3-18.1 ms (mean of 15,
 * one thread), 13.4 ms with buffers under 4 MiB taken from the heap and 32 MiB of freed
 * memory kept for reuse (the resolve stage, which first writes the pixels, 0.9-2.4 ->
 * 0.8 ms). Larger buffers (a DEM's heights) still get their own mappings, returned when
 * freed. A library leaves the process's allocator alone: core itself never calls this. */
void td_bigalloc_policy(void);

#endif
