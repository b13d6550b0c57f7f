/* test_bigalloc.c: large buffers (core/bigalloc.c): small ones plain, large ones
 * 2 MiB-aligned with their whole huge pages advised (the VMA's "hg" flag in
 * /proc/self/smaps, where the kernel has transparent huge pages), a partial last page
 * only when it is mostly the buffer's or its only one; every byte writable, freed by free(); the
 * zeroing variant zeroes reused memory and refuses an overflowing size; scratch on whole huge
 * pages in a one-shot process only. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <cmocka.h>

#include "bigalloc.h"

#define MB ((size_t)1 << 20)

/* Whether the kernel has transparent huge pages at all (else madvise refuses the advice). */
static int have_thp(void)
{
    return access("/sys/kernel/mm/transparent_hugepage/enabled", R_OK) == 0;
}

/* The VmFlags of the mapping that holds address a contains "hg" (MADV_HUGEPAGE):
 * 1 yes, 0 no, -1 no such mapping found. */
static int advised_huge(const void *a)
{
    FILE *f = fopen("/proc/self/smaps", "r");
    char line[512];
    int in = 0, r = -1;
    uintptr_t x = (uintptr_t)a;
    while (f && r < 0 && fgets(line, sizeof line, f)) {
        unsigned long lo, hi;
        if (sscanf(line, "%lx-%lx ", &lo, &hi) == 2 && strchr(line, '-') < strchr(line, ' '))
            in = x >= lo && x < hi;
        else if (in && !strncmp(line, "VmFlags:", 8))
            r = strstr(line, " hg") != NULL;
    }
    if (f)
        fclose(f);
    return r;
}

static void fill_and_check(unsigned char *p, size_t n)
{
    for (size_t k = 0; k < n; k += 4096)
        p[k] = (unsigned char)(k >> 12);
    p[n - 1] = 0x5a;
    for (size_t k = 0; k < n; k += 4096)
        assert_int_equal(p[k], (unsigned char)(k >> 12));
    assert_int_equal(p[n - 1], 0x5a);
}

static void test_small_is_plain(void **state)
{
    (void)state;
    unsigned char *p = td_bigalloc(1000), *q = td_bigalloc(0);
    assert_non_null(p);
    assert_non_null(q); /* a size of 0 still gives a pointer free() takes */
    fill_and_check(p, 1000);
    free(p);
    free(q);
}

/* td_bigalloc(n) is 2 MiB-aligned, writable, and advised huge to its last byte (the last
 * page rounded up) */
static void check_all_huge(size_t n)
{
    unsigned char *p = td_bigalloc(n);
    assert_non_null(p);
    assert_int_equal((uintptr_t)p % TD_BIGALLOC_PAGE, 0);
    fill_and_check(p, n);
    if (have_thp()) {
        assert_int_equal(advised_huge(p), 1);
        assert_int_equal(advised_huge(p + n - 1), 1);
    }
    free(p);
}

static void test_large_is_aligned_and_advised(void **state)
{
    (void)state;
    check_all_huge(11 * MB + MB / 2); /* trinidad's heights: rounded up to 12 MiB */
}

static void test_partial_tail_stays_small(void **state)
{
    (void)state;
    const size_t n = 2 * MB + MB / 8; /* rounding up would nearly double it */
    unsigned char *p = td_bigalloc(n);
    assert_non_null(p);
    assert_int_equal((uintptr_t)p % TD_BIGALLOC_PAGE, 0);
    fill_and_check(p, n);
    if (have_thp()) {
        assert_int_equal(advised_huge(p), 1);                    /* the whole first 2 MiB */
        assert_int_equal(advised_huge(p + 2 * MB + 4096), 0);    /* the tail: 4 KiB pages */
    }
    free(p);
}

static void test_one_page_is_huge(void **state)
{
    (void)state;
    check_all_huge(714 * 482 * 4); /* picos's heights, 1.3 MiB: its only huge page */
}

/* Scratch (td_bigalloc_scratch): malloc in a serving process; in a one-shot one, from
 * TD_BIGALLOC_SCRATCH_MIN on, whole huge pages (picos's visibility, 336 KiB, on one). */
static void test_scratch_follows_oneshot(void **state)
{
    (void)state;
    const size_t n = 714 * 482;
    unsigned char *p = td_bigalloc_scratch(n), *q;
    assert_non_null(p);
    fill_and_check(p, n);
    if (have_thp()) /* from a heap no earlier test advised (main's order) */
        assert_int_equal(advised_huge(p), 0);
    free(p);
    td_bigalloc_oneshot(1);
    p = td_bigalloc_scratch(n);
    q = td_bigalloc_scratch(TD_BIGALLOC_SCRATCH_MIN - 1);
    assert_non_null(p);
    assert_non_null(q);
    assert_int_equal((uintptr_t)p % TD_BIGALLOC_PAGE, 0);
    fill_and_check(p, TD_BIGALLOC_PAGE); /* the whole page is the buffer's */
    fill_and_check(q, TD_BIGALLOC_SCRATCH_MIN - 1);
    if (have_thp()) {
        assert_int_equal(advised_huge(p), 1);
        assert_int_equal(advised_huge(p + TD_BIGALLOC_PAGE - 1), 1);
    }
    free(p);
    free(q);
    td_bigalloc_oneshot(0);
}

static void test_calloc_zeroes_and_checks(void **state)
{
    (void)state;
    const size_t n = 3 * MB;
    unsigned char *p = td_bigalloc(n);
    assert_non_null(p);
    memset(p, 0xff, n);
    free(p);
    p = td_bigcalloc(n / 4, 4); /* may reuse the memory just freed */
    assert_non_null(p);
    for (size_t k = 0; k < n; k++)
        if (p[k])
            fail_msg("byte %zu is %d, not 0", k, p[k]);
    free(p);
    assert_null(td_bigcalloc(SIZE_MAX / 2, 4));
}

int main(void)
{
    /* test_one_page_is_huge first: glibc's threshold for mapping a buffer of its own
       rises to the largest one freed, after which buffers come from a heap whose ranges
       earlier tests advised (its "hg" would then not be this buffer's doing) */
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_one_page_is_huge),
        cmocka_unit_test(test_scratch_follows_oneshot),
        cmocka_unit_test(test_small_is_plain),
        cmocka_unit_test(test_large_is_aligned_and_advised),
        cmocka_unit_test(test_partial_tail_stays_small),
        cmocka_unit_test(test_calloc_zeroes_and_checks),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
