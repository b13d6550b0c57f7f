/* test_dynlib.c: the run-time loader of core/dynlib.c (GDAL's and libmicrohttpd's tables
 * are filled by it): every name resolved into its slot and callable; a missing function
 * or library refused with its name or dlerror's reason, never a partly filled table taken
 * for whole; a message buffer too short is cut, not overrun; td_dynlib_open loads once
 * and answers every call alike; and libmicrohttpd's table
 * (server/mhdapi.h), loaded as `terrad serve` loads it, holds every function http.c calls. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "dynlib.h"
#define TD_MHDAPI_IMPL /* the table's members by their names, not the calls */
#include "mhdapi.h"

typedef double (*fn_d)(double);

static void test_resolves(void **state)
{
    fn_d c = NULL, s = NULL;
    static const char *const names[] = {"cos", "sin"};
    void **const slots[] = {(void **)&c, (void **)&s};
    char msg[128] = "stale";
    (void)state;
    assert_int_equal(td_dynlib_load("libm.so.6", names, slots, 2, msg, sizeof msg), 1);
    assert_string_equal(msg, "");
    assert_non_null(c);
    assert_non_null(s);
    assert_true(c(0.0) == 1.0);
    assert_true(fabs(s(1.0) - sin(1.0)) == 0.0);
}

static void test_missing_function(void **state)
{
    fn_d c = NULL, x = NULL;
    static const char *const names[] = {"cos", "td_no_such_function"};
    void **const slots[] = {(void **)&c, (void **)&x};
    char msg[128] = "";
    (void)state;
    assert_int_equal(td_dynlib_load("libm.so.6", names, slots, 2, msg, sizeof msg), 0);
    assert_string_equal(msg, "libm.so.6 has no td_no_such_function");
    assert_null(x);
}

static void test_missing_library(void **state)
{
    fn_d c = NULL;
    static const char *const names[] = {"cos"};
    void **const slots[] = {(void **)&c};
    char msg[256] = "", tiny[8] = "";
    (void)state;
    assert_int_equal(td_dynlib_load("libtd_no_such_library.so.1", names, slots, 1, msg, sizeof msg), 0);
    assert_non_null(strstr(msg, "libtd_no_such_library.so.1")); /* dlerror names it */
    assert_null(c);
    assert_int_equal(td_dynlib_load("libtd_no_such_library.so.1", names, slots, 1, tiny, sizeof tiny), 0);
    assert_int_equal(strlen(tiny), sizeof tiny - 1);
}

static int loaded_calls;
static void count_loaded(void) { loaded_calls++; }

/* td_dynlib_open: loads once (the callback once), the same answer on every call, a
 * failure named by the library's name, its soname and the reason */
static void test_open_once(void **state)
{
    static fn_d c;
    static const char *const names[] = {"cos"};
    static void **const slots[] = {(void **)&c};
    static td_dynlib ok = {"libm.so.6", "libm", names, slots, 1, count_loaded, PTHREAD_MUTEX_INITIALIZER, 0, ""};
    static td_dynlib bad = {"libtd_no_such_library.so.1", "nothing", names, slots, 1, count_loaded,
                            PTHREAD_MUTEX_INITIALIZER, 0, ""};
    td_err err = {0};
    (void)state;
    loaded_calls = 0;
    for (int i = 0; i < 3; i++)
        assert_int_equal(td_dynlib_open(&ok, &err), TD_OK);
    assert_int_equal(loaded_calls, 1);
    assert_true(c(0.0) == 1.0);
    for (int i = 0; i < 2; i++) {
        assert_int_equal(td_dynlib_open(&bad, &err), TD_EUNSUPPORTED);
        assert_non_null(strstr(err.msg, "nothing could not be loaded (libtd_no_such_library.so.1): "));
    }
    assert_int_equal(loaded_calls, 1);
}

static void test_mhd_table(void **state)
{
    td_err err = {0};
    (void)state;
    assert_int_equal(td_mhd_open(&err), TD_OK);
    assert_int_equal(td_mhd_open(&err), TD_OK); /* once; the same answer after */
#define TD_MHD_CHECK(f) assert_non_null(td_mhd.f);
    TD_MHD_FNS(TD_MHD_CHECK)
#undef TD_MHD_CHECK
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_resolves),
        cmocka_unit_test(test_missing_function),
        cmocka_unit_test(test_missing_library),
        cmocka_unit_test(test_open_once),
        cmocka_unit_test(test_mhd_table),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
