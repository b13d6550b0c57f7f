/* test_hash.c: FNV-1a (core/hash.c) against the published 64-bit test vectors, and
 * chaining (two calls hash the concatenation). */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "hash.h"

static void test_vectors(void **state)
{
    (void)state;
    assert_true(td_fnv1a(TD_FNV1A_INIT, "", 0) == 0xcbf29ce484222325ULL);
    assert_true(td_fnv1a(TD_FNV1A_INIT, "a", 1) == 0xaf63dc4c8601ec8cULL);
    assert_true(td_fnv1a(TD_FNV1A_INIT, "foobar", 6) == 0x85944171f73967e8ULL);
}

static void test_chaining(void **state)
{
    (void)state;
    assert_true(td_fnv1a(td_fnv1a(TD_FNV1A_INIT, "foo", 3), "bar", 3) ==
                td_fnv1a(TD_FNV1A_INIT, "foobar", 6));
    assert_true(td_fnv1a(TD_FNV1A_INIT, "foobar", 6) != td_fnv1a(TD_FNV1A_INIT, "foobaz", 6));
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_vectors),
        cmocka_unit_test(test_chaining),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
