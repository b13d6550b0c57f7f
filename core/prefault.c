/* prefault.c: see prefault.h. */
#include "prefault.h"

#include <stdint.h>
#include <sys/mman.h>

#ifndef MADV_POPULATE_WRITE
#define MADV_POPULATE_WRITE 23 /* Linux 5.14; an older kernel refuses it (EINVAL): harmless */
#endif

void td_prefault(void *p, size_t n)
{
    const uintptr_t page = 4096;
    uintptr_t a = ((uintptr_t)p + page - 1) & ~(page - 1), b = ((uintptr_t)p + n) & ~(page - 1);
    if (p && n >= TD_PREFAULT_MIN && b > a)
        (void)madvise((void *)a, (size_t)(b - a), MADV_POPULATE_WRITE); /* advice: failure is harmless */
}
