/* bigalloc.c: see bigalloc.h. */
#include "bigalloc.h"

#include <stdatomic.h>
#include <stdlib.h>
#if defined(__GLIBC__)
#include <malloc.h>
#endif
#include <string.h>
#include <sys/mman.h>

#ifndef MADV_POPULATE_WRITE
#define MADV_POPULATE_WRITE 23 /* Linux 5.14; an older kernel refuses it (EINVAL): harmless */
#endif

#include "status.h"

void *td_bigalloc(size_t n)
{
    const size_t hp = TD_BIGALLOC_PAGE;
    void *p = NULL;
    if (n < TD_BIGALLOC_MIN || n > (size_t)-1 - hp) {
        p = malloc(n ? n : 1);
    } else {
        size_t up = (n + hp - 1) & ~(hp - 1), down = n & ~(hp - 1);
        size_t whole = (up - n) * 4 <= n || up == hp ? up : down; /* the last page: mostly ours, or the only one */
        size_t rest = whole < n ? ((n - whole) & ~(size_t)4095) : 0; /* whole 4 KiB pages after them */
        if (posix_memalign(&p, hp, whole > n ? whole : n) != 0) {
            p = NULL;
        } else { /* advice: where it fails, pages fault in one at a time as before */
            if (whole)
                (void)madvise(p, whole, MADV_HUGEPAGE);
            if (rest)
                (void)madvise((char *)p + whole, rest, MADV_POPULATE_WRITE);
        }
    }
    return p;
}

void *td_bigcalloc(size_t count, size_t size)
{
    size_t n = 0;
    void *p = td_mul_size(count, size, &n) ? td_bigalloc(n) : NULL;
    if (p)
        memset(p, 0, n);
    return p;
}

static atomic_int oneshot;

void td_bigalloc_oneshot(int on) { atomic_store_explicit(&oneshot, on != 0, memory_order_relaxed); }

void *td_bigalloc_scratch(size_t n)
{
    const size_t hp = TD_BIGALLOC_PAGE;
    int round = atomic_load_explicit(&oneshot, memory_order_relaxed) && n >= TD_BIGALLOC_SCRATCH_MIN &&
                n <= (size_t)-1 - 2 * hp;
    return round ? td_bigalloc((n + hp - 1) & ~(hp - 1)) : malloc(n ? n : 1);
}

void td_bigalloc_policy(void)
{
#if defined(__GLIBC__)
    (void)mallopt(M_MMAP_THRESHOLD, 4 << 20);
    (void)mallopt(M_TRIM_THRESHOLD, 32 << 20);
#endif
}
