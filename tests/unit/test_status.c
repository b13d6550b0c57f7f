/* test_status.c: the error record (core/status.c): td_err_field names the field at fault
 * in err->field and at the front of the message, td_err_set leaves no stale field behind,
 * a NULL record is allowed, and an overlong field or text is cut, never overrun. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "status.h"

static void test_err_field(void **state)
{
    td_err err = {0};
    (void)state;
    assert_int_equal(td_err_field(&err, TD_ERANGE, "quality.samples", "%d is outside %d .. %d", 9, 1, 8),
                     TD_ERANGE);
    assert_string_equal(err.field, "quality.samples");
    assert_string_equal(err.msg, "quality.samples: 9 is outside 1 .. 8");
    /* a later error without a field clears it */
    assert_int_equal(td_err_set(&err, TD_ENOMEM, "render: no memory"), TD_ENOMEM);
    assert_string_equal(err.field, "");
    assert_string_equal(err.msg, "render: no memory");
    /* NULL records are allowed; the status comes back */
    assert_int_equal(td_err_field(NULL, TD_EINVAL, "image.format", "x"), TD_EINVAL);
    assert_int_equal(td_err_set(NULL, TD_EIO, "x"), TD_EIO);
}

static void test_err_truncates(void **state)
{
    td_err err;
    char longf[200], longt[1000];
    (void)state;
    memset(&err, 'x', sizeof err);
    memset(longf, 'f', sizeof longf - 1);
    longf[sizeof longf - 1] = '\0';
    memset(longt, 't', sizeof longt - 1);
    longt[sizeof longt - 1] = '\0';
    td_err_field(&err, TD_ERANGE, longf, "%s", longt);
    assert_int_equal(strlen(err.field), sizeof err.field - 1);
    assert_int_equal(strlen(err.msg), sizeof err.msg - 1);
    assert_memory_equal(err.msg, longf, sizeof longf - 1); /* the field first, then the text */
    assert_memory_equal(err.msg + sizeof longf - 1, ": t", 3);
    /* a field longer than the whole message still leaves a terminated message */
    char huge[600];
    memset(huge, 'h', sizeof huge - 1);
    huge[sizeof huge - 1] = '\0';
    td_err_field(&err, TD_ERANGE, huge, "text");
    assert_int_equal(strlen(err.msg), sizeof err.msg - 1);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_err_field),
        cmocka_unit_test(test_err_truncates),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
